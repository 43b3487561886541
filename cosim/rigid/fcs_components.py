"""The components of JSBSim's flight-control channels compiled to
vectorised numpy steps: the part of ``cosim.rigid.fcs`` that knows each
component class (FGFCSComponent, FGSwitch and FGCondition, FGSummer,
FGGain, FGPID, FGActuator, FGFilter, FGDeadBand, FGKinemat, FGFCSFunction)
and computes it as JSBSim 1.3 does, over arrays of N aircraft.

A component compiles to a ``Component``: the properties it reads, those it
writes (its own property ``fcs/<normalized name>`` or its name, its
``<output>``s, its private state ``_fcs:<property>:<what>``) and a ``step``
that returns the new arrays. The channel that runs it (``cosim.rigid.fcs``)
writes them into ``props``, or only into the rows whose channel ran.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.rigid.functions import CompileError, compile_function

Props = dict[str, np.ndarray]
#: a value read each frame: a number, or a property (maybe negated)
Source = Callable[[Props], "np.ndarray | float"]
#: one component's frame: (props, its dt_s) -> {key: new array}
Step = Callable[[Props, float], dict[str, np.ndarray]]
#: a component's own computation: its Output (under its name) and state
Compute = Callable[[Props, float], dict[str, Any]]

_EPS = 2.0 * np.finfo(np.float64).eps
_DESCRIBE = {"description", "documentation"}
_COMMON = {"input", "output", "clipto"}


_RADTODEG = 57.295779513082320876798154814105
_DEGTORAD = 0.017453292519943295769236907684886
#: FGFCS's surface positions and whether it also ties a magnitude
_SURFACES = {"elevator": True, "left-aileron": True, "right-aileron": True, "rudder": True,
             "speedbrake": True, "spoiler": True, "flap": False}


def _tied(name: str) -> list[tuple[str, Callable[[np.ndarray], np.ndarray]]]:
    """What FGFCS sets with a surface position: writing ``fcs/X-pos-rad``
    sets ``fcs/X-pos-deg`` (and ``fcs/mag-X-pos-rad``), and the other way
    round; ``-norm`` stands alone."""
    for surface, mag in _SURFACES.items():
        rad, deg = f"fcs/{surface}-pos-rad", f"fcs/{surface}-pos-deg"
        out: list[tuple[str, Callable[[np.ndarray], np.ndarray]]] = []
        if name == rad:
            out.append((deg, lambda r: r * _RADTODEG))
            if mag:
                out.append((f"fcs/mag-{surface}-pos-rad", np.abs))
        elif name == deg:
            out.append((rad, lambda d: d * _DEGTORAD))
            if mag:
                out.append((f"fcs/mag-{surface}-pos-rad", lambda d: np.abs(d * _DEGTORAD)))
        if out:
            return out
    return []


def normalize(name: str) -> str:
    """A component's own property: ``fcs/`` + its name lower-cased with
    blanks as dashes (JSBSim's mkPropertyName), or the name itself when it
    holds a ``/``."""
    if "/" in name:
        return name
    return "fcs/" + "".join(c.lower() if c.isupper() else "-" if c.isspace() else c
                            for c in name)


@dataclass(frozen=True)
class Component:
    """One compiled component: what it reads and writes, its state at
    load, and its step."""

    name: str                 # its own property
    reads: frozenset[str]
    writes: tuple[str, ...]   # its own property first, then <output>s, then extras
    state: dict[str, float]   # private keys and their values at load
    step: Step


# ------------------------------------------------------------------ parsing

class Context:
    """What compiling one file needs: its name, the problem list."""

    def __init__(self, source: str, problems: list[CompileError] | None) -> None:
        self.source = source
        self.problems = problems

    def where(self, el: ET.Element) -> str:
        return f"{self.source}:{el.get('_line', '?')}: <{el.tag}>"

    def fail(self, el: ET.Element, msg: str) -> CompileError:
        return CompileError(f"{self.where(el)}: {msg}")


def text(el: ET.Element) -> str:
    return " ".join((el.text or "").split())


def kids(el: ET.Element) -> list[ET.Element]:
    return [c for c in el if c.tag not in _DESCRIBE]


def attrs(el: ET.Element, ctx: Context, allowed: set[str]) -> None:
    for a in el.attrib:
        if a != "_line" and a not in allowed:
            raise ctx.fail(el, f"attribute {a}={el.get(a)!r} is not supported"
                               + (f" (supported: {', '.join(sorted(allowed))})" if allowed
                                  else ""))


def _number(el: ET.Element, ctx: Context) -> float:
    attrs(el, ctx, set())
    try:
        return float(text(el))
    except ValueError:
        raise ctx.fail(el, f"expected a number, got {text(el)!r}") from None


def is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _prop(text: str, reads: set[str]) -> Source:
    """A property read (a leading ``-`` negates)."""
    name = text.lstrip("-")
    reads.add(name)
    if text.startswith("-"):
        return lambda p: -p[name]
    return lambda p: p[name]


def _param(text: str, reads: set[str]) -> Source:
    """JSBSim's parameter value: a number, or a property (maybe negated)."""
    if is_number(text):
        x = float(text)
        return lambda p: x
    return _prop(text, reads)


def _param_el(el: ET.Element, ctx: Context, reads: set[str]) -> Source:
    attrs(el, ctx, set())
    t = text(el)
    if not t or " " in t:
        raise ctx.fail(el, f"expected a number or a property, got {t!r}")
    return _param(t, reads)


def _one(el: ET.Element, tag: str, ctx: Context, *, need: bool = False) -> ET.Element | None:
    found = el.findall(tag)
    if len(found) > 1:
        raise ctx.fail(found[1], f"only one <{tag}> is supported in <{el.tag}>")
    if need and not found:
        raise ctx.fail(el, f"needs a <{tag}>")
    return found[0] if found else None


# ------------------------------------------------------------ components

class _Build:
    """One component being compiled: its inputs, outputs and clip."""

    def __init__(self, el: ET.Element, ctx: Context, allowed: set[str]) -> None:
        self.el, self.ctx = el, ctx
        attrs(el, ctx, {"name"} | ({"type"} if el.tag == "pid" else set()))
        name = el.get("name")
        if not name:
            raise ctx.fail(el, "needs a name attribute")
        self.name = normalize(name)
        for c in kids(el):
            if c.tag not in allowed | _COMMON:
                raise ctx.fail(c, f"is not supported in <{el.tag}> (supported: "
                                  f"{', '.join(sorted(allowed | _COMMON))})")
        self.reads: set[str] = set()
        self.inputs: list[Source] = []
        for i in el.findall("input"):
            attrs(i, ctx, set())
            t = text(i)
            if not t or " " in t:
                raise ctx.fail(i, f"expected a property, got {t!r}")
            self.inputs.append(_param(t, self.reads) if is_number(t)
                               else _prop(t, self.reads))
        self.outputs = [self.name]
        for o in el.findall("output"):
            attrs(o, ctx, set())
            t = text(o)
            if not t or " " in t or t.startswith("-"):
                raise ctx.fail(o, f"expected a property, got {t!r}")
            if t not in self.outputs:
                self.outputs.append(t)
        self.clip: Callable[[np.ndarray, Props], np.ndarray] | None = None
        self.clip_minmax: tuple[Source, Source] | None = None
        clip_el = _one(el, "clipto", ctx)
        if clip_el is not None:
            self._clipto(clip_el)
        self.state: dict[str, float] = {}

    def key(self, what: str) -> str:
        k = f"_fcs:{self.name}:{what}"
        return k

    def input_count(self, lo: int, hi: int) -> None:
        n = len(self.inputs)
        if not lo <= n <= hi:
            want = str(lo) if lo == hi else f"{lo} or more"
            raise self.ctx.fail(self.el, f"takes {want} <input>, has {n}")

    def _clipto(self, c: ET.Element) -> None:
        ctx = self.ctx
        attrs(c, ctx, {"type"})
        kind = c.get("type", "")
        if kind not in ("", "cyclic"):
            raise ctx.fail(c, f"type={kind!r} is not supported (only 'cyclic')")
        for k in kids(c):
            if k.tag not in ("min", "max"):
                raise ctx.fail(k, "is not supported in <clipto> (supported: min, max)")
        lo_el, hi_el = _one(c, "min", ctx, need=True), _one(c, "max", ctx, need=True)
        assert lo_el is not None and hi_el is not None
        lo, hi = _param_el(lo_el, ctx, self.reads), _param_el(hi_el, ctx, self.reads)
        if is_number(text(lo_el)) and is_number(text(hi_el)) \
                and float(text(hi_el)) < float(text(lo_el)):
            raise ctx.fail(c, "max is lower than min")
        self.clip_minmax = (lo, hi)
        if kind == "cyclic":
            def cyc(x: np.ndarray, p: Props) -> np.ndarray:
                vmin, vmax = lo(p), hi(p)
                rng = np.subtract(vmax, vmin)
                safe = np.where(rng != 0.0, rng, 1.0)
                y = np.fmod(x - vmin, safe) + vmin
                y = np.where(y < vmin, y + rng, y)
                return np.where(rng != 0.0, y, np.clip(x, vmin, vmax))
            self.clip = cyc
        else:
            # Constrain(min, x, max); two ufuncs cost less than np.clip
            self.clip = lambda x, p: np.minimum(np.maximum(x, lo(p)), hi(p))

    def done(self, compute: Compute,
             extra: tuple[str, ...] = ()) -> Component:
        """Wrap ``compute`` (which returns the component's Output under
        ``self.name`` and its state) with the clip and the output copies."""
        name, outs, clip = self.name, self.outputs[1:], self.clip
        tied = [t for o in self.outputs for t in _tied(o)]
        reads = tuple(self.reads)

        def step(p: Props, dt: float) -> dict[str, np.ndarray]:
            new: dict[str, np.ndarray] = compute(p, dt)
            out = new[name]
            if clip is not None:
                out = clip(out, p)
            ref = p[name]
            if not (isinstance(out, np.ndarray) and out.shape == ref.shape
                    and out.dtype == np.float64):
                out = np.broadcast_to(np.asarray(out, dtype=np.float64), ref.shape).copy()
            new[name] = out
            for o in outs:
                new[o] = out.copy()
            for key, f in tied:
                new[key] = f(out)
            # no array may serve two keys: a step may hand back an input
            # (a function of one property) or one array as output and state
            taken = {id(p[r]) for r in reads if r in p}
            for k, v in new.items():
                if id(v) in taken:
                    new[k] = v = v.copy()
                taken.add(id(v))
            return new

        writes = (tuple(self.outputs) + tuple(k for k, _ in tied) + tuple(self.state)
                  + extra)
        return Component(name, frozenset(self.reads), writes, dict(self.state), step)


def _fcs_function(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"function"})
    b.input_count(0, 0)
    fel = _one(el, "function", ctx, need=True)
    assert fel is not None
    f = compile_function(fel, ctx.source)
    b.reads |= f.inputs
    kernel, name = f.kernel, b.name
    return b.done(lambda p, dt: {name: kernel(p)})


