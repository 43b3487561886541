"""An aircraft's ``<propulsion>`` compiled to one vectorised plan: the
turbine engines with their ``direct`` thrusters, and the fuel tanks, of
every aircraft of a worker stepped together, as JSBSim 1.3's
``FGPropulsion``, ``FGTurbine``, ``FGThruster``, ``FGForce`` and ``FGTank``
compute them.

``compile_propulsion(aircraft_xml, engine_dir)`` reads the aircraft file's
``<propulsion>`` and the engine and thruster files it names (found as
JSBSim finds them: ``<aircraft dir>/Engines``, ``engines``, ``Engine``,
``engine``, then ``engine_dir``) and returns a ``Propulsion``: a stateless
plan whose state lives in the caller's ``props`` (one float64 array per
property, one value per aircraft, JSBSim's names and units).

Each frame (``run(props, dt_s)``), in JSBSim's order, for each engine:

- the turbine's running phase (``FGTurbine::Run``): the ``IdleThrust`` and
  ``MilThrust`` functions of the engine file (``cosim.rigid.functions``),
  N2 then N1 moved towards their throttle targets by JSBSim's seek at the
  spool rates it derives from the bypass ratio, the N2 reached and the
  density ratio (``FGSpoolUp``), thrust idle + (mil - idle) x N2norm^2,
  the simplified TSFC corrected for temperature and N2, the fuel flow
  sought towards thrust x TSFC and never below the idle flow, bleed;
- the direct thruster: thrust x cos(reverser angle) along the thruster's
  orientation, and its moment about the CG (the acting location, inches
  in the structural frame, x aft and z up, taken from the CG
  ``inertia/cg-[xyz]-in`` into body axes and feet);
- the fuel it burns (``FGPropulsion::ConsumeFuel``), unless
  ``propulsion/fuel_freeze`` is set: drained equally from its feed tanks of
  the best priority holding usable fuel.

then the total fuel (``propulsion/total-fuel-lbs``).

The state: ``propulsion/engine[i]/n1``, ``n2``, ``fuel-used-lbs`` and
``fuel-flow-rate-pps``, two of JSBSim's members that have no property: the
fuel flow in pounds an hour (``FuelFlow_pph``:
``_propulsion/engine[i]/fuel-flow-pph``) and the N2 fraction of the last
frame the spool rates use (``N2norm``: ``_propulsion/engine[i]/n2norm``;
as in JSBSim, writing ``n2`` does not change it until the next frame), each tank's
``propulsion/tank[j]/contents-lbs``; and the settings JSBSim lets a user
write: ``propulsion/engine[i]/reverser-angle-rad`` and the acting location
``x-position``, ``y-position``, ``z-position`` (inches). ``init(props, n)``
starts every engine running as JSBSim's ``propulsion/set-running`` = -1
leaves it (N1 and N2 at their full-throttle values; the fuel flow at its
steady value when the flight inputs are already in ``props``, else the idle
flow) and every tank at its initial contents. Index 0 is written without
brackets, as JSBSim's property tree names it (``propulsion/engine/n1``).

The mass balance adds the tanks: ``Propulsion.tanks`` gives each tank's
location in inches (``location_in``) and the ``props`` key of its contents
in pounds (``contents_key``).

What it does not know it refuses (``CompileError``, ``FILE:LINE:
<element>``), never guesses: engines other than ``turbine_engine``
(``piston_engine``, ``turboprop_engine``, ``rocket_engine``,
``electric_engine``, ...), thrusters other than ``direct`` (``propeller``,
``nozzle``, ``rotor``), augmentation, water injection, the spool-rate and
TSFC functions, any other element or function, oxidizer tanks and tank
temperature, drain locations, radius and grain. Engines only run: the
phases off, spin-up, start, stall and seize are not compiled (cut-off and
starter commands are not read), and a ``run`` in which an engine's feed
tanks hold no usable fuel (JSBSim would starve it) raises ``PropulsionError``
naming the engine and the aircraft (``PropulsionError``). The thruster's orientation is fixed at
compile time; a tank's priority too.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.errors import CosimError
from cosim.rigid.functions import Compiled, CompileError, compile_function, parse

#: JSBSim's conversion factors (``FGJSBBase``, ``FGXMLElement``)
_M_TO_FT = 3.2808399
_TO: dict[str, dict[str, float]] = {
    "IN": {"IN": 1.0, "FT": 12.0, "M": _M_TO_FT * 12.0},
    "LBS": {"LBS": 1.0, "KG": 1.0 / 0.45359237},
    "RAD": {"RAD": 1.0, "DEG": 1.0 / (180.0 / math.pi)},
    "GAL": {"GAL": 1.0, "L": 0.26417287},
    "LBS/GAL": {"LBS/GAL": 1.0, "KG/L": 8.3454045},
}
_INCH_TO_FT = 1.0 / 12.0
#: ``FGTank::ProcessFuelName``'s densities (lbs/gal)
_FUEL_DENSITY = {
    "AVGAS": 6.02, "JET-A": 6.74, "JET-A1": 6.74, "JET-B": 6.48, "JP-1": 6.76, "JP-2": 6.38,
    "JP-3": 6.34, "JP-4": 6.48, "JP-5": 6.81, "JP-6": 6.55, "JP-7": 6.61, "JP-8": 6.66,
    "JP-8+100": 6.66, "RP-1": 6.73, "T-1": 6.88, "ETHANOL": 6.58, "HYDRAZINE": 8.61,
    "F-34": 6.66, "F-35": 6.74, "F-40": 6.48, "F-44": 6.81, "AVTAG": 6.48, "AVCAT": 6.81,
}
_OTHER_ENGINES = ("piston_engine", "turboprop_engine", "rocket_engine", "electric_engine",
                  "brushless_dc_motor")
#: turbine numbers read as they are; those that only the phases this plan
#: does not compile use (starting, windmilling) are accepted and unused
_TURBINE_NUMBERS = {"milthrust", "maxthrust", "bypassratio", "bleed", "tsfc", "atsfc",
                    "idlen1", "idlen2", "maxn1", "maxn2", "n1spinup", "n2spinup",
                    "n1startrate", "n2startrate", "n1spindown", "n2spindown", "ignitionn1",
                    "ignitionn2", "disable-windmill"}
#: must be 0: augmentation and water injection are not compiled
_TURBINE_OFF = ("augmented", "augmethod", "injected")
_TANK_ELEMENTS = {"location", "capacity", "contents", "unusable-volume", "priority",
                  "density", "type"}


def _where(el: ET.Element, source: str) -> str:
    return f"{source}:{el.get('_line', '?')}: <{el.tag}>"


def _kids(el: ET.Element) -> list[ET.Element]:
    return [c for c in el if c.tag != "description"]


def _number(el: ET.Element, source: str, target: str = "") -> float:
    try:
        x = float((el.text or "").strip())
    except ValueError:
        raise CompileError(f"{_where(el, source)}: expected a number, got "
                           f"{(el.text or '').strip()!r}") from None
    return x * _factor(el, source, target)


def _factor(el: ET.Element, source: str, target: str) -> float:
    unit = el.get("unit", "")
    if not unit or not target:
        return 1.0
    f = _TO.get(target, {}).get(unit)
    if f is None:
        known = ", ".join(sorted(_TO.get(target, {})))
        raise CompileError(f"{_where(el, source)}: unit {unit!r} is not supported here "
                           f"(supported: {known})")
    return f


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


def _indexed(base: str, i: int) -> str:
    """JSBSim's property name of index ``i`` as its tree lists it."""
    head, _, tail = base.partition("/#")
    return f"{head}{'' if i == 0 else f'[{i}]'}{tail}"


