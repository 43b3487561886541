"""The fixed-wing command vocabulary: parsing and validation.

One vocabulary for every fixed-wing vehicle, used by the scenario schedule
now and by MAVLink and the swarm controller later:

- ``heading_deg``: fly this true heading (ends any goto/waypoints/loiter)
- ``alt_msl_m`` / ``alt_agl_m``: hold this altitude
- ``airspeed_kt`` / ``airspeed_mps``: hold this true airspeed (throttle)
- ``throttle``: manual throttle 0..1 (ends the airspeed hold)
- ``bank_limit_deg``: the autopilot's bank limit (default 45)
- ``stall_protection``: true/false
- ``goto``: a point (``lat_deg``/``lon_deg``, or ``north_m``/``east_m`` in the
  scenario frame, or with ``frame: start`` metres relative to the vehicle's
  own start position), optional ``alt_*``, ``airspeed_*``, ``loiter_radius_m``;
  the vehicle flies there and loiters around it; ``from`` (a point): follow
  the track from that point rather than from where the vehicle is (a
  mission's leg from its previous waypoint); ``continue: true``: fly on
  along the leg past the point until the next command rather than loiter
  there (a mission waypoint with more to come)
- ``waypoints``: a list of such points flown in order (each may carry its
  own ``alt_*``/``airspeed_*``), then a loiter around the last
- ``loiter``: ``center`` (a point; default: where the vehicle is),
  ``radius_m``, ``direction`` (``cw``/``ccw``), optional ``alt_*``/``airspeed_*``
- ``takeoff_agl_m``: (vertical-lift vehicles) take off and hold this height
  above the ground where it is
- ``land``: ``true``: (vertical-lift vehicles) land where it is, or with
  ``waypoints``/``goto`` at the last point
- ``velocity``: (vertical-lift vehicles) ``north_mps``/``east_mps``: fly this
  ground velocity (ends a goto, waypoints or a hold)
- ``gimbal``: point the vehicle's gimbal cameras: ``pitch_deg`` (-90 nadir
  .. 30) and/or ``yaw_deg`` (relative to the nose, -180..180); or
  ``look_at`` (a point, as goto's, with optional ``alt_msl_m``/``alt_agl_m``;
  default the ground at the scenario's origin height): the cameras keep
  pointing at it as the vehicle moves, within those limits, until a gimbal
  command with angles or another ``look_at``; ``look_at: null`` ends the
  tracking, the angles staying where it left them. Not a flight command: a
  command of only ``gimbal`` leaves the flight as it is.
- ``camera``: the vehicle's renderer cameras take stills (full frames with
  their ground truth, into the run folder's ``stills/``): ``shoot: true``
  one now; ``interval_s`` one every so many seconds (``count``: that many,
  else until stopped); ``distance_m`` one every so many metres flown over
  the ground; ``stop: true`` ends interval and distance triggering. Not a
  flight command either.

Parsing returns a ``Command`` of plain values; problems are reported through
a callback with the key path, so the scenario loader can attach file lines.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cosim.core.geo import MAX_DISTANCE_M
from cosim.core.units import G_MPS2, KT_TO_MPS

DEFAULT_BANK_LIMIT_DEG = 45.0
P = tuple[Any, ...]
Report = Callable[[P, str], None]

COMMAND_KEYS = ("heading_deg", "alt_msl_m", "alt_agl_m", "airspeed_kt", "airspeed_mps",
                "throttle", "bank_limit_deg", "stall_protection", "goto", "waypoints", "loiter",
                "takeoff_agl_m", "land", "velocity", "gimbal", "camera")
#: gimbal angle bounds: pitch (nadir -90, forward 0), yaw relative to the nose
GIMBAL_PITCH_DEG = (-90.0, 30.0)
GIMBAL_YAW_DEG = (-180.0, 180.0)
_POINT_KEYS = ("lat_deg", "lon_deg", "north_m", "east_m", "frame")
_TARGET_EXTRA = ("alt_msl_m", "alt_agl_m", "airspeed_kt", "airspeed_mps")
_LOOK_AT_EXTRA = ("alt_msl_m", "alt_agl_m")


def min_turn_radius_m(airspeed_mps: float, bank_limit_deg: float) -> float:
    """R = v^2 / (g tan(phi)) at the bank limit (docs/physics.md, Fixed-wing aircraft)."""
    return airspeed_mps ** 2 / (G_MPS2 * math.tan(math.radians(bank_limit_deg)))


def waypoint_accept_radius_m(airspeed_mps: float, bank_limit_deg: float) -> float:
    """A waypoint counts as reached within half the turn radius (at least 50 m)."""
    return max(0.5 * min_turn_radius_m(airspeed_mps, bank_limit_deg), 50.0)


@dataclass(frozen=True)
class Point:
    """A horizontal position: geodetic, scenario-frame metres, or metres from
    the vehicle's start (``frame == "start"``)."""

    frame: str  # "geodetic", "local" or "start"
    a: float  # lat_deg or north_m
    b: float  # lon_deg or east_m
    alt_m: float | None = None  # altitude (MSL, or AGL if alt_agl)
    alt_agl: bool = False
    airspeed_mps: float | None = None