_OPS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "EQ": np.equal, "NE": np.not_equal, "GT": np.greater, "GE": np.greater_equal,
    "LT": np.less, "LE": np.less_equal, "==": np.equal, "!=": np.not_equal,
    ">": np.greater, ">=": np.greater_equal, "<": np.less, "<=": np.less_equal}

Test = Callable[[Props], np.ndarray]


def _leaf(a: Source, op: Callable[[Any, Any], np.ndarray], b: Source) -> Test:
    return lambda p: op(a(p), b(p))


def model_function(el: ET.Element, ctx: Context) -> tuple[bool, Component]:
    """A ``<function>`` of a system (FGModelFunctions): whether it runs
    after the channels (``type="post"``), and it as a component setting
    the property it names."""
    attrs(el, ctx, {"name", "type"})
    name = el.get("name", "")
    if "/" not in name:
        raise ctx.fail(el, f"name={name!r}: expected the path of the property it sets")
    kind = el.get("type", "pre")
    if kind not in ("pre", "post"):
        raise ctx.fail(el, f"type={kind!r}: expected pre or post")
    line = el.get("_line", "?")
    wrapper = ET.Element("fcs_function", {"name": name, "_line": line})
    fn = ET.SubElement(wrapper, "function", {"_line": line})
    fn.text = el.text
    fn.extend(list(el))
    return kind == "post", _fcs_function(wrapper, ctx)


