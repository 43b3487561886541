"""The scenario reader's problem list and typed access: every problem of a
file collected at once with its line (``Problems``), each mapping read
through a ``Reader`` that checks types and ranges and reports unknown keys,
vehicles chosen by id or pattern (``select``). The scenario's parts and the
study files (``cosim.trials.study``) read through these."""

from __future__ import annotations

import math
import re
from fnmatch import fnmatchcase
from typing import Any

from cosim.core import limits as lim
from cosim.errors import ConfigError
from cosim.scenario.yaml_lines import format_path

P = tuple[Any, ...]
#: an identifier that may become part of a file name (vehicle ids)
ID = re.compile(rf"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]{{0,{lim.MAX_NAME_CHARS - 1}}}$")
ID_RULE = (f"may only contain letters, digits, '_', '.', '-', must not start with '.' and "
           f"may be at most {lim.MAX_NAME_CHARS} characters")


class Problems:
    """Collects problems with file and line."""

    def __init__(self, fname: str, lines: dict[P, int], vehicles: Any = None) -> None:
        self.fname = fname
        self.lines = lines
        self.problems: list[tuple[int, str]] = []
        self.more = 0  # problems found beyond MAX_PROBLEMS_KEPT (counted only)
        self.vehicles = vehicles  # the ``vehicles:`` node as written (``declared``)
        self._declared: list[str] | None = None

    def declared(self) -> list[str]:
        """The vehicle ids the ``vehicles:`` entries ask for, those in error
        included (a pattern matching one of them has been answered by that
        entry's own problem)."""
        if self._declared is None:
            self._declared = []
            for vd in self.vehicles if isinstance(self.vehicles, list) else []:
                vid = vd.get("id") if isinstance(vd, dict) else None
                if not isinstance(vid, str):
                    continue
                n = vd.get("count", 1)
                n = n if isinstance(n, int) and 1 <= n <= lim.MAX_ALL_VEHICLES else 1
                w = len(str(n - 1))
                self._declared += [vid] if n == 1 else [f"{vid}{j:0{w}d}" for j in range(n)]
        return self._declared

    def line(self, path: P) -> int:
        while path and path not in self.lines:
            path = path[:-1]
        return self.lines.get(path, 1)

    def err(self, path: P, msg: str) -> None:
        self.add((self.line(path), f"{format_path(path)}: {msg}"))

    def add(self, problem: tuple[int, str]) -> None:
        """Keep ``(line, message)``, or count it beyond ``MAX_PROBLEMS_KEPT``."""
        if len(self.problems) >= lim.MAX_PROBLEMS_KEPT:
            self.more += 1
            return
        self.problems.append(problem)

    def format(self) -> list[str]:
        return [f"{self.fname}:{ln}: {m}" for ln, m in sorted(self.problems, key=lambda x: x[0])]

    def error(self) -> ConfigError:
        return ConfigError(self.format(), self.more)


MISSING = object()


def clip(text: str, n: int = 80) -> str:
    """``text`` cut to ``n`` characters for a message (with how long it was)."""
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"


def describe(v: Any) -> str:
    if isinstance(v, dict):
        return "a mapping"
    if isinstance(v, list):
        return "a list"
    if v is None:
        return "nothing (null)"
    return repr(v)


