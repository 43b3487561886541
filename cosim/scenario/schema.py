"""Scenario files (YAML, ``schema_version: 1``) -> validated, frozen ``Scenario``.

Every problem is collected and reported at once, each as
``file:line: path: message``; unknown keys are errors; model names are
looked up on the aircraft search path and JSBSim property names are checked
to exist in the model (JSBSim silently creates misspelled properties).
This module owns the schema; it never steps an FDM.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from cosim.core import limits as lim
from cosim.core.section import Section, scenario_sections
from cosim.core.state import VehicleSpec
from cosim.scenario.memo import Memo
from cosim.scenario.model import SCHEMA_VERSION, Origin, Rates, Scenario
from cosim.scenario.reader import MISSING, P, Problems, Reader, clip, select
from cosim.scenario.schedule import parse_schedule
from cosim.scenario.vehicles import derive_seeds, parse_vehicles
from cosim.scenario.writes import check_property_names, check_writes
from cosim.scenario.yaml_lines import read_scenario_text
from cosim.vehicles import get_class
from cosim.world.model import World

#: what a scenario name may not hold (it names the run's folder)
_NAME_UNSAFE = re.compile(r"[/\\\x00-\x1f\x7f]")


def _name(ctx: Problems, name: str | None, given: bool) -> str | None:
    """The scenario's ``name`` (it names the run folder): refused when it could
    leave its folder (a path separator, ``..``) or is unprintable or long."""
    if name is None or not given:
        return name
    path: P = ("name",)
    if _NAME_UNSAFE.search(name) or ".." in name:
        ctx.err(path, f"{clip(name)!r} may not contain '/', '\\', '..' or control "
                      f"characters: it names the run's folder (runs/<name>-<date>-<time>)")
        return None
    if not name.strip() or len(name) > lim.MAX_NAME_CHARS:
        ctx.err(path, f"{clip(name)!r}: expected 1 to {lim.MAX_NAME_CHARS} characters")
        return None
    return name


def _aircraft_path(ctx: Problems, entries: list[str], base: Path) -> list[str]:
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
    ctx = Problems(fname, lines)
    ctx.problems.extend(dups)
    data = substitute(data, ctx.err, sweep_point, fname, placeholders)
    ctx.vehicles = data.get("vehicles") if isinstance(data, dict) else None
    top = Reader(ctx, data, (), ("schema_version", "name", "description", "origin", "rates",
                                  "duration_s", "seed", "aircraft_path", "plot", "mavlink",
                                  "vehicles", "schedule", *scenario_sections()))
    version = top.integer("schema_version")
    if version is not None and version != SCHEMA_VERSION:
        ctx.err(("schema_version",), f"unsupported schema_version {version}; this cosim reads "
                                     f"{SCHEMA_VERSION}")
    name = _name(ctx, top.string("name", Path(fname).stem), top.has("name"))
    description = top.string("description", "")
    o = Reader(ctx, top.d.get("origin"), ("origin",), ("lat_deg", "lon_deg", "ground_alt_m"))
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

    raw_vehicles, raw_schedule = top.d.get("vehicles", MISSING), top.d.get("schedule", [])
    # the vehicles and the schedule are most of the work: a sweep's combinations
    # that give them the same input share one check (``Memo``)
    vkey = (repr(raw_vehicles), origin, tuple(apath), not ctx.problems)
    vehicles = memo.part("vehicles", vkey, ctx, lambda sub: parse_vehicles(
        sub, raw_vehicles, origin, tuple(apath), separation=vkey[-1]))
    if duration is None:
        duration = 1.0
    schedule = memo.part("schedule", (repr(raw_schedule), vkey, rates, duration), ctx,
                         lambda sub: parse_schedule(sub, raw_schedule, vehicles, rates, duration))
    check_writes(ctx, vehicles, schedule)
    if mavlink is not None and "vehicles" in mavlink:
        _mavlink_vehicles(ctx, mavlink, vehicles)
    if check_properties:
        check_property_names(ctx, vehicles, schedule, memo.fdms)
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
    vehicles = derive_seeds(vehicles, seed or 0)
    return Scenario(name=name or Path(fname).stem, path=fname, origin=origin, rates=rates,
                    duration_s=duration,
                    seed=seed, vehicles=tuple(v for v, _ in vehicles), schedule=tuple(schedule),
                    description=description, aircraft_path=tuple(apath), plot=plot,
                    mavlink=mavlink, sections=sections, world=world,
                    section_sources={k: top.d[k] for k in sections if k in top.d},
                    extra={"vehicle_paths": [pp for _, pp in vehicles],
                           "vehicle_lines": [ctx.line(pp) for _, pp in vehicles]})


def _with_world(ctx: Problems, vehicles: list[tuple[VehicleSpec, P]], world: World,
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


def _parse_section(info: SectionInfo, ctx: Problems, *, section: Section, node: Any) -> Any:
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

    ctx: Problems
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

    def reader(self, d: Any, path: P, allowed: tuple[str, ...]) -> Reader:
        """Typed access to the mapping ``d`` at ``path`` (num, integer, string,
        boolean, one_of); unknown keys are reported."""
        return Reader(self.ctx, d, path, allowed)

    def select(self, sel: Any, path: P) -> list[int]:
        """Vehicle rows chosen by ``'all'``, an id, a pattern or a list of them."""
        return select(self.ctx, sel, path, self.ids)

    #: problems found before the section being parsed (reported elsewhere)
    earlier_problems: int = 0

    @property
    def problems(self) -> int:
        """Problems found so far in the whole scenario."""
        return self.earlier_problems + len(self.ctx.problems)


def _mavlink(ctx: Problems, d: Any) -> dict[str, Any] | None:
    """``mavlink:``, read by its part (``cosim.mavlink.scenario``)."""
    from cosim.mavlink.scenario import parse_mavlink

    return parse_mavlink(d, ctx.err, lambda node, path, keys: Reader(ctx, node, path, keys))


def _mavlink_vehicles(ctx: Problems, mavlink: dict[str, Any],
                      vehicles: list[tuple[VehicleSpec, P]]) -> None:
    """``mavlink.vehicles``, checked against the vehicles by its part."""
    from cosim.mavlink.scenario import check_vehicles

    ids = [v.id for v, _ in vehicles]
    check_vehicles(mavlink, lambda sel, path: select(ctx, sel, path, ids))


def _rates(ctx: Problems, d: Any) -> Rates:
    r = Reader(ctx, d, ("rates",), ("physics_hz", "control_hz", "log_hz"))
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