def _condition_lines(text: str | None, line0: int, el: ET.Element, ctx: Context,
                     reads: set[str]) -> list[Test]:
    """The ``PROPERTY OP VALUE`` lines of a test's text."""
    out = []
    for i, line in enumerate((text or "").splitlines()):
        words = line.split()
        if not words:
            continue
        if len(words) != 3 or words[1].upper() not in _OPS or is_number(words[0]):
            raise CompileError(f"{ctx.source}:{line0 + i}: <{el.tag}>: condition "
                               f"{line.strip()!r}: expected 'PROPERTY OP VALUE' with OP one "
                               f"of EQ NE GT GE LT LE == != > >= < <=")
        out.append(_leaf(_prop(words[0], reads), _OPS[words[1].upper()],
                         _param(words[2], reads)))
    return out


def _condition(el: ET.Element, ctx: Context, reads: set[str]) -> Test:
    """FGCondition: its data lines and nested tests, all evaluated, AND or OR."""
    attrs(el, ctx, {"logic", "value"} if el.tag == "test" else {"logic"})
    logic = el.get("logic", "AND")
    if logic not in ("AND", "OR"):
        raise ctx.fail(el, f"logic={logic!r}: expected AND or OR")
    parts = _condition_lines(el.text, int(el.get("_line", "0")), el, ctx, reads)
    for c in el:
        if c.tag not in _DESCRIBE:
            if c.tag != el.tag:
                raise ctx.fail(c, f"is not supported in <{el.tag}> (only nested <{el.tag}>)")
            parts.append(_condition(c, ctx, reads))
        # text after a nested test: its line is where that test starts
        parts += _condition_lines(c.tail, int(c.get("_line", "0")), el, ctx, reads)
    if not parts:
        raise ctx.fail(el, "has no condition")
    join = np.logical_and if logic == "AND" else np.logical_or
    if len(parts) == 1:
        return parts[0]

    def cond(p: Props) -> np.ndarray:
        acc = parts[0](p)
        for q in parts[1:]:
            acc = join(acc, q(p))
        return acc
    return cond