@dataclass(frozen=True)
class Tank:
    """One fuel tank: where it is and where its contents live in ``props``."""

    index: int
    location_in: tuple[float, float, float]
    capacity_lbs: float
    initial_lbs: float
    unusable_lbs: float
    priority: int

    @property
    def contents_key(self) -> str:
        return _indexed("propulsion/tank/#/contents-lbs", self.index)


@dataclass(frozen=True)
class Turbine:
    """One turbine engine and its direct thruster, compiled."""

    index: int
    name: str
    milthrust_lbs: float
    idle_n1: float
    idle_n2: float
    n1_factor: float
    n2_factor: float
    tsfc: float
    one_minus_bleed: float
    idle_ff_pph: float
    #: FGSpoolUp's delays: N2 up, N2 down, N1 up, N1 down
    delays: tuple[float, float, float, float]
    idle_thrust: Compiled
    mil_thrust: Compiled
    feeds: tuple[int, ...]
    location_in: tuple[float, float, float]
    #: the thruster's first column of FGForce's custom transform
    axis: tuple[float, float, float]

    def key(self, leaf: str) -> str:
        return _indexed(f"propulsion/engine/#/{leaf}", self.index)

    @property
    def throttle_key(self) -> str:
        return _indexed("fcs/throttle-pos-norm/#", self.index)


class PropulsionError(CosimError):
    """A compiled propulsion plan met a state it does not compile (an
    engine without fuel, which JSBSim would shut down)."""


