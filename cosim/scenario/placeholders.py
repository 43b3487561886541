"""The scenario language's ``${...}`` placeholders and the names they read
(a ``sweep:`` section's values).

A scenario names values in its ``sweep:`` section and uses them anywhere in
the file as ``${name}`` placeholders::

    sweep:
      speed_kt: [50, 100, 200]       # a list: swept
      alt_agl_m: [30, 100, 300]
      target: [truck, fire_truck]
      vfov_deg: 40                   # a single value: a constant
    vehicles:
      - {id: uav, model: uav700, init: {alt_agl_m: ${alt_agl_m}, airspeed_kt: ${speed_kt}}}
    targets:
      - {id: t, kind: ${target}, north_m: 0, east_m: 0}

Before the YAML is parsed each ``${...}`` is swapped for a plain token (so
placeholders need no quotes, even in flow style ``{a: ${x}}`` or with commas
in them); the tokens are then substituted in the parsed values, so every
value keeps the file line it was written on and errors still say
``file:line: path``. A value that is exactly one placeholder takes the
value's own type (``50`` stays a number); a placeholder inside a longer
string is replaced by the value's text (``name: pass-${target}``). A
placeholder may also be an arithmetic expression over the names: numbers,
``+ - * / // % **``, comparisons, ``and or not``, ``A if COND else B`` and
the functions ``tan sin cos atan asin acos radians degrees sqrt abs min max
round``, e.g. ``north_m: ${-(alt_agl_m * tan(radians(vfov_deg / 2)) + 40)}``.

Rules (each breach is a config error with file and line): names are
identifiers; a list holds at least one value, each a number, a string or a
boolean, without repeats; every placeholder is known and evaluates; a name
swept over several values is used by at least one placeholder (otherwise
every run would be the same). Placeholders are not substituted inside the
``sweep:`` section itself nor in mapping keys. The work of one placeholder
is bounded (``MAX_EXPR_CHARS`` ... ``MAX_ROUND_DIGITS``).

Loading a scenario uses the first value of each name (and says so in a log
line) unless given a combination (``cosim sweep`` loads each). After
substitution the ``sweep:`` section holds the combination used, as single
values, so ``scenario.resolved.yaml`` records it and loads again. Which
combinations a sweep runs is the sweep part's (``cosim.sweep.spec``).
"""

from __future__ import annotations

import ast
import functools
import logging
import math
import operator
import re
from collections.abc import Callable, Mapping
from typing import Any

from cosim.errors import ConfigError

log = logging.getLogger(__name__)

P = tuple[Any, ...]
Report = Callable[[P, str], None]
Scalar = int | float | str | bool

#: the ``sweep:`` key that says which combinations run (an expression, not a
#: name; ``cosim.sweep.spec`` reads it)
ONLY = "only"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_PLACEHOLDER = re.compile(r"\$\{([^}\n]*)\}")
TOKEN = re.compile(r"__cosim_placeholder_(\d+)__")

_FUNCS: dict[str, Callable[..., Any]] = {
    "tan": math.tan, "sin": math.sin, "cos": math.cos, "atan": math.atan, "asin": math.asin,
    "acos": math.acos, "radians": math.radians, "degrees": math.degrees, "sqrt": math.sqrt,
    "abs": abs, "min": min, "max": max, "round": round,
}
_CMPOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
    ast.Gt: operator.gt, ast.GtE: operator.ge,
}

#: what one placeholder may ask for: its text, its syntax tree, whole numbers
#: (as the scenario's, a signed 64-bit integer), text results, arguments
MAX_EXPR_CHARS = 500
MAX_EXPR_NODES = 200
MAX_INT = 2 ** 63 - 1
MAX_STR_CHARS = 1000
MAX_ARGS = 16
#: ``round(x, n)``: |n| at most this
MAX_ROUND_DIGITS = 20