def _switch(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"default", "test"})
    b.input_count(0, 0)
    d = _one(el, "default", ctx)
    default: Source = lambda p: 0.0  # noqa: E731 - JSBSim's output without a default
    if d is not None:
        attrs(d, ctx, {"value"})
        if d.get("value") is None or list(kids(d)) or text(d):
            raise ctx.fail(d, "expected only a value attribute")
        default = _param(d.get("value", ""), b.reads)
    tests = []
    for t in el.findall("test"):
        v = t.get("value")
        if v is None:
            raise ctx.fail(t, "needs a value attribute")
        tests.append((_condition(t, ctx, b.reads), _param(v.strip(), b.reads)))
    name = b.name
    tests.reverse()  # the first test that passes wins

    def compute(p: Props, dt: float) -> dict[str, Any]:
        out = default(p)
        for cond, val in tests:
            out = np.where(cond(p), val(p), out)
        return {name: out}
    return b.done(compute)


def _summer(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"bias"})
    b.input_count(1, 10_000)
    be = _one(el, "bias", ctx)
    bias = _number(be, ctx) if be is not None else 0.0
    ins, name = b.inputs, b.name

    # JSBSim starts from 0.0 and adds the bias even when 0: both only turn
    # a -0.0 into 0.0, which compares equal, so they are left out
    first, rest = ins[0], ins[1:]

    def compute(p: Props, dt: float) -> dict[str, Any]:
        out = first(p)
        for s in rest:
            out = out + s(p)
        return {name: out + bias if bias else out}
    return b.done(compute)


