"""The components of JSBSim's flight-control channels compiled to
vectorised numpy steps, as JSBSim 1.3 computes them over arrays of N
aircraft: what every component shares (FGFCSComponent's inputs, outputs
and clip, the surface positions FGFCS ties together) and the components
without state (FGFCSFunction, FGSwitch with FGCondition, FGSummer, FGGain,
FGDeadBand, and a system's own functions). Those with state are in
``cosim.rigid.fcs_dynamics``.

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
    #: the element it was compiled from and its file (``cosim.rigid.fcs_fused``
    #: writes its code from them)
    element: ET.Element | None = None
    source: str = ""


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


def number(el: ET.Element, ctx: Context) -> float:
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


def prop(text: str, reads: set[str]) -> Source:
    """A property read (a leading ``-`` negates)."""
    name = text.lstrip("-")
    reads.add(name)
    if text.startswith("-"):
        return lambda p: -p[name]
    return lambda p: p[name]


def param(text: str, reads: set[str]) -> Source:
    """JSBSim's parameter value: a number, or a property (maybe negated)."""
    if is_number(text):
        x = float(text)
        return lambda p: x
    return prop(text, reads)


def param_el(el: ET.Element, ctx: Context, reads: set[str]) -> Source:
    attrs(el, ctx, set())
    t = text(el)
    if not t or " " in t:
        raise ctx.fail(el, f"expected a number or a property, got {t!r}")
    return param(t, reads)


def one(el: ET.Element, tag: str, ctx: Context, *, need: bool = False) -> ET.Element | None:
    found = el.findall(tag)
    if len(found) > 1:
        raise ctx.fail(found[1], f"only one <{tag}> is supported in <{el.tag}>")
    if need and not found:
        raise ctx.fail(el, f"needs a <{tag}>")
    return found[0] if found else None


# ------------------------------------------------------------ components

class Build:
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
            if is_number(t):  # FGPropertyValue takes a property only
                raise ctx.fail(i, f"expected a property, got the number {t!r}")
            self.inputs.append(prop(t, self.reads))
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
        clip_el = one(el, "clipto", ctx)
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
        lo_el, hi_el = one(c, "min", ctx, need=True), one(c, "max", ctx, need=True)
        assert lo_el is not None and hi_el is not None
        lo, hi = param_el(lo_el, ctx, self.reads), param_el(hi_el, ctx, self.reads)
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

    def done(self, compute: Compute, extra: tuple[str, ...] = (), *,
             fresh: bool = False) -> Component:
        """Wrap ``compute`` (which returns the component's Output under
        ``self.name`` and its state) with the clip and the output copies
        (``fresh``: ``compute`` returns only arrays it made, each once)."""
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
            if fresh:
                return new
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
        return Component(name, frozenset(self.reads), writes, dict(self.state), step,
                         self.el, self.ctx.source)


def _fcs_function(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"function"})
    b.input_count(0, 0)
    fel = one(el, "function", ctx, need=True)
    assert fel is not None
    f = compile_function(fel, ctx.source)
    b.reads |= f.inputs
    kernel, name = f.kernel, b.name
    return b.done(lambda p, dt: {name: kernel(p)})


_OPS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "EQ": np.equal, "NE": np.not_equal, "GT": np.greater, "GE": np.greater_equal,
    "LT": np.less, "LE": np.less_equal, "==": np.equal, "!=": np.not_equal,
    ">": np.greater, ">=": np.greater_equal, "<": np.less, "<=": np.less_equal}
_OPS.update({k.lower(): v for k, v in _OPS.items() if k.isalpha()})  # FGCondition's list

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
        if len(words) != 3 or words[1] not in _OPS or is_number(words[0]):
            raise CompileError(f"{ctx.source}:{line0 + i}: <{el.tag}>: condition "
                               f"{line.strip()!r}: expected 'PROPERTY OP VALUE' with OP one "
                               f"of EQ NE GT GE LT LE (or in lower case) == != > >= < <=")
        out.append(_leaf(prop(words[0], reads), _OPS[words[1]],
                         param(words[2], reads)))
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
    b = Build(el, ctx, {"default", "test"})
    b.input_count(0, 0)
    d = one(el, "default", ctx)
    default: Source = lambda p: 0.0  # noqa: E731 - JSBSim's output without a default
    if d is not None:
        attrs(d, ctx, {"value"})
        if d.get("value") is None or list(kids(d)) or text(d):
            raise ctx.fail(d, "expected only a value attribute")
        default = param(d.get("value", ""), b.reads)
    tests = []
    for t in el.findall("test"):
        v = t.get("value")
        if v is None:
            raise ctx.fail(t, "needs a value attribute")
        tests.append((_condition(t, ctx, b.reads), param(v.strip(), b.reads)))
    name = b.name
    tests.reverse()  # the first test that passes wins

    def compute(p: Props, dt: float) -> dict[str, Any]:
        out = default(p)
        for cond, val in tests:
            out = np.where(cond(p), val(p), out)
        return {name: out}
    return b.done(compute, fresh=bool(tests))


