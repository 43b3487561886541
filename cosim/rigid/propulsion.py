"""An aircraft's ``<propulsion>`` compiled to one vectorised plan: the
turbine engines with their ``direct`` thrusters, the piston engines with
their fixed-pitch propellers, and the fuel tanks, of every aircraft of a
worker stepped together, as JSBSim 1.3's ``FGPropulsion``, ``FGTurbine``,
``FGPiston``, ``FGPropeller``, ``FGThruster``, ``FGForce`` and ``FGTank``
compute them.

``compile_propulsion(aircraft_xml, engine_dir)`` reads the aircraft file's
``<propulsion>`` and the engine and thruster files it names (found as
JSBSim finds them: ``<aircraft dir>/Engines``, ``engines``, ``Engine``,
``engine``, then ``engine_dir``) and returns a ``Propulsion``: a stateless
plan whose state lives in the caller's ``props`` (one float64 array per
property, one value per aircraft, JSBSim's names and units).
This module compiles the tanks, the turbine and its direct thruster; the
piston engine and its propeller are compiled by ``cosim.rigid.piston``,
with the XML readers both share (``cosim.rigid.propulsion_xml``). The plan
they give is ``cosim.rigid.propulsion_plan``'s ``Propulsion`` (engines and
tanks together), its engines ``turbine_plan``'s and ``piston_plan``'s.

Each frame (``run(props, dt_s)``), in JSBSim's order, for each engine:

- the turbine (``FGTurbine::Calculate``): the ``IdleThrust`` and
  ``MilThrust`` functions of the engine file (``cosim.rigid.functions``),
  then its phase. Running (``Run``): N2 then N1 moved towards their
  throttle targets by JSBSim's seek at the spool rates it derives from the
  bypass ratio, the last N2 fraction and the density ratio
  (``FGSpoolUp``), thrust idle + (mil - idle) x N2norm^2, the simplified
  TSFC corrected for temperature and N2, the fuel flow sought towards
  thrust x TSFC and never below the idle flow, bleed. Cut off
  (``propulsion/cutoff_cmd``) or starved it is off (``Off``: no thrust, N1
  and N2 spooling down to their windmilling speeds from ``aero/qbar-psf``
  unless ``disable-windmill``); cut off with the starter
  (``propulsion/starter_cmd``) it spins up to the ignition speeds
  (``SpinUp``); not cut off above 15 % N2 with the starter or a dynamic
  pressure above 30 psf it starts (``Start``: to idle at the start rates,
  then running). The running engine clears the starter, as JSBSim's does.
  A frame without time (``dt_s`` 0, JSBSim's suspended integration) is
  its trim (``Trim``: the thrust of the throttle's N2 at once, nothing
  moves); the next frame with time runs a running engine from the
  throttle's N1 and N2 and leaves any other off and cut off;
- the direct thruster: thrust x cos(reverser angle) along the thruster's
  orientation, and its moment about the CG (the acting location, inches
  in the structural frame, x aft and z up, taken from the CG
  ``inertia/cg-[xyz]-in`` into body axes and feet);
- the piston engine (``FGPiston::Calculate``, unboosted), at the engine
  speed the propeller left: running while the magnetos are on, fuel flowed
  last frame and the speed is above 80 % of idle (started again above it
  when windmilling); the manifold pressure lagging (``man-press-lag``)
  towards the ram pressure (the pitot total pressure of the Mach number)
  times the engine's share of the engine, airbox and throttle impedances;
  the air flow of the swept volume at the volumetric efficiency the
  manifold-to-ambient pressure ratio reduces; the fuel flow of the
  mixture's equivalence ratio (none when starved); the indicated power of
  the fuel flow over the ISFC times the mixture efficiency table (the spark
  fail drop with a magneto off) less the static friction, or the starter's
  power while cranking (``propulsion/starter_cmd``), plus the pumping and
  friction mean effective pressures' power; below 0.125 hp it stops. The
  exhaust gas, cylinder head and oil temperatures and the oil pressure
  feed nothing else and are not computed;
- the fixed-pitch propeller (``FGPropeller::Calculate``): the air velocity
  at the propeller (the body's plus the rotation's at its location), the
  advance ratio, the helical tip Mach number, the power and thrust
  coefficients of their tables (times ``CP_MACH``/``CT_MACH`` when given),
  the power it absorbs and the thrust, the induced velocity of momentum
  theory, the P-factor's shift of the acting location (y by the angle of
  the local flow times w, z times v), the reaction torque, the speed
  moved by the excess torque over the propeller's inertia, and the moments:
  the torque, the gyroscopic moment of the inertial body rates and the
  thrust's at the acting location;
- the fuel it burns (``FGPropulsion::ConsumeFuel``), unless
  ``propulsion/fuel_freeze`` is set or the frame is part of a trim
  (``run(..., trimming=True)``, as JSBSim's trim status): drained equally
  from its feed tanks of the best priority holding usable fuel; none there,
  the engine starves.

then the total fuel (``propulsion/total-fuel-lbs``).

The state: ``propulsion/engine[i]/n1``, ``n2``, ``fuel-used-lbs`` and
``fuel-flow-rate-pps``; JSBSim's members that have no property, under
private keys ``_propulsion/engine[i]/...``: ``fuel-flow-pph`` (the fuel
flow in pounds an hour), ``n2norm`` (the N2 fraction of the last running
frame, which the spool rates use: as in JSBSim, writing ``n2`` does not
change it), ``phase`` (0 off, 1 running, 2 spinning up, 3 starting, 4 trimming),
``running`` and ``starved``; each tank's ``propulsion/tank[j]/contents-lbs``;
and what JSBSim lets a user write: ``propulsion/cutoff_cmd``,
``propulsion/starter_cmd``, ``propulsion/engine[i]/reverser-angle-rad`` and
the acting location ``x-position``, ``y-position``, ``z-position``
(inches). ``init(props, n)`` starts every engine running as JSBSim's
``propulsion/set-running`` = -1 leaves it (N1 and N2 at their full-throttle
values; the fuel flow at its steady value when the flight inputs are
already in ``props``, else the idle flow) and every tank at its initial
contents; ``set_running(props)`` is that command written after the initial
conditions' frame, as an untrimmed start writes it (JSBSim's engine then
runs from full speed, its steady state at full throttle, which the next
frames spool down to the throttle's). Index 0 is written without brackets, as JSBSim's property tree
names it (``propulsion/engine/n1``). Every phase but running is computed
only in a frame where some aircraft needs it.

The mass balance adds the tanks: ``Propulsion.tanks`` gives each tank's
location in inches (``location_in``) and the ``props`` key of its contents
in pounds (``contents_key``).

A piston's state: ``propulsion/engine[i]/map-pa`` (the manifold pressure),
``engine-rpm``, ``propeller-rpm``, ``fuel-flow-rate-pps``, ``power-hp``,
the propeller's ``advance-ratio``, ``thrust-coefficient``,
``helical-tip-Mach``, ``prop-induced-velocity_fps``,
``propeller-power-ftlbps``, ``propeller-torque-ftlb``, the acting location
``x-position``..., and privately ``running``, ``magnetos`` (3: both; no
command writes them) and ``starved``. ``init`` leaves it as
``FGPiston::InitRunning`` does (twice the idle speed, running, the mixture
command at 1); ``set_running`` then iterates ``GetSteadyState`` at full
throttle and a mixture of 1.3 x the pressure ratio at 0.5 s steps, as
JSBSim does, to the same doubles.

What it does not know it refuses (``CompileError``, ``FILE:LINE:
<element>``), never guesses: engines other than ``turbine_engine`` and
``piston_engine`` (``turboprop_engine``, ``rocket_engine``,
``electric_engine``, ...), thrusters other than ``direct`` and a
fixed-pitch ``propeller`` (``nozzle``, ``rotor``, ``pointing``; a
variable-pitch or constant-speed propeller, one turned off the body's x
axis), a piston's supercharger (``numboostspeeds`` and the boost
elements), its functions and units JSBSim converts but the compiler does
not know; a turbine driving a propeller or a piston a direct thruster;
augmentation, water injection, the
spool-rate and TSFC functions, any other element or function, oxidizer
tanks and tank temperature, drain locations, radius and grain (an
engine's own ``location`` and ``orient`` are ignored, as JSBSim ignores
them: the thruster's count). Not
compiled, so never entered: the turbine's stall and seize phases
(``stalled`` and ``seized`` are not read), refuelling, dumping and a tank's
external flow. On an aircraft with several engines the starter, and an
engine leaving a trim cut off, are a ``PropulsionError`` (JSBSim keeps a
starter and a cut-off per engine behind the one command each). The
thruster's orientation and a tank's priority are fixed at compile time.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from cosim.rigid.functions import Compiled, CompileError, _where, compile_function, parse
from cosim.rigid.piston import compile_piston, compile_propeller
from cosim.rigid.piston_plan import Piston, Propeller
from cosim.rigid.propulsion_base import PropulsionError, Tank
from cosim.rigid.propulsion_plan import Propulsion
from cosim.rigid.propulsion_xml import children, find_file, number_in, triplet
from cosim.rigid.turbine_plan import Turbine

__all__ = ["Piston", "Propeller", "Propulsion", "PropulsionError", "Tank", "Turbine",
           "compile_propulsion"]

#: ``FGTank::ProcessFuelName``'s densities (lbs/gal)
_FUEL_DENSITY = {
    "AVGAS": 6.02, "JET-A": 6.74, "JET-A1": 6.74, "JET-B": 6.48, "JP-1": 6.76, "JP-2": 6.38,
    "JP-3": 6.34, "JP-4": 6.48, "JP-5": 6.81, "JP-6": 6.55, "JP-7": 6.61, "JP-8": 6.66,
    "JP-8+100": 6.66, "RP-1": 6.73, "T-1": 6.88, "ETHANOL": 6.58, "HYDRAZINE": 8.61,
    "F-34": 6.66, "F-35": 6.74, "F-40": 6.48, "F-44": 6.81, "AVTAG": 6.48, "AVCAT": 6.81,
}
_OTHER_ENGINES = ("turboprop_engine", "rocket_engine", "electric_engine",
                  "brushless_dc_motor")
#: the turbine's numbers (disable-windmill: 0 or 1)
_TURBINE_NUMBERS = {"milthrust", "maxthrust", "bypassratio", "bleed", "tsfc", "atsfc",
                    "idlen1", "idlen2", "maxn1", "maxn2", "n1spinup", "n2spinup",
                    "n1startrate", "n2startrate", "n1spindown", "n2spindown", "ignitionn1",
                    "ignitionn2", "disable-windmill"}
#: must be 0: augmentation and water injection are not compiled
_TURBINE_OFF = ("augmented", "augmethod", "injected")
_TANK_ELEMENTS = {"location", "capacity", "contents", "unusable-volume", "priority",
                  "density", "type"}


def _tank(el: ET.Element, index: int, source: str) -> Tank:
    where = _where(el, source)
    if el.get("type") != "FUEL":
        raise CompileError(f"{where}: type {el.get('type')!r} is not supported "
                           f"(supported: FUEL)")
    extra = sorted(a for a in el.attrib if a not in ("_line", "type", "name"))
    if extra:
        raise CompileError(f"{where}: attribute {extra[0]!r} is not supported")
    for c in children(el):
        if c.tag not in _TANK_ELEMENTS:
            raise CompileError(f"{_where(c, source)}: not supported in a tank (supported: "
                               f"{', '.join(sorted(_TANK_ELEMENTS))})")
    loc = el.find("location")
    if loc is None:
        raise CompileError(f"{where}: needs a <location>")
    cap_el, con_el = el.find("capacity"), el.find("contents")
    capacity = 0.00001 if cap_el is None else number_in(cap_el, source, "LBS")
    contents = 0.0 if con_el is None else number_in(con_el, source, "LBS")
    if capacity == 0:
        capacity, contents = 0.00001, 0.0
    density = 6.6
    d_el, t_el = el.find("density"), el.find("type")
    if d_el is not None:
        density = number_in(d_el, source, "LBS/GAL")
    if t_el is not None:
        fuel = (t_el.text or "").strip()
        if fuel not in _FUEL_DENSITY:
            raise CompileError(f"{_where(t_el, source)}: unknown fuel {fuel!r} (known: "
                               f"{', '.join(sorted(_FUEL_DENSITY))})")
        density = _FUEL_DENSITY[fuel]
    u_el = el.find("unusable-volume")
    unusable = 0.0 if u_el is None else number_in(u_el, source, "GAL") * density
    p_el = el.find("priority")
    priority = 1 if p_el is None else int(number_in(p_el, source))
    if capacity <= unusable or contents > capacity:
        raise CompileError(f"{where}: contents {contents} lbs, capacity {capacity} lbs and "
                           f"unusable fuel {unusable} lbs are inconsistent")
    return Tank(index, triplet(loc, source, "IN", ("x", "y", "z")), capacity, contents,
                unusable, priority)


def _turbine(el: ET.Element, index: int, source: str,
             thruster: tuple[tuple[float, float, float], tuple[float, float, float]],
             feeds: tuple[int, ...], problems: list[CompileError] | None) -> Turbine:
    values: dict[str, float] = {}
    functions: dict[str, Compiled] = {}
    for c in children(el):
        try:
            if c.tag == "function":
                name = c.get("name", "")
                if name not in ("IdleThrust", "MilThrust"):
                    raise CompileError(f"{_where(c, source)}: function {name!r} is not "
                                       f"supported (supported: IdleThrust, MilThrust)")
                functions[name] = compile_function(c, source)
            elif c.tag in _TURBINE_OFF:
                if number_in(c, source) != 0:
                    raise CompileError(f"{_where(c, source)}: only 0 is supported "
                                       f"(augmentation and water injection are not compiled)")
            elif c.tag in _TURBINE_NUMBERS:
                unit = "LBS" if c.tag in ("milthrust", "maxthrust") else ""
                values[c.tag] = number_in(c, source, unit)
            else:
                raise CompileError(f"{_where(c, source)}: not supported in a turbine_engine "
                                   f"(supported: {', '.join(sorted(_TURBINE_NUMBERS))}, "
                                   f"{', '.join(_TURBINE_OFF)} = 0, functions IdleThrust "
                                   f"and MilThrust)")
        except CompileError as err:
            if problems is None:
                raise
            problems.append(err)
    missing = [k for k in ("IdleThrust", "MilThrust") if k not in functions]
    if missing:
        raise CompileError(f"{_where(el, source)}: needs the function {missing[0]}")
    mil = values.get("milthrust", 10000.0)
    bpr = values.get("bypassratio", 0.0)
    idle_n1, idle_n2 = values.get("idlen1", 30.0), values.get("idlen2", 60.0)
    location, (roll, pitch, yaw) = thruster
    cp, sp, cr, sr, cy, sy = (math.cos(pitch), math.sin(pitch), math.cos(roll),
                              math.sin(roll), math.cos(yaw), math.sin(yaw))
    del cr, sr  # the thrust is along the first axis: roll does not move it
    return Turbine(
        index=index, name=el.get("name", ""), milthrust_lbs=mil, idle_n1=idle_n1,
        idle_n2=idle_n2, n1_factor=values.get("maxn1", 100.0) - idle_n1,
        n2_factor=values.get("maxn2", 100.0) - idle_n2, tsfc=values.get("tsfc", 0.8),
        one_minus_bleed=1.0 - values.get("bleed", 0.0), idle_ff_pph=mil ** 0.2 * 107.0,
        delays=(1.0 * 90.0 / (bpr + 3.0), 3.0 * 90.0 / (bpr + 3.0), 1.0 * 90.0 / (bpr + 3.0),
                2.4 * 90.0 / (bpr + 3.0)),
        spindown=(values.get("n1spindown", 2.0), values.get("n2spindown", 2.0)),
        spinup=(values.get("n1spinup", 1.0), values.get("n2spinup", 3.0)),
        ignition=(values.get("ignitionn1", 5.21), values.get("ignitionn2", 25.18)),
        start_rate=(values.get("n1startrate", 1.4), values.get("n2startrate", 2.0)),
        windmill=values.get("disable-windmill", 0.0) == 0.0,
        idle_thrust=functions["IdleThrust"], mil_thrust=functions["MilThrust"], feeds=feeds,
        location_in=location, axis=(cp * cy, cp * sy, -sp))



def _thruster(engine: ET.Element, aircraft_dir: Path, engine_dir: Path, source: str
              ) -> tuple[tuple[float, float, float], tuple[float, float, float]] | Propeller:
    """A ``direct`` thruster's location (inches) and orientation (radians),
    or a fixed-pitch ``propeller``."""
    th = engine.find("thruster")
    if th is None:
        raise CompileError(f"{_where(engine, source)}: needs a <thruster>")
    if th.get("file"):
        path = find_file(th.get("file", ""), aircraft_dir, engine_dir, th, source)
        root = parse(path)
        if root.tag == "propeller":
            return compile_propeller(th, root, str(path), source)
        if root.tag != "direct":
            raise CompileError(f"{_where(root, str(path))}: thruster not supported by the "
                               f"rigid-body compiler (supported: direct, propeller)")
        extra = children(root)
        if extra:
            raise CompileError(f"{_where(extra[0], str(path))}: not supported in a direct "
                               f"thruster (it takes no elements)")
    else:
        raise CompileError(f"{_where(th, source)}: needs a file attribute")
    for c in children(th):
        if c.tag not in ("location", "orient"):
            raise CompileError(f"{_where(c, source)}: not supported in a direct thruster "
                               f"(supported: location, orient)")
    loc, orient = th.find("location"), th.find("orient")
    if loc is None:
        raise CompileError(f"{_where(th, source)}: needs a <location>")
    angles = (0.0, 0.0, 0.0) if orient is None else triplet(
        orient, source, "RAD", ("roll", "pitch", "yaw"))
    return triplet(loc, source, "IN", ("x", "y", "z")), angles


def _engine_body(el: ET.Element, aircraft_dir: Path, engine_dir: Path, source: str
                 ) -> tuple[ET.Element, str]:
    """The ``turbine_engine`` element an ``<engine>`` names, and its file."""
    if not el.get("file"):
        raise CompileError(f"{_where(el, source)}: needs a file attribute")
    path = find_file(el.get("file", ""), aircraft_dir, engine_dir, el, source)
    body = parse(path)
    if body.tag in _OTHER_ENGINES:
        raise CompileError(f"{_where(body, str(path))}: not supported by the rigid-body "
                           f"compiler (supported: turbine_engine, piston_engine)")
    if body.tag not in ("turbine_engine", "piston_engine"):
        raise CompileError(f"{_where(body, str(path))}: not an engine (supported: "
                           f"turbine_engine, piston_engine)")
    return body, str(path)


def _engine(el: ET.Element, index: int, aircraft_dir: Path, engine_dir: Path, source: str,
            n_tanks: int, problems: list[CompileError] | None) -> Turbine | Piston | None:
    """One ``<engine>`` compiled (None when ``problems`` got its refusals)."""
    found: list[CompileError] = []

    def note(err: CompileError) -> None:
        if problems is None:
            raise err
        found.append(err)

    feeds = []
    for c in children(el):
        if c.tag not in ("feed", "thruster", "location", "orient"):
            note(CompileError(f"{_where(c, source)}: not supported in an <engine> "
                              f"(supported: feed, thruster)"))
    for f in el.findall("feed"):
        try:
            tank = int(number_in(f, source))
            if not 0 <= tank < n_tanks:
                raise CompileError(f"{_where(f, source)}: tank {tank} does not exist "
                                   f"({n_tanks} tanks)")
            feeds.append(tank)
        except CompileError as err:
            note(err)
    body = thruster = None
    try:
        body = _engine_body(el, aircraft_dir, engine_dir, source)
    except CompileError as err:
        note(err)
    try:
        thruster = _thruster(el, aircraft_dir, engine_dir, source)
    except CompileError as err:
        note(err)
    engine: Turbine | Piston | None = None
    if body is not None and thruster is not None:
        try:
            pair = (body[0].tag, isinstance(thruster, Propeller))
            if pair == ("turbine_engine", False):
                assert not isinstance(thruster, Propeller)
                engine = _turbine(body[0], index, body[1], thruster, tuple(feeds),
                                  None if problems is None else found)
            elif pair == ("piston_engine", True):
                assert isinstance(thruster, Propeller)
                engine = compile_piston(body[0], index, body[1], thruster, tuple(feeds),
                                        None if problems is None else found)
            else:
                raise CompileError(f"{_where(el, source)}: a {body[0].tag} with a "
                                   f"{'propeller' if pair[1] else 'direct thruster'} is not "
                                   f"compiled (a turbine_engine drives a direct thruster, a "
                                   f"piston_engine a propeller)")
        except CompileError as err:
            note(err)
    if problems is not None:
        problems.extend(found)
    return None if found else engine


def compile_propulsion(aircraft_xml: Path, engine_dir: Path, *,
                       problems: list[CompileError] | None = None) -> Propulsion:
    """The ``<propulsion>`` of ``aircraft_xml`` compiled (``problems``: a
    list to collect every refusal in, skipping the part, instead of raising
    the first)."""
    aircraft_xml = Path(aircraft_xml)
    source = str(aircraft_xml)
    prop = parse(aircraft_xml).find("propulsion")
    if prop is None:
        return Propulsion(source, (), ())
    found: list[CompileError] = []
    for c in children(prop):
        if c.tag not in ("engine", "tank"):
            found.append(CompileError(f"{_where(c, source)}: not supported in <propulsion> "
                                      f"(supported: engine, tank)"))
    tanks: list[Tank] = []
    tank_els = prop.findall("tank")
    for i, el in enumerate(tank_els):
        try:
            tanks.append(_tank(el, i, source))
        except CompileError as err:
            found.append(err)
    engines: list[Turbine | Piston] = []
    for i, el in enumerate(prop.findall("engine")):
        if found and problems is None:
            break
        engine = _engine(el, i, aircraft_xml.parent, Path(engine_dir), source,
                         len(tank_els), found if problems is not None else None)
        if engine is not None:
            engines.append(engine)
    if problems is None:
        if found:
            raise found[0]
    else:
        problems.extend(found)
    return Propulsion(source, tuple(engines), tuple(tanks))