@dataclass(frozen=True)
class CameraTrigger:
    """A ``camera`` command: one still now (``shoot``), stills every
    ``interval_s`` seconds (at most ``count``) or every ``distance_m`` metres,
    or ``stop`` interval and distance triggering."""

    shoot: bool = False
    interval_s: float | None = None
    distance_m: float | None = None
    count: int | None = None
    stop: bool = False


#: the shortest still interval (s) and distance (m) a camera command may ask for
MIN_STILL_INTERVAL_S, MIN_STILL_DISTANCE_M = 0.05, 1.0


@dataclass(frozen=True)
class Command:
    heading_deg: float | None = None
    alt_m: float | None = None
    alt_agl: bool = False
    airspeed_mps: float | None = None
    throttle: float | None = None
    bank_limit_deg: float | None = None
    stall_protection: bool | None = None
    #: "goto", "waypoints", "loiter" or None
    nav: str | None = None
    points: tuple[Point, ...] = ()
    loiter_radius_m: float | None = None
    loiter_cw: bool = True
    loiter_here: bool = False  # loiter around the current position
    #: a goto's leg starts here rather than where the vehicle is (a mission's
    #: previous waypoint: the track between the two is followed)
    leg_from: Point | None = None
    #: a goto flies on along its leg past the point until the next command
    #: (a mission waypoint with more to come) instead of loitering there
    leg_continue: bool = False
    #: vertical-lift vehicles: take off to this height, land, fly this (north, east) m/s
    takeoff_agl_m: float | None = None
    land: bool = False
    velocity_ne: tuple[float, float] | None = None
    #: gimbal cameras' new angles (None: unchanged); not part of the flight
    gimbal_pitch_deg: float | None = None
    gimbal_yaw_deg: float | None = None
    #: a point the gimbal cameras keep pointing at (None: no tracking asked)
    gimbal_look_at: Point | None = None
    #: the gimbal cameras stop tracking, holding the angles they have (``look_at: null``)
    gimbal_hold: bool = False
    #: stills from the vehicle's cameras (None: none); not part of the flight
    camera: CameraTrigger | None = None
    source: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def flies(self) -> bool:
        """Whether the command says anything to the vehicle's guidance (a
        command of only gimbal angles or camera stills does not)."""
        return (self.heading_deg is not None or self.alt_m is not None
                or self.airspeed_mps is not None or self.throttle is not None
                or self.bank_limit_deg is not None or self.stall_protection is not None
                or self.nav is not None or self.takeoff_agl_m is not None or self.land
                or self.velocity_ne is not None)

    @property
    def points_gimbal(self) -> bool:
        return (self.gimbal_pitch_deg is not None or self.gimbal_yaw_deg is not None
                or self.gimbal_look_at is not None or self.gimbal_hold)

    def label(self) -> str:
        """A short description for the state log's ``command`` column."""
        parts = []
        if self.nav:
            parts.append(self.nav)
        elif self.heading_deg is not None:
            parts.append(f"heading {self.heading_deg:g}")
        if self.alt_m is not None:
            parts.append(f"alt {'agl' if self.alt_agl else 'msl'} {self.alt_m:g}")
        if self.airspeed_mps is not None:
            parts.append(f"speed {self.airspeed_mps / KT_TO_MPS:.0f}kt")
        if self.throttle is not None:
            parts.append(f"throttle {self.throttle:g}")
        if self.takeoff_agl_m is not None:
            parts.append(f"takeoff {self.takeoff_agl_m:g} m")
        if self.land:
            parts.append("land")
        if self.velocity_ne is not None:
            parts.append("velocity {:g} {:g}".format(*self.velocity_ne))
        if self.gimbal_look_at is not None:
            p = self.gimbal_look_at
            parts.append(f"gimbal look at {p.a:g},{p.b:g}"
                         + (" (lat/lon)" if p.frame == "geodetic" else
                            " (from start)" if p.frame == "start" else ""))
        elif self.gimbal_hold:
            parts.append("gimbal hold")
        elif self.points_gimbal:
            parts.append("gimbal " + " ".join(
                f"{k} {v:g}" for k, v in (("pitch", self.gimbal_pitch_deg),
                                          ("yaw", self.gimbal_yaw_deg)) if v is not None))
        return ", ".join(parts) or "settings"


