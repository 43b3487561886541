"""The conditions of a live-console study (``protocol: live``).

Owns reading the study file's ``scenarios:`` list: each condition names a
scenario file (inside the study's folder), the camera feeds the participant
watches and, optionally, how long it runs and its condition values. It does
not run anything (``live``) or serve anything (``server``, ``live_routes``).

Example (in a study file)::

    protocol: live
    scenarios:
      - id: two_feeds
        scenario: scenarios/pair.yaml   # relative to the study file
        feeds: [uav1/belly, uav2/belly] # VEHICLE/CAMERA, or a count: the first K
        duration_s: 60                  # default: the scenario's own
        map: {tracks: true, footprints: true, targets: false}  # (the defaults)
        tasking: [go, orbit, look]      # the map's commands allowed (the default)
        orbit_radius_m: 300             # default 150, widened to one they can fly
        conditions: {feeds: 2, alt_agl_m: 100}

A feed is one camera of one vehicle (``VEHICLE/CAMERA``, the names the
scenario gives them); ``feeds: K`` takes the first K in the scenario's order
(its cameras as listed, each over its vehicles). 1 to ``MAX_FEEDS`` feeds.
The study's ``timing_limits: {latency_ms_p50: 200, dropped_percent: 1}``
(``TimingLimits``) flag a trial whose timing is worse.
``tasking:`` lists what the participant may tell an aircraft from the map
(``TASKING_ACTIONS``: ``go`` there, ``orbit`` there at ``orbit_radius_m``,
``look`` there with its gimbal cameras); by default ``go`` and ``orbit``
where the scenario has aircraft that take commands and ``look`` where one
of those has a camera on a gimbal, none where none takes commands; ``[]``
or ``false``: none. Only the scenario's aircraft that take commands may be
tasked (``LiveCondition.taskable``), and only those with a gimbal camera
told to look (``LiveCondition.lookers``).
Each scenario is loaded and checked as the study is read, so a misspelt
feed or a broken scenario is a ``ConfigError`` before any session starts.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.scenario.reader import Problems, Reader, describe
from cosim.trials.clips import inside

#: the most feeds one condition shows (a 4 x 4 grid)
MAX_FEEDS = 16
#: the most conditions a live study has
MAX_CONDITIONS = 200
#: the longest live trial (s): an hour
MAX_DURATION_S = 3600.0
CONDITION_KEYS = ("id", "scenario", "feeds", "duration_s", "conditions", "map", "tasking",
                  "orbit_radius_m")
#: what the participant may tell an aircraft from the map: fly to a point, orbit
#: it, point the gimbal cameras at it
TASKING_ACTIONS = ("go", "orbit", "look")
#: an orbit's radius (m) unless the condition says, and the radii it may say
ORBIT_RADIUS_M = 150.0
ORBIT_RADIUS_RANGE_M = (10.0, 5000.0)
#: what the map may show, and whether it does unless a condition says
MAP_LAYERS = {"tracks": True, "footprints": True, "targets": False}
TIMING_KEYS = ("latency_ms_p50", "dropped_percent")


@dataclass(frozen=True)
class TimingLimits:
    """A live study's ``timing_limits:``: a trial whose page's median
    glass-to-glass latency or share of frames lost (dropped for a slow page,
    or skipped by it) is over these is flagged for the experimenter (None:
    no limit)."""

    latency_ms_p50: float | None = None
    dropped_percent: float | None = None


def read_timing_limits(ctx: Problems, d: Any) -> TimingLimits:
    """The study's ``timing_limits:`` mapping (problems go to ``ctx``)."""
    r = Reader(ctx, d, ("timing_limits",), TIMING_KEYS)
    return TimingLimits(r.num("latency_ms_p50", None, lo=0, hi=60_000, lo_open=True),
                        r.num("dropped_percent", None, lo=0, hi=100))


@dataclass(frozen=True)
class Feed:
    """One camera of one vehicle as the participant sees it: its name
    (``VEHICLE/CAMERA``), its frame size and rate."""

    name: str
    vehicle: str
    camera: str
    width_px: int
    height_px: int
    rate_hz: float


@dataclass(frozen=True)
class LiveCondition:
    """One live trial's scenario and feeds."""

    id: str
    scenario: Path
    feeds: tuple[Feed, ...]
    duration_s: float | None
    conditions: tuple[tuple[str, str], ...]
    #: the SHA-256 (hex) of the scenario file when the study was read
    scenario_sha256: str = ""
    #: what the map shows (``MAP_LAYERS``' names)
    map_layers: tuple[str, ...] = tuple(k for k, on in MAP_LAYERS.items() if on)
    #: the map's commands allowed (``TASKING_ACTIONS``' names; empty: none)
    tasking: tuple[str, ...] = ()
    orbit_radius_m: float = ORBIT_RADIUS_M
    #: the vehicles that take commands (those the participant may task)
    taskable: tuple[str, ...] = ()
    #: those of them with a camera on a gimbal (those that may be told to look)
    lookers: tuple[str, ...] = ()
    #: the vehicles whose class records no fuel (a SAGAT fuel question cannot
    #: be scored for them)
    no_fuel: tuple[str, ...] = ()

    @property
    def fingerprint(self) -> dict[str, Any]:
        """What a session records to know the condition again."""
        return {"scenario_sha256": self.scenario_sha256}

    @property
    def condition_map(self) -> dict[str, str]:
        return dict(self.conditions)


