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

from cosim.rigid.functions import (
    Compiled,
    CompileError,
    _numbers,
    _where,
    compile_function,
    parse,
)
from cosim.rigid.piston_plan import (
    FTTOM,
    IN3TOM3,
    INHGTOPA,
    MIXTURE_TABLE,
    STANDARD_PRESSURE,
    Piston,
    Propeller,
    Table,
)
from cosim.rigid.propulsion_plan import Propulsion, PropulsionError, Tank, Turbine
from cosim.rigid.units import factor, number

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


def _kids(el: ET.Element) -> list[ET.Element]:
    return [c for c in el if c.tag != "description"]


def _number(el: ET.Element, source: str, target: str = "") -> float:
    """An element's number, in ``target`` units (none: as written)."""
    return number(el, source) * _factor(el, source, target)


def _factor(el: ET.Element, source: str, target: str) -> float:
    return factor(el.get("unit", ""), target, el, source) if target else 1.0


def _triplet(el: ET.Element, source: str, target: str, names: tuple[str, str, str]
             ) -> tuple[float, float, float]:
    """``FindElementTripletConvertTo``: three children in the parent's unit."""
    extra = [c for c in _kids(el) if c.tag not in names]
    if extra:
        raise CompileError(f"{_where(extra[0], source)}: not supported in <{el.tag}> "
                           f"(expected {', '.join(names)})")
    f = _factor(el, source, target)
    out = []
    for name in names:
        item = el.find(name)
        out.append(0.0 if item is None else _number(item, source) * f)
    return out[0], out[1], out[2]



def _find(name: str, aircraft_dir: Path, engine_dir: Path, el: ET.Element,
          source: str) -> Path:
    """``FGPropulsion::FindFullPathName`` for an engine or thruster file."""
    file = name if name.endswith(".xml") else name + ".xml"
    dirs = [aircraft_dir / d for d in ("Engines", "engines", "Engine", "engine")]
    for d in [*dirs, engine_dir]:
        if (d / file).is_file():
            return d / file
    raise CompileError(f"{_where(el, source)}: file {file!r} not found in "
                       f"{', '.join(str(d) for d in dirs)} or {engine_dir}")


def _tank(el: ET.Element, index: int, source: str) -> Tank:
    where = _where(el, source)
    if el.get("type") != "FUEL":
        raise CompileError(f"{where}: type {el.get('type')!r} is not supported "
                           f"(supported: FUEL)")
    extra = sorted(a for a in el.attrib if a not in ("_line", "type", "name"))
    if extra:
        raise CompileError(f"{where}: attribute {extra[0]!r} is not supported")
    for c in _kids(el):
        if c.tag not in _TANK_ELEMENTS:
            raise CompileError(f"{_where(c, source)}: not supported in a tank (supported: "
                               f"{', '.join(sorted(_TANK_ELEMENTS))})")
    loc = el.find("location")
    if loc is None:
        raise CompileError(f"{where}: needs a <location>")
    cap_el, con_el = el.find("capacity"), el.find("contents")
    capacity = 0.00001 if cap_el is None else _number(cap_el, source, "LBS")
    contents = 0.0 if con_el is None else _number(con_el, source, "LBS")
    if capacity == 0:
        capacity, contents = 0.00001, 0.0
    density = 6.6
    d_el, t_el = el.find("density"), el.find("type")
    if d_el is not None:
        density = _number(d_el, source, "LBS/GAL")
    if t_el is not None:
        fuel = (t_el.text or "").strip()
        if fuel not in _FUEL_DENSITY:
            raise CompileError(f"{_where(t_el, source)}: unknown fuel {fuel!r} (known: "
                               f"{', '.join(sorted(_FUEL_DENSITY))})")
        density = _FUEL_DENSITY[fuel]
    u_el = el.find("unusable-volume")
    unusable = 0.0 if u_el is None else _number(u_el, source, "GAL") * density
    p_el = el.find("priority")
    priority = 1 if p_el is None else int(_number(p_el, source))
    if capacity <= unusable or contents > capacity:
        raise CompileError(f"{where}: contents {contents} lbs, capacity {capacity} lbs and "
                           f"unusable fuel {unusable} lbs are inconsistent")
    return Tank(index, _triplet(loc, source, "IN", ("x", "y", "z")), capacity, contents,
                unusable, priority)