def _num(d: dict[str, Any], key: str, path: P, report: Report, lo: float | None = None,
         hi: float | None = None) -> float | None:
    v = d.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        report(path + (key,), f"expected a number, got {v!r}")
        return None
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f"{lo:g}..{hi:g}" if lo is not None and hi is not None else (
            f">= {lo:g}" if lo is not None else f"<= {hi:g}")
        report(path + (key,), f"must be {rng}, got {v!r}")
        return None
    return float(v)


def _one_of(d: dict[str, Any], keys: tuple[str, str], path: P, report: Report) -> str | None:
    present = [k for k in keys if k in d]
    if len(present) > 1:
        report(path, f"give only one of {keys[0]} / {keys[1]}")
        return None
    return present[0] if present else None


def _alt_speed(d: dict[str, Any], path: P, report: Report
               ) -> tuple[float | None, bool, float | None]:
    alt = None
    agl = False
    k = _one_of(d, ("alt_msl_m", "alt_agl_m"), path, report)
    if k:
        alt = _num(d, k, path, report, lo=-500, hi=30000)
        agl = k == "alt_agl_m"
    spd = None
    k = _one_of(d, ("airspeed_kt", "airspeed_mps"), path, report)
    if k:
        s = _num(d, k, path, report, lo=0, hi=2000)
        spd = None if s is None else s * (KT_TO_MPS if k == "airspeed_kt" else 1.0)
    return alt, agl, spd


def _point(d: Any, path: P, report: Report, extra: tuple[str, ...] = _TARGET_EXTRA
           ) -> Point | None:
    if not isinstance(d, dict):
        report(path, f"expected a point (lat_deg/lon_deg or north_m/east_m), got {d!r}")
        return None
    for k in d:
        if k not in _POINT_KEYS + extra:
            report(path + (k,), f"unknown key {k!r}; expected one of: "
                                f"{', '.join(_POINT_KEYS + extra)}")
    frame = d.get("frame", "local")
    if frame not in ("local", "start"):
        report(path + ("frame",), f"expected local or start, got {frame!r}")
        return None
    geo = "lat_deg" in d or "lon_deg" in d
    ned = "north_m" in d or "east_m" in d
    if geo and ned:
        report(path, "give lat_deg/lon_deg or north_m/east_m, not both")
        return None
    if geo:
        if frame == "start":
            report(path + ("frame",), "frame: start takes north_m/east_m offsets, not lat/lon")
            return None
        a, b = _num(d, "lat_deg", path, report, -90, 90), _num(d, "lon_deg", path, report,
                                                                 -180, 180)
    elif ned:
        far = MAX_DISTANCE_M
        a = _num(d, "north_m", path, report, -far, far) if "north_m" in d else 0.0
        b = _num(d, "east_m", path, report, -far, far) if "east_m" in d else 0.0
    else:
        report(path, "missing the position: lat_deg/lon_deg or north_m/east_m")
        return None
    alt, agl, spd = _alt_speed(d, path, report) if extra else (None, False, None)
    if a is None or b is None:
        return None
    return Point("geodetic" if geo else frame, a, b, alt, agl, spd)