def scenario_feeds(scn: Any) -> list[Feed]:
    """Every camera stream of a loaded scenario, in the cameras participant's
    order (each camera as listed, over its vehicles)."""
    cams = scn.sections.get("cameras") if hasattr(scn, "sections") else None
    if cams is None:
        return []
    return [Feed(f"{scn.vehicles[row].id}/{cam.name}", scn.vehicles[row].id, cam.name,
                 int(cam.width_px), int(cam.height_px), float(cam.rate_hz))
            for cam in cams.views for row in cam.vehicles]


def read_live_conditions(ctx: Problems, items: Any, base: Path, roots: tuple[Path, ...],
                         condition_values: Callable[[Problems, tuple[Any, ...], Any],
                                                    dict[str, str]]) -> list[LiveCondition]:
    """The conditions of ``scenarios:`` (problems go to ``ctx``);
    ``condition_values`` reads a ``conditions:`` mapping as the clips' are."""
    from cosim.scenario import load_scenario

    if not isinstance(items, list) or not items:
        ctx.err(("scenarios",), f"expected a non-empty list of live conditions "
                                f"({{id, scenario, feeds}}), got {describe(items)}")
        return []
    if len(items) > MAX_CONDITIONS:
        ctx.err(("scenarios",), f"{len(items)} conditions; a live study may have at most "
                                f"{MAX_CONDITIONS}")
        return []
    out: list[LiveCondition] = []
    for i, item in enumerate(items):
        at: tuple[Any, ...] = ("scenarios", i)
        r = Reader(ctx, item, at, CONDITION_KEYS)
        before = len(ctx.problems)
        cid = r.string("id", f"live{i}")
        duration = r.num("duration_s", None, lo=0, hi=MAX_DURATION_S, lo_open=True)
        value = r.d.get("scenario")
        path = None
        if not isinstance(value, str) or not value or "\x00" in value:
            ctx.err(at + ("scenario",), f"expected the path of a scenario file, got "
                                        f"{describe(value)}")
        else:
            path, instead = inside(base / value, roots)
            if path is None:
                ctx.err(at + ("scenario",), f"{value[:200]!r}: the scenario must be an existing "
                                            f"file inside the study's folder ({base}){instead}")
        conds = condition_values(ctx, at, r.d.get("conditions", {}))
        shown = Reader(ctx, r.d.get("map", {}), at + ("map",), tuple(MAP_LAYERS))
        layers = tuple(k for k, on in MAP_LAYERS.items() if shown.boolean(k, on))
        radius_m = r.num("orbit_radius_m", None, lo=ORBIT_RADIUS_RANGE_M[0],
                         hi=ORBIT_RADIUS_RANGE_M[1])
        radius_given = "orbit_radius_m" in r.d
        if path is None or len(ctx.problems) != before:
            continue
        try:
            scn = load_scenario(path)
        except ConfigError as e:
            for m in e.problems[:20]:
                ctx.err(at + ("scenario",), m)
            continue
        feeds = _feeds(ctx, at + ("feeds",), r.d.get("feeds"), scenario_feeds(scn), path)
        taskable = commandable_vehicles(scn)
        lookers = tuple(v for v in taskable if v in gimbal_vehicles(scn))
        tasking = _tasking(ctx, at + ("tasking",), r.d.get("tasking", None), taskable,
                           lookers, path)
        if "orbit" in (tasking or ()):
            radius_m = _orbit_radius(ctx, at + ("orbit_radius_m",), radius_m if radius_given
                                     else None, scn, taskable)
            if radius_m is None:
                continue
        if feeds and tasking is not None:
            sha = hashlib.sha256(path.read_bytes()).hexdigest()
            out.append(LiveCondition(cid, path, tuple(feeds), duration, tuple(conds.items()),
                                     sha, layers, tasking, radius_m or ORBIT_RADIUS_M,
                                     taskable if tasking else (),
                                     lookers if "look" in tasking else (),
                                     fuelless_vehicles(scn)))
    ids = [c.id for c in out]
    if len(set(ids)) != len(ids):
        ctx.err(("scenarios",), f"condition ids given twice: "
                                f"{', '.join(sorted({i for i in ids if ids.count(i) > 1})[:10])}")
    return out


