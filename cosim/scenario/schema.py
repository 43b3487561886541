"""Scenario files (YAML, ``schema_version: 1``) -> validated, frozen ``Scenario``.

Every problem is collected and reported at once, each as
``file:line: path: message``; unknown keys are errors; model names are
looked up on the aircraft search path and JSBSim property names are checked
to exist in the model (JSBSim silently creates misspelled properties).
This module owns the schema; it never steps an FDM.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from cosim.core import limits as lim
from cosim.core.geo import LocalFrame
from cosim.core.section import Section, scenario_sections
from cosim.core.state import VehicleSpec
from cosim.core.units import KT_TO_MPS
from cosim.errors import ConfigError, CosimError
from cosim.guidance import (
    DEFAULT_BANK_LIMIT_DEG,
    Command,
    parse_command,
)
from cosim.guidance.safety import Limits, speed_after
from cosim.jsb import find_model, has_property, is_writable, new_fdm
from cosim.scenario.formation import FORMATIONS, formation_offsets
from cosim.scenario.yaml_lines import (
    YamlProblem,
    format_path,
    load_with_lines,
    read_scenario_text,
)
from cosim.vehicles import DEFAULT_CLASS, ModelChoice, VehicleClass, get_class
from cosim.world import World

SCHEMA_VERSION = 1
ALT_MIN_M, ALT_MAX_M = -500.0, 100_000.0  # every vehicle's resolved height must lie here
#: an identifier that may become part of a file name (vehicle ids)
_ID = re.compile(rf"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]{{0,{lim.MAX_NAME_CHARS - 1}}}$")
_ID_RULE = (f"may only contain letters, digits, '_', '.', '-', must not start with '.' and "
            f"may be at most {lim.MAX_NAME_CHARS} characters")
#: what a scenario name may not hold (it names the run's folder)
_NAME_UNSAFE = re.compile(r"[/\\\x00-\x1f\x7f]")
P = tuple[Any, ...]


@dataclass(frozen=True)
class Origin:
    lat_deg: float
    lon_deg: float
    ground_alt_m: float = 0.0

    @property
    def frame(self) -> LocalFrame:
        return LocalFrame(self.lat_deg, self.lon_deg, self.ground_alt_m)


@dataclass(frozen=True)
class Rates:
    physics_hz: float = 120.0
    control_hz: float = 30.0
    log_hz: float = 10.0

    @property
    def dt_s(self) -> float:
        return 1.0 / self.physics_hz

    @property
    def control_every(self) -> int:
        """Physics ticks per control exchange."""
        return round(self.physics_hz / self.control_hz)

    @property
    def log_every(self) -> int:
        """Physics ticks per logged row."""
        return round(self.physics_hz / self.log_hz)


@dataclass(frozen=True)
class ScheduleItem:
    at_s: float
    tick: int  # the control tick at which it applies (first at or after at_s)
    vehicles: tuple[int, ...]  # indices into Scenario.vehicles
    sets: tuple[tuple[str, float], ...]
    index: int = 0  # position in the file's schedule list
    command: Command | None = None  # the fixed-wing command vocabulary


@dataclass(frozen=True)
class Scenario:
    name: str
    path: str
    origin: Origin
    rates: Rates
    duration_s: float
    seed: int
    vehicles: tuple[VehicleSpec, ...]
    schedule: tuple[ScheduleItem, ...] = ()
    description: str = ""
    aircraft_path: tuple[str, ...] = ()
    plot: bool = False  # write track.png (ground track and altitude) after the run
    #: MAVLink link of the run: {"url": ..., "rates_hz": {...}}; None: no MAVLink
    mavlink: dict[str, Any] | None = None
    #: parsed top-level sections (``cosim.scenario.sections``): key -> object
    sections: dict[str, Any] = field(default_factory=dict, compare=False)
    #: what exists in the scenario (ground, targets, obstacles), from the sections
    world: World = field(default_factory=World, compare=False)
    #: the sections as written (YAML data), for ``resolved_dict``
    section_sources: dict[str, Any] = field(default_factory=dict, compare=False)
    schema_version: int = SCHEMA_VERSION
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def total_ticks(self) -> int:
        """Physics ticks in the run, rounded up to whole control exchanges (at least one)."""
        return _total_ticks(self.duration_s, self.rates)

    @property
    def folder_name(self) -> str:
        """The name as a folder name (``runs/<folder_name>-<date>-<time>``): every
        character but letters, digits, ``_ . -`` becomes ``_``."""
        return safe_folder_name(self.name)

    @property
    def classes(self) -> tuple[str, ...]:
        """The vehicle classes of the run, in order of first appearance."""
        return tuple(dict.fromkeys(v.vehicle_class for v in self.vehicles))

    @property
    def channels(self) -> tuple[str, ...]:
        """Setpoint channels: each class's (its guidance's), then every JSBSim
        property the schedule writes, in first-use order."""
        seen: dict[str, None] = {}
        for name in self.classes:
            seen.update(dict.fromkeys(get_class(name).channels))
        for item in self.schedule:
            for name, _ in item.sets:
                seen.setdefault(name)
        return tuple(seen)

    def with_duration(self, duration_s: float) -> Scenario:
        import dataclasses

        return dataclasses.replace(self, duration_s=float(duration_s))

    def resolved_dict(self) -> dict[str, Any]:
        """A scenario document equivalent to this one with every vehicle listed
        (loads back to the same vehicles, bit for bit)."""
        vehicles = []
        for v in self.vehicles:
            cls = get_class(v.vehicle_class)
            d: dict[str, Any] = {"id": v.id, "class": v.vehicle_class}
            if cls.model_kind == "jsbsim":
                d["model"] = v.model
            d["init"] = {"lat_deg": v.lat_deg, "lon_deg": v.lon_deg, "alt_msl_m": v.alt_msl_m,
                         "heading_deg": v.heading_deg, "airspeed_mps": v.airspeed_mps}
            if not v.trim and "trim" in cls.vehicle_keys:
                d["trim"] = False
            if v.initial_props and "set" in cls.vehicle_keys:
                d["set"] = dict(v.initial_props)
            d.update({k: v.class_params[k] for k in cls.vehicle_keys
                      if k not in ("trim", "set") and v.class_params.get(k) is not None})
            d["random_seed"] = v.random_seed
            vehicles.append(d)
        ids = [v.id for v in self.vehicles]
        return {
            "schema_version": self.schema_version,
            "name": self.name,
            "description": self.description,
            "origin": {"lat_deg": self.origin.lat_deg, "lon_deg": self.origin.lon_deg,
                       "ground_alt_m": self.origin.ground_alt_m},
            "rates": {"physics_hz": self.rates.physics_hz, "control_hz": self.rates.control_hz,
                      "log_hz": self.rates.log_hz},
            "duration_s": self.duration_s,
            "seed": self.seed,
            "aircraft_path": list(self.aircraft_path),
            "plot": self.plot,
            **({"mavlink": self.mavlink} if self.mavlink is not None else {}),
            "vehicles": vehicles,
            "schedule": [self._item_dict(s, ids) for s in self.schedule],
            **self.section_sources,
        }


    @staticmethod
    def _item_dict(s: ScheduleItem, ids: list[str]) -> dict[str, Any]:
        d: dict[str, Any] = {"at_s": s.at_s, "vehicles": [ids[i] for i in s.vehicles]}
        if s.sets:
            d["set"] = dict(s.sets)
        if s.command is not None:
            d["command"] = s.command.source
        return d


class _Ctx:
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


_MISSING = object()


def _clip(text: str, n: int = 80) -> str:
    """``text`` cut to ``n`` characters for a message (with how long it was)."""
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"


def safe_folder_name(name: str) -> str:
    """``name`` as one safe folder name: letters, digits and ``_ . -`` kept,
    everything else ``_``, no leading ``.``, at most ``MAX_NAME_CHARS``."""
    out = re.sub(r"[^A-Za-z0-9_.\-]", "_", name)[:lim.MAX_NAME_CHARS].lstrip(".")
    return out or "run"


def _name(ctx: _Ctx, name: str | None, given: bool) -> str | None:
    """The scenario's ``name`` (it names the run folder): refused when it could
    leave its folder (a path separator, ``..``) or is unprintable or long."""
    if name is None or not given:
        return name
    path: P = ("name",)
    if _NAME_UNSAFE.search(name) or ".." in name:
        ctx.err(path, f"{_clip(name)!r} may not contain '/', '\\', '..' or control "
                      f"characters: it names the run's folder (runs/<name>-<date>-<time>)")
        return None
    if not name.strip() or len(name) > lim.MAX_NAME_CHARS:
        ctx.err(path, f"{_clip(name)!r}: expected 1 to {lim.MAX_NAME_CHARS} characters")
        return None
    return name


def _aircraft_path(ctx: _Ctx, entries: list[str], base: Path) -> list[str]:
    """The ``aircraft_path`` folders, resolved against the scenario's folder;
    each must exist and hold at least one JSBSim model (``NAME/NAME.xml``)."""
    out = []
    for i, raw in enumerate(entries):
        p = (base / raw).resolve()
        where: P = ("aircraft_path", i)
        if not p.is_dir():
            ctx.err(where, f"{raw!r}: {'not a folder' if p.exists() else 'no such folder'} "
                           f"({p})")
            continue
        try:
            has_model = any((sub / f"{sub.name}.xml").is_file() for sub in p.iterdir())
        except OSError as e:
            ctx.err(where, f"{raw!r}: cannot list {p}: {e.strerror or e}")
            continue
        if not has_model:
            ctx.err(where, f"{raw!r}: {p} holds no aircraft model (a folder NAME with "
                           f"NAME.xml in it)")
            continue
        out.append(str(p))
    return out


def _describe(v: Any) -> str:
    if isinstance(v, dict):
        return "a mapping"
    if isinstance(v, list):
        return "a list"
    if v is None:
        return "nothing (null)"
    return repr(v)


class _Reader:
    """Typed access to one mapping, reporting into a context."""

    def __init__(self, ctx: _Ctx, d: Any, path: P, allowed: tuple[str, ...]) -> None:
        self.ctx, self.path = ctx, path
        if not isinstance(d, dict):
            ctx.err(path, f"expected a mapping, got {_describe(d)}")
            d = {}
        self.d = d
        for k in d:
            if k not in allowed:
                ctx.err(path + (k,), f"unknown key {k!r}; expected one of: {', '.join(allowed)}")

    def has(self, key: str) -> bool:
        return key in self.d

    def num(self, key: str, default: Any = _MISSING, lo: float | None = None,
            hi: float | None = None, lo_open: bool = False) -> Any:
        p = self.path + (key,)
        if key not in self.d:
            if default is _MISSING:
                self.ctx.err(self.path, f"missing required key {key!r}")
                return None
            return default
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.ctx.err(p, f"expected a number, got {_describe(v)}")
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

    def integer(self, key: str, default: Any = _MISSING, lo: int | None = None,
                hi: int | None = None) -> Any:
        p = self.path + (key,)
        if key not in self.d:
            if default is _MISSING:
                self.ctx.err(self.path, f"missing required key {key!r}")
                return None
            return default
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, int):
            self.ctx.err(p, f"expected a whole number, got {_describe(v)}")
            return None
        if lo is not None and v < lo:
            self.ctx.err(p, f"must be >= {lo}, got {v}")
            return None
        if hi is not None and v > hi:
            self.ctx.err(p, f"must be <= {hi}, got {v}")
            return None
        return v

    def string(self, key: str, default: Any = _MISSING, pattern: re.Pattern[str] | None = None,
               choices: tuple[str, ...] | None = None) -> Any:
        p = self.path + (key,)
        if key not in self.d:
            if default is _MISSING:
                self.ctx.err(self.path, f"missing required key {key!r}")
                return None
            return default
        v = self.d[key]
        if not isinstance(v, str):
            self.ctx.err(p, f"expected a string, got {_describe(v)}")
            return None
        if choices is not None and v not in choices:
            self.ctx.err(p, f"expected one of: {', '.join(choices)}; got {v!r}")
            return None
        if pattern is not None and not pattern.match(v):
            self.ctx.err(p, f"{_clip(v)!r} {_ID_RULE}")
            return None
        return v

    def boolean(self, key: str, default: bool) -> bool:
        v = self.d.get(key, default)
        if not isinstance(v, bool):
            self.ctx.err(self.path + (key,), f"expected true or false, got {_describe(v)}")
            return default
        return v

    def one_of(self, *keys: str) -> str | None:
        present = [k for k in keys if k in self.d]
        if len(present) > 1:
            self.ctx.err(self.path,
                         f"give only one of {' / '.join(keys)}, not {' and '.join(present)}")
            return None
        return present[0] if present else None


def _prop_values(ctx: _Ctx, d: Any, path: P) -> list[tuple[str, float]]:
    """A ``{jsbsim/property: number}`` mapping."""
    out: list[tuple[str, float]] = []
    if not isinstance(d, dict) or not d:
        ctx.err(path, f"expected a non-empty mapping of JSBSim property: value, got {_describe(d)}")
        return out
    for k, v in d.items():
        if not isinstance(k, str) or not re.match(r"^[A-Za-z0-9_\-/\[\].]+$", k):
            ctx.err(path + (k,), f"{k!r} is not a JSBSim property name")
        elif isinstance(v, bool):
            out.append((k, 1.0 if v else 0.0))
        elif not isinstance(v, (int, float)) or not math.isfinite(v):
            ctx.err(path + (k,), f"expected a number, got {_describe(v)}")
        elif abs(v) > lim.MAX_NUMBER:
            ctx.err(path + (k,), f"{v:g} is out of range (no scenario value exceeds "
                                 f"+-{lim.MAX_NUMBER:g}; a unit mistake?)")
        else:
            out.append((k, float(v)))
    return out


class Memo:
    """Work shared by the loads of one scenario file at many sweep
    combinations (``cosim validate`` and ``cosim sweep`` load every one): the
    file is read and parsed once, and a part whose input, once the
    placeholders are substituted, equals that of an earlier combination is not
    checked again: its result is reused and its problems reported again,
    exactly as a fresh check would report them. At most ``MAX_PARTS`` results
    of each part are kept (the most recent)."""

    MAX_PARTS = 64

    def __init__(self) -> None:
        self._texts: dict[str, str] = {}
        self._parsed: dict[str, tuple[Any, dict[P, int], list[tuple[int, str]],
                                      dict[str, str]]] = {}
        self._parts: dict[str, dict[Any, tuple[Any, list[tuple[int, str]], int]]] = {}
        #: (model, aircraft folder) -> an FDM whose properties are looked up
        self.fdms: dict[tuple[str, str], Any] = {}
        self.hits = 0  # parts reused (for tests and progress)

    def read(self, path: Path) -> str:
        key = str(path)
        if key not in self._texts:
            self._texts = {key: read_scenario_text(path)}  # one file at a time
        return self._texts[key]

    def parsed(self, text: str, fname: str
               ) -> tuple[Any, dict[P, int], list[tuple[int, str]], dict[str, str]]:
        """(data, lines, duplicate-key problems, placeholders) of ``text``.
        The data is shared: callers must not change it (``substitute`` copies)."""
        if text not in self._parsed:
            from cosim.scenario.placeholders import protect_placeholders

            protected, placeholders = protect_placeholders(text)
            try:
                data, lines, dups = load_with_lines(protected)
            except YamlProblem as e:
                raise ConfigError([f"{fname}:{ln}: {m}" for ln, m in e.problems]) from None
            self._parsed = {text: (data, lines, dups, placeholders)}
        return self._parsed[text]

    def part(self, name: str, key: Any, ctx: _Ctx, check: Callable[[_Ctx], Any]) -> Any:
        """``check(sub)`` (a part's check, reporting into ``sub``), or its
        result for the same ``key`` kept from an earlier call; its problems
        are reported into ``ctx`` either way."""
        kept = self._parts.setdefault(name, {})
        if key in kept:
            self.hits += 1
            result, problems, more = kept.pop(key)
        else:
            sub = _Ctx(ctx.fname, ctx.lines, ctx.vehicles)
            result = check(sub)
            problems, more = sub.problems, sub.more
            if len(kept) >= self.MAX_PARTS:
                del kept[next(iter(kept))]
        kept[key] = (result, problems, more)  # most recent last
        for problem in problems:
            ctx.add(problem)
        ctx.more += more
        return result


def load_scenario(path: str | Path, check_properties: bool = True,
                  sweep_point: dict[str, Any] | None = None, memo: Memo | None = None
                  ) -> Scenario:
    """Read, validate and resolve a scenario file; ``ConfigError`` lists every problem.
    ``sweep_point``: the values of the ``sweep:`` names (default: the first of each).
    ``memo``: shared by the loads of one file at several sweep points (see ``Memo``)."""
    p = Path(path)
    text = memo.read(p) if memo is not None else read_scenario_text(p)
    return parse_scenario(text, str(p), check_properties=check_properties,
                          sweep_point=sweep_point, memo=memo)


def check_scenario(path: str | Path, sweep_point: dict[str, Any] | None = None,
                   memo: Memo | None = None) -> None:
    """``load_scenario`` without its result: ``ConfigError`` listing every
    problem, or nothing. Quicker where only the problems matter (the vehicles'
    random seeds are not derived)."""
    p = Path(path)
    text = memo.read(p) if memo is not None else read_scenario_text(p)
    _parse(text, str(p), True, sweep_point, memo, seeds=False)


def parse_scenario(text: str, fname: str = "<scenario>", check_properties: bool = True,
                   sweep_point: dict[str, Any] | None = None, memo: Memo | None = None
                   ) -> Scenario:
    scn = _parse(text, fname, check_properties, sweep_point, memo, seeds=True)
    assert scn is not None
    return scn


def _parse(text: str, fname: str, check_properties: bool, sweep_point: dict[str, Any] | None,
           memo: Memo | None, seeds: bool) -> Scenario | None:
    from cosim.scenario.placeholders import substitute

    memo = memo or Memo()
    data, lines, dups, placeholders = memo.parsed(text, fname)
    ctx = _Ctx(fname, lines)
    ctx.problems.extend(dups)
    data = substitute(data, ctx.err, sweep_point, fname, placeholders)
    ctx.vehicles = data.get("vehicles") if isinstance(data, dict) else None
    top = _Reader(ctx, data, (), ("schema_version", "name", "description", "origin", "rates",
                                  "duration_s", "seed", "aircraft_path", "plot", "mavlink",
                                  "vehicles", "schedule", *scenario_sections()))
    version = top.integer("schema_version")
    if version is not None and version != SCHEMA_VERSION:
        ctx.err(("schema_version",), f"unsupported schema_version {version}; this cosim reads "
                                     f"{SCHEMA_VERSION}")
    name = _name(ctx, top.string("name", Path(fname).stem), top.has("name"))
    description = top.string("description", "")
    o = _Reader(ctx, top.d.get("origin"), ("origin",), ("lat_deg", "lon_deg", "ground_alt_m"))
    origin = Origin(o.num("lat_deg", lo=-90, hi=90) or 0.0,
                    o.num("lon_deg", lo=-180, hi=180) or 0.0,
                    o.num("ground_alt_m", 0.0, lo=-500, hi=9000) or 0.0)
    rates = _rates(ctx, top.d.get("rates", {}))
    duration = top.num("duration_s", lo=0, lo_open=True, hi=lim.MAX_DURATION_S)
    seed = top.integer("seed", 0, lo=0, hi=lim.MAX_SEED)
    plot = top.boolean("plot", False)
    mavlink = _mavlink(ctx, top.d["mavlink"]) if top.has("mavlink") else None
    apath: list[str] = []
    raw_ap = top.d.get("aircraft_path", [])
    if isinstance(raw_ap, str):
        raw_ap = [raw_ap]
    if not isinstance(raw_ap, list) or not all(isinstance(x, str) for x in raw_ap):
        ctx.err(("aircraft_path",), "expected a folder or a list of folders")
    else:
        apath = _aircraft_path(ctx, raw_ap, Path(fname).resolve().parent)

    raw_vehicles, raw_schedule = top.d.get("vehicles", _MISSING), top.d.get("schedule", [])
    # the vehicles and the schedule are most of the work: a sweep's combinations
    # that give them the same input share one check (``Memo``)
    vkey = (repr(raw_vehicles), origin, tuple(apath), not ctx.problems)
    vehicles = memo.part("vehicles", vkey, ctx, lambda sub: _vehicles(
        sub, raw_vehicles, origin, tuple(apath), separation=vkey[-1]))
    if duration is None:
        duration = 1.0
    schedule = memo.part("schedule", (repr(raw_schedule), vkey, rates, duration), ctx,
                         lambda sub: _schedule(sub, raw_schedule, vehicles, rates, duration))
    _check_writes(ctx, vehicles, schedule)
    if mavlink is not None and "vehicles" in mavlink:
        _mavlink_vehicles(ctx, mavlink, vehicles)
    if check_properties:
        _check_properties(ctx, vehicles, schedule, memo.fdms)
    sections: dict[str, Any] = {}
    info = SectionInfo(ctx, origin, rates, duration, [v for v, _ in vehicles], Path(fname),
                       mavlink, seed or 0)
    earlier: list[tuple[str, str]] = []  # the sections parsed so far, as written
    adds: list[tuple[str, Any]] = []  # what each adds to the world
    for key, section in scenario_sections().items():  # each after those it reads
        if key not in top.d:
            continue
        raw = repr(top.d[key])
        # a section's parser sees its own node, the scenario so far and the
        # sections it reads: with the same of each, it gives the same
        skey = (key, raw, origin, rates, duration, vkey, repr(mavlink), seed,
                tuple(earlier), len(ctx.problems))
        info.sections = MappingProxyType({k: sections[k] for k in section.reads
                                          if k in sections})
        parsed = memo.part("section", skey, ctx, functools.partial(
            _parse_section, info, section=section, node=top.d[key]))
        sections[key] = parsed
        earlier.append((key, raw))
        if parsed is not None:
            adds.append((key, section.world(parsed)))
    world, clashes = World.assemble(adds)
    for key, problem in clashes:
        ctx.err((key,), problem)
    vehicles = _with_world(ctx, vehicles, world, sections, origin)
    if ctx.problems:
        raise ctx.error()
    if not seeds:
        return None
    vehicles = _derive_seeds(vehicles, seed or 0)
    return Scenario(name=name or Path(fname).stem, path=fname, origin=origin, rates=rates,
                    duration_s=duration,
                    seed=seed, vehicles=tuple(v for v, _ in vehicles), schedule=tuple(schedule),
                    description=description, aircraft_path=tuple(apath), plot=plot,
                    mavlink=mavlink, sections=sections, world=world,
                    section_sources={k: top.d[k] for k in sections if k in top.d},
                    extra={"vehicle_paths": [pp for _, pp in vehicles],
                           "vehicle_lines": [ctx.line(pp) for _, pp in vehicles]})


def _with_world(ctx: _Ctx, vehicles: list[tuple[VehicleSpec, P]], world: World,
                sections: dict[str, Any], origin: Origin) -> list[tuple[VehicleSpec, P]]:
    """Each vehicle given what of the world (and of the sections) its class
    needs (``with_world``), and checked in it."""
    out = []
    o = (origin.lat_deg, origin.lon_deg, origin.ground_alt_m)
    view = MappingProxyType(sections)
    for v, p in vehicles:
        vc = get_class(v.vehicle_class)
        v = vc.with_world(v, world, view, o)
        for problem in vc.world_problems(v):
            ctx.err(p, problem)
        out.append((v, p))
    return out


def _parse_section(info: SectionInfo, ctx: _Ctx, *, section: Section, node: Any) -> Any:
    """``section`` parsed from ``node``, its problems reported into ``ctx``."""
    outer, info.ctx = info.ctx, ctx
    info.earlier_problems = len(outer.problems)
    try:
        return section.parse(info, node, (section.key,))
    finally:
        info.ctx, info.earlier_problems = outer, 0


@dataclass
class SectionInfo:
    """What a section parser sees (``cosim.core.section.SectionContext``): the
    scenario parsed so far, the sections it reads, and the problem list."""

    ctx: _Ctx
    origin: Origin
    rates: Rates
    duration_s: float
    vehicles: list[VehicleSpec]
    path: Path  # the scenario file (relative file names in sections resolve against it)
    #: the scenario's ``mavlink:`` section as resolved ({"url", "rates_hz"}), or None
    mavlink: dict[str, Any] | None = None
    seed: int = 0  # the scenario's random seed
    #: the parsed objects of the sections the one being parsed reads (read only)
    sections: Mapping[str, Any] = field(default_factory=dict)

    @property
    def ids(self) -> list[str]:
        return [v.id for v in self.vehicles]

    def err(self, path: P, msg: str) -> None:
        """Report a problem at ``path`` (the file line is found from it)."""
        self.ctx.err(path, msg)

    def reader(self, d: Any, path: P, allowed: tuple[str, ...]) -> _Reader:
        """Typed access to the mapping ``d`` at ``path`` (num, integer, string,
        boolean, one_of); unknown keys are reported."""
        return _Reader(self.ctx, d, path, allowed)

    def select(self, sel: Any, path: P) -> list[int]:
        """Vehicle rows chosen by ``'all'``, an id, a pattern or a list of them."""
        return _select(self.ctx, sel, path, self.ids)

    #: problems found before the section being parsed (reported elsewhere)
    earlier_problems: int = 0

    @property
    def problems(self) -> int:
        """Problems found so far in the whole scenario."""
        return self.earlier_problems + len(self.ctx.problems)


def _mavlink(ctx: _Ctx, d: Any) -> dict[str, Any] | None:
    """``mavlink:``, read by its part (``cosim.mavlink.scenario``)."""
    from cosim.mavlink.scenario import parse_mavlink

    return parse_mavlink(d, ctx.err, lambda node, path, keys: _Reader(ctx, node, path, keys))


def _mavlink_vehicles(ctx: _Ctx, mavlink: dict[str, Any],
                      vehicles: list[tuple[VehicleSpec, P]]) -> None:
    """``mavlink.vehicles``, checked against the vehicles by its part."""
    from cosim.mavlink.scenario import check_vehicles

    ids = [v.id for v, _ in vehicles]
    check_vehicles(mavlink, lambda sel, path: _select(ctx, sel, path, ids))


def _rates(ctx: _Ctx, d: Any) -> Rates:
    r = _Reader(ctx, d, ("rates",), ("physics_hz", "control_hz", "log_hz"))
    ph = r.num("physics_hz", 120.0, lo=lim.PHYSICS_HZ_RANGE[0], hi=lim.PHYSICS_HZ_RANGE[1])
    ch = r.num("control_hz", 30.0, lo=lim.MIN_EXCHANGE_HZ)
    lh = r.num("log_hz", 10.0, lo=lim.MIN_EXCHANGE_HZ)
    if None in (ph, ch, lh):
        return Rates()

    def divides(a: float, b: float) -> bool:
        q = b / a
        return abs(q - round(q)) < 1e-9 and round(q) >= 1

    if not divides(ch, ph):
        ctx.err(("rates", "control_hz"), f"control_hz {ch:g} must divide physics_hz {ph:g} "
                                         f"(a whole number of physics ticks per exchange)")
    elif not divides(lh, ch):
        ctx.err(("rates", "log_hz"), f"log_hz {lh:g} must divide control_hz {ch:g} (states "
                                     f"are exchanged at control_hz; physics_hz is {ph:g})")
    else:
        return Rates(ph, ch, lh)
    return Rates()  # reported: the rest of the file is checked against the defaults


#: a vehicle's ``random_seed`` until ``_derive_seeds`` derives it from the scenario's
_DERIVED_SEED = -1


def _derive_seeds(vehicles: list[tuple[VehicleSpec, P]], seed: int
                  ) -> list[tuple[VehicleSpec, P]]:
    """Each vehicle without a ``random_seed`` of its own given one derived from
    the scenario's ``seed`` and its row."""
    import dataclasses

    return [(v if v.random_seed != _DERIVED_SEED else dataclasses.replace(
        v, random_seed=int(np.random.SeedSequence([seed, i]).generate_state(1)[0]
                           % (2**31 - 1))), p) for i, (v, p) in enumerate(vehicles)]


def _vehicles(ctx: _Ctx, d: Any, origin: Origin, apath: tuple[str, ...],
              separation: bool = True) -> list[tuple[VehicleSpec, P]]:
    """The vehicle entries, each expanded by its ``count`` and formation (seeds
    to derive: ``_derive_seeds``); ``separation``: check the start positions
    are apart too (when nothing else is wrong)."""
    path: P = ("vehicles",)
    if d is _MISSING:
        ctx.err((), "missing required key 'vehicles'")
        return []
    if not isinstance(d, list) or not d:
        ctx.err(path, f"expected a non-empty list of vehicles, got {_describe(d)}")
        return []
    frame = origin.frame
    ground = origin.ground_alt_m
    out: list[tuple[VehicleSpec, P]] = []
    where_ned: list[np.ndarray] = []  # (count, 3) north, east, height of each entry's vehicles
    seen: dict[str, P] = {}
    planned = 0  # vehicles asked for so far (count included)
    planned_jsbsim = 0  # of them, JSBSim vehicles
    dist = lim.MAX_DISTANCE_M
    for i, vd in enumerate(d):
        vp = path + (i,)
        vclass, model = _vehicle_class(ctx, vd, vp, apath)
        r = _Reader(ctx, vd, vp, _VEHICLE_KEYS + (vclass.vehicle_keys if vclass else ("trim",
                                                                                        "set")))
        vid = r.string("id", pattern=_ID)
        jsbsim = vclass is None or vclass.model_kind == "jsbsim"
        count = r.integer("count", 1, lo=1,
                          hi=lim.MAX_VEHICLES if jsbsim else lim.MAX_ALL_VEHICLES)
        if count is not None:
            planned += count
            planned_jsbsim += count if jsbsim else 0
            if planned_jsbsim > lim.MAX_VEHICLES and jsbsim:
                ctx.err(vp + (("count",) if r.has("count") else ()),
                        f"the scenario would have {planned_jsbsim} or more JSBSim vehicles; "
                        f"at most {lim.MAX_VEHICLES} (each takes about "
                        f"{lim.MIB_PER_VEHICLE} MiB)")
                count = None
            elif planned > lim.MAX_ALL_VEHICLES:
                ctx.err(vp + (("count",) if r.has("count") else ()),
                        f"the scenario would have {planned} or more vehicles; at most "
                        f"{lim.MAX_ALL_VEHICLES} of every kind")
                count = None
        trim = r.boolean("trim", True) if jsbsim and (vclass is None or vclass.trims) \
            else False
        props = _prop_values(ctx, r.d["set"], vp + ("set",)) if r.has("set") else []
        params = vclass.parse_vehicle(r, vp) if vclass else {}
        fixed_seed = r.integer("random_seed", None, lo=0, hi=lim.MAX_VEHICLE_SEED)
        if fixed_seed is not None and count is not None and count > 1:
            ctx.err(vp + ("random_seed",), "random_seed is for a single vehicle; with count, "
                                           "each vehicle's seed derives from the scenario seed")
        ini = _Reader(ctx, r.d.get("init"), vp + ("init",),
                      ("lat_deg", "lon_deg", "north_m", "east_m", "alt_msl_m", "alt_agl_m",
                       "heading_deg", "airspeed_kt", "airspeed_mps"))
        if not r.has("init"):
            continue
        pos_geo = ini.has("lat_deg") or ini.has("lon_deg")
        pos_ned = ini.has("north_m") or ini.has("east_m")
        if pos_geo and pos_ned:
            ctx.err(vp + ("init",), "give the position as lat_deg/lon_deg or as north_m/east_m, "
                                    "not both")
        if pos_geo:
            lat, lon = ini.num("lat_deg", lo=-90, hi=90), ini.num("lon_deg", lo=-180, hi=180)
            n0 = e0 = None
        else:
            n0 = ini.num("north_m", 0.0, lo=-dist, hi=dist)
            e0 = ini.num("east_m", 0.0, lo=-dist, hi=dist)
            lat = lon = None
        alt_key = ini.one_of("alt_msl_m", "alt_agl_m")
        alt = None
        on_ground = vclass is not None and vclass.on_ground
        if alt_key is None and on_ground:
            alt = ground  # a ground vehicle: on the ground unless told otherwise
        elif alt_key is None:
            ctx.err(vp + ("init",), "missing the altitude: give alt_msl_m or alt_agl_m")
        else:
            a = ini.num(alt_key, lo=ALT_MIN_M, hi=ALT_MAX_M)
            if a is not None:
                alt = a + (ground if alt_key == "alt_agl_m" else 0.0)
        heading = ini.num("heading_deg", 0.0, lo=-360, hi=360)
        spd_key = ini.one_of("airspeed_kt", "airspeed_mps")
        speed = None
        if spd_key is None and vclass is not None and (on_ground or vclass.hovers):
            speed = 0.0  # at rest
        elif spd_key is None:
            ctx.err(vp + ("init",), "missing the airspeed: give airspeed_kt or airspeed_mps")
        else:
            s = ini.num(spd_key, lo=0, hi=2000)
            if s is not None:
                speed = s * (KT_TO_MPS if spd_key == "airspeed_kt" else 1.0)
                if trim and s == 0:
                    ctx.err(vp + ("init", spd_key), "a trimmed start flies: it needs an "
                                                    "airspeed > 0 (give trim: false for a "
                                                    "vehicle at rest)")
                    speed = None
        offsets = (np.zeros(1), np.zeros(1))
        alt_step = 0.0
        no_formation = count is not None and count > 1 and not r.has("formation")
        if no_formation:
            ctx.err(vp, f"count {count} needs a formation (type: line, grid or circle, "
                        f"with spacing_m)")
        if r.has("formation"):
            fp = vp + ("formation",)
            f = _Reader(ctx, r.d.get("formation"), fp,
                        ("type", "spacing_m", "bearing_deg", "columns", "radius_m", "alt_step_m"))
            kind = f.string("type", choices=FORMATIONS)
            spacing = f.num("spacing_m", None if f.has("radius_m") else _MISSING, lo=0, hi=dist)
            bearing = f.num("bearing_deg", None, lo=-360, hi=360)
            columns = f.integer("columns", None, lo=1, hi=lim.MAX_ALL_VEHICLES)
            radius = f.num("radius_m", None, lo=0, hi=dist)
            alt_step = f.num("alt_step_m", 0.0, lo=-ALT_MAX_M, hi=ALT_MAX_M) or 0.0
            if kind is not None and (spacing is not None or radius is not None) and count:
                offsets = formation_offsets(kind, count, spacing or 0.0, heading or 0.0,
                                            bearing, columns, radius)
                size = (radius if kind == "circle" and radius is not None else spacing) or 0.0
                if count > 1 and size == 0 and alt_step == 0:
                    ctx.err(fp, f"{count} vehicles would start on one point: give "
                                f"{'radius_m' if kind == 'circle' else 'spacing_m'} > 0 "
                                f"(or alt_step_m)")
                    no_formation = True
        if None in (vid, model, alt, heading, speed, count) or (pos_geo and None in (lat, lon)) \
                or (not pos_geo and None in (n0, e0)) or no_formation:
            continue
        assert model is not None and vid is not None and count is not None
        assert vclass is not None
        assert alt is not None and heading is not None and speed is not None
        dn, de = offsets
        alts = alt + np.arange(count) * alt_step
        alt_p = vp + ("init", alt_key or "alt_msl_m")
        if alts.min() < ALT_MIN_M or alts.max() > ALT_MAX_M:
            ctx.err(alt_p, f"gives altitudes {alts.min():g}..{alts.max():g} m above the "
                           f"ellipsoid (with ground_alt_m and alt_step_m); allowed "
                           f"{ALT_MIN_M:g}..{ALT_MAX_M:g}")
            continue
        agl_min = float(alts.min()) - ground
        if agl_min < 0:
            step = ", with alt_step_m" if count > 1 else ""
            ctx.err(alt_p, f"starts {-agl_min:g} m below the ground (the ground is at "
                           f"{ground:g} m, origin.ground_alt_m{step})")
            continue
        if trim and agl_min < lim.MIN_TRIM_AGL_M:
            ctx.err(alt_p, f"starts {agl_min:g} m above the ground; a trimmed start is in the "
                           f"air: at least {lim.MIN_TRIM_AGL_M:g} m (give trim: false for a "
                           f"vehicle on the ground)")
            continue
        if pos_geo:
            assert lat is not None and lon is not None
            n_base, e_base, _ = frame.geodetic_to_ned(lat, lon, alt)
        else:
            assert n0 is not None and e0 is not None
            n_base, e_base = np.asarray(n0), np.asarray(e0)
        north, east = n_base + dn, e_base + de
        far = float(np.hypot(north, east).max())
        if far > dist:
            ctx.err(vp + ("init",), f"places a vehicle {far / 1000:.0f} km from the origin; at "
                                    f"most {dist / 1000:.0f} km (move origin: closer)")
            continue
        # exact: each vehicle's local north/east are the formation's, at its own height
        lats, lons = frame.place(north, east, alts)
        if count == 1 and pos_geo:
            lats, lons = np.array([lat]), np.array([lon])
        width = len(str(count - 1))
        rows = []
        said: set[str] = set()  # a class's start problems, once an entry
        for j in range(count):
            uid = vid if count == 1 else f"{vid}{j:0{width}d}"
            if len(uid) > lim.MAX_NAME_CHARS:
                ctx.err(vp + ("id",), f"id {_clip(uid)!r} (with the number count adds) is "
                                      f"longer than {lim.MAX_NAME_CHARS} characters")
                break
            if uid in seen:
                ctx.err(vp + ("id",), f"duplicate vehicle id {uid!r} (also at "
                                      f"{format_path(seen[uid])}, line {ctx.line(seen[uid])})")
                continue
            seen[uid] = vp
            # derived from the scenario's seed later (``_derive_seeds``)
            vseed = fixed_seed if fixed_seed is not None and count == 1 else _DERIVED_SEED
            spec = VehicleSpec(
                id=uid, model=model.name, aircraft_dir=model.aircraft_dir,
                model_source=model.source, lat_deg=float(lats[j]), lon_deg=float(lons[j]),
                vehicle_class=vclass.name, class_params=dict(params),
                alt_msl_m=float(alts[j]), heading_deg=float(heading) % 360.0,
                airspeed_mps=float(speed), terrain_alt_m=ground, trim=trim,
                random_seed=vseed, initial_props=tuple(props),
                profile=dict(model.profile or {}))
            for problem in vclass.check_start(spec):
                if problem not in said:
                    said.add(problem)
                    ctx.err(vp + ("init",), problem)
            out.append((spec, vp))
            rows.append(j)
        where_ned.append(np.stack([np.broadcast_to(north, (count,))[rows],
                                   np.broadcast_to(east, (count,))[rows], alts[rows]], axis=1))
    if where_ned and separation and not ctx.problems:
        _check_separation(ctx, out, np.concatenate(where_ned))
    return out


#: vehicles closer than this at the start are reported (stacked on one point)
MIN_SEPARATION_M = 1.0


def _check_separation(ctx: _Ctx, vehicles: list[tuple[VehicleSpec, P]], ned: np.ndarray
                      ) -> None:
    """Report vehicles that start within ``MIN_SEPARATION_M`` of each other (a
    hash grid of that cell size: each vehicle is compared with its neighbours'
    cells only, so this is linear in the number of vehicles)."""
    cells: dict[tuple[int, int, int], list[int]] = {}
    keys = np.floor(ned / MIN_SEPARATION_M).astype(np.int64)
    reported = 0
    for i, key in enumerate(map(tuple, keys.tolist())):
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for j in cells.get((key[0] + dx, key[1] + dy, key[2] + dz), ()):
                        gap = float(np.linalg.norm(ned[i] - ned[j]))
                        if gap < MIN_SEPARATION_M and reported < 20:
                            reported += 1
                            a, b = vehicles[j][0].id, vehicles[i][0].id
                            ctx.err(vehicles[i][1], f"vehicles {a!r} and {b!r} start "
                                                    f"{gap:.2f} m apart (at least "
                                                    f"{MIN_SEPARATION_M:g} m)")
        cells.setdefault(key, []).append(i)


#: the keys of a vehicle entry every class has (a class adds its ``vehicle_keys``)
_VEHICLE_KEYS = ("id", "class", "model", "count", "formation", "init", "random_seed")


def _vehicle_class(ctx: _Ctx, vd: Any, vp: P, apath: tuple[str, ...]
                   ) -> tuple[VehicleClass | None, ModelChoice | None]:
    """A vehicle entry's class (its ``class:``, else its model profile's, else
    ``jsbsim``) and its model as that class resolves it; problems reported."""
    if not isinstance(vd, dict):
        return None, None  # the entry's reader says what it is
    raw, model_name = vd.get("class"), vd.get("model")
    if raw is not None and not isinstance(raw, str):
        ctx.err(vp + ("class",), f"expected a vehicle class name, got {_describe(raw)}")
        return None, None
    if model_name is not None and not isinstance(model_name, str):
        ctx.err(vp + ("model",), f"expected a string, got {_describe(model_name)}")
        return None, None
    name = raw
    if name is None:
        if model_name is None:
            ctx.err(vp, "missing required key 'model'")
            return None, None
        try:
            name = str(find_model(model_name, apath).profile.get("class", DEFAULT_CLASS))
        except CosimError as e:
            ctx.err(vp + ("model",), str(e))
            return None, None
    try:
        vclass = get_class(name)
    except ConfigError as e:
        where = vp + ("class",) if raw is not None else vp + ("model",)
        ctx.err(where, str(e) if raw is not None else f"model {model_name!r}: its profile's "
                                                        f"{e}")
        return None, None
    try:
        return vclass, vclass.resolve_model(model_name, apath)
    except CosimError as e:
        ctx.err(vp if model_name is None else vp + ("model",), str(e))
        return vclass, None


def _select(ctx: _Ctx, sel: Any, path: P, ids: list[str]) -> list[int]:
    if sel == "all":
        return list(range(len(ids)))
    pats = [sel] if isinstance(sel, str) else sel
    if not isinstance(pats, list) or not pats or not all(isinstance(x, str) for x in pats):
        ctx.err(path, f"expected 'all', a vehicle id, a pattern such as 'uav*', or a list of "
                      f"them; got {_describe(sel)}")
        return []
    chosen: set[int] = set()
    for pat in pats:
        hits = [i for i, v in enumerate(ids) if fnmatchcase(v, pat)]
        if not hits and not any(fnmatchcase(v, pat) for v in ctx.declared()):
            shown = ", ".join(ids[:8]) + (", ..." if len(ids) > 8 else "")
            ctx.err(path, f"{pat!r} matches no vehicle (vehicles: {shown})")
        chosen.update(hits)
    return sorted(chosen)


def _schedule_tick(at_s: float, rates: Rates) -> int:
    """The control tick at which an item at ``at_s`` applies (first at or after it)."""
    k = rates.control_every
    return math.ceil(round(at_s * rates.physics_hz, 6) / k) * k


def _total_ticks(duration_s: float, rates: Rates) -> int:
    """Ticks in a run of ``duration_s``: rounded up to whole exchanges, at least one."""
    return max(rates.control_every, _schedule_tick(duration_s, rates))


def _schedule(ctx: _Ctx, d: Any, vehicles: list[tuple[VehicleSpec, P]], rates: Rates,
              duration: float) -> list[ScheduleItem]:
    if not isinstance(d, list):
        ctx.err(("schedule",), f"expected a list of timed actions, got {_describe(d)}")
        return []
    ids = [v.id for v, _ in vehicles]
    out = []
    k = rates.control_every
    total = _total_ticks(duration, rates)  # Scenario.total_ticks
    for i, sd in enumerate(d):
        sp: P = ("schedule", i)
        r = _Reader(ctx, sd, sp, ("at_s", "vehicles", "set", "command"))
        at = r.num("at_s", lo=0)
        if at is not None and _schedule_tick(at, rates) >= total:
            ctx.err(sp + ("at_s",), f"at_s {at:g} is at or after the end of the run (duration_s "
                                    f"{duration:g}), so it would never run; the last control "
                                    f"exchange starts at {(total - k) / rates.physics_hz:g} s")
        sel = _select(ctx, r.d.get("vehicles", "all"), sp + ("vehicles",), ids)
        if not r.has("set") and not r.has("command"):
            ctx.err(sp, "missing 'set' (JSBSim property: value) or 'command' (heading_deg, "
                        "alt_msl_m, airspeed_kt, goto, waypoints, loiter, ...)")
            continue
        sets = _prop_values(ctx, r.d["set"], sp + ("set",)) if r.has("set") else []
        cmd = parse_command(r.d["command"], sp + ("command",), ctx.err) if r.has(
            "command") else None
        if at is None or (r.has("command") and cmd is None):
            continue
        out.append(ScheduleItem(at, _schedule_tick(at, rates), tuple(sel), tuple(sets), i, cmd))
    out.sort(key=lambda s: s.tick)  # stable: file order within a tick
    _check_commands(ctx, out, [v for v, _ in vehicles])
    return out


def _check_commands(ctx: _Ctx, schedule: list[ScheduleItem], specs: list[VehicleSpec]) -> None:
    """Commands only for vehicles whose class takes them, and each as its class
    allows at that point of the schedule (``VehicleClass.command_problems``:
    the model's envelope, then the rule of every command path, with the speed
    and bank limit in force)."""
    speed = [v.airspeed_mps for v in specs]
    bank = [DEFAULT_BANK_LIMIT_DEG] * len(specs)
    for item in schedule:
        cmd = item.command
        if cmd is None or not cmd.flies:  # gimbal angles are for the cameras
            continue
        path: P = ("schedule", item.index, "command")
        mute = sorted({(specs[j].model, specs[j].vehicle_class) for j in item.vehicles
                       if not get_class(specs[j].vehicle_class).commandable})
        if mute:
            ctx.err(path, "; ".join(f"model {m} (class {c}) takes no commands" for m, c in mute)
                    + " (fixed-wing profiles: aircraft/profiles/, aircraft/<model>/cosim.yaml)")
            continue
        for j in item.vehicles:
            vc = get_class(specs[j].vehicle_class)
            lim = Limits(specs[j].terrain_alt_m, vc.min_alt_agl_m(specs[j].profile), speed[j],
                         bank[j])
            if cmd.bank_limit_deg is not None:
                bank[j] = cmd.bank_limit_deg
            speed[j] = speed_after(cmd, speed[j])
            problems = vc.command_problems(cmd, specs[j], lim)
            for problem in problems:
                ctx.err(path, problem)
            if problems:
                break


def _check_writes(ctx: _Ctx, vehicles: list[tuple[VehicleSpec, P]],
                  schedule: list[ScheduleItem]) -> None:
    """Every raw property write (a vehicle's ``set:``, a schedule item's) as
    the vehicle's class allows it (``VehicleClass.write_problems``: nothing
    that moves a vehicle by decree or bypasses the rule of the commands)."""
    def check(where: P, specs: list[VehicleSpec], props: Sequence[tuple[str, float]]) -> None:
        for name, value in props:
            said: set[str] = set()
            for spec in specs:
                for problem in get_class(spec.vehicle_class).write_problems(name, value, spec):
                    if problem not in said:
                        said.add(problem)
                        ctx.err(where + (name,), problem)

    done: set[P] = set()
    for spec, vp in vehicles:
        if spec.initial_props and vp not in done:
            done.add(vp)
            check(vp + ("set",), [spec], spec.initial_props)
    specs = [v for v, _ in vehicles]
    for item in schedule:
        if item.sets:
            check(("schedule", item.index, "set"), [specs[j] for j in item.vehicles], item.sets)


def _check_properties(ctx: _Ctx, vehicles: list[tuple[VehicleSpec, P]],
                      schedule: list[ScheduleItem], fdms: dict[tuple[str, str], Any]) -> None:
    """Every property written must exist, and be writable, in every model it is
    written to (JSBSim silently creates misspelled properties and silently
    ignores writes to read-only ones). ``fdms``: one FDM of each model, built
    when first needed (kept by the caller: only read, never stepped)."""

    def fdm_of(spec: VehicleSpec) -> Any:
        key = (spec.model, spec.aircraft_dir)
        if key not in fdms:
            from cosim.jsb import ModelInfo

            fdms[key] = new_fdm(ModelInfo(spec.model, spec.aircraft_dir, spec.model_source,
                                          profile=spec.profile), 0.01)
        return fdms[key]

    def exists(spec: VehicleSpec, name: str) -> bool:
        return has_property(fdm_of(spec), name)

    def writable(spec: VehicleSpec, name: str) -> bool:
        return is_writable(fdm_of(spec), name)

    def check(where: P, specs: list[VehicleSpec], props: list[tuple[str, float]],
              report: Callable[[P, str], None]) -> None:
        kinds = {c: get_class(c).model_kind for c in {s.vehicle_class for s in specs}}
        batched = [s for s in specs if kinds[s.vehicle_class] != "jsbsim"]
        specs = [s for s in specs if kinds[s.vehicle_class] == "jsbsim"]
        for name, _ in props:  # a batched class's inputs are its channels
            for bad in sorted({s.vehicle_class for s in batched
                               if name not in get_class(s.vehicle_class).channels}):
                report(where + (name,), f"{name!r} is not an input of class {bad} (its "
                                        f"inputs: {', '.join(get_class(bad).channels) or 'none'})")
        for name, value in props:
            if any(get_class(s.vehicle_class).write_problems(name, value, s) for s in specs):
                continue  # refused already (``_check_writes``)
            missing = sorted({s.model for s in specs if not exists(s, name)})
            if missing:
                report(where + (name,), f"JSBSim property {name!r} does not exist in model "
                                        f"{', '.join(missing)} (check the spelling; "
                                        f"`cosim models --properties MODEL` lists them)")
                continue
            read_only = sorted({s.model for s in specs if not writable(s, name)})
            if read_only:
                report(where + (name,), f"JSBSim property {name!r} is read-only in model "
                                        f"{', '.join(read_only)}: JSBSim would ignore the "
                                        f"value (`cosim models --properties MODEL` marks "
                                        f"writable ones RW)")

    done: set[P] = set()
    for spec, vp in vehicles:
        if spec.initial_props and vp not in done:
            done.add(vp)
            check(vp + ("set",), [spec], list(spec.initial_props), ctx.err)
    specs = [v for v, _ in vehicles]
    for item in schedule:
        check(("schedule", item.index, "set"), [specs[j] for j in item.vehicles],
              list(item.sets), ctx.err)