_CG = ("inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in")
_FLIGHT = ("atmosphere/sigma", "atmosphere/T-R")
_FORCES = ("forces/fbx-prop-lbs", "forces/fby-prop-lbs", "forces/fbz-prop-lbs")
_MOMENTS = ("moments/l-prop-lbsft", "moments/m-prop-lbsft", "moments/n-prop-lbsft")
_FREEZE = "propulsion/fuel_freeze"
_TOTAL = "propulsion/total-fuel-lbs"
_POSITION = ("x-position", "y-position", "z-position")


def _seek(v: np.ndarray, target: np.ndarray, up: float, down: float, dt_s: float,
          den: np.ndarray | None = None) -> np.ndarray:
    """``FGTurbine::Seek``: ``v`` moved towards ``target`` by dt x ``up``
    or dt x ``down`` (each divided by ``den`` first when given), never past
    it. A rate's sign is exact in every product and quotient, so v - dt x
    (down / den) is v + dt x (-down / den) to the bit."""
    above = v > target
    if den is None:
        step = np.where(above, -dt_s * down, dt_s * up)
    else:
        step = dt_s * (np.where(above, -down, up) / den)
    moved = v + step
    return np.where(above, np.maximum(moved, target), np.minimum(moved, target))


def _times(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    return None if a is None or b is None else a * b


def _minus(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """a - b, a missing term a zero (0 - b is -b exactly)."""
    if b is None:
        return a
    return -b if a is None else a - b


@dataclass(frozen=True)
class Propulsion:
    """The compiled ``<propulsion>``: engines and tanks, a stateless plan."""

    source: str
    engines: tuple[Turbine, ...]
    tanks: tuple[Tank, ...]

    @property
    def inputs(self) -> frozenset[str]:
        names: set[str] = {*_CG, *_FLIGHT, _FREEZE}
        for e in self.engines:
            names |= e.idle_thrust.inputs | e.mil_thrust.inputs | {e.throttle_key}
        return frozenset(names)

    @property
    def outputs(self) -> frozenset[str]:
        names: set[str] = {*_FORCES, *_MOMENTS, _TOTAL}
        for e in self.engines:
            names |= {e.key(k) for k in ("thrust-lbs", "n1", "n2", "fuel-flow-rate-pps",
                                         "fuel-used-lbs", "tsfc", "IdleThrust", "MilThrust")}
            names |= {"_" + e.key("fuel-flow-pph"), "_" + e.key("n2norm")}
        return frozenset(names | {t.contents_key for t in self.tanks})

    def init(self, props: dict[str, np.ndarray], n: int) -> None:
        """Every engine running (``propulsion/set-running`` = -1), every
        tank at its initial contents, the settings at the file's values."""
        zeros = np.zeros(n)
        props.setdefault(_FREEZE, zeros.copy())
        for t in self.tanks:
            props[t.contents_key] = np.full(n, t.initial_lbs)
        props[_TOTAL] = self._total(props, n)
        for k in (*_FORCES, *_MOMENTS):
            props[k] = zeros.copy()
        for e in self.engines:
            props[e.key("n1")] = np.full(n, e.idle_n1 + 1.0 * e.n1_factor)
            props[e.key("n2")] = np.full(n, e.idle_n2 + 1.0 * e.n2_factor)
            props["_" + e.key("n2norm")] = (props[e.key("n2")] - e.idle_n2) / e.n2_factor
            for k in ("thrust-lbs", "fuel-flow-rate-pps", "fuel-used-lbs", "tsfc",
                      "IdleThrust", "MilThrust"):
                props[e.key(k)] = zeros.copy()
            props[e.key("reverser-angle-rad")] = zeros.copy()
            for k, x in zip(_POSITION, e.location_in):
                props[e.key(k)] = np.full(n, x)
            props["_" + e.key("fuel-flow-pph")] = self._steady_flow(e, props, n)

    def _steady_flow(self, e: Turbine, props: dict[str, np.ndarray], n: int) -> np.ndarray:
        """The fuel flow JSBSim's steady state at full throttle leaves: the
        target thrust x TSFC at N2norm 1, never below the idle flow."""
        needed = e.idle_thrust.inputs | e.mil_thrust.inputs | {"atmosphere/T-R"}
        if not needed <= set(props):
            return np.full(n, e.idle_ff_pph)
        n2norm = (e.idle_n2 + 1.0 * e.n2_factor - e.idle_n2) / e.n2_factor
        idle = e.milthrust_lbs * e.idle_thrust.evaluate(props)
        mil = (e.milthrust_lbs - idle) * e.mil_thrust.evaluate(props)
        thrust = idle + mil * n2norm * n2norm
        tsfc = e.tsfc * np.sqrt(props["atmosphere/T-R"] / 389.7) * (
            0.84 + (1 - n2norm) * (1 - n2norm))
        return np.maximum(thrust * tsfc, e.idle_ff_pph)

    def _total(self, props: dict[str, np.ndarray], n: int) -> np.ndarray:
        if not self.tanks:
            return np.zeros(n)
        total = 0.0 + props[self.tanks[0].contents_key]
        for t in self.tanks[1:]:
            total = total + props[t.contents_key]
        return total

    def run(self, props: dict[str, np.ndarray], dt_s: float) -> None:
        """One physics frame of every aircraft (``dt_s`` > 0)."""
        if not dt_s > 0:
            raise ValueError(f"dt_s must be positive, got {dt_s}")
        n = len(props[_CG[0]])
        cg = [props[k] for k in _CG]
        frozen = props[_FREEZE] != 0.0
        force: list[np.ndarray | None] = [None, None, None]
        moment: list[np.ndarray | None] = [None, None, None]
        for e in self.engines:
            fb, mb = self._engine(e, props, dt_s, cg, frozen)
            for acc, part in ((force, fb), (moment, mb)):
                for k in range(3):
                    a, b = acc[k], part[k]
                    acc[k] = b if a is None else a if b is None else a + b
        for keys, acc in ((_FORCES, force), (_MOMENTS, moment)):
            for k in range(3):
                got = acc[k]
                props[keys[k]] = np.zeros(n) if got is None else got
        props[_TOTAL] = self._total(props, n)

    def _engine(self, e: Turbine, props: dict[str, np.ndarray], dt_s: float,
                cg: list[np.ndarray], frozen: np.ndarray
                ) -> tuple[list[np.ndarray | None], list[np.ndarray | None]]:
        tp = props[e.throttle_key]
        if bool((tp > 1.0).any()):  # FGTurbine::Calculate: above 1 is augmentation
            over = tp - 1.0
            tp = np.where(over > 0.0, tp - over, tp)
        idle_fraction = e.idle_thrust.evaluate(props)
        mil_fraction = e.mil_thrust.evaluate(props)
        idle = e.milthrust_lbs * idle_fraction
        mil = (e.milthrust_lbs - idle) * mil_fraction
        n1, n2 = props[e.key("n1")], props[e.key("n2")]
        # FGSpoolUp with the N2norm of the previous frame, the same for N1 and N2
        norm_key = "_" + e.key("n2norm")
        m = 1.0 - np.minimum(1.0, props[norm_key] + 0.1)
        den = 1 + 3 * m * m * m + (1 - props["atmosphere/sigma"])
        d2u, d2d, d1u, d1d = e.delays
        n2 = _seek(n2, e.idle_n2 + tp * e.n2_factor, d2u, d2d, dt_s, den)
        n1 = _seek(n1, e.idle_n1 + tp * e.n1_factor, d1u, d1d, dt_s, den)
        n2norm = (n2 - e.idle_n2) / e.n2_factor
        props[norm_key] = n2norm
        thrust = idle + mil * n2norm * n2norm
        rest = 1 - n2norm
        tsfc = e.tsfc * np.sqrt(props["atmosphere/T-R"] / 389.7) * (0.84 + rest * rest)
        pph_key = "_" + e.key("fuel-flow-pph")
        pph = np.maximum(_seek(props[pph_key], thrust * tsfc, 1000.0, 10000.0, dt_s),
                         e.idle_ff_pph)
        if e.one_minus_bleed != 1.0:
            thrust = thrust * e.one_minus_bleed
        reverser = props[e.key("reverser-angle-rad")]
        if bool(reverser.any()):  # cos(0) x thrust is thrust
            thrust = np.cos(reverser) * thrust
        props[e.key("IdleThrust")] = idle_fraction
        props[e.key("MilThrust")] = mil_fraction
        props[e.key("n1")], props[e.key("n2")] = n1, n2
        props[e.key("tsfc")] = tsfc
        props[pph_key] = pph
        props[e.key("thrust-lbs")] = thrust
        self._burn(e, props, dt_s, pph, frozen)
        # FGForce: the body force and the moment about the CG, the arm from
        # the structural frame to body axes in feet. A zero of the transform
        # (known when compiled) gives no force (None), as JSBSim's zero
        # products add nothing, and no term of the moment
        fb = [None if a == 0.0 else thrust * a for a in e.axis]
        need = [any(fb[j] is not None for j in range(3) if j != k) for k in range(3)]
        x, y, z = (props[e.key(k)] for k in _POSITION)
        arms = [_INCH_TO_FT * (cg[0] - x) if need[0] else None,
                _INCH_TO_FT * (y - cg[1]) if need[1] else None,
                _INCH_TO_FT * (cg[2] - z) if need[2] else None]
        mb = [_minus(_times(arms[1], fb[2]), _times(arms[2], fb[1])),
              _minus(_times(arms[2], fb[0]), _times(arms[0], fb[2])),
              _minus(_times(arms[0], fb[1]), _times(arms[1], fb[0]))]
        return fb, mb

    def _burn(self, e: Turbine, props: dict[str, np.ndarray], dt_s: float,
              pph: np.ndarray, frozen: np.ndarray) -> None:
        """``FGPropulsion::ConsumeFuel`` for one engine (nothing while frozen)."""
        if bool(frozen.all()):
            return
        feeds = [self.tanks[i] for i in e.feeds]
        has = [props[t.contents_key] > t.unusable_lbs for t in feeds]
        best = np.full(len(pph), np.inf)
        for t, h in zip(feeds, has):
            if 1 <= t.priority <= len(self.tanks):
                best = np.where(h, np.minimum(best, t.priority), best)
        live = ~frozen
        starved = live & np.isinf(best)
        if bool(starved.any()):
            rows = np.flatnonzero(starved)
            raise PropulsionError(f"{self.source}: engine {e.index} ({e.name}) of aircraft "
                               f"{rows[:5].tolist()} has no usable fuel in its feed tanks "
                               f"{list(e.feeds)}: JSBSim would starve it, and the engine-off "
                               f"phase is not compiled")
        rate = pph / 3600.0
        burned = rate * dt_s
        ff_key, used_key = e.key("fuel-flow-rate-pps"), e.key("fuel-used-lbs")
        props[ff_key] = np.where(live, rate, props[ff_key])
        props[used_key] = np.where(live, props[used_key] + burned, props[used_key])
        feeding = [h & (best == t.priority) for t, h in zip(feeds, has)]
        if len(feeds) == 1:
            each = burned
        else:
            count = feeding[0].astype(np.float64)
            for f in feeding[1:]:
                count = count + f
            each = burned / count
        for t, f in zip(feeds, feeding):
            c = props[t.contents_key]
            left = c - each
            drained = np.where(left >= t.unusable_lbs, left, np.minimum(c, t.unusable_lbs))
            props[t.contents_key] = np.where(f & live, drained, c)


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
                unit = "LBS" if c.tag in ("milthrust", "maxthrust") and c.get("unit") else ""
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
        idle_thrust=functions["IdleThrust"], mil_thrust=functions["MilThrust"], feeds=feeds,
        location_in=location, axis=(cp * cy, cp * sy, -sp))


def _thruster(engine: ET.Element, aircraft_dir: Path, engine_dir: Path, source: str
              ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The thruster's location (inches) and orientation (radians): a
    ``direct`` thruster only."""
    th = engine.find("thruster")
    if th is None:
        raise CompileError(f"{_where(engine, source)}: needs a <thruster>")
    if th.get("file"):
        path = _find(th.get("file", ""), aircraft_dir, engine_dir, th, source)
        root = parse(path)
        if root.tag != "direct":
            raise CompileError(f"{_where(root, str(path))}: thruster not supported by the "
                               f"rigid-body compiler (supported: direct)")
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
                           f"compiler (supported: turbine_engine)")
    if body.tag != "turbine_engine":
        raise CompileError(f"{_where(body, str(path))}: not an engine (supported: "
                           f"turbine_engine)")
    return body, str(path)


def _engine(el: ET.Element, index: int, aircraft_dir: Path, engine_dir: Path, source: str,
            n_tanks: int, problems: list[CompileError] | None) -> Turbine | None:
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
    turbine = None
    if body is not None and thruster is not None:
        try:
            turbine = _turbine(body[0], index, body[1], thruster, tuple(feeds),
                               None if problems is None else found)
        except CompileError as err:
            note(err)
    if problems is not None:
        problems.extend(found)
    return None if found else turbine


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
    engines: list[Turbine] = []
    for i, el in enumerate(prop.findall("engine")):
        if found and problems is None:
            break
        turbine = _engine(el, i, aircraft_xml.parent, Path(engine_dir), source,
                          len(tank_els), found if problems is not None else None)
        if turbine is not None:
            engines.append(turbine)
    if problems is None:
        if found:
            raise found[0]
    else:
        problems.extend(found)
    return Propulsion(source, tuple(engines), tuple(tanks))