def _feeds(ctx: Problems, at: tuple[Any, ...], spec: Any, have: list[Feed],
           path: Path) -> list[Feed]:
    names = ", ".join(f.name for f in have[:20]) or "none: it has no cameras: section"
    if isinstance(spec, int) and not isinstance(spec, bool):
        if not 1 <= spec <= MAX_FEEDS or spec > len(have):
            ctx.err(at, f"{spec} feeds: expected 1..{min(MAX_FEEDS, len(have))} ({path} has "
                        f"{len(have)} camera streams: {names})")
            return []
        return have[:spec]
    if not isinstance(spec, list) or not spec or len(spec) > MAX_FEEDS:
        ctx.err(at, f"expected a list of 1..{MAX_FEEDS} feeds (VEHICLE/CAMERA) or a count, "
                    f"got {describe(spec)}")
        return []
    by_name = {f.name: f for f in have}
    out = []
    for k, name in enumerate(spec):
        f = by_name.get(name) if isinstance(name, str) else None
        if f is None:
            ctx.err(at + (k,), f"no feed {str(name)[:100]!r} in {path}; it has: {names}")
        elif f in out:
            ctx.err(at + (k,), f"feed {name!r} given twice")
        else:
            out.append(f)
    return out if len(out) == len(spec) else []


def commandable_vehicles(scn: Any) -> tuple[str, ...]:
    """The ids of a loaded scenario's vehicles whose class takes commands."""
    from cosim.vehicles import get_class

    return tuple(v.id for v in scn.vehicles if get_class(v.vehicle_class).commandable)


def fuelless_vehicles(scn: Any) -> tuple[str, ...]:
    """The ids of a loaded scenario's vehicles whose class records no fuel."""
    from cosim.vehicles import get_class

    return tuple(v.id for v in scn.vehicles if not get_class(v.vehicle_class).logs_fuel)


def gimbal_vehicles(scn: Any) -> set[str]:
    """The ids of a loaded scenario's vehicles with a camera on a gimbal (one
    a ``gimbal`` command, ``look_at`` too, points)."""
    cams = scn.sections.get("cameras") if hasattr(scn, "sections") else None
    if cams is None:
        return set()
    return {scn.vehicles[row].id for cam in cams.views if cam.mount == "gimbal"
            for row in cam.vehicles}


def _tasking(ctx: Problems, at: tuple[Any, ...], spec: Any, taskable: tuple[str, ...],
             lookers: tuple[str, ...], path: Path) -> tuple[str, ...] | None:
    """A condition's ``tasking:`` (None: refused, said to ``ctx``)."""
    if spec is None:  # not given: every action some vehicle can take
        return tuple(a for a in TASKING_ACTIONS if taskable and (a != "look" or lookers))
    if spec is False:
        return ()
    if not isinstance(spec, list) or len(spec) > len(TASKING_ACTIONS):
        ctx.err(at, f"expected a list of the map's commands allowed (some of "
                    f"{', '.join(TASKING_ACTIONS)}), [] or false, got {describe(spec)}")
        return None
    out: list[str] = []
    for k, action in enumerate(spec):
        if action not in TASKING_ACTIONS:
            ctx.err(at + (k,), f"expected one of {', '.join(TASKING_ACTIONS)}, got "
                               f"{describe(action)}")
            return None
        if action in out:
            ctx.err(at + (k,), f"{action!r} given twice")
            return None
        out.append(action)
    if out and not taskable:
        ctx.err(at, f"{', '.join(out)}: none of the vehicles of {path} takes commands")
        return None
    if "look" in out and not lookers:
        ctx.err(at + (out.index("look"),), f"look: none of the vehicles of {path} that take "
                                           f"commands has a camera on a gimbal (a camera's "
                                           f"mount: gimbal or {{pitch_deg, yaw_deg}})")
        return None
    return tuple(a for a in TASKING_ACTIONS if a in out)


def _orbit_radius(ctx: Problems, at: tuple[Any, ...], given: float | None, scn: Any,
                  taskable: tuple[str, ...]) -> float | None:
    """The orbit's radius: ``given``, refused (None, said to ``ctx``) if a
    vehicle that may be tasked could not fly it at its start airspeed (its
    class's rule for every command path, as a loiter command's); else
    ``ORBIT_RADIUS_M``, widened in steps of 50 m to the first every such
    vehicle can fly."""
    from cosim.guidance import DEFAULT_BANK_LIMIT_DEG, parse_command
    from cosim.guidance.safety import Limits
    from cosim.vehicles import get_class

    def problems(radius_m: float) -> list[str]:
        cmd = parse_command({"loiter": {"radius_m": radius_m}}, (), lambda p, m: None)
        out: list[str] = []
        for v in scn.vehicles:
            if v.id in taskable and cmd is not None:
                vc = get_class(v.vehicle_class)
                lim = Limits(v.terrain_alt_m, vc.min_alt_agl_m(v.profile), v.airspeed_mps,
                             DEFAULT_BANK_LIMIT_DEG)
                out += vc.command_problems(cmd, v, lim)
        return out

    if given is not None:
        said = problems(given)
        if said:
            ctx.err(at, f"{given:g} m: an orbit must be one the aircraft can fly: {said[0]}")
            return None
        return given
    radius_m = ORBIT_RADIUS_M
    while problems(radius_m) and radius_m < ORBIT_RADIUS_RANGE_M[1]:
        radius_m += 50.0
    return radius_m
