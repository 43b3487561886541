"""A compiled ``Systems`` plan (``cosim.rigid.fcs``) fused into a few numba
loops over the aircraft: the same frame, on the same doubles, as the plan's
numpy steps, in a handful of calls instead of one or more numpy calls a
component.

``fuse_systems(pre, channels, post, engines)`` writes, from the elements
the components were compiled from (``Component.element``), the source of
one loop over the aircraft that runs the system functions, FGFCS's engine
commands and every channel in JSBSim's order: each property a local value,
loaded where first read and stored where computed; a channel's gate (its
``execute`` property and ``execrate`` counter, the same test as the numpy
plan's, computed once a frame for the channels that share a counter) an
``if`` around its components, so a channel that is not due costs a test.
The source goes through ``cosim.rigid.fused`` (its expression writer for
the functions, its on-disk cache).

The loop is cut where a function calls a transcendental function (tan,
the inverse functions, atan2, exp, ln, pow): numpy's vectorised functions
(SVML on AVX-512) and the math library a loop would call differ in the
last bit, so the loop ends, numpy computes that function on the column of
arguments (or on the property's own array, as the numpy plan does), and
the next loop goes on from there, inside the same gate (gates are kept in
a scratch row). Sine and cosine stay in the loop: numpy 2 computes float64
ones with the math library too (a test holds numba's to numpy's). The
uav700's systems: four loops and three numpy calls a frame. ``<min>``,
``<max>`` and a ``<clipto>`` are numpy's ``minimum`` and ``maximum`` (a NaN
wins).

State stays in ``props`` under the same keys as the numpy plan's, so the
two paths are interchangeable frame by frame. The loops write the arrays
of the keys the plan writes in place (the shared contract allows it: such
an array belongs to its key alone), so a snapshot is a copy of the arrays,
not of the dict; an array that cannot be written (read-only, not float64)
is replaced by a float64 copy first.

Fused: ``fcs_function``, ``switch``, ``summer``, ``pure_gain``,
``scheduled_gain``, ``aerosurface_scale``, ``deadband``, ``pid``,
``actuator`` and ``kinematic`` with every option the numpy plan supports,
``<clipto>`` (not ``type="cyclic"``), the surface positions FGFCS ties:
the uav700's and the c172p's systems. Not fused: the filters and the
``integrator``, a cyclic clip, a channel whose ``execute`` property a
component writes, a transcendental function of constants only; a plan
with any of them runs on its numpy steps, whole (``fuse_systems`` raises
``CompileError`` saying which and where, and ``compile_systems`` logs it
and keeps the numpy plan).
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from cosim.rigid.fcs_components import (
    _DEGTORAD,
    _RADTODEG,
    _SURFACES,
    Component,
    Context,
    is_number,
    one,
    text,
)
from cosim.rigid.fcs_dynamics import _EPS
from cosim.rigid.functions import CompileError, _children
from cosim.rigid.fused import _HEADER, _Gen, load

log = logging.getLogger(__name__)
Props = dict[str, np.ndarray]

_EXTRA = '''

@jit
def _mx(a, b):
    return a if (a >= b or a != a) else b


@jit
def _mn(a, b):
    return a if (a <= b or a != a) else b


@jit
def _ss(a, v, right):
    # numpy's searchsorted of v in the sorted a (NaN after every number)
    k = 0
    for e in a:
        if (e <= v if right else e < v) or v != v:
            k += 1
    return k

'''

#: what numpy computes between the loops, by element (sine and cosine are
#: not among them: numpy 2 computes float64 ones with libm, as a loop does)
_NUMPY: dict[str, Callable[..., Any]] = {
    "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan, "exp": np.exp,
    "ln": np.log, "atan2": np.arctan2, "pow": np.power}

#: an argument of a numpy call between loops: a scratch row, a property
#: as the plan holds it, or a row of the frame's new block
_Arg = tuple[str, Any]
#: numpy's call after a loop: the function, its arguments, the scratch row
#: of its result, the gate it is inside (not called when no row is due)
_After = tuple[Callable[..., Any], tuple[_Arg, ...], int, "int | None"]


class _Channel(Protocol):
    """What a loop needs of ``cosim.rigid.fcs``'s channel."""

    @property
    def name(self) -> str: ...
    @property
    def rate(self) -> int: ...
    @property
    def execute(self) -> str | None: ...
    @property
    def counter(self) -> str: ...
    @property
    def components(self) -> tuple[Component, ...]: ...


