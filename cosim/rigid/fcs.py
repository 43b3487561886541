"""JSBSim's flight-control systems (``<system>``, ``<autopilot>``,
``<flight_control>``) compiled to one stateless, vectorised plan.

``compile_systems(aircraft_xml, systems_dir)`` reads an aircraft's
systems (inline, or ``<system file="NAME"/>`` looked up as JSBSim looks it
up: the aircraft's folder, its ``Systems`` folder, then ``systems_dir``;
an ``<autopilot file=...>`` or ``<flight_control file=...>`` in the
aircraft's folder only), then its ``<autopilot>`` and its
``<flight_control>``, and returns a ``Systems``: every channel of every
system in JSBSim's order (FGFCS runs them as one list, systems first, then
the autopilot, then the flight control), each component computed as
JSBSim 1.3's class computes it, over arrays of N aircraft. A system's own
``<function name=...>`` sets its property before the channels
(``type="post"``: after them).

State lives in the caller's ``props`` dict (JSBSim's property names, float64
arrays of N); a component's own state (a PID's integrator, an actuator's
last output, a filter's past values, a channel's frame counter) lives under
a private key ``_fcs:<component property>:<what>``. ``init(props, n)``
adds what is missing (JSBSim's values at load: ``<property value=...>``
declarations, component outputs 0); ``run(props, dt_s)`` runs one physics
frame: as a few numba loops (``cosim.rigid.fcs_fused``, the same doubles)
where every component can be fused, else on the numpy steps here
(``Systems.fused`` is None; ``compile_systems(..., fuse=False)`` asks
for them). ``run_ic(props, dt_s)`` does what ``fdm.run_ic()`` does to the
systems: every channel whose ``execute`` property is on runs twice with
integration suspended (channel frame counters stand still); a channel at
``execrate`` R then runs on the R-th frame after it.

What FGFCS does besides the channels is done too: first each engine's
throttle, mixture, propeller advance and feather position set to its
command; and a component writing a surface position in radians
(``fcs/elevator-pos-rad``...) also sets it in degrees and its magnitude
(``fcs/mag-elevator-pos-rad``), and the other way round, as FGFCS's tied
properties do. The default nose-wheel steering angle
(``fcs/steer-pos-deg``) belongs to the ground reactions and is not
computed here. Trimming is not modelled.

Measured against JSBSim 1.3.3 where its behaviour is not what its older
sources say: a filter's first run (at ``run_ic``) sets its past to the
input it held (0 at load) and outputs that, an integrator's does not; an
integrator's trigger resets its output to 0 when negative and holds it
beyond 1e-6, while its past input keeps following the input.

Supported, exactly as JSBSim 1.3 computes them: ``<property value=...>``
declarations; channels with ``execute`` and ``execrate`` (a channel at
rate R runs every R-th frame its ``execute`` property is non-zero, its
components stepping R x dt); components ``fcs_function``, ``switch``
(``default``, ``test`` with ``logic`` AND/OR, nested tests, values and
properties), ``summer`` (``bias``), ``pure_gain``, ``scheduled_gain``,
``aerosurface_scale`` (``domain``, ``range``, ``zero_centered``, ``gain``),
``pid`` (``kp``/``ki``/``kd`` numbers or properties, ``type="standard"``,
the integrator types ``rect``/``trap``/``ab2``/``ab3``, ``trigger``,
``pvdot``), ``actuator`` (``lag``, ``rate_limit`` with ``sense``,
``deadband_width``, ``hysteresis_width``, ``bias``, the fail properties,
``saturated``), ``kinematic`` (``traverse``/``setting``, ``noscale``),
``lag_filter``, ``lead_lag_filter``, ``washout_filter``,
``second_order_filter``, ``integrator`` (Tustin coefficients, ``c1``..``c6``
numbers; the integrator ``c1/s`` with its ``trigger``), ``deadband``;
``<input>`` a property with a leading ``-`` or not, ``<output>``
(several), ``<clipto>`` (``type="cyclic"`` too). Anything else is a
``CompileError`` naming the file, the line and the element: among them
the sensors (``sensor``, ``accelerometer``, ``gyro``, ``magnetometer``),
``waypoint_*``, ``angle``, ``distributor``, a ``<delay>``, a component
without a name, a filter coefficient or actuator lag given as a
property, an unknown attribute (``login="AND"``, which JSBSim reads as
AND). With ``problems=[...]`` every problem is listed and the part
skipped instead. A PID's ``initial-integrator-value`` property is not
modelled.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from cosim.rigid.fcs_components import (
    STATELESS,
    Component,
    Context,
    Props,
    attrs,
    is_number,
    kids,
    model_function,
    text,
)
from cosim.rigid.fcs_dynamics import DYNAMIC
from cosim.rigid.fcs_fused import FusedSystems, fuse_systems
from cosim.rigid.functions import CompileError, parse

log = logging.getLogger(__name__)

#: every component the compiler knows, by element
COMPONENTS = {**STATELESS, **DYNAMIC}

#: the elements FGFCS loads (a file's root may be any of them)
_KINDS = ("system", "autopilot", "flight_control")


@dataclass(frozen=True)
class _Channel:
    name: str
    rate: int
    execute: str | None
    counter: str
    components: tuple[Component, ...]


@dataclass(frozen=True)
class Systems:
    """The compiled plan: stateless; ``props`` holds every value."""

    inputs: frozenset[str]
    outputs: frozenset[str]
    channels: tuple[_Channel, ...]
    defaults: dict[str, float] = field(repr=False)
    engines: int = 0
    #: the systems' own <function>s, before and after the channels
    pre: _Channel | None = None
    post: _Channel | None = None
    #: the same frame as numba loops (``cosim.rigid.fcs_fused``), or None:
    #: the numpy steps
    fused: FusedSystems | None = field(default=None, repr=False, compare=False)

    def init(self, props: Props, n: int) -> None:
        """Add JSBSim's values at load for ``n`` aircraft (keys already in
        ``props`` are kept)."""
        for k, v in self.defaults.items():
            if k not in props:
                props[k] = np.full(n, v, dtype=np.float64)

    def run_ic(self, props: Props, dt_s: float) -> None:
        """What JSBSim's ``run_ic()`` does to the systems: every channel
        whose ``execute`` property is on runs twice with integration
        suspended (measured against JSBSim 1.3.3: a PID integrates twice,
        a filter initialises, then steps once)."""
        self.run(props, dt_s, suspended=True)
        self.run(props, dt_s, suspended=True)

    def run(self, props: Props, dt_s: float, *, suspended: bool = False) -> None:
        """One physics frame (``suspended``: a frame of JSBSim's RunIC, the
        channel frame counters standing still). ``dt_s`` is the physics step
        in either case: JSBSim's components keep the step they were built
        with, so a RunIC frame at 0 would freeze rate limits, filters and
        kinematics and make a PID's derivative infinite."""
        if self.fused is not None:
            self.fused.run(props, dt_s, suspended)
            return
        gates: dict[str, _Gate] = {}
        if self.pre is not None:
            _run_channel(self.pre, props, dt_s, suspended, gates)
        for i in range(self.engines):
            sfx = f"[{i}]" if i else ""
            for cmd, pos in (("throttle-cmd-norm", "throttle-pos-norm"),
                             ("mixture-cmd-norm", "mixture-pos-norm"),
                             ("advance-cmd-norm", "advance-pos-norm")):
                props[f"fcs/{pos}{sfx}"] = props[f"fcs/{cmd}{sfx}"].copy()
            props[f"fcs/feather-pos-norm{sfx}"] = (
                props[f"fcs/feather-cmd-norm{sfx}"] != 0.0).astype(np.float64)
        # IEEE arithmetic without warnings, as JSBSim computes (a quotient
        # by zero is infinite, 0/0 NaN)
        with np.errstate(all="ignore"):
            for ch in self.channels:
                _run_channel(ch, props, dt_s, suspended, gates)
        if self.post is not None:
            _run_channel(self.post, props, dt_s, suspended, gates)