class Reader:
    """Typed access to one mapping, reporting into a context."""

    def __init__(self, ctx: Problems, d: Any, path: P, allowed: tuple[str, ...]) -> None:
        self.ctx, self.path = ctx, path
        if not isinstance(d, dict):
            ctx.err(path, f"expected a mapping, got {describe(d)}")
            d = {}
        self.d = d
        for k in d:
            if k not in allowed:
                ctx.err(path + (k,), f"unknown key {k!r}; expected one of: {', '.join(allowed)}")

    def has(self, key: str) -> bool:
        return key in self.d

    def _absent(self, key: str, default: Any) -> tuple[bool, Any]:
        """(True, what to return) when ``key`` is not given: its default, or
        None once a required key is reported missing; (False, None) when it is."""
        if key in self.d:
            return False, None
        if default is MISSING:
            self.ctx.err(self.path, f"missing required key {key!r}")
            return True, None
        return True, default

    def num(self, key: str, default: Any = MISSING, lo: float | None = None,
            hi: float | None = None, lo_open: bool = False) -> Any:
        absent, out = self._absent(key, default)
        if absent:
            return out
        p, v = self.path + (key,), self.d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.ctx.err(p, f"expected a number, got {describe(v)}")
            return None
        if lo is not None and (v <= lo if lo_open else v < lo):
            self.ctx.err(p, f"must be {'>' if lo_open else '>='} {lo:g}, got {v!r}")
            return None
        if hi is not None and v > hi:
            self.ctx.err(p, f"must be <= {hi:g}, got {v!r}")
            return None
        if abs(v) > lim.MAX_NUMBER:  # a field without its own range: still bounded
            self.ctx.err(p, f"{v:g} is out of range (no scenario value exceeds "
                            f"+-{lim.MAX_NUMBER:g}; a unit mistake?)")
            return None
        return float(v)

    def integer(self, key: str, default: Any = MISSING, lo: int | None = None,
                hi: int | None = None) -> Any:
        absent, out = self._absent(key, default)
        if absent:
            return out
        p, v = self.path + (key,), self.d[key]
        if isinstance(v, bool) or not isinstance(v, int):
            self.ctx.err(p, f"expected a whole number, got {describe(v)}")
            return None
        if lo is not None and v < lo:
            self.ctx.err(p, f"must be >= {lo}, got {v}")
            return None
        if hi is not None and v > hi:
            self.ctx.err(p, f"must be <= {hi}, got {v}")
            return None
        return v

    def string(self, key: str, default: Any = MISSING, pattern: re.Pattern[str] | None = None,
               choices: tuple[str, ...] | None = None) -> Any:
        absent, out = self._absent(key, default)
        if absent:
            return out
        p, v = self.path + (key,), self.d[key]
        if not isinstance(v, str):
            self.ctx.err(p, f"expected a string, got {describe(v)}")
            return None
        if choices is not None and v not in choices:
            self.ctx.err(p, f"expected one of: {', '.join(choices)}; got {v!r}")
            return None
        if pattern is not None and not pattern.match(v):
            self.ctx.err(p, f"{clip(v)!r} {ID_RULE}")
            return None
        return v

    def boolean(self, key: str, default: bool) -> bool:
        v = self.d.get(key, default)
        if not isinstance(v, bool):
            self.ctx.err(self.path + (key,), f"expected true or false, got {describe(v)}")
            return default
        return v

    def one_of(self, *keys: str) -> str | None:
        present = [k for k in keys if k in self.d]
        if len(present) > 1:
            self.ctx.err(self.path,
                         f"give only one of {' / '.join(keys)}, not {' and '.join(present)}")
            return None
        return present[0] if present else None


def prop_values(ctx: Problems, d: Any, path: P) -> list[tuple[str, float]]:
    """A ``{jsbsim/property: number}`` mapping."""
    out: list[tuple[str, float]] = []
    if not isinstance(d, dict) or not d:
        ctx.err(path, f"expected a non-empty mapping of JSBSim property: value, got {describe(d)}")
        return out
    for k, v in d.items():
        if not isinstance(k, str) or not re.match(r"^[A-Za-z0-9_\-/\[\].]+$", k):
            ctx.err(path + (k,), f"{k!r} is not a JSBSim property name")
        elif isinstance(v, bool):
            out.append((k, 1.0 if v else 0.0))
        elif not isinstance(v, (int, float)) or not math.isfinite(v):
            ctx.err(path + (k,), f"expected a number, got {describe(v)}")
        elif abs(v) > lim.MAX_NUMBER:
            ctx.err(path + (k,), f"{v:g} is out of range (no scenario value exceeds "
                                 f"+-{lim.MAX_NUMBER:g}; a unit mistake?)")
        else:
            out.append((k, float(v)))
    return out


def select(ctx: Problems, sel: Any, path: P, ids: list[str]) -> list[int]:
    if sel == "all":
        return list(range(len(ids)))
    pats = [sel] if isinstance(sel, str) else sel
    if not isinstance(pats, list) or not pats or not all(isinstance(x, str) for x in pats):
        ctx.err(path, f"expected 'all', a vehicle id, a pattern such as 'uav*', or a list of "
                      f"them; got {describe(sel)}")
        return []
    chosen: set[int] = set()
    for pat in pats:
        hits = [i for i, v in enumerate(ids) if fnmatchcase(v, pat)]
        if not hits and not any(fnmatchcase(v, pat) for v in ctx.declared()):
            shown = ", ".join(ids[:8]) + (", ..." if len(ids) > 8 else "")
            ctx.err(path, f"{pat!r} matches no vehicle (vehicles: {shown})")
        chosen.update(hits)
    return sorted(chosen)