def _gain(el: ET.Element, ctx: Context) -> Component:
    tag = el.tag
    allowed = {"gain"} | ({"table"} if tag == "scheduled_gain" else set()) \
        | ({"domain", "range", "zero_centered"} if tag == "aerosurface_scale" else set())
    b = _Build(el, ctx, allowed)
    b.input_count(1, 1)
    ge = _one(el, "gain", ctx, need=tag == "pure_gain")
    gain = _param_el(ge, ctx, b.reads) if ge is not None else (lambda p: 1.0)
    x, name = b.inputs[0], b.name
    if tag == "pure_gain":
        return b.done(lambda p, dt: {name: gain(p) * x(p)})
    if tag == "scheduled_gain":
        te = _one(el, "table", ctx, need=True)
        assert te is not None
        fn = ET.Element("function", {"_line": te.get("_line", "?")})
        fn.append(te)
        f = compile_function(fn, ctx.source)
        b.reads |= f.inputs
        table = f.kernel
        return b.done(lambda p, dt: {name: gain(p) * table(p) * x(p)})

    def pair(tag2: str, lo: float, hi: float, need: bool) -> tuple[float, float]:
        e = _one(el, tag2, ctx, need=need)
        if e is None:
            return lo, hi
        attrs(e, ctx, set())
        for k in kids(e):
            if k.tag not in ("min", "max"):
                raise ctx.fail(k, f"is not supported in <{tag2}> (supported: min, max)")
        mn, mx = _one(e, "min", ctx, need=True), _one(e, "max", ctx, need=True)
        assert mn is not None and mx is not None
        return _number(mn, ctx), _number(mx, ctx)

    in_min, in_max = pair("domain", -1.0, 1.0, False)
    out_min, out_max = pair("range", 0.0, 0.0, True)
    zc = _one(el, "zero_centered", ctx)
    centered = not (zc is not None and text(zc) in ("0", "false"))

    zero_end = in_min == 0.0 or in_max == 0.0
    scaled = ge is not None

    def scale(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        if centered and not zero_end:
            # both sides computed, in place; an input of 0 gives a signed
            # zero where JSBSim gives 0.0 (equal in every comparison)
            # dividing by 1 or -1 is exact, so skipped (the usual domain)
            hi = u * out_max if in_max == 1.0 else (u / in_max) * out_max
            lo = u * -out_min if in_min == -1.0 else (u / in_min) * out_min
            out = np.where(u > 0, hi, lo)
        elif centered:  # a domain ending at 0: 0/0 where JSBSim gives 0.0
            out = np.where(u > 0, (u / in_max) * out_max, (u / in_min) * out_min)
            out = np.where(u == 0.0, 0.0, out)
        else:
            out = out_min + ((u - in_min) / (in_max - in_min)) * (out_max - out_min)
        return {name: out * gain(p) if scaled else out}
    return b.done(scale)


def _pid(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"kp", "ki", "kd", "trigger", "pvdot"})
    kind = el.get("type", "")
    if kind not in ("", "standard"):
        raise ctx.fail(el, f"type={kind!r} is not supported (only 'standard')")
    standard = kind == "standard"
    b.input_count(1, 1)
    zero: Source = lambda p: 0.0  # noqa: E731

    def gain(tag: str) -> tuple[Source, ET.Element | None]:
        e = _one(el, tag, ctx)
        if e is None:
            return zero, None
        t = text(e)
        allowed = {"type"} if tag == "ki" else set()
        attrs(e, ctx, allowed)
        if not t or " " in t:
            raise ctx.fail(e, f"expected a number or a property, got {t!r}")
        return _param(t, b.reads), e

    kp, _ = gain("kp")
    ki, ki_el = gain("ki")
    kd, _ = gain("kd")
    integ = "none"
    if ki_el is not None:
        integ = ki_el.get("type", "ab2")
        if integ not in ("rect", "trap", "ab2", "ab3"):
            integ = "ab2"  # JSBSim's default for any other type
    tr = _one(el, "trigger", ctx)
    trigger = _prop(text(tr), b.reads) if tr is not None else None
    pv = _one(el, "pvdot", ctx)
    pvdot = _prop(text(pv), b.reads) if pv is not None else None
    x, name = b.inputs[0], b.name
    k_tot, k_prev, k_prev2 = b.key("i_out_total"), b.key("input_prev"), b.key("input_prev2")
    b.state.update({k_tot: 0.0, k_prev: 0.0, k_prev2: 0.0})

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        prev, prev2, total = p[k_prev], p[k_prev2], p[k_tot]
        dval = pvdot(p) if pvdot is not None else (u - prev) / dt
        if integ == "rect":
            delta = u
        elif integ == "trap":
            delta = 0.5 * (u + prev)
        elif integ == "ab2":
            delta = 1.5 * u - 0.5 * prev
        elif integ == "ab3":
            delta = (23.0 * u - 16.0 * prev + 5.0 * prev2) / 12.0
        else:
            delta = np.zeros_like(u)
        if trigger is not None:
            test = trigger(p)
            delta = np.where(np.abs(test) < 0.000001, delta, 0.0)
            reset = test < 0.0
            total = np.where(reset, 0.0, total)
            new_prev2 = np.where(reset, 0.0, prev)
        else:
            new_prev2 = prev
        total = total + ki(p) * dt * delta
        if standard:
            out = kp(p) * (u + total + kd(p) * dval)
        else:
            out = kp(p) * u + total + kd(p) * dval
        return {name: out, k_tot: total, k_prev: u, k_prev2: new_prev2}
    return b.done(compute)