#: a channel's gate this frame: skip it, or run it on these rows (None: all)
_Gate = tuple[bool, "np.ndarray | None"]


def _run_channel(ch: _Channel, props: Props, dt_s: float, suspended: bool,
                 gates: dict[str, _Gate]) -> None:
    gate = gates.get(ch.counter)
    if gate is None:
        gate = gates[ch.counter] = _gate(ch, props, suspended)
    skip, mask = gate
    if skip:
        return
    dt = dt_s * ch.rate
    for comp in ch.components:
        new = comp.step(props, dt)
        if mask is None:
            props.update(new)
        else:
            for k, v in new.items():
                props[k] = np.where(mask, v, props[k])


def _gate(ch: _Channel, props: Props, suspended: bool) -> _Gate:
    """FGFCSChannel::Execute's test: whether the channel runs this frame,
    and for which rows; its frame counter advanced."""
    mask: np.ndarray | None = None
    on: np.ndarray | None = None
    if ch.execute is not None:
        on = props[ch.execute] != 0.0
        n_on = np.count_nonzero(on)
        if n_on == 0:
            return True, None
        if n_on == on.size:
            on = None
        mask = on
    if ch.rate > 1:
        count = props[ch.counter]
        if not suspended:
            if on is None:  # counts 1, 2 .. rate, 1 ..
                count = np.remainder(count, ch.rate) + 1.0
            else:  # only where the channel is on
                count = np.where(on & (count >= ch.rate), 0.0, count) + on
            props[ch.counter] = count
        due = count >= ch.rate
        if on is not None:
            due &= on
        n_due = np.count_nonzero(due)
        if n_due == 0:
            return True, None
        mask = None if n_due == due.size else due
    return False, mask


