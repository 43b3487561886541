"""JSBSim's ``<function>`` elements compiled to vectorised numpy: the first
part of a rigid-body tier that flies many aircraft from their own JSBSim
files at once.

``compile_function(element, source)`` turns one ``<function>`` (or any of
its operations) into a ``Compiled``: the property names it reads
(``inputs``) and ``evaluate(values)``, which takes a mapping of each input
to an array (one value per aircraft) and returns the function's value for
every aircraft, computed as JSBSim's ``FGFunction`` and ``FGTable`` compute
it: the same operations in the same order (so the same doubles where the
operations are exact), tables interpolated linearly and clamped to their
ends, a quotient by zero infinite, comparisons 1 or 0.

What it does not know it refuses, never guesses: an element, attribute or
table form outside the supported set is a ``CompileError`` naming the file,
the line and the element. ``read_functions(path)`` compiles every function
of an aircraft file, in file order, by output name.

Supported: ``property`` (a leading ``-`` negates), ``value``, ``product``,
``sum``, ``difference``, ``quotient``, ``pow``, ``abs``, ``sqrt``, ``exp``,
``ln``, ``sin``, ``cos``, ``tan``, ``asin``, ``acos``, ``atan``, ``atan2``,
``toradians``, ``todegrees``, ``min``, ``max``, ``lt``, ``le``, ``gt``, ``ge``,
``eq``, ``nq``, ``and``, ``or``, ``not``, ``ifthen``, ``table`` of one,
two or three dimensions, and the short forms ``p`` and ``v``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np

from cosim.errors import ConfigError
from cosim.rigid import kernels

Values = Mapping[str, np.ndarray]
Kernel = Callable[[Values], np.ndarray]

#: elements that only describe
_IGNORED = {"description"}


class CompileError(ConfigError):
    """A JSBSim element the compiler does not support (file, line, element)."""


@dataclass(frozen=True)
class Compiled:
    """One compiled function: the properties it reads and its kernel."""

    name: str
    inputs: frozenset[str]
    kernel: Kernel
    #: the operation it was compiled from (for ``cosim.rigid.fused``)
    element: ET.Element | None = field(default=None, compare=False, repr=False)

    def evaluate(self, values: Values) -> np.ndarray:
        """The function's value for every aircraft (``values``: each input's
        array, all of one length)."""
        missing = sorted(self.inputs - set(values))
        if missing:
            raise KeyError(f"{self.name}: no values for {', '.join(missing)}")
        return np.asarray(self.kernel(values), dtype=np.float64)


def parse(path: Path) -> ET.Element:
    """An aircraft file's root element, each element with its line (``_line``)."""
    builder = ET.TreeBuilder()
    p = expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        builder.start(tag, {**attrs, "_line": str(p.CurrentLineNumber)})

    p.StartElementHandler = start
    p.EndElementHandler = builder.end
    p.CharacterDataHandler = builder.data
    try:
        p.Parse(Path(path).read_bytes(), True)
    except expat.ExpatError as e:
        raise CompileError(f"{path}:{e.lineno}: not well-formed XML ({e})") from None
    return builder.close()


def _where(el: ET.Element, source: str) -> str:
    return f"{source}:{el.get('_line', '?')}: <{el.tag}>"


def _children(el: ET.Element) -> list[ET.Element]:
    return [c for c in el if c.tag not in _IGNORED]


_UNARY: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "ln": np.log, "sin": np.sin,
    "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan,
    # as FGFunction: x*pi/180 and x*180/pi, multiplied first
    "toradians": lambda x: x * np.pi / 180.0, "todegrees": lambda x: x * 180.0 / np.pi,
}
_COMPARE: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "lt": np.less, "le": np.less_equal, "gt": np.greater, "ge": np.greater_equal,
    "eq": np.equal, "nq": np.not_equal,
}