class ExprError(Exception):
    pass


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _checked(v: Any) -> Any:
    """``v`` if it is within the limits (whole numbers, text length)."""
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > MAX_INT:
        raise ExprError(f"a whole number beyond +-{MAX_INT} (2**63 - 1)")
    if isinstance(v, str) and len(v) > MAX_STR_CHARS:
        raise ExprError(f"text longer than {MAX_STR_CHARS} characters")
    return v


def _pow(a: Any, b: Any) -> Any:
    """``a ** b`` for numbers, refused before computing when the result would
    exceed the limits (``10**10**10`` would otherwise run for hours)."""
    if not (_number(a) and _number(b)):
        raise ExprError("** takes numbers")
    if abs(a) not in (0, 1) and b > 0:
        bits = b * math.log2(abs(a))
        limit = 63 if isinstance(a, int) and isinstance(b, int) else 1023
        if bits > limit:
            raise ExprError(f"{format_value(a)} ** {format_value(b)} is too large")
    if a == 0 and b < 0:
        raise ExprError("0 to a negative power")
    return a ** b


def _mul(a: Any, b: Any) -> Any:
    if isinstance(a, str) or isinstance(b, str):  # text repeated: bound its length first
        text, n = (a, b) if isinstance(a, str) else (b, a)
        if not isinstance(n, int) or isinstance(n, (bool, str)) \
                or len(text) * max(n, 0) > MAX_STR_CHARS:
            raise ExprError(f"text repeated beyond {MAX_STR_CHARS} characters")
    return a * b


def _mod(a: Any, b: Any) -> Any:
    if not (_number(a) and _number(b)):
        raise ExprError("% takes numbers (no text formatting)")
    return a % b


_BINOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: _mul,
    ast.Div: operator.truediv, ast.FloorDiv: operator.floordiv, ast.Mod: _mod,
    ast.Pow: _pow,
}


def _call(name: str, args: list[Any]) -> Any:
    if len(args) > MAX_ARGS:
        raise ExprError(f"{name}() with more than {MAX_ARGS} arguments")
    if name == "round" and len(args) == 2:
        if not isinstance(args[1], int) or isinstance(args[1], bool) \
                or abs(args[1]) > MAX_ROUND_DIGITS:
            raise ExprError(f"round(x, n) takes a whole n within +-{MAX_ROUND_DIGITS}")
    return _FUNCS[name](*args)


def _eval(node: ast.AST, env: Mapping[str, Scalar]) -> Any:
    if isinstance(node, ast.Expression):
        return _eval(node.body, env)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool)):
        return _checked(node.value)
    if isinstance(node, ast.Name):
        if node.id not in env:
            raise ExprError(f"unknown name {node.id!r}")
        return env[node.id]
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        return _checked(_BINOPS[type(node.op)](_eval(node.left, env), _eval(node.right, env)))
    if isinstance(node, ast.UnaryOp):
        v = _eval(node.operand, env)
        if isinstance(node.op, ast.USub):
            return _checked(-v)
        if isinstance(node.op, ast.UAdd):
            return +v
        if isinstance(node.op, ast.Not):
            return not v
    if isinstance(node, ast.BoolOp):
        vals = [_eval(v, env) for v in node.values]
        return all(vals) if isinstance(node.op, ast.And) else any(vals)
    if isinstance(node, ast.Compare) and all(type(o) in _CMPOPS for o in node.ops):
        left = _eval(node.left, env)
        for op, comp in zip(node.ops, node.comparators):
            right = _eval(comp, env)
            if not _CMPOPS[type(op)](left, right):
                return False
            left = right
        return True
    if isinstance(node, ast.IfExp):
        cond = _eval(node.test, env)
        return _eval(node.body if cond else node.orelse, env)
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in _FUNCS and not node.keywords):
        return _checked(_call(node.func.id, [_eval(a, env) for a in node.args]))
    raise ExprError(f"not allowed in a placeholder: {ast.unparse(node)[:80]!r}")