# --------------------------------------------------------------- systems

def _problem(ctx: Context, err: CompileError) -> None:
    """Raise ``err``, or with a problem list, record it and go on."""
    if ctx.problems is None:
        raise err
    ctx.problems.append(err)


def _guard(ctx: Context, fn: Callable[[], object]) -> object:
    """Run ``fn``; with a problem list, record its CompileError and go on."""
    try:
        return fn()
    except CompileError as e:
        _problem(ctx, e)
        return None


def _declare(c: ET.Element, ctx: Context, declared: dict[str, float]) -> None:
    attrs(c, ctx, {"value"})
    t = text(c)
    if not t or " " in t:
        raise ctx.fail(c, f"expected a property name, got {t!r}")
    v = c.get("value", "0")
    if not is_number(v):
        raise ctx.fail(c, f"value={v!r}: expected a number")
    declared.setdefault(t, float(v))  # JSBSim keeps the first definition


def _system(el: ET.Element, ctx: Context, declared: dict[str, float],
            channels: list[_Channel], functions: tuple[list[Component], list[Component]]
            ) -> None:
    xml_ns = {a for a in el.attrib if a.startswith(("xmlns", "xsi:"))}  # schema notes
    _guard(ctx, partial(attrs, el, ctx, {"name", "file"} | xml_ns))
    for c in kids(el):
        if c.tag == "property":
            _guard(ctx, partial(_declare, c, ctx, declared))
        elif c.tag == "channel":
            ch = _guard(ctx, partial(_channel, c, ctx, len(channels)))
            if isinstance(ch, _Channel):
                channels.append(ch)
        elif c.tag == "function":
            got = _guard(ctx, partial(model_function, c, ctx))
            if isinstance(got, tuple):
                functions[got[0]].append(got[1])
        else:
            _problem(ctx, ctx.fail(c, f"is not supported in <{el.tag}> (supported: property, "
                                      f"function, channel)"))


def _channel(el: ET.Element, ctx: Context, index: int) -> _Channel:
    attrs(el, ctx, {"name", "execute", "execrate"})
    rate_s = el.get("execrate", "1")
    try:
        rate = max(1, int(float(rate_s)))
    except ValueError:
        raise ctx.fail(el, f"execrate={rate_s!r}: expected a whole number") from None
    if float(rate_s) != int(float(rate_s)):
        raise ctx.fail(el, f"execrate={rate_s!r}: expected a whole number")
    comps: list[Component] = []
    for c in kids(el):
        make = COMPONENTS.get(c.tag)
        if make is None:
            _problem(ctx, ctx.fail(c, f"is not supported (supported components: "
                                      f"{', '.join(sorted(COMPONENTS))})"))
            continue
        comp = _guard(ctx, partial(make, c, ctx))
        if isinstance(comp, Component):
            comps.append(comp)
    return _Channel(el.get("name", f"channel {index}"), rate, el.get("execute") or None,
                    f"_fcs:channel{index}:frames", tuple(comps))


def _find_system(kind: str, name: str, aircraft_dir: Path, systems_dir: Path
                 ) -> Path | None:
    """A system's file: in the aircraft's folder, then (a <system> only)
    its Systems folder, then the systems folder; ``.xml`` added when the
    name has no suffix."""
    fname = name if Path(name).suffix else name + ".xml"
    folders = [aircraft_dir]
    if kind == "system":
        folders += [aircraft_dir / "Systems", systems_dir]
    for folder in folders:
        if (folder / fname).is_file():
            return folder / fname
    return None