@dataclass
class _Segment:
    lines: list[str]
    arrays: list[str]            # props keys passed as arrays, in order
    after: _After | None = None


class _SysGen(_Gen):
    """The loops' source: a property's local loaded where first read in a
    loop, each new value stored in place where it is computed."""

    MINMAX = {"min": "_mn({}, {})", "max": "_mx({}, {})"}

    def __init__(self) -> None:
        super().__init__()
        self.written: dict[str, None] = {}  # keys stored, in order
        self.local: dict[str, str] = {}
        self.done: list[_Segment] = []
        self.used: set[str] = set()        # read or written by this loop
        self.loaded: set[str] = set()      # loaded where the code now is
        self.outer: set[str] = set()       # loaded before the open gate
        self.comp_loaded: set[str] = set()  # loaded by this component in this loop
        self.body: list[str] = []
        self.indent = 2
        self.gate: int | None = None       # the open gate
        self.gates: dict[str, int] = {}    # counter -> gate row
        self.dt_line = "dt = dt_s"
        self.flags: list[str] = []         # execute properties tested whole
        self.scratch = 0
        self.temps = 0

    # ---------------------------------------------------------- values
    def var(self, name: str) -> str:
        if name not in self.local:
            self.local[name] = f"x{len(self.local)}"
        v = self.local[name]
        self.used.add(name)
        if name not in self.loaded:
            self.line(f"{v} = a_{v}[i]")
            self.loaded.add(name)
        self.comp_loaded.add(name)
        return v

    def temp(self, expr: str) -> str:
        t = f"t{self.temps}"
        self.temps += 1
        self.line(f"{t} = {expr}")
        return t

    def store(self, key: str, expr: str) -> None:
        if key not in self.local:
            self.local[key] = f"x{len(self.local)}"
        v = self.local[key]
        self.used.add(key)
        self.loaded.add(key)
        self.line(f"{v} = {expr}")
        self.line(f"a_{v}[i] = {v}")
        self.written.setdefault(key)

    def line(self, s: str) -> None:
        self.body.append("    " * self.indent + s)

    def param(self, t: str) -> str:
        """JSBSim's parameter: a number or a property (maybe negated)."""
        if is_number(t):
            return repr(float(t))
        v = self.var(t.lstrip("-"))
        return f"(-{v})" if t.startswith("-") else v

    # ------------------------------------------------- numpy between loops
    def expr(self, el: ET.Element, source: str) -> str:
        if el.tag in _NUMPY:
            for c in _children(el):
                if not any(d.tag in ("property", "p", "table") for d in c.iter()):
                    raise CompileError(f"{source}:{el.get('_line', '?')}: <{el.tag}>: a "
                                       f"function of a constant is not fused")
            kid = _children(el)
            parts = [self.expr(c, source) for c in kid]
            args: list[_Arg] = []
            for c, p in zip(kid, parts):
                name = (c.text or "").strip()
                if c.tag in ("property", "p") and not name.startswith("-"):
                    # numpy reads the property's own array: so does the call here
                    args.append(("P", name))
                else:
                    s = self.scratch
                    self.scratch += 1
                    self.line(f"S[{s}, i] = {p}")
                    args.append(("S", s))
            r = self.scratch
            self.scratch += 1
            self.cut((_NUMPY[el.tag], tuple(args), r, self.gate))
            return f"S[{r}, i]"  # a row every later loop reads
        return super().expr(el, source)

    def cut(self, after: _After | None) -> None:
        """End this loop (then numpy's call ``after``) and open the next in
        the same gate, with what the component had loaded loaded again
        (an expression being written may read it)."""
        self.done.append(_Segment(self.body or ["        pass"], sorted(self.used), after))
        carry = sorted(self.comp_loaded)
        self.body, self.used, self.loaded, self.outer = [], set(), set(), set()
        self.indent = 2
        if self.gate is not None:
            self.line(f"if G[{self.gate}, i] != 0.0:")
            self.indent += 1
        self.line(self.dt_line)
        for k in carry:
            self.var(k)

    # ------------------------------------------------------------ gates
    def open_gate(self, ch: _Channel, written_anywhere: set[str]) -> None:
        if ch.execute is None and ch.rate == 1:
            return
        g = self.gates.get(ch.counter)
        if g is None:
            g = self.gates[ch.counter] = len(self.gates)
            if ch.execute is not None and ch.execute in written_anywhere:
                raise CompileError(f"channel {ch.name!r}: its execute property "
                                   f"{ch.execute!r} is written by a component: not fused")
            on = "True" if ch.execute is None else f"({self.var(ch.execute)} != 0.0)"
            self.line(f"on = {on}")
            if ch.rate > 1:
                c, r = self.var(ch.counter), float(ch.rate)
                if ch.execute is None:
                    whole = "True"
                else:
                    if ch.execute not in self.flags:
                        self.flags.append(ch.execute)
                    whole = f"whole[{self.flags.index(ch.execute)}]"
                self.line("if not suspended:")
                self.line(f"    if {whole}:")
                self.line(f"        {c} = ({c} % {r}) + 1.0")
                self.line("    else:")
                self.line(f"        {c} = (0.0 if (on and {c} >= {r}) else {c})"
                          f" + (1.0 if on else 0.0)")
                self.store(ch.counter, c)
                self.line(f"G[{g}, i] = 1.0 if ({c} >= {r} and on) else 0.0")
            else:
                self.line(f"G[{g}, i] = 1.0 if on else 0.0")
        self.line(f"if G[{g}, i] != 0.0:")
        self.indent += 1
        self.gate = g
        self.outer = set(self.loaded)

    def close_gate(self) -> None:
        if self.gate is not None:
            self.line("pass")
            self.indent -= 1
            self.gate = None
            self.loaded = self.outer  # what the gate loaded is not loaded after it