def _fold(op: Callable[[np.ndarray, np.ndarray], np.ndarray], parts: list[Kernel]) -> Kernel:
    """JSBSim's left-to-right fold of an n-ary operation."""
    def k(v: Values) -> np.ndarray:
        acc = np.asarray(parts[0](v), dtype=np.float64)
        for p in parts[1:]:
            acc = op(acc, p(v))
        return acc
    return k


def _quotient(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0.0, a / np.where(b != 0.0, b, 1.0), np.inf)


def _op(el: ET.Element, source: str, inputs: set[str]) -> Kernel:
    tag = el.tag
    kids = _children(el)
    where = _where(el, source)
    extra = sorted(a for a in el.attrib if a != "_line")
    if tag in ("property", "p"):  # <p> is JSBSim's short form
        name = (el.text or "").strip()
        if not name or extra:
            raise CompileError(f"{where}: expected a property name and no attributes")
        sign = -1.0 if name.startswith("-") else 1.0
        name = name.lstrip("-")
        inputs.add(name)
        if sign < 0:
            return lambda v: -np.asarray(v[name], dtype=np.float64)
        return lambda v: np.asarray(v[name], dtype=np.float64)
    if tag in ("value", "v"):
        try:
            x = float((el.text or "").strip())
        except ValueError:
            raise CompileError(f"{where}: not a number: {el.text!r}") from None
        const = np.asarray(x, dtype=np.float64)
        return lambda v: const
    if extra and tag != "table":
        raise CompileError(f"{where}: attribute {extra[0]!r} is not supported")
    if tag == "table":
        return _table(el, source, inputs)
    parts = [_op(c, source, inputs) for c in kids]
    n = len(parts)

    def need(lo: int, hi: int | None = None) -> None:
        if n < lo or (hi is not None and n > hi):
            want = f"{lo}" if hi == lo else f"{lo} or more" if hi is None else f"{lo} to {hi}"
            raise CompileError(f"{where}: takes {want} arguments, has {n}")

    if tag == "product":
        need(1)
        return _fold(np.multiply, parts)
    if tag == "sum":
        need(1)
        return _fold(np.add, parts)
    if tag == "difference":
        need(1)
        return _fold(np.subtract, parts)
    if tag == "quotient":
        need(2, 2)
        return _fold(_quotient, parts)
    if tag == "pow":
        need(2, 2)
        return _fold(np.power, parts)
    if tag == "atan2":
        need(2, 2)
        return _fold(np.arctan2, parts)
    if tag in ("min", "max"):
        need(1)
        return _fold(np.minimum if tag == "min" else np.maximum, parts)
    if tag in _UNARY:
        need(1, 1)
        f, p0 = _UNARY[tag], parts[0]
        return lambda v: f(p0(v))
    if tag in _COMPARE:
        need(2, 2)
        cmp, a, b = _COMPARE[tag], parts[0], parts[1]
        return lambda v: cmp(a(v), b(v)).astype(np.float64)
    if tag in ("and", "or"):
        need(1)
        logic = np.logical_and if tag == "and" else np.logical_or
        return _fold(lambda x, y: logic(x != 0.0, y != 0.0).astype(np.float64), parts)
    if tag == "not":
        need(1, 1)
        p0 = parts[0]
        return lambda v: (p0(v) == 0.0).astype(np.float64)
    if tag == "ifthen":
        need(3, 3)
        c, a, b = parts
        return lambda v: np.where(c(v) != 0.0, a(v), b(v))
    raise CompileError(f"{where}: not supported by the rigid-body compiler")


def _numbers(el: ET.Element, source: str) -> list[list[float]]:
    rows = []
    for i, line in enumerate((el.text or "").strip().splitlines()):
        if line.strip():
            try:
                rows.append([float(x) for x in line.split()])
            except ValueError:
                line_no = int(el.get("_line", "0")) + i + 1
                raise CompileError(f"{source}:{line_no}: <tableData>: not numbers: "
                                   f"{line.strip()!r}") from None
    return rows