def _turbine(el: ET.Element, index: int, source: str,
             thruster: tuple[tuple[float, float, float], tuple[float, float, float]],
             feeds: tuple[int, ...], problems: list[CompileError] | None) -> Turbine:
    values: dict[str, float] = {}
    functions: dict[str, Compiled] = {}
    for c in _kids(el):
        try:
            if c.tag == "function":
                name = c.get("name", "")
                if name not in ("IdleThrust", "MilThrust"):
                    raise CompileError(f"{_where(c, source)}: function {name!r} is not "
                                       f"supported (supported: IdleThrust, MilThrust)")
                functions[name] = compile_function(c, source)
            elif c.tag in _TURBINE_OFF:
                if _number(c, source) != 0:
                    raise CompileError(f"{_where(c, source)}: only 0 is supported "
                                       f"(augmentation and water injection are not compiled)")
            elif c.tag in _TURBINE_NUMBERS:
                unit = "LBS" if c.tag in ("milthrust", "maxthrust") else ""
                values[c.tag] = _number(c, source, unit)
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


#: the piston's numbers: (JSBSim's unit, default); a None default is
#: computed (JSBSim's constructor). Read but feeding only what is not
#: computed (the cylinder head, exhaust gas and oil temperatures): _PISTON_UNUSED
_PISTON_NUMBERS: dict[str, tuple[str, float | None]] = {
    "minmp": ("INHG", 6.5), "maxmp": ("INHG", 28.5), "man-press-lag": ("", 1.0),
    "displacement": ("IN3", 360.0), "maxhp": ("HP", 200.0), "static-friction": ("HP", 1.5),
    "sparkfaildrop": ("", None), "cycles": ("", 4.0), "idlerpm": ("", 600.0),
    "maxrpm": ("", 2800.0), "maxthrottle": ("", 1.0), "minthrottle": ("", 0.0),
    "bsfc": ("LBS/HP*HR", None), "volumetric-efficiency": ("", 0.85),
    "compression-ratio": ("", 8.5), "stroke": ("IN", 4.375),
    "air-intake-impedance-factor": ("", None), "ram-air-factor": ("", 1.0),
    "starter-rpm": ("", None), "starter-torque": ("", None), "dynamic-fmep": ("PA", 18400.0),
    "static-fmep": ("PA", 46500.0), "peak-piston-speed": ("", 100.0)}
_PISTON_UNUSED = {"bore", "cylinders", "cylinder-head-mass", "cooling-factor",
                  "oil-pressure-relief-valve-psi", "design-oil-temp-degK",
                  "oil-pressure-rpm-max", "oil-viscosity-index"}
_PROPELLER_NUMBERS = {"ixx": "SLUG*FT2", "diameter": "FT", "numblades": "", "gearratio": "",
                      "minpitch": "", "maxpitch": "", "ct_factor": "", "cp_factor": ""}
_PROPELLER_TABLES = ("C_THRUST", "C_POWER", "CT_MACH", "CP_MACH")