def parse_command(d: Any, path: P, report: Report) -> Command | None:
    """Parse one ``command:`` mapping; problems go to ``report(path, message)``."""
    if not isinstance(d, dict) or not d:
        report(path, f"expected a mapping of commands ({', '.join(COMMAND_KEYS)}), got {d!r}")
        return None
    for k in d:
        if k not in COMMAND_KEYS:
            report(path + (k,), f"unknown command {k!r}; expected one of: "
                                f"{', '.join(COMMAND_KEYS)}")
    navs = [k for k in ("goto", "waypoints", "loiter") if k in d]
    if len(navs) > 1:
        report(path, f"give one of goto / waypoints / loiter, not {' and '.join(navs)}")
        return None
    if navs and "heading_deg" in d:
        report(path, f"heading_deg and {navs[0]} conflict: a heading ends the {navs[0]}")
        return None
    heading = _num(d, "heading_deg", path, report, -360, 360) if "heading_deg" in d else None
    alt, agl, spd = _alt_speed(d, path, report)
    throttle = _num(d, "throttle", path, report, 0, 1) if "throttle" in d else None
    if throttle is not None and spd is not None:
        report(path, "throttle (manual) and an airspeed hold conflict: give one")
    bank = _num(d, "bank_limit_deg", path, report, 5, 75) if "bank_limit_deg" in d else None
    stall = d.get("stall_protection")
    if stall is not None and not isinstance(stall, bool):
        report(path + ("stall_protection",), f"expected true or false, got {stall!r}")
        stall = None
    gimbal = _gimbal(d["gimbal"], path + ("gimbal",), report) if "gimbal" in d \
        else (None, None, None, False)
    camera = _camera(d["camera"], path + ("camera",), report) if "camera" in d else None
    takeoff = _num(d, "takeoff_agl_m", path, report, 0.5, 3000) if "takeoff_agl_m" in d else None
    land = d.get("land", False)
    if not isinstance(land, bool):
        report(path + ("land",), f"expected true or false, got {land!r}")
        land = False
    velocity = _velocity(d["velocity"], path + ("velocity",), report) if "velocity" in d \
        else None
    if velocity is not None and (navs or "heading_deg" in d):
        report(path, "velocity and a goto, waypoints, loiter or heading conflict: give one")
    if takeoff is not None and land and not navs:
        report(path, "takeoff_agl_m and land conflict: give one (or a route between them)")
    nav = navs[0] if navs else None
    points: list[Point] = []
    radius = None
    cw = True
    here = False
    leg_from: Point | None = None
    leg_continue = False
    if nav == "goto":
        g = d["goto"]
        p = _point({k: v for k, v in g.items() if k not in ("from", "continue")}
                   if isinstance(g, dict) else g,
                   path + ("goto",), report, _TARGET_EXTRA + ("loiter_radius_m",))
        if p is not None:
            points.append(p)
        if isinstance(g, dict) and "loiter_radius_m" in g:
            radius = _num(g, "loiter_radius_m", path + ("goto",), report, lo=1)
        if isinstance(g, dict) and "from" in g:
            leg_from = _point(g["from"], path + ("goto", "from"), report, ())
        if isinstance(g, dict) and "continue" in g:
            if not isinstance(g["continue"], bool):
                report(path + ("goto", "continue"), f"expected true or false, got "
                                                    f"{g['continue']!r}")
            leg_continue = g["continue"] is True
    elif nav == "waypoints":
        w = d["waypoints"]
        if isinstance(w, dict):
            wp = w
            w = wp.get("points")
            for k in wp:
                if k not in ("points", "loiter_radius_m"):
                    report(path + ("waypoints", k), f"unknown key {k!r}; expected points, "
                                                    f"loiter_radius_m")
            if "loiter_radius_m" in wp:
                radius = _num(wp, "loiter_radius_m", path + ("waypoints",), report, lo=1)
        if not isinstance(w, list) or not w:
            report(path + ("waypoints",), "expected a non-empty list of points")
        else:
            for i, item in enumerate(w):
                p = _point(item, path + ("waypoints", i), report)
                if p is not None:
                    points.append(p)
    elif nav == "loiter":
        lo = d["loiter"]
        if not isinstance(lo, dict):
            report(path + ("loiter",), f"expected a mapping (center, radius_m, direction), "
                                       f"got {lo!r}")
        else:
            for k in lo:
                if k not in ("center", "radius_m", "direction") + _TARGET_EXTRA:
                    report(path + ("loiter", k), f"unknown key {k!r}; expected one of: center, "
                                                 f"radius_m, direction, alt_msl_m, alt_agl_m, "
                                                 f"airspeed_kt, airspeed_mps")
            if "center" in lo:
                p = _point(lo["center"], path + ("loiter", "center"), report, ())
                if p is not None:
                    points.append(p)
            else:
                here = True
            if "radius_m" in lo:
                radius = _num(lo, "radius_m", path + ("loiter",), report, lo=1)
            direction = lo.get("direction", "cw")
            if direction not in ("cw", "ccw"):
                report(path + ("loiter", "direction"), f"expected cw or ccw, got {direction!r}")
            cw = direction != "ccw"
            la, lagl, ls = _alt_speed(lo, path + ("loiter",), report)
            if la is not None:
                alt, agl = la, lagl
            if ls is not None:
                spd = ls
    if nav == "goto" and points:
        # the target's own altitude/speed are the command's
        if points[0].alt_m is not None:
            alt, agl = points[0].alt_m, points[0].alt_agl
        if points[0].airspeed_mps is not None:
            spd = points[0].airspeed_mps
    return Command(heading_deg=None if heading is None else heading % 360.0, alt_m=alt,
                   alt_agl=agl, airspeed_mps=spd, throttle=throttle, bank_limit_deg=bank,
                   stall_protection=stall, nav=nav, points=tuple(points),
                   loiter_radius_m=radius, loiter_cw=cw, loiter_here=here, leg_from=leg_from,
                   leg_continue=leg_continue,
                   takeoff_agl_m=takeoff, land=land, velocity_ne=velocity,
                   gimbal_pitch_deg=gimbal[0], gimbal_yaw_deg=gimbal[1],
                   gimbal_look_at=gimbal[2], gimbal_hold=gimbal[3], camera=camera,
                   source=d)