# --------------------------------------------------------------- components

def _tied_code(name: str, out: str) -> list[tuple[str, str]]:
    """What FGFCS sets with a surface position (``fcs_components._tied``)."""
    for surface, mag in _SURFACES.items():
        rad, deg = f"fcs/{surface}-pos-rad", f"fcs/{surface}-pos-deg"
        if name == rad:
            return [(deg, f"{out} * {_RADTODEG!r}")] + (
                [(f"fcs/mag-{surface}-pos-rad", f"abs({out})")] if mag else [])
        if name == deg:
            return [(rad, f"{out} * {_DEGTORAD!r}")] + (
                [(f"fcs/mag-{surface}-pos-rad", f"abs({out} * {_DEGTORAD!r})")] if mag
                else [])
    return []


def _input(g: _SysGen, el: ET.Element, k: int = 0) -> str:
    return g.param(text(el.findall("input")[k]))


def _clip(g: _SysGen, el: ET.Element, src: str) -> tuple[str, str] | None:
    c = one(el, "clipto", Context(src, None))
    if c is None:
        return None
    if c.get("type", "") == "cyclic":
        raise CompileError(f"{src}:{c.get('_line', '?')}: <clipto type='cyclic'>: not fused")
    lo, hi = c.find("min"), c.find("max")
    assert lo is not None and hi is not None
    return g.param(text(lo)), g.param(text(hi))