def _actuator(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"lag", "rate_limit", "deadband_width", "hysteresis_width", "bias"})
    b.input_count(1, 1)

    def num(tag: str) -> float:
        e = _one(el, tag, ctx)
        return _number(e, ctx) if e is not None else 0.0

    lag, dbw, hyw, bias = num("lag"), num("deadband_width"), num("hysteresis_width"), num("bias")
    incr: Source | None = None
    decr: Source | None = None
    for r in el.findall("rate_limit"):
        attrs(r, ctx, {"sense"})
        sense = r.get("sense", "")
        t = text(r)
        if not t or " " in t or list(kids(r)):
            raise ctx.fail(r, f"expected a number or a property, got {t!r}")
        src = _param(t, b.reads)
        if sense.startswith("incr"):
            incr = src
        elif sense.startswith("decr"):
            decr = src
        else:
            incr = decr = src
    x, name = b.inputs[0], b.name
    fz, fh, fs = (f"{name}/malfunction/fail_zero", f"{name}/malfunction/fail_hardover",
                  f"{name}/malfunction/fail_stuck")
    sat = f"{name}/saturated"
    b.reads |= {fz, fh, fs}
    k_init, k_prev = b.key("initialized"), b.key("previous_output")
    k_lag_in, k_lag_out = b.key("lag_input"), b.key("lag_output")
    k_rate, k_hyst = b.key("rate_output"), b.key("hysteresis_output")
    b.state.update({k_init: 0.0, k_prev: 0.0, k_lag_in: 0.0, k_lag_out: 0.0,
                    k_rate: 0.0, k_hyst: 0.0})
    clip = b.clip_minmax

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        inited = p[k_init] != 0.0
        u = np.where(p[fz] != 0.0, 0.0, u)
        if clip is not None:
            u = np.where(p[fh] != 0.0, np.where(u < 0.0, clip[0](p), clip[1](p)), u)
        else:
            u = np.where(p[fh] != 0.0, 0.0, u)
        out = u
        new: dict[str, np.ndarray] = {}
        if lag != 0.0:
            denom = 2.0 + dt * lag
            ca, cb = dt * lag / denom, (2.0 - dt * lag) / denom
            lagged = np.where(inited, ca * (out + p[k_lag_in]) + p[k_lag_out] * cb, out)
            new[k_lag_in], new[k_lag_out] = out, lagged
            out = lagged
        if incr is not None or decr is not None:
            prev_r = p[k_rate]
            delta = out - prev_r
            r_out = out
            if incr is not None:
                lim = incr(p)
                r_out = np.where(delta > dt * lim, prev_r + lim * dt, r_out)
            if decr is not None:
                lim = -decr(p)
                r_out = np.where(delta < dt * lim, prev_r + lim * dt, r_out)
            out = np.where(inited, r_out, out)
            new[k_rate] = out
        if dbw != 0.0:
            half = dbw / 2.0
            out = np.where(out < -half, out + half, np.where(out > half, out - half, 0.0))
        if hyw != 0.0:
            ph = p[k_hyst]
            h = np.where(out > ph, np.maximum(ph, out - 0.5 * hyw),
                         np.where(out < ph, np.minimum(ph, out + 0.5 * hyw), out))
            out = np.where(inited, h, out)
            new[k_hyst] = out
        if bias != 0.0:
            out = out + bias
        stuck = p[fs] != 0.0
        out = np.where(stuck, p[k_prev], out)
        for k in list(new):  # a stuck actuator's filters stand still
            new[k] = np.where(stuck, p[k], new[k])
        new[k_prev] = out
        new[k_init] = np.ones_like(u)
        if clip is not None:
            vmin, vmax = clip[0](p), clip[1](p)
            out = np.minimum(np.maximum(out, vmin), vmax)
            s = ((out >= vmax) & (vmax != 0)) | ((out <= vmin) & (vmin != 0))
            new[sat] = s.astype(np.float64)
        new[name] = out
        return new

    saved_clip, b.clip = b.clip, None  # clipped above (before the saturation test)
    return b.done(compute, (sat,) if saved_clip is not None else ())