def _velocity(v: Any, path: P, report: Report) -> tuple[float, float] | None:
    if not isinstance(v, dict) or not v:
        report(path, f"expected a mapping with north_mps and/or east_mps, got {v!r}")
        return None
    for k in v:
        if k not in ("north_mps", "east_mps"):
            report(path + (k,), f"unknown key {k!r}; expected north_mps, east_mps")
    n = _num(v, "north_mps", path, report, -100, 100) if "north_mps" in v else 0.0
    e = _num(v, "east_mps", path, report, -100, 100) if "east_mps" in v else 0.0
    return None if n is None or e is None else (n, e)


def _gimbal(g: Any, path: P, report: Report
            ) -> tuple[float | None, float | None, Point | None, bool]:
    """A ``gimbal`` command: its (pitch_deg, yaw_deg, look_at point, hold:
    ``look_at: null``)."""
    if not isinstance(g, dict) or not g:
        report(path, f"expected a mapping with pitch_deg and/or yaw_deg, or look_at, got {g!r}")
        return None, None, None, False
    for k in g:
        if k not in ("pitch_deg", "yaw_deg", "look_at"):
            report(path + (k,), f"unknown key {k!r}; expected pitch_deg, yaw_deg, look_at")
    if "look_at" in g:
        angles = [k for k in ("pitch_deg", "yaw_deg") if k in g]
        if angles:
            report(path, f"give look_at or angles ({' / '.join(angles)}), not both: look_at "
                         f"points the gimbal itself")
            return None, None, None, False
        if g["look_at"] is None:
            return None, None, None, True
        return None, None, _point(g["look_at"], path + ("look_at",), report,
                                  _LOOK_AT_EXTRA), False
    pitch = _num(g, "pitch_deg", path, report, *GIMBAL_PITCH_DEG) if "pitch_deg" in g else None
    yaw = _num(g, "yaw_deg", path, report, *GIMBAL_YAW_DEG) if "yaw_deg" in g else None
    return pitch, yaw, None, False


def _camera(c: Any, path: P, report: Report) -> CameraTrigger | None:
    keys = ("shoot", "interval_s", "distance_m", "count", "stop")
    if not isinstance(c, dict) or not c:
        report(path, f"expected a mapping with one of shoot, interval_s, distance_m, stop, "
                     f"got {c!r}")
        return None
    for k in c:
        if k not in keys:
            report(path + (k,), f"unknown key {k!r}; expected one of: {', '.join(keys)}")
    modes = [k for k in ("shoot", "interval_s", "distance_m", "stop") if k in c]
    if len(modes) != 1:
        report(path, f"give exactly one of shoot, interval_s, distance_m, stop; got "
                     f"{', '.join(modes) or 'none'}")
        return None
    mode = modes[0]
    if mode in ("shoot", "stop"):
        if c[mode] is not True:
            report(path + (mode,), f"expected true, got {c[mode]!r}")
            return None
        if "count" in c:
            report(path + ("count",), "count goes with interval_s or distance_m")
        return CameraTrigger(shoot=mode == "shoot", stop=mode == "stop")
    lo = MIN_STILL_INTERVAL_S if mode == "interval_s" else MIN_STILL_DISTANCE_M
    value = _num(c, mode, path, report, lo, 86_400.0 if mode == "interval_s" else 1e6)
    count = None
    if "count" in c:
        n = c["count"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100_000:
            report(path + ("count",), f"expected a whole number 1..100000, got {n!r}")
            return None
        count = n
    if value is None:
        return None
    return CameraTrigger(interval_s=value if mode == "interval_s" else None,
                         distance_m=value if mode == "distance_m" else None, count=count)