def _summer(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"bias"})
    b.input_count(1, 10_000)
    be = one(el, "bias", ctx)
    bias = number(be, ctx) if be is not None else 0.0
    ins, name = b.inputs, b.name

    # JSBSim starts from 0.0 and adds the bias even when 0: both only turn
    # a -0.0 into 0.0, which compares equal, so they are left out
    first, rest = ins[0], ins[1:]

    def compute(p: Props, dt: float) -> dict[str, Any]:
        out = first(p)
        for s in rest:
            out = out + s(p)
        return {name: out + bias if bias else out}
    return b.done(compute, fresh=bool(rest or bias))


def _gain(el: ET.Element, ctx: Context) -> Component:
    tag = el.tag
    allowed = {"gain"} | ({"table"} if tag == "scheduled_gain" else set()) \
        | ({"domain", "range", "zero_centered"} if tag == "aerosurface_scale" else set())
    b = Build(el, ctx, allowed)
    b.input_count(1, 1)
    ge = one(el, "gain", ctx, need=tag == "pure_gain")
    gain = param_el(ge, ctx, b.reads) if ge is not None else (lambda p: 1.0)
    x, name = b.inputs[0], b.name
    if tag == "pure_gain":
        return b.done(lambda p, dt: {name: gain(p) * x(p)}, fresh=True)
    if tag == "scheduled_gain":
        te = one(el, "table", ctx, need=True)
        assert te is not None
        fn = ET.Element("function", {"_line": te.get("_line", "?")})
        fn.append(te)
        f = compile_function(fn, ctx.source)
        b.reads |= f.inputs
        table = f.kernel
        return b.done(lambda p, dt: {name: gain(p) * table(p) * x(p)}, fresh=True)

    def pair(tag2: str, lo: float, hi: float, need: bool) -> tuple[float, float]:
        e = one(el, tag2, ctx, need=need)
        if e is None:
            return lo, hi
        attrs(e, ctx, set())
        for k in kids(e):
            if k.tag not in ("min", "max"):
                raise ctx.fail(k, f"is not supported in <{tag2}> (supported: min, max)")
        mn, mx = one(e, "min", ctx, need=True), one(e, "max", ctx, need=True)
        assert mn is not None and mx is not None
        return number(mn, ctx), number(mx, ctx)

    in_min, in_max = pair("domain", -1.0, 1.0, False)
    out_min, out_max = pair("range", 0.0, 0.0, True)
    zc = one(el, "zero_centered", ctx)
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
    return b.done(scale, fresh=True)


def _deadband(el: ET.Element, ctx: Context) -> Component:
    b = Build(el, ctx, {"width", "gain"})
    b.input_count(1, 1)
    we = one(el, "width", ctx, need=True)
    assert we is not None
    width = param_el(we, ctx, b.reads)
    ge = one(el, "gain", ctx)
    gain = number(ge, ctx) if ge is not None else 1.0
    x, name = b.inputs[0], b.name

    def compute(p: Props, dt: float) -> dict[str, Any]:
        u = np.asarray(x(p), dtype=np.float64)
        half = 0.5 * np.asarray(width(p))
        out = np.where(u < -half, (u + half) * gain, np.where(u > half, (u - half) * gain, 0.0))
        return {name: out}
    return b.done(compute, fresh=True)


#: the components without state
STATELESS: dict[str, Callable[[ET.Element, Context], Component]] = {
    "fcs_function": _fcs_function, "switch": _switch, "summer": _summer,
    "pure_gain": _gain, "scheduled_gain": _gain, "aerosurface_scale": _gain,
    "deadband": _deadband,
}