def _filter(el: ET.Element, ctx: Context) -> Component:
    tag = el.tag
    coeffs = {"lag_filter": 1, "washout_filter": 1, "lead_lag_filter": 4,
              "second_order_filter": 6, "integrator": 1}[tag]
    allowed = {f"c{i}" for i in range(1, coeffs + 1)} | ({"trigger"} if tag == "integrator"
                                                        else set())
    b = _Build(el, ctx, allowed)
    b.input_count(1, 1)
    c = [0.0] * 7
    for i in range(1, coeffs + 1):
        e = _one(el, f"c{i}", ctx)
        if e is not None:
            t = text(e)
            if not is_number(t):
                raise ctx.fail(e, f"a coefficient given as a property ({t!r}) is not "
                                  f"supported: give a number")
            c[i] = _number(e, ctx)
    tr = _one(el, "trigger", ctx)
    trigger = _prop(text(tr), b.reads) if tr is not None else None
    x, name = b.inputs[0], b.name
    k_first = b.key("initialize")
    k_i1, k_i2, k_o1, k_o2 = (b.key("input_prev1"), b.key("input_prev2"),
                              b.key("output_prev1"), b.key("output_prev2"))
    # a filter's first run sets its past to the input it last held (0 at
    # load) and outputs that; an integrator's first run is an ordinary step
    # (both measured against JSBSim 1.3.3)
    first_run = 0.0 if tag == "integrator" else 1.0
    b.state.update({k_first: first_run, k_i1: 0.0, k_i2: 0.0, k_o1: 0.0, k_o2: 0.0})

    def coefficients(dt: float) -> tuple[float, ...]:
        if tag == "lag_filter":
            denom = 2.0 + dt * c[1]
            return dt * c[1] / denom, (2.0 - dt * c[1]) / denom
        if tag == "washout_filter":
            denom = 2.0 + dt * c[1]
            return 2.0 / denom, (2.0 - dt * c[1]) / denom
        if tag == "lead_lag_filter":
            denom = 2.0 * c[3] + dt * c[4]
            return ((2.0 * c[1] + dt * c[2]) / denom, (dt * c[2] - 2.0 * c[1]) / denom,
                    (2.0 * c[3] - dt * c[4]) / denom)
        if tag == "second_order_filter":
            denom = 4.0 * c[4] + 2.0 * c[5] * dt + c[6] * dt * dt
            return ((4.0 * c[1] + 2.0 * c[2] * dt + c[3] * dt * dt) / denom,
                    (2.0 * c[3] * dt * dt - 8.0 * c[1]) / denom,
                    (4.0 * c[1] - 2.0 * c[2] * dt + c[3] * dt * dt) / denom,
                    (2.0 * c[6] * dt * dt - 8.0 * c[4]) / denom,
                    (4.0 * c[4] - 2.0 * c[5] * dt + c[6] * dt * dt) / denom)
        return (dt * c[1] / 2.0,)

    def compute(p: Props, dt: float) -> dict[str, Any]:
        first = p[k_first] != 0.0
        u = np.asarray(x(p), dtype=np.float64)
        i1, i2, o1, o2 = p[k_i1], p[k_i2], p[k_o1], p[k_o2]
        k = coefficients(dt)
        if tag == "lag_filter":
            out = (u + i1) * k[0] + o1 * k[1]
        elif tag == "lead_lag_filter":
            out = u * k[0] + i1 * k[1] + o1 * k[2]
        elif tag == "second_order_filter":
            out = u * k[0] + i1 * k[1] + i2 * k[2] - o1 * k[3] - o2 * k[4]
        elif tag == "washout_filter":
            out = u * k[0] - i1 * k[0] + o1 * k[1]
        else:
            if trigger is not None:
                # a negative trigger resets the output to 0 first; one beyond
                # 1e-6 either way then holds it (the inputs are not added);
                # the past inputs follow the input all the while (measured
                # against JSBSim 1.3.3 at 1, 2e-6, 5e-7, -5e-7, -2e-6 and -1)
                test = trigger(p)
                o1 = np.where(test < 0.0, 0.0, o1)
                out = np.where(np.abs(test) > 0.000001, o1, u * k[0] + i1 * k[0] + o1)
            else:
                out = u * k[0] + i1 * k[0] + o1
        # the first frame: the output is the input held from before (0 at load)
        held = p[k_i1]  # JSBSim's Input member: the last input
        u = np.where(first, held, u)
        out = np.where(first, held, out)
        i1 = np.where(first, held, i1)
        o1 = np.where(first, held, o1)
        return {name: out, k_o2: o1, k_o1: out, k_i2: i1, k_i1: u,
                k_first: np.zeros_like(u)}
    return b.done(compute)