def _finish(g: _SysGen, comp: Component, out: str, state: dict[str, str],
            clip: tuple[str, str] | None) -> None:
    """Build.done's part: the clip, the outputs and the tied positions, then
    every new value stored (all computed from the old ones first)."""
    if clip is not None:
        out = g.temp(f"_mn(_mx({out}, {clip[0]}), {clip[1]})")
    el = comp.element
    assert el is not None
    outs = [comp.name] + [o for o in (text(e) for e in el.findall("output"))
                          if o != comp.name]
    outs = list(dict.fromkeys(outs))
    tied = [t for o in outs for t in _tied_code(o, out)]
    tied_vals = [(k, g.temp(e)) for k, e in tied]
    # every new value computed from the old ones before any is stored
    for k, v in [(k, g.temp(v)) for k, v in state.items()]:
        g.store(k, v)
    for o in outs:
        g.store(o, out)
    for k, v in tied_vals:
        g.store(k, v)


def _fcs_function(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    fel = el.find("function")
    assert fel is not None
    out = g.temp(g.expr(_children(fel)[0], src))
    _finish(g, comp, out, {}, _clip(g, el, src))


def _cond(g: _SysGen, el: ET.Element) -> str:
    """FGCondition: every line and nested test, AND or OR."""
    ops = {"EQ": "==", "NE": "!=", "GT": ">", "GE": ">=", "LT": "<", "LE": "<="}
    parts: list[str] = []

    def lines(t: str | None) -> None:
        for line in (t or "").splitlines():
            w = line.split()
            if w:
                op = ops.get(w[1].upper(), w[1])
                parts.append(f"({g.param(w[0])} {op} {g.param(w[2])})")
    lines(el.text)
    for c in el:
        if c.tag == el.tag:
            parts.append(_cond(g, c))
        lines(c.tail)
    join = " and " if el.get("logic", "AND") == "AND" else " or "
    return "(" + join.join(parts) + ")"


def _switch(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    d = one(el, "default", Context(src, None))
    # every condition and value read first (a property's load is a line)
    tests = [(g.temp(_cond(g, t)), g.param((t.get("value") or "").strip()))
             for t in el.findall("test")]
    default = g.param(d.get("value", "")) if d is not None else "0.0"
    out = f"t{g.temps}"
    g.temps += 1
    for k, (cond, val) in enumerate(tests):  # the first test that passes wins
        g.line(f"{'elif' if k else 'if'} {cond}:")
        g.line(f"    {out} = {val}")
    if tests:
        g.line("else:")
        g.line(f"    {out} = {default}")
    else:
        g.line(f"{out} = {default}")
    _finish(g, comp, out, {}, _clip(g, el, src))


def _summer(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    acc = _input(g, el)
    for k in range(1, len(el.findall("input"))):
        acc = f"({acc} + {_input(g, el, k)})"
    be = el.find("bias")
    bias = float(text(be)) if be is not None else 0.0
    if bias:
        acc = f"({acc} + {bias!r})"
    _finish(g, comp, g.temp(acc), {}, _clip(g, el, src))


def _gain(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    ge = el.find("gain")
    gain = g.param(text(ge)) if ge is not None else "1.0"
    x = g.temp(_input(g, el))
    if el.tag == "pure_gain":
        out = g.temp(f"{gain} * {x}")
    elif el.tag == "scheduled_gain":
        te = el.find("table")
        assert te is not None
        out = g.temp(f"({gain} * {g.table(te, src)}) * {x}")
    else:
        def pair(tag: str, lo: float, hi: float) -> tuple[float, float]:
            e = el.find(tag)
            if e is None:
                return lo, hi
            mn, mx = e.find("min"), e.find("max")
            assert mn is not None and mx is not None
            return float(text(mn)), float(text(mx))
        in_min, in_max = pair("domain", -1.0, 1.0)
        out_min, out_max = pair("range", 0.0, 0.0)
        zc = el.find("zero_centered")
        centered = not (zc is not None and text(zc) in ("0", "false"))
        if centered and not (in_min == 0.0 or in_max == 0.0):
            hi = (f"{x} * {out_max!r}" if in_max == 1.0
                  else f"({x} / {in_max!r}) * {out_max!r}")
            lo = (f"{x} * {-out_min!r}" if in_min == -1.0
                  else f"({x} / {in_min!r}) * {out_min!r}")
            out = g.temp(f"({hi}) if {x} > 0 else ({lo})")
        elif centered:
            out = g.temp(f"0.0 if {x} == 0.0 else (({x} / {in_max!r}) * {out_max!r} if "
                         f"{x} > 0 else ({x} / {in_min!r}) * {out_min!r})")
        else:
            out = g.temp(f"{out_min!r} + (({x} - {in_min!r}) / {in_max - in_min!r}) * "
                         f"{out_max - out_min!r}")
        if ge is not None:
            out = g.temp(f"{out} * {gain}")
    _finish(g, comp, out, {}, _clip(g, el, src))


def _deadband(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    we, ge = el.find("width"), el.find("gain")
    assert we is not None
    gain = float(text(ge)) if ge is not None else 1.0
    u = g.temp(_input(g, el))
    half = g.temp(f"0.5 * {g.param(text(we))}")
    out = g.temp(f"({u} + {half}) * {gain!r} if {u} < (-{half}) else "
                 f"(({u} - {half}) * {gain!r} if {u} > {half} else 0.0)")
    _finish(g, comp, out, {}, _clip(g, el, src))


def _pid(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    def gain(tag: str) -> str:
        e = el.find(tag)
        return g.param(text(e)) if e is not None else "0.0"
    ki_el = el.find("ki")
    integ = "none"
    if ki_el is not None:
        integ = ki_el.get("type", "ab2")
        if integ not in ("rect", "trap", "ab2", "ab3"):
            integ = "ab2"
    key = [k for k in comp.state]
    k_tot, k_prev, k_prev2 = (next(k for k in key if k.endswith(w))
                              for w in (":i_out_total", ":input_prev", ":input_prev2"))
    u = g.temp(_input(g, el))
    prev, prev2, total = g.var(k_prev), g.var(k_prev2), g.var(k_tot)
    pv = el.find("pvdot")
    dval = g.temp(g.param(text(pv)) if pv is not None else f"({u} - {prev}) / dt")
    delta = g.temp({"rect": u, "trap": f"0.5 * ({u} + {prev})",
                    "ab2": f"1.5 * {u} - 0.5 * {prev}",
                    "ab3": f"(23.0 * {u} - 16.0 * {prev} + 5.0 * {prev2}) / 12.0",
                    "none": "0.0"}[integ])
    tot = g.temp(total)
    new_prev2 = prev
    tr = el.find("trigger")
    if tr is not None:
        test = g.temp(g.param(text(tr)))
        g.line(f"if not abs({test}) < 0.000001:")
        g.line(f"    {delta} = 0.0")
        new_prev2 = g.temp(f"0.0 if {test} < 0.0 else {prev}")
        g.line(f"if {test} < 0.0:")
        g.line(f"    {tot} = 0.0")
    tot2 = g.temp(f"{tot} + {gain('ki')} * dt * {delta}")
    kp, kd = gain("kp"), gain("kd")
    if el.get("type", "") == "standard":
        out = g.temp(f"{kp} * ({u} + {tot2} + {kd} * {dval})")
    else:
        out = g.temp(f"{kp} * {u} + {tot2} + {kd} * {dval}")
    _finish(g, comp, out, {k_tot: tot2, k_prev: u, k_prev2: new_prev2}, _clip(g, el, src))


def _actuator(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    def num(tag: str) -> float:
        e = el.find(tag)
        return float(text(e)) if e is not None else 0.0
    lag, dbw, hyw, bias = num("lag"), num("deadband_width"), num("hysteresis_width"), num("bias")
    incr = decr = None
    for r in el.findall("rate_limit"):
        sense = r.get("sense", "")
        if sense.startswith("incr"):
            incr = text(r)
        elif sense.startswith("decr"):
            decr = text(r)
        else:
            incr = decr = text(r)
    name = comp.name
    k = {w: f"_fcs:{name}:{w}" for w in ("initialized", "previous_output", "lag_input",
                                          "lag_output", "rate_output", "hysteresis_output")}
    fz, fh, fs = (g.var(f"{name}/malfunction/fail_{w}") for w in ("zero", "hardover", "stuck"))
    clip = _clip(g, el, src)
    inited = g.temp(f"{g.var(k['initialized'])} != 0.0")
    u = g.temp(f"0.0 if {fz} != 0.0 else {_input(g, el)}")
    if clip is not None:
        u = g.temp(f"(({clip[0]}) if {u} < 0.0 else ({clip[1]})) if {fh} != 0.0 else {u}")
    else:
        u = g.temp(f"0.0 if {fh} != 0.0 else {u}")
    out = u
    new: dict[str, str] = {}
    if lag != 0.0:
        d = g.temp(f"2.0 + dt * {lag!r}")
        ca, cb = g.temp(f"dt * {lag!r} / {d}"), g.temp(f"(2.0 - dt * {lag!r}) / {d}")
        lagged = g.temp(f"{ca} * ({out} + {g.var(k['lag_input'])}) + "
                        f"{g.var(k['lag_output'])} * {cb} if {inited} else {out}")
        new[k["lag_input"]], new[k["lag_output"]] = out, lagged
        out = lagged
    if incr is not None or decr is not None:
        prev_r = g.var(k["rate_output"])
        delta = g.temp(f"{out} - {prev_r}")
        r_out = g.temp(out)
        if incr is not None:
            lim = g.temp(g.param(incr))
            g.line(f"if {delta} > dt * {lim}:")
            g.line(f"    {r_out} = {prev_r} + {lim} * dt")
        if decr is not None:
            lim = g.temp(f"-{g.param(decr)}")
            g.line(f"if {delta} < dt * {lim}:")
            g.line(f"    {r_out} = {prev_r} + {lim} * dt")
        out = g.temp(f"{r_out} if {inited} else {out}")
        new[k["rate_output"]] = out
    if dbw != 0.0:
        half = dbw / 2.0
        out = g.temp(f"{out} + {half!r} if {out} < {-half!r} else "
                     f"({out} - {half!r} if {out} > {half!r} else 0.0)")
    if hyw != 0.0:
        ph = g.var(k["hysteresis_output"])
        h = g.temp(f"_mx({ph}, {out} - 0.5 * {hyw!r}) if {out} > {ph} else "
                   f"(_mn({ph}, {out} + 0.5 * {hyw!r}) if {out} < {ph} else {out})")
        out = g.temp(f"{h} if {inited} else {out}")
        new[k["hysteresis_output"]] = out
    if bias != 0.0:
        out = g.temp(f"{out} + {bias!r}")
    stuck = g.temp(f"{fs} != 0.0")
    out = g.temp(f"{g.var(k['previous_output'])} if {stuck} else {out}")
    state = {key: g.temp(f"{g.var(key)} if {stuck} else {v}") for key, v in new.items()}
    state[k["previous_output"]] = out
    state[k["initialized"]] = "1.0"
    if clip is not None:
        out = g.temp(f"_mn(_mx({out}, {clip[0]}), {clip[1]})")
        state[f"{name}/saturated"] = g.temp(
            f"1.0 if (({out} >= {clip[1]}) and ({clip[1]} != 0)) or "
            f"(({out} <= {clip[0]}) and ({clip[0]} != 0)) else 0.0")
    _finish(g, comp, out, state, None)


def _kinematic(g: _SysGen, comp: Component, el: ET.Element, src: str) -> None:
    """FGKinemat: the input moved towards at each interval's own rate, the
    numpy step's loop over intervals per aircraft (a row's loop ends where
    the numpy step leaves that row unchanged)."""
    tv = el.find("traverse")
    assert tv is not None
    pos = [float(text(st.find("position"))) for st in tv.findall("setting")]  # type: ignore[arg-type]
    times = [float(text(st.find("time"))) for st in tv.findall("setting")]  # type: ignore[arg-type]
    det, tt = g.const(np.array(pos)), g.const(np.array(times))
    inner = g.const(np.array(pos[1:]))
    last, first = repr(pos[-1]), repr(pos[0])
    outs = [text(e) for e in el.findall("output")]
    current = g.var(next((o for o in outs if o != comp.name), comp.name))
    u = g.temp(_input(g, el))
    if el.find("noscale") is None:
        u = g.temp(f"{u} * {last}")
    u = g.temp(f"_mn(_mx({u}, {first}), {last})")
    out, left = g.temp(current), g.temp("dt")
    k = g.temps
    g.temps += 1
    ind, t, rate, into, need = (f"{w}{k}" for w in ("ind", "tt", "rate", "into", "need"))
    g.line(f"for _ in range({len(pos) + 1}):")
    g.line(f"    if not ({left} > 0.0 and not (abs({u} - {out}) <= {float(_EPS)!r} * "
           f"_mx(abs({u}), abs({out})))):")
    g.line("        break")
    g.line(f"    {ind} = min((_ss({inner}, {out}, False) if {u} < {out} else "
           f"_ss({inner}, {out}, True)) + 1, {len(pos) - 1})")
    g.line(f"    {t} = {tt}[{ind}]")
    g.line(f"    if {t} <= 0.0:")
    g.line(f"        {out} = {u}")
    g.line(f"        {left} = 0.0")
    g.line("    else:")
    g.line(f"        {rate} = ({det}[{ind}] - {det}[{ind} - 1]) / {t}")
    g.line(f"        {into} = _mn(_mx({u}, {det}[{ind} - 1]), {det}[{ind}])")
    g.line(f"        {need} = abs(({into} - {out}) / {rate})")
    g.line(f"        if {left} < {need}:")
    g.line(f"            {out} = {out} + {left} * {rate} if {out} < {u} else "
           f"{out} - {left} * {rate}")
    g.line(f"            {left} = {left} - {left}")
    g.line("        else:")
    g.line(f"            {out} = {into}")
    g.line(f"            {left} = {left} - {need}")
    _finish(g, comp, out, {}, _clip(g, el, src))


_EMIT = {"fcs_function": _fcs_function, "switch": _switch, "summer": _summer,
         "pure_gain": _gain, "scheduled_gain": _gain, "aerosurface_scale": _gain,
         "deadband": _deadband, "pid": _pid, "actuator": _actuator, "kinematic": _kinematic}


# --------------------------------------------------------------------- plan

@dataclass(frozen=True)
class FusedSystems:
    """The loops of a plan and what each takes; stateless."""

    segments: tuple[tuple[Any, tuple[str, ...], Any], ...]  # kernel, arrays, after
    written: tuple[str, ...]
    flags: tuple[str, ...]
    gates: int
    scratch: int
    tables: tuple[np.ndarray, ...]
    reads: tuple[str, ...]      # what the loops read and do not write

    def run(self, props: Props, dt_s: float, suspended: bool) -> None:
        """One frame, each key the plan writes written in place (an array
        that cannot be, read-only or not float64, replaced by a copy first;
        one it only reads and is not float64 read through a float64 copy,
        so numba compiles the loops for float64 arrays only)."""
        for k in self.written:
            a = props[k]
            if not (a.flags.writeable and a.dtype == np.float64):
                props[k] = np.array(a, dtype=np.float64)
        other = [k for k in self.reads if props[k].dtype != np.float64]
        if other:
            props = {**props, **{k: props[k].astype(np.float64) for k in other}}
        n = len(props[self.written[0]])
        gates = np.empty((max(self.gates, 1), n))
        scratch = np.empty((max(self.scratch, 1), n))
        whole = np.array([bool(props[f].all()) for f in self.flags] or [True])
        with np.errstate(all="ignore"):
            for kernel, arrays, after in self.segments:
                kernel(n, dt_s, suspended, whole, gates, scratch,
                       *[props[k] for k in arrays], *self.tables)
                if after is None:
                    continue
                fn, args, r, gate = after
                # a channel due on no row (3 frames in 4 at execrate 4) needs
                # no value: the numpy plan skips it whole
                if gate is None or gates[gate].any():
                    fn(*[scratch[a] if w == "S" else props[a] for w, a in args],
                       out=scratch[r])


def fuse_systems(pre: _Channel | None, chans: Sequence[_Channel], post: _Channel | None,
                 engines: int) -> FusedSystems:
    """A plan's frame (its system functions ``pre`` and ``post``, its
    channels, its ``engines``) as numba loops; CompileError for what is not
    fused."""
    channels = [c for c in (pre, *chans, post) if c is not None]
    written_anywhere = {w for ch in channels for comp in ch.components for w in comp.writes}
    g = _SysGen()
    order = [pre, None, *chans, post] if post is not None else [pre, None, *chans]
    for ch in order[0 if pre is not None else 1:]:
        if ch is None:  # FGFCS's engine commands, after the system functions
            for e in range(engines):
                sfx = f"[{e}]" if e else ""
                for cmd, pos in (("throttle-cmd-norm", "throttle-pos-norm"),
                                 ("mixture-cmd-norm", "mixture-pos-norm"),
                                 ("advance-cmd-norm", "advance-pos-norm")):
                    g.store(f"fcs/{pos}{sfx}", g.var(f"fcs/{cmd}{sfx}"))
                g.store(f"fcs/feather-pos-norm{sfx}",
                      f"1.0 if {g.var(f'fcs/feather-cmd-norm{sfx}')} != 0.0 else 0.0")
            continue
        g.open_gate(ch, written_anywhere)
        dt = "dt_s" if ch.rate == 1 else f"(dt_s * {float(ch.rate)!r})"
        g.dt_line = f"dt = {dt}"
        g.line(g.dt_line)
        for comp in ch.components:
            el = comp.element
            emit = _EMIT.get(el.tag) if el is not None else None
            if el is None or emit is None:
                where = f"{comp.source}:{el.get('_line', '?')}: <{el.tag}>" if el is not None \
                    else comp.name
                raise CompileError(f"{where}: not fused (fused: {', '.join(sorted(_EMIT))})")
            g.comp_loaded = set()
            emit(g, comp, el, comp.source)
        g.close_gate()
    g.cut(None)
    segs = g.done
    tables = [t for t, _ in g.tables]
    header = _HEADER + _EXTRA
    src_parts = [header]
    for s, seg in enumerate(segs):
        args = ", ".join(["n", "dt_s", "suspended", "whole", "G", "S",
                          *(f"a_{g.local[k]}" for k in seg.arrays), *tables])
        src_parts.append(f"\n@jit\ndef seg{s}({args}):\n    for i in range(n):\n"
                         + "\n".join(seg.lines) + "\n\n")
    module = load("".join(src_parts), "fcs")
    log.debug("the systems fused into %d loops", len(segs))
    return FusedSystems(tuple((getattr(module, f"seg{s}"), tuple(seg.arrays), seg.after)
                              for s, seg in enumerate(segs)),
                        tuple(g.written), tuple(g.flags), len(g.gates), g.scratch,
                        tuple(a for _, a in g.tables),
                        tuple(sorted({k for seg in segs for k in seg.arrays} - set(g.written))))