@functools.lru_cache(maxsize=4096)
def _parse(expr: str) -> tuple[ast.Expression | None, frozenset[str], str | None]:
    """(syntax tree, names it mentions, problem) of one expression, parsed once
    however many sweep combinations evaluate it. Every name mentioned counts as
    used, also in a branch not taken, and the names of an expression that
    cannot be parsed too, so a typo is not also reported as "unused"."""
    if len(expr) > MAX_EXPR_CHARS:
        words = frozenset(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", expr[:MAX_EXPR_CHARS * 4]))
        return None, words, f"longer than {MAX_EXPR_CHARS} characters"
    try:
        tree = ast.parse(expr.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return None, frozenset(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", expr)), \
            "not a valid expression"
    nodes = list(ast.walk(tree))
    names = frozenset(n.id for n in nodes if isinstance(n, ast.Name))
    if len(nodes) > MAX_EXPR_NODES:
        return None, names, f"more than {MAX_EXPR_NODES} terms"
    return tree, names, None


def evaluate(expr: str, env: Mapping[str, Scalar], used: set[str] | None = None) -> Scalar:
    """The value of one placeholder's expression; ``used`` collects the names it
    reads. The work is bounded: at most ``MAX_EXPR_CHARS`` characters and
    ``MAX_EXPR_NODES`` syntax nodes, whole numbers within +-``MAX_INT``
    (powers checked before they are computed), text within ``MAX_STR_CHARS``;
    anything beyond is an ``ExprError``, found in microseconds."""
    used = used if used is not None else set()
    tree, names, problem = _parse(expr)
    used.update(names)
    if problem is not None or tree is None:
        raise ExprError(problem or "not a valid expression")
    try:
        value = _eval(tree, env)
    except ExprError:
        raise
    except (ArithmeticError, TypeError, ValueError, RecursionError, MemoryError) as e:
        raise ExprError(f"{type(e).__name__}: {e}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise ExprError(f"the result is {value}")
    if not isinstance(value, (int, float, str, bool)):
        raise ExprError(f"the result is not a number, string or boolean: {value!r}")
    return value


def format_value(v: Scalar) -> str:
    """A value as text: ``50``, ``2.5``, ``truck``, ``true``."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.12g}" if v != int(v) or abs(v) >= 1e15 else str(int(v))
    return str(v)


def sweep_values(node: Any, err: Report, path: P = ("sweep",)) -> dict[str, tuple[Scalar, ...]]:
    """The names and their values from a ``sweep:`` node (a single value becomes
    a one-value tuple); problems go to ``err``."""
    if node is None:
        return {}
    if not isinstance(node, dict):
        err(path, f"expected a mapping of name: [values], got {type(node).__name__}")
        return {}
    out: dict[str, tuple[Scalar, ...]] = {}
    for name, vals in node.items():
        p = path + (name,)
        if name == ONLY:  # which combinations run (``read_sweep``), not a name
            continue
        if not isinstance(name, str) or not _NAME.match(name):
            err(p, f"sweep name {name!r} must be an identifier (letters, digits, _)")
            continue
        items = vals if isinstance(vals, list) else [vals]
        if not items:
            err(p, "expected at least one value")
            continue
        good = True
        for i, v in enumerate(items):
            if not isinstance(v, (int, float, str, bool)) or (
                    isinstance(v, float) and not math.isfinite(v)):
                err(p + ((i,) if isinstance(vals, list) else ()),
                    f"expected a number, a string or a boolean, got {v!r}")
                good = False
        seen: list[Any] = []
        for v in items:
            if any(v == s and type(v) is type(s) for s in seen):
                err(p, f"value {format_value(v)} is listed twice")
                good = False
            seen.append(v)
        if good:
            out[name] = tuple(items)
    return out


def swept_names(node: Any) -> list[str]:
    """Names given as a list in the ``sweep:`` node (the swept ones, not constants)."""
    if not isinstance(node, dict):
        return []
    return [k for k, v in node.items() if isinstance(v, list) and k != ONLY]


def protect_placeholders(text: str) -> tuple[str, dict[str, str]]:
    """Swap every ``${expr}`` in the YAML text for a token that parses as a
    plain string anywhere (line numbers unchanged); return the text and
    token -> expr."""
    exprs: dict[str, str] = {}

    def swap(m: re.Match[str]) -> str:
        token = f"__cosim_placeholder_{len(exprs)}__"
        exprs[token] = m.group(1)
        return token

    return _PLACEHOLDER.sub(swap, text), exprs


def _substitute_str(s: str, exprs: Mapping[str, str], env: Mapping[str, Scalar],
                    used: set[str], err: Report, path: P) -> Any:
    def one(token: str) -> Scalar:
        expr = exprs.get(token, token)
        try:
            return evaluate(expr, env, used)
        except ExprError as e:
            names = ", ".join(env) or "none (no sweep: section)"
            raise ExprError(f"cannot substitute ${{{expr}}}: {e}; sweep names: {names}"
                             ) from None

    try:
        if TOKEN.fullmatch(s):
            return one(s)
        return TOKEN.sub(lambda m: format_value(one(m.group(0))), s)
    except ExprError as e:
        err(path, str(e))
        return _restore(s, exprs)


def _restore(s: str, exprs: Mapping[str, str]) -> str:
    """The text as written: tokens back to ``${...}``."""
    return TOKEN.sub(lambda m: "${" + exprs.get(m.group(0), "?") + "}", s)


def substitute(data: Any, err: Report, point: Mapping[str, Any] | None = None,
               fname: str = "<scenario>", exprs: Mapping[str, str] | None = None) -> Any:
    """Replace every placeholder token in ``data`` (YAML parsed from the text
    of ``protect_placeholders``; ``exprs`` its token -> expr) with its value at
    ``point`` (default: the first value of each name) and replace the
    ``sweep:`` section with the point used. Problems go to ``err``."""
    exprs = exprs or {}
    raw = data.get("sweep") if isinstance(data, dict) else None
    values = sweep_values(raw, err)
    if point is None:
        env: dict[str, Scalar] = {k: v[0] for k, v in values.items()}
        if any(len(v) > 1 for v in values.values()):
            log.info("%s: a sweep scenario; this run uses the first value of each swept name "
                     "(%s); 'cosim sweep' runs every combination", fname,
                     ", ".join(f"{k}={format_value(v)}" for k, v in env.items()))
    else:
        env = dict(point)
        if set(env) != set(values):
            raise ConfigError(f"{fname}: sweep point names {sorted(env)} differ from the "
                              f"sweep: section's {sorted(values)}")
    used: set[str] = set()

    def walk(x: Any, path: P) -> Any:
        if isinstance(x, dict):
            for k in x:
                if isinstance(k, str) and TOKEN.search(k):
                    err(path, f"placeholders are not substituted in keys: "
                              f"{_restore(k, exprs)!r}")
            return {k: (_no_tokens(x[k], err, path + (k,)) if path == () and k == "sweep"
                        else walk(x[k], path + (k,))) for k in x}
        if isinstance(x, list):
            return [walk(v, path + (i,)) for i, v in enumerate(x)]
        if isinstance(x, str) and "__cosim_placeholder_" in x:
            return _substitute_str(x, exprs, env, used, err, path)
        return x

    out = walk(data, ())
    for name, vals in values.items():
        if len(vals) > 1 and name not in used:
            err(("sweep", name), f"{name!r} is swept over {len(vals)} values but no "
                                 f"placeholder uses it; write ${{{name}}} where it belongs")
    if isinstance(out, dict) and "sweep" in out:
        out["sweep"] = env  # the point used: scenario.resolved.yaml records it
    return out


def _no_tokens(x: Any, err: Report, path: P) -> Any:
    if isinstance(x, dict):
        for k, v in x.items():
            _no_tokens(v, err, path + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            _no_tokens(v, err, path + (i,))
    elif isinstance(x, str) and TOKEN.search(x):
        err(path, "placeholders are not allowed in the sweep: section")
    return x