def _deadband(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"width", "gain"})
    b.input_count(1, 1)
    we = _one(el, "width", ctx, need=True)
    assert we is not None
    width = _param_el(we, ctx, b.reads)
    ge = _one(el, "gain", ctx)
    gain = _number(ge, ctx) if ge is not None else 1.0
    x, name = b.inputs[0], b.name

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        half = 0.5 * np.asarray(width(p))
        out = np.where(u < -half, (u + half) * gain, np.where(u > half, (u - half) * gain, 0.0))
        return {name: out}
    return b.done(compute)


def _kinematic(el: ET.Element, ctx: Context) -> Component:
    b = _Build(el, ctx, {"traverse", "noscale"})
    b.input_count(1, 1)
    tv = _one(el, "traverse", ctx, need=True)
    assert tv is not None
    attrs(tv, ctx, set())
    pos: list[float] = []
    times: list[float] = []
    for s in kids(tv):
        if s.tag != "setting":
            raise ctx.fail(s, "is not supported in <traverse> (only <setting>)")
        for k in kids(s):
            if k.tag not in ("position", "time"):
                raise ctx.fail(k, "is not supported in <setting> (position, time)")
        pe, te = _one(s, "position", ctx, need=True), _one(s, "time", ctx, need=True)
        assert pe is not None and te is not None
        pos.append(_number(pe, ctx))
        times.append(_number(te, ctx))
    if len(pos) < 2:
        raise ctx.fail(tv, "needs two or more <setting>")
    if any(b2 <= a for a, b2 in zip(pos, pos[1:])):
        raise ctx.fail(tv, "setting positions must increase")
    scale = _one(el, "noscale", ctx) is None
    det, tt = np.array(pos), np.array(times)
    inner = det[1:]
    x, name = b.inputs[0], b.name
    current = b.outputs[1] if len(b.outputs) > 1 else name

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        if scale:
            u = u * det[-1]
        u = np.clip(u, det[0], det[-1])
        out = p[current].copy()
        left = np.full(u.shape, dt)
        for _ in range(len(det) + 1):
            live = (left > 0.0) & ~(np.abs(u - out) <= _EPS * np.maximum(np.abs(u), np.abs(out)))
            if not live.any():
                break
            ind = np.where(u < out, np.searchsorted(inner, out, "left"),
                           np.searchsorted(inner, out, "right")) + 1
            ind = np.minimum(ind, len(det) - 1)
            t = tt[ind]
            jump = live & (t <= 0.0)
            rate = (det[ind] - det[ind - 1]) / np.where(t > 0.0, t, 1.0)
            this_in = np.clip(u, det[ind - 1], det[ind])
            this_dt = np.abs((this_in - out) / rate)
            partial = left < this_dt
            moved = np.where(partial, np.where(out < u, out + left * rate, out - left * rate),
                             this_in)
            out = np.where(jump, u, np.where(live, moved, out))
            left = np.where(jump, 0.0, np.where(live, left - np.where(partial, left, this_dt),
                                                left))
        return {name: out}
    return b.done(compute)


COMPONENTS: dict[str, Callable[[ET.Element, Context], Component]] = {
    "fcs_function": _fcs_function, "switch": _switch, "summer": _summer,
    "pure_gain": _gain, "scheduled_gain": _gain, "aerosurface_scale": _gain,
    "pid": _pid, "actuator": _actuator, "kinematic": _kinematic, "deadband": _deadband,
    "lag_filter": _filter, "lead_lag_filter": _filter, "washout_filter": _filter,
    "second_order_filter": _filter, "integrator": _filter,
}