def table1_data(data: ET.Element, source: str) -> tuple[np.ndarray, np.ndarray]:
    """A ``<tableData>`` of one dimension: its breakpoints and values (two
    or more rows of two numbers, the breakpoints increasing)."""
    rows = _numbers(data, source)
    if len(rows) < 2 or any(len(r) != 2 for r in rows):
        raise CompileError(f"{_where(data, source)}: a table of one dimension needs "
                           f"two or more rows of two numbers")
    bp = np.array([r[0] for r in rows])
    val = np.array([r[1] for r in rows])
    if np.any(np.diff(bp) <= 0):
        raise CompileError(f"{_where(data, source)}: breakpoints must increase")
    return bp, val


def _lookup(el: ET.Element, source: str, inputs: set[str]) -> dict[str, str]:
    out = {}
    for iv in el.findall("independentVar"):
        name = (iv.text or "").strip().lstrip("-")
        if (iv.text or "").strip().startswith("-"):
            raise CompileError(f"{_where(iv, source)}: a negated lookup is not supported")
        out[iv.get("lookup", "row")] = name
        inputs.add(name)
    return out


def _factor(key: np.ndarray, bp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The upper breakpoint's index (1 .. len - 1) and the clamped factor."""
    r = np.clip(np.searchsorted(bp, key, side="left"), 1, len(bp) - 1)
    lo, hi = bp[r - 1], bp[r]
    f = np.clip((key - lo) / (hi - lo), 0.0, 1.0)
    return r, f


def _table(el: ET.Element, source: str, inputs: set[str]) -> Kernel:
    where = _where(el, source)
    extra = sorted(a for a in el.attrib if a not in ("_line", "name"))
    if extra:
        raise CompileError(f"{where}: attribute {extra[0]!r} is not supported")
    unknown = [c for c in _children(el) if c.tag not in ("independentVar", "tableData")]
    if unknown:
        raise CompileError(f"{_where(unknown[0], source)}: not supported in a table")
    datas = el.findall("tableData")
    look = _lookup(el, source, inputs)
    if set(look) == {"row", "column", "table"} and len(datas) >= 2:
        return _table3(datas, look, where, source)
    if len(datas) != 1 or set(look) - {"row", "column"} or "row" not in look:
        raise CompileError(f"{where}: only tables of one, two or three dimensions (one "
                           f"<tableData> and a row and optionally a column lookup; or a row, "
                           f"a column and a table lookup with a <tableData breakPoint=...> "
                           f"for each breakpoint) are supported")
    if "column" not in look:
        bp, val = table1_data(datas[0], source)
        rname = look["row"]

        def k1(v: Values) -> np.ndarray:
            key = np.asarray(v[rname], dtype=np.float64)
            if key.ndim == 1:
                return kernels.table1(bp, val, key)
            r, f = _factor(key, bp)
            return f * (val[r] - val[r - 1]) + val[r - 1]
        return k1
    rbp, cols, data = _grid(_numbers(datas[0], source), datas[0], source)
    rname, cname = look["row"], look["column"]

    def k2(v: Values) -> np.ndarray:
        rkey = np.asarray(v[rname], dtype=np.float64)
        ckey = np.asarray(v[cname], dtype=np.float64)
        if rkey.ndim == 1 and rkey.shape == ckey.shape:
            return kernels.table2(rbp, cols, data, rkey, ckey)
        r, rf = _factor(rkey, rbp)
        c, cf = _factor(ckey, cols)
        col1 = rf * (data[r, c - 1] - data[r - 1, c - 1]) + data[r - 1, c - 1]
        col2 = rf * (data[r, c] - data[r - 1, c]) + data[r - 1, c]
        return col1 + cf * (col2 - col1)
    return k2


def _grid(rows: list[list[float]], el: ET.Element, source: str
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A two-dimensional <tableData>: row breakpoints, column breakpoints, values."""
    cols = np.array(rows[0])
    body = rows[1:]
    if len(cols) < 2 or len(body) < 2 or any(len(r) != len(cols) + 1 for r in body):
        raise CompileError(f"{_where(el, source)}: a table of two dimensions needs a "
                           f"line of column breakpoints, then rows of a breakpoint and one "
                           f"value a column")
    rbp = np.array([r[0] for r in body])
    data = np.array([r[1:] for r in body])
    if np.any(np.diff(rbp) <= 0) or np.any(np.diff(cols) <= 0):
        raise CompileError(f"{_where(el, source)}: breakpoints must increase")
    return rbp, cols, data


def _table3(datas: list[ET.Element], look: dict[str, str], where: str, source: str) -> Kernel:
    """FGTable of three dimensions: one two-dimensional table per breakpoint
    of the table lookup, interpolated linearly between the two around the
    key; at or beyond the ends, the end table's value."""
    tbp, grids = [], []
    for d in datas:
        bp = d.get("breakPoint")
        extra = sorted(k for k in d.attrib if k not in ("_line", "breakPoint"))
        if bp is None or extra:
            raise CompileError(f"{_where(d, source)}: each <tableData> of a table of three "
                               f"dimensions needs a breakPoint attribute and no other")
        try:
            tbp.append(float(bp))
        except ValueError:
            raise CompileError(f"{_where(d, source)}: breakPoint {bp!r} is not a number") from None
        grids.append(_grid(_numbers(d, source), d, source))
    tb = np.array(tbp)
    if np.any(np.diff(tb) <= 0):
        raise CompileError(f"{where}: breakPoints must increase")
    rname, cname, tname = look["row"], look["column"], look["table"]

    def sub(v: Values, i: int) -> np.ndarray:
        rbp, cbp, data = grids[i]
        rkey = np.atleast_1d(np.asarray(v[rname], dtype=np.float64))
        ckey = np.broadcast_to(np.asarray(v[cname], dtype=np.float64), rkey.shape)
        return kernels.table2(rbp, cbp, data, np.ascontiguousarray(rkey),
                              np.ascontiguousarray(ckey))

    def k3(v: Values) -> np.ndarray:
        key = np.atleast_1d(np.asarray(v[tname], dtype=np.float64))
        r, f = _factor(key, tb)
        out = np.empty(np.broadcast(key, np.asarray(v[rname])).shape)
        for i in np.unique(r).tolist():  # the pairs of tables some aircraft are between
            m = r == i
            lo, hi = sub(v, i - 1), sub(v, i)
            val = f * (hi - lo) + lo
            val = np.where(key <= tb[0], lo, np.where(key >= tb[-1], hi, val))
            out[m] = np.broadcast_to(val, out.shape)[m]
        return out
    return k3


def compile_function(el: ET.Element, source: str) -> Compiled:
    """Compile one ``<function>`` element (its single operation)."""
    where = _where(el, source)
    if el.tag != "function":
        raise CompileError(f"{where}: expected <function>")
    extra = sorted(a for a in el.attrib if a not in ("_line", "name"))
    if extra:
        raise CompileError(f"{where}: attribute {extra[0]}={el.get(extra[0])!r} is not "
                           f"supported")
    kids = _children(el)
    if len(kids) != 1:
        raise CompileError(f"{where}: expected one operation, has {len(kids)}")
    inputs: set[str] = set()
    kernel = _op(kids[0], source, inputs)
    return Compiled(el.get("name", ""), frozenset(inputs), kernel, kids[0])


def read_functions(path: Path, *, skip_post: bool = True) -> dict[str, Compiled]:
    """Every named ``<function>`` of an aircraft file, compiled, in file
    order (``type="post"`` ones, which JSBSim runs after the frame, left out
    unless ``skip_post`` is False, and then refused)."""
    root = parse(path)
    out: dict[str, Compiled] = {}
    for el in root.iter("function"):
        if skip_post and el.get("type") == "post":
            continue
        if el.get("name"):
            out[el.get("name", "")] = compile_function(el, str(path))
    return out