def _table1(el: ET.Element, source: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """An engine file's table of one dimension (``type="internal"``: no lookup)."""
    extra = [c for c in _kids(el) if c.tag != "tableData"]
    if extra or len(el.findall("tableData")) != 1:
        raise CompileError(f"{_where(extra[0] if extra else el, source)}: only a table of "
                           f"one dimension (one <tableData>) is supported here")
    data = el.find("tableData")
    assert data is not None
    rows = _numbers(data, source)
    if len(rows) < 2 or any(len(r) != 2 for r in rows):
        raise CompileError(f"{_where(data, source)}: a table of one dimension needs two or "
                           f"more rows of two numbers")
    if any(b[0] <= a[0] for a, b in zip(rows, rows[1:])):
        raise CompileError(f"{_where(data, source)}: breakpoints must increase")
    return tuple(r[0] for r in rows), tuple(r[1] for r in rows)


def _piston(el: ET.Element, index: int, source: str, propeller: Propeller,
            feeds: tuple[int, ...], problems: list[CompileError] | None) -> Piston:
    """``FGPiston``'s constructor: the numbers read, the defaults and the
    derived constants (impedances, ISFC) as JSBSim computes them."""
    values: dict[str, float] = {}
    mixture: Table = MIXTURE_TABLE
    for c in _kids(el):
        try:
            if c.tag in _PISTON_NUMBERS:
                values[c.tag] = _number(c, source, _PISTON_NUMBERS[c.tag][0])
            elif c.tag in _PISTON_UNUSED:
                _number(c, source)
            elif c.tag == "table" and c.get("name") == "MIXTURE":
                mixture = _table1(c, source)
            elif c.tag == "table" and c.get("name") == "COMBUSTION":
                _table1(c, source)  # the exhaust gas temperature's only
            else:
                raise CompileError(f"{_where(c, source)}: not supported in a piston_engine "
                                   f"(supported: {', '.join(sorted(_PISTON_NUMBERS))}, "
                                   f"{', '.join(sorted(_PISTON_UNUSED))}, tables MIXTURE and "
                                   f"COMBUSTION; no supercharger, no functions)")
        except CompileError as err:
            if problems is None:
                raise
            problems.append(err)

    def get(name: str) -> float:
        v = values.get(name, _PISTON_NUMBERS[name][1])
        assert v is not None
        return v

    min_mp, max_mp, max_rpm, idle_rpm = get("minmp"), get("maxmp"), get("maxrpm"), get("idlerpm")
    stroke, ve, cycles, peak = get("stroke"), get("volumetric-efficiency"), get("cycles"), \
        get("peak-piston-speed")
    displacement, max_hp, friction = get("displacement"), get("maxhp"), get("static-friction")
    fmep_dynamic, fmep_static = get("dynamic-fmep"), get("static-fmep")
    displacement_m3 = displacement * IN3TOM3
    rated_mps = (max_rpm * stroke) / 360
    isfc = values.get("bsfc", -1.0)
    if isfc < 0:
        pmep = (29.92 - max_mp) * INHGTOPA * ve
        fmep = fmep_dynamic * rated_mps * FTTOM + fmep_static
        hp_loss = ((pmep + fmep) * displacement_m3 * max_rpm) / (cycles * 22371)
        isfc = (1.1 * displacement * max_rpm * ve * (max_mp / 29.92)) / (
            9411 * (max_hp + hp_loss - friction))
    max_mp = min(max_mp, 29.9) if max_mp > 29.9 else max_mp
    min_map, max_map = min_mp * INHGTOPA, max_mp * INHGTOPA
    z_airbox = values.get("air-intake-impedance-factor", -999.0)
    if z_airbox < 0.0:
        ze = peak / rated_mps
        z_airbox = (STANDARD_PRESSURE * ze / max_map) - ze
    z_throttle = (peak / ((idle_rpm * stroke) / 360)) * (STANDARD_PRESSURE / min_map - 1) - z_airbox
    drop = values.get("sparkfaildrop")
    return Piston(
        index=index, name=el.get("name", ""), min_throttle=get("minthrottle"),
        max_throttle=get("maxthrottle"), idle_rpm=idle_rpm, max_rpm=max_rpm, stroke_in=stroke,
        cycles=cycles, displacement_m3=displacement_m3, isfc=isfc, volumetric_efficiency=ve,
        compression_ratio=get("compression-ratio"), peak_piston_speed_fps=peak,
        z_airbox=z_airbox, z_throttle=z_throttle, man_press_lag_s=get("man-press-lag"),
        ram_air_factor=get("ram-air-factor"), fmep_dynamic_pa=fmep_dynamic,
        fmep_static_pa=fmep_static, static_friction_hp=friction,
        spark_fail_drop=1.0 if drop is None else min(max(0.0, 1 - drop), 1.0),
        starter_rpm=values.get("starter-rpm", 2 * idle_rpm) if values.get(
            "starter-rpm", -1.0) >= 0.0 else 2 * idle_rpm,
        starter_torque=values.get("starter-torque", max_hp * 0.4) if values.get(
            "starter-torque", -1.0) >= 0 else max_hp * 0.4,
        mixture=mixture, feeds=feeds, propeller=propeller)


def _propeller(th: ET.Element, root: ET.Element, path: str, source: str) -> Propeller:
    """``FGPropeller``'s constructor for a fixed-pitch propeller along the
    body's x axis (``th``: the aircraft file's <thruster>; ``root``: the
    propeller file's <propeller>)."""
    values: dict[str, float] = {}
    tables: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
    extra = sorted(a for a in root.attrib if a not in ("_line", "name", "version"))
    if extra:
        raise CompileError(f"{_where(root, path)}: attribute {extra[0]!r} is not supported")
    for c in _kids(root):
        if c.tag in _PROPELLER_NUMBERS:
            values[c.tag] = _number(c, path, _PROPELLER_NUMBERS[c.tag])
        elif c.tag == "table" and c.get("name") in _PROPELLER_TABLES:
            tables[c.get("name", "")] = _table1(c, path)
        else:
            raise CompileError(f"{_where(c, path)}: not supported in a propeller (supported: "
                               f"{', '.join(sorted(_PROPELLER_NUMBERS))}, tables "
                               f"{', '.join(_PROPELLER_TABLES)} of one dimension: a fixed-pitch "
                               f"propeller)")
    if values.get("minpitch", 0.0) != values.get("maxpitch", 0.0):
        raise CompileError(f"{_where(root, path)}: a variable-pitch propeller (minpitch "
                           f"{values.get('minpitch', 0.0)} != maxpitch "
                           f"{values.get('maxpitch', 0.0)}) is not compiled (fixed pitch only)")
    missing = [t for t in ("C_THRUST", "C_POWER") if t not in tables]
    if missing:
        raise CompileError(f"{_where(root, path)}: needs the table {missing[0]}")
    for c in _kids(th):
        if c.tag not in ("location", "orient", "sense", "p_factor"):
            raise CompileError(f"{_where(c, source)}: not supported in a propeller thruster "
                               f"(supported: location, orient, sense, p_factor)")
    loc, orient = th.find("location"), th.find("orient")
    if loc is None:
        raise CompileError(f"{_where(th, source)}: needs a <location>")
    if orient is not None and any(_triplet(orient, source, "RAD", ("roll", "pitch", "yaw"))):
        raise CompileError(f"{_where(orient, source)}: a propeller turned off the body's x "
                           f"axis is not compiled (roll, pitch and yaw must be 0)")
    sense_el, pf_el = th.find("sense"), th.find("p_factor")
    sense = 1.0 if sense_el is None else (1.0 if _number(sense_el, source) >= 0.0 else -1.0)
    p_factor = 0.0 if pf_el is None else _number(pf_el, source)
    if p_factor < 0:
        assert pf_el is not None
        raise CompileError(f"{_where(pf_el, source)}: the P-factor must be 0 or more")
    version = root.get("version")
    try:
        newer = version is not None and float(version) > 1.0
    except ValueError:
        raise CompileError(f"{_where(root, path)}: version {version!r} is not a number") from None
    return Propeller(
        diameter_ft=max(values.get("diameter", 0.0), 0.001),
        ixx_slugft2=max(values.get("ixx", 0.0), 1e-06),
        gear_ratio=max(values.get("gearratio", 1.0), 0.001), ct=tables["C_THRUST"],
        cp=tables["C_POWER"], ct_mach=tables.get("CT_MACH"), cp_mach=tables.get("CP_MACH"),
        ct_factor=values.get("ct_factor", 1.0), cp_factor=values.get("cp_factor", 1.0),
        sense=sense, sense_multiplier=-1.0 if newer else 1.0, p_factor=p_factor,
        location_in=_triplet(loc, source, "IN", ("x", "y", "z")))


def _thruster(engine: ET.Element, aircraft_dir: Path, engine_dir: Path, source: str
              ) -> tuple[tuple[float, float, float], tuple[float, float, float]] | Propeller:
    """A ``direct`` thruster's location (inches) and orientation (radians),
    or a fixed-pitch ``propeller``."""
    th = engine.find("thruster")
    if th is None:
        raise CompileError(f"{_where(engine, source)}: needs a <thruster>")
    if th.get("file"):
        path = _find(th.get("file", ""), aircraft_dir, engine_dir, th, source)
        root = parse(path)
        if root.tag == "propeller":
            return _propeller(th, root, str(path), source)
        if root.tag != "direct":
            raise CompileError(f"{_where(root, str(path))}: thruster not supported by the "
                               f"rigid-body compiler (supported: direct, propeller)")
        extra = _kids(root)
        if extra:
            raise CompileError(f"{_where(extra[0], str(path))}: not supported in a direct "
                               f"thruster (it takes no elements)")
    else:
        raise CompileError(f"{_where(th, source)}: needs a file attribute")
    for c in _kids(th):
        if c.tag not in ("location", "orient"):
            raise CompileError(f"{_where(c, source)}: not supported in a direct thruster "
                               f"(supported: location, orient)")
    loc, orient = th.find("location"), th.find("orient")
    if loc is None:
        raise CompileError(f"{_where(th, source)}: needs a <location>")
    angles = (0.0, 0.0, 0.0) if orient is None else _triplet(
        orient, source, "RAD", ("roll", "pitch", "yaw"))
    return _triplet(loc, source, "IN", ("x", "y", "z")), angles


def _engine_body(el: ET.Element, aircraft_dir: Path, engine_dir: Path, source: str
                 ) -> tuple[ET.Element, str]:
    """The ``turbine_engine`` element an ``<engine>`` names, and its file."""
    if not el.get("file"):
        raise CompileError(f"{_where(el, source)}: needs a file attribute")
    path = _find(el.get("file", ""), aircraft_dir, engine_dir, el, source)
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
    for c in _kids(el):
        if c.tag not in ("feed", "thruster", "location", "orient"):
            note(CompileError(f"{_where(c, source)}: not supported in an <engine> "
                              f"(supported: feed, thruster)"))
    for f in el.findall("feed"):
        try:
            tank = int(_number(f, source))
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
                engine = _piston(body[0], index, body[1], thruster, tuple(feeds),
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
    for c in _kids(prop):
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