def compile_systems(aircraft_xml: Path, systems_dir: Path, *,
                    problems: list[CompileError] | None = None,
                    fuse: bool = True) -> Systems:
    """An aircraft's systems, autopilot and flight control as one plan
    (``fuse``: run as numba loops where every component can be fused)."""
    aircraft_xml = Path(aircraft_xml)
    root = parse(aircraft_xml)
    ctx = Context(str(aircraft_xml), problems)
    declared: dict[str, float] = {}
    channels: list[_Channel] = []
    functions: tuple[list[Component], list[Component]] = ([], [])
    order = [e for kind in _KINDS for e in root if e.tag == kind]
    for el in order:
        f = el.get("file")
        if f:
            path = _find_system(el.tag, f, aircraft_xml.parent, Path(systems_dir))
            if path is None:
                where = (f"{aircraft_xml.parent}, {aircraft_xml.parent / 'Systems'} or "
                         f"{systems_dir}" if el.tag == "system" else str(aircraft_xml.parent))
                _problem(ctx, ctx.fail(el, f"file {f!r} not found in {where}"))
                continue
            sub = parse(path)
            if sub.tag not in _KINDS:
                _problem(ctx, CompileError(f"{path}:{sub.get('_line', '?')}: <{sub.tag}>: "
                                           f"expected one of <{'>, <'.join(_KINDS)}>"))
                continue
            _system(sub, Context(str(path), problems), declared, channels, functions)
        else:
            _system(el, ctx, declared, channels, functions)
    propulsion = root.find("propulsion")
    engines = len(propulsion.findall("engine")) if propulsion is not None else 0
    plan = _assemble(channels, declared, engines, functions)
    if fuse and plan.channels:
        try:
            plan = replace(plan, fused=fuse_systems(plan.pre, plan.channels, plan.post,
                                                     plan.engines))
        except CompileError as e:
            log.info("%s: the systems run on numpy's steps: %s", aircraft_xml, e)
    log.debug("%s: %d channels, %d components, %d inputs", aircraft_xml, len(plan.channels),
              sum(len(c.components) for c in plan.channels), len(plan.inputs))
    return plan


def _assemble(channels: list[_Channel], declared: dict[str, float], engines: int,
              functions: tuple[list[Component], list[Component]]) -> Systems:
    writes: dict[str, float] = {}
    reads: set[str] = set()
    for i in range(engines):
        sfx = f"[{i}]" if i else ""
        for cmd, pos in (("throttle-cmd-norm", "throttle-pos-norm"),
                         ("mixture-cmd-norm", "mixture-pos-norm"),
                         ("advance-cmd-norm", "advance-pos-norm"),
                         ("feather-cmd-norm", "feather-pos-norm")):
            reads.add(f"fcs/{cmd}{sfx}")
            writes[f"fcs/{pos}{sfx}"] = 0.0
    defaults: dict[str, float] = dict(declared)
    pre, post = (_Channel(f"{when} functions", 1, None, f"_fcs:{when}", tuple(fs))
                 if fs else None for when, fs in zip(("pre", "post"), functions))
    # channels with the same execute property (written by no component) and
    # the same rate count the same frames: one counter, one test a frame
    written = {w for ch in channels for comp in ch.components for w in comp.writes}
    channels = [ch if ch.execute in written else
                replace(ch, counter=f"_fcs:frames:{ch.execute or ''}:{ch.rate}")
                for ch in channels]
    for ch in channels + [c for c in (pre, post) if c is not None]:
        if ch.execute:
            reads.add(ch.execute)
        if ch.rate > 1:
            defaults[ch.counter] = float(ch.rate)
        for comp in ch.components:
            reads |= comp.reads
            for w in comp.writes:
                writes.setdefault(w, 0.0)
            for k, v in comp.state.items():
                defaults[k] = v
    for k, v in writes.items():
        defaults.setdefault(k, v)
    for r in reads:
        defaults.setdefault(r, 0.0)
    outputs = frozenset(k for k in writes if not k.startswith("_"))
    inputs = frozenset(reads - set(writes))
    return Systems(inputs, outputs, tuple(channels), defaults, engines, pre, post)
