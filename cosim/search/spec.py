"""The scenario's ``search:`` section -> ``SearchSpec``.

::

    search:
      area: [[n, e], ...]            # or area_latlon: [[lat, lon], ...]
      no_fly: [[[n, e], ...], ...]   # or no_fly_latlon: zones the plan keeps out of
      base: {north_m: 0, east_m: 0}  # or {lat_deg, lon_deg}; default the origin
      aircraft: all                  # which vehicles search (ids, patterns)
      airspeed_kt: 200
      bank_deg: 45                   # turn radius v^2 / (g tan(bank))
      flown_bank_deg: 55             # the aircraft's bank limit (room to follow)
      alt_agl_m: auto                # auto: the highest that still sees a fire
                                     # with detection.min_pixels
      overlap: 0.1                   # of the swath, between neighbouring lanes
      sweep_deg: null                # lane direction; default the area's long axis
      camera: {hfov_deg: 60, width_px: 1280, height_px: 720, rate_hz: 2}
      fires:
        target: random               # or {north_m, east_m} / {lat_deg, lon_deg}
        decoys: 3                    # how many at random, or a list of positions
        size_m: 8                    # burning patch side at the start
        height_m: 3                  # flame height
        growth_m_per_min: 1          # patch side growth
      detection: {min_pixels: 16, dwell_s: 1.0, position_sigma_m: 0,
                  attitude_sigma_deg: 0, image: false}   # image: also run the image
                                     # detector on the aircraft's rendered frames
      coverage_cell_m: auto          # the coverage map's cell
      coverage_hz: 1                 # steps of the coverage map (each the ground
                                     # swept since the last)

Everything is bounded: the area's extent, vertex counts, the number of fires,
the coverage map's cells. Fires placed at random are drawn from the
scenario's seed, inside the area and outside the no-fly zones, so the same
scenario always hides them in the same places. The fires join the world's
targets (kind ``fire``), so cameras render them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.core.geo import MAX_DISTANCE_M
from cosim.core.units import KT_TO_MPS

P = tuple[Any, ...]

#: the search area's largest side (m) and vertex count; zones and fires
MAX_SIDE_M = 64_000.0
MAX_VERTICES = 1000
MAX_ZONES = 100
MAX_FIRES = 100
#: cells of the coverage map at most (4096 x 4096)
MAX_CELLS = 1 << 24
#: the coverage cell when ``auto``: about 2,000 a side over the area's bounding
#: box, finer where a quarter of the swath is finer, never more than 4096 a side
AUTO_CELLS_SIDE = 2000
MIN_CELL_M = 2.0

TARGET_ID, DECOY_PREFIX = "fire_target", "decoy"
_RANDOM_TRIES = 10_000


@dataclass(frozen=True)
class FireSpec:
    id: str
    north_m: float
    east_m: float
    size_m: float
    height_m: float
    growth_m_per_s: float
    decoy: bool


@dataclass(frozen=True)
class DetectionSpec:
    min_pixels: float = 16.0  # pixels on the fire in one frame
    dwell_s: float = 1.0  # that long in view (consecutive frames of one camera)
    position_sigma_m: float = 0.0  # navigation error of the reporting aircraft
    attitude_sigma_deg: float = 0.0  # and of its camera's pointing
    #: also search the rendered frames of the search aircraft's cameras
    #: (``cameras:``) with the image detector (``image_detect``)
    image: bool = False


@dataclass(frozen=True)
class SearchSpec:
    area_ne: tuple[tuple[float, float], ...]
    no_fly_ne: tuple[tuple[tuple[float, float], ...], ...]
    base_ne: tuple[float, float]
    rows: tuple[int, ...]
    airspeed_kt: float
    bank_deg: float
    flown_bank_deg: float  # the aircraft's bank limit in flight (ROLL_LIMIT_DEG)
    alt_agl_m: float
    alt_auto: bool
    overlap: float
    sweep_deg: float | None
    camera: Any  # cosim.renderer.config.CameraSpec (nadir, never rendered)
    fires: tuple[FireSpec, ...]
    detection: DetectionSpec
    cell_m: float
    coverage_every: int  # physics ticks between coverage steps
    turn_step_m: float = 100.0  # turns flown as waypoints this far apart
    #: lanes flown this far past their ends (None: the waypoints' acceptance radius)
    lane_overrun_m: float | None = None

    @property
    def airspeed_mps(self) -> float:
        return self.airspeed_kt * KT_TO_MPS

    @property
    def dwell_frames(self) -> int:
        return dwell_frames(self.detection.dwell_s, self.camera.rate_hz)


def dwell_frames(dwell_s: float, rate_hz: float) -> int:
    """Frames in a row that a fire must be seen in: each frame stands for
    ``1 / rate_hz`` s of the camera's, at least one."""
    return max(1, math.ceil(dwell_s * rate_hz - 1e-9))


def _points(info: Any, raw: Any, p: P, what: str, latlon: bool, frame: Any
            ) -> tuple[tuple[float, float], ...] | None:
    """A polygon's corners as (north_m, east_m) from [n, e] or [lat, lon] pairs."""
    from shapely.geometry import Polygon

    pair = "[lat_deg, lon_deg]" if latlon else "[north_m, east_m]"
    if not isinstance(raw, list) or not 3 <= len(raw) <= MAX_VERTICES:
        info.err(p, f"expected {what} as a list of 3 to {MAX_VERTICES} {pair} corners, "
                    f"got {raw!r}"[:300])
        return None
    pts: list[tuple[float, float]] = []
    for j, c in enumerate(raw):
        ok = (isinstance(c, list) and len(c) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                      and math.isfinite(x) for x in c))
        if ok and latlon:
            ok = abs(c[0]) <= 90 and abs(c[1]) <= 180
        if ok and not latlon:
            ok = all(abs(x) <= MAX_DISTANCE_M for x in c)
        if not ok:
            bound = "latitude and longitude in degrees" if latlon else \
                f"within {MAX_DISTANCE_M:g} m of the origin"
            info.err(p + (j,), f"expected {pair} ({bound}), got {c!r}"[:300])
            return None
        pts.append((float(c[0]), float(c[1])))
    if latlon:
        n, e, _ = frame.geodetic_to_ned([q[0] for q in pts], [q[1] for q in pts],
                                        [frame.alt_m] * len(pts))
        pts = [(float(a), float(b)) for a, b in zip(n, e)]
        if max(abs(x) for q in pts for x in q) > MAX_DISTANCE_M:
            info.err(p, f"{what} reaches farther than {MAX_DISTANCE_M:g} m from the origin")
            return None
    poly = Polygon([(e, n) for n, e in pts])
    if not poly.is_valid:
        info.err(p, f"{what}: its edges cross each other")
        return None
    if poly.area < 1.0:
        info.err(p, f"{what} has no area")
        return None
    return tuple(pts)


def _polygon_of(info: Any, r: Any, key: str, p: P, frame: Any
                ) -> tuple[tuple[float, float], ...] | None:
    which = r.one_of(key, f"{key}_latlon")
    if which is None:
        return None
    return _points(info, r.d[which], p + (which,), key, which.endswith("_latlon"), frame)


def _zones(info: Any, r: Any, p: P, frame: Any) -> tuple[tuple[tuple[float, float], ...], ...]:
    which = r.one_of("no_fly", "no_fly_latlon")
    if which is None:
        return ()
    raw = r.d[which]
    if not isinstance(raw, list) or len(raw) > MAX_ZONES:
        info.err(p + (which,), f"expected a list of at most {MAX_ZONES} polygons")
        return ()
    out = []
    for i, z in enumerate(raw):
        pts = _points(info, z, p + (which, i), f"no-fly zone {i}", which.endswith("_latlon"),
                      frame)
        if pts is not None:
            out.append(pts)
    return tuple(out)


def _position(info: Any, d: Any, p: P, frame: Any, size: float | None = None
              ) -> tuple[tuple[float, float] | None, float]:
    """A point (north_m/east_m or lat_deg/lon_deg) as (north, east), or None
    if it is wrong (reported); with ``size`` (a fire's default), the point
    may also give its ``size_m``, returned beside it."""
    keys = ("north_m", "east_m", "lat_deg", "lon_deg") + (("size_m",) if size is not None
                                                          else ())
    r = info.reader(d, p, keys)
    own = (r.num("size_m", size, lo=0.5, hi=500.0) or size) if size is not None else 0.0
    if r.has("lat_deg") or r.has("lon_deg"):
        if r.has("north_m") or r.has("east_m"):
            info.err(p, "give north_m/east_m or lat_deg/lon_deg, not both")
            return None, own
        la, lo = r.num("lat_deg", lo=-90, hi=90), r.num("lon_deg", lo=-180, hi=180)
        if la is None or lo is None:
            return None, own
        n, e, _ = frame.geodetic_to_ned(la, lo, frame.alt_m)
        return (float(n), float(e)), own
    n = r.num("north_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
    e = r.num("east_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
    return (None if n is None or e is None else (n, e)), own


def _random_points(area: Any, zones: list[Any], n: int, seed: int, salt: int
                   ) -> list[tuple[float, float]] | None:
    """``n`` points uniformly inside ``area`` and outside ``zones`` (shapely,
    x east, y north), from ``seed``; None if they cannot be found."""
    from shapely import prepared
    from shapely.geometry import Point

    rng = np.random.default_rng([seed, 0x5EA2C4, salt])
    x0, y0, x1, y1 = area.bounds
    inside = prepared.prep(area)
    zs = [prepared.prep(z) for z in zones]
    out: list[tuple[float, float]] = []
    for _ in range(_RANDOM_TRIES):
        if len(out) == n:
            return out
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        q = Point(x, y)
        if inside.contains(q) and not any(z.contains(q) for z in zs):
            out.append((float(y), float(x)))
    return out if len(out) == n else None


def _fires(info: Any, d: Any, p: P, frame: Any, area: Any, zones: list[Any], seed: int
           ) -> tuple[FireSpec, ...]:
    r = info.reader(d, p, ("target", "decoys", "size_m", "height_m", "growth_m_per_min"))
    size = r.num("size_m", 8.0, lo=0.5, hi=500.0)
    height = r.num("height_m", 3.0, lo=0.1, hi=100.0)
    growth = r.num("growth_m_per_min", 0.0, lo=0.0, hi=100.0)
    if None in (size, height, growth):
        return ()
    wanted: list[tuple[str, Any, float, bool]] = []  # id, position or None, size, decoy
    raw_t = r.d.get("target", "random")
    if raw_t == "random":
        wanted.append((TARGET_ID, None, size, False))
    elif raw_t is None or raw_t is False:
        pass  # no target: an exercise with decoys only
    else:
        pos, sz = _position(info, raw_t, p + ("target",), frame, size)
        if pos is not None:
            wanted.append((TARGET_ID, pos, sz, False))
    raw_d = r.d.get("decoys", 0)
    if isinstance(raw_d, int) and not isinstance(raw_d, bool):
        if not 0 <= raw_d < MAX_FIRES:
            info.err(p + ("decoys",), f"expected 0 to {MAX_FIRES - 1} decoys, got {raw_d}")
        else:
            wanted += [(f"{DECOY_PREFIX}{i + 1}", None, size, True) for i in range(raw_d)]
    elif isinstance(raw_d, list) and len(raw_d) < MAX_FIRES:
        for i, dd in enumerate(raw_d):
            q = p + ("decoys", i)
            pos, sz = _position(info, dd, q, frame, size)
            if pos is not None:
                wanted.append((f"{DECOY_PREFIX}{i + 1}", pos, sz, True))
    else:
        info.err(p + ("decoys",), f"expected a number of decoys or a list of at most "
                                  f"{MAX_FIRES - 1} positions, got {raw_d!r}"[:200])
    need = sum(1 for w in wanted if w[1] is None)
    drawn = _random_points(area, zones, need, seed, 1) if need and area is not None else []
    if drawn is None:
        info.err(p, f"could not place {need} fire(s) at random inside the area and outside "
                    f"the no-fly zones")
        return ()
    out = []
    it = iter(drawn or [])
    for fid, pos, sz, decoy in wanted:
        n, e = pos if pos is not None else next(it)
        out.append(FireSpec(fid, n, e, sz, height, growth / 60.0, decoy))
    return tuple(out)


def parse_search(info: Any, node: Any, path: P) -> SearchSpec | None:
    """The ``search:`` section (see the module docstring); problems go to ``info``.
    Its fires join the world as targets (``fire_targets``, through the section)."""
    from shapely.geometry import Polygon

    from cosim.renderer.config import parse_camera

    frame = info.origin.frame
    r = info.reader(node, path, ("area", "area_latlon", "no_fly", "no_fly_latlon", "base",
                                 "aircraft", "airspeed_kt", "bank_deg", "flown_bank_deg",
                                 "alt_agl_m", "overlap", "sweep_deg", "camera", "fires",
                                 "detection", "coverage_cell_m", "coverage_hz", "turn_step_m",
                                 "lane_overrun_m"))
    area_pts = _polygon_of(info, r, "area", path, frame)
    if area_pts is None and not r.one_of("area", "area_latlon"):
        info.err(path, "missing required key 'area' (or 'area_latlon')")
    area = Polygon([(e, n) for n, e in area_pts]) if area_pts else None
    if area is not None:
        x0, y0, x1, y1 = area.bounds
        if max(x1 - x0, y1 - y0) > MAX_SIDE_M:
            info.err(path, f"the area is {(x1 - x0) / 1000:.1f} x {(y1 - y0) / 1000:.1f} km; at "
                           f"most {MAX_SIDE_M / 1000:g} km a side")
            area = None
    zone_pts = _zones(info, r, path, frame)
    zones = [Polygon([(e, n) for n, e in z]) for z in zone_pts]
    base = (0.0, 0.0)
    if r.has("base"):
        base = _position(info, r.d["base"], path + ("base",), frame)[0] or base
    rows = info.select(r.d.get("aircraft", "all"), path + ("aircraft",))
    if not rows:
        info.err(path + ("aircraft",), "no vehicle to search with")
    v_kt = r.num("airspeed_kt", 200.0, lo=10.0, hi=1000.0)
    bank = r.num("bank_deg", 45.0, lo=5.0, hi=70.0)
    flown = r.num("flown_bank_deg", min((bank or 45.0) + 10.0, 75.0), lo=5.0, hi=75.0)
    if bank is not None and flown is not None and flown < bank:
        info.err(path + ("flown_bank_deg",), f"the aircraft must be allowed at least the "
                                             f"plan's bank ({bank:g} deg), got {flown:g}")
    overlap = r.num("overlap", 0.1, lo=0.0, hi=0.9)
    sweep = r.num("sweep_deg", None, lo=-360.0, hi=360.0) if r.d.get("sweep_deg") is not None \
        else None
    step = r.num("turn_step_m", 100.0, lo=5.0, hi=5000.0)
    overrun = r.num("lane_overrun_m", lo=0.0, hi=5000.0) \
        if r.d.get("lane_overrun_m", "auto") != "auto" else None
    cam_node = dict(r.d.get("camera") or {}) if isinstance(r.d.get("camera", {}), dict) \
        else r.d.get("camera")
    if isinstance(cam_node, dict):
        if "mount" in cam_node:
            info.err(path + ("camera", "mount"), "the search camera looks straight down "
                                                 "(nadir): leave out mount")
        if "sensor" in cam_node:
            info.err(path + ("camera", "sensor"), "the search camera sees by geometry, not "
                                                  "pixels: give sensor: to a view of cameras:")
        cam_node = {"name": "search", "width_px": 1280, "height_px": 720, "rate_hz": 2.0,
                    "stabilised": True, **cam_node, "mount": "nadir",
                    "vehicles": "all"}
    camera = parse_camera(info, cam_node, path + ("camera",), 0)
    if camera is not None and camera.frame_every % info.rates.control_every:
        info.err(path + ("camera", "rate_hz"),
                 f"the search camera's frames must fall on exchanges: rate_hz "
                 f"{camera.rate_hz:g} is not control_hz {info.rates.control_hz:g} divided by a "
                 f"whole number")
        camera = None
    dr = info.reader(r.d.get("detection", {}), path + ("detection",),
                     ("min_pixels", "dwell_s", "position_sigma_m", "attitude_sigma_deg",
                      "image"))
    det = DetectionSpec(dr.num("min_pixels", 16.0, lo=1.0, hi=1e7) or 16.0,
                        dr.num("dwell_s", 1.0, lo=0.0, hi=600.0) or 0.0,
                        dr.num("position_sigma_m", 0.0, lo=0.0, hi=1000.0) or 0.0,
                        dr.num("attitude_sigma_deg", 0.0, lo=0.0, hi=30.0) or 0.0,
                        dr.boolean("image", False))
    fires = _fires(info, r.d.get("fires", {}), path + ("fires",), frame, area, zones,
                   info.seed) if area is not None else ()
    if len(fires) > MAX_FIRES:
        info.err(path + ("fires",), f"{len(fires)} fires; at most {MAX_FIRES}")
    alt_raw = r.d.get("alt_agl_m", "auto")
    alt_auto = alt_raw == "auto"
    alt = 300.0
    if alt_auto:
        if camera is not None:
            from cosim.coverage import max_alt_for_detection_m

            size = min((f.size_m for f in fires), default=8.0)
            alt = max_alt_for_detection_m(size, math.sqrt(det.min_pixels), camera.width_px,
                                          camera.hfov_deg)
            alt = min(max(alt, 30.0), 3000.0)
    else:
        alt = r.num("alt_agl_m", lo=10.0, hi=10_000.0) or alt
    if camera is not None:  # the footprint's corners must be drawn whole (not cut back)
        from cosim.search.sensing import MAX_RANGE_M

        corner = alt * math.hypot(math.tan(math.radians(camera.hfov_deg) / 2),
                                  math.tan(math.radians(camera.vfov_deg) / 2))
        if corner > MAX_RANGE_M:
            info.err(path + ("alt_agl_m",), f"at {alt:.0f} m the camera's footprint reaches "
                                            f"{corner:.0f} m away; at most {MAX_RANGE_M:.0f} m: "
                                            f"fly lower or narrow the camera")
    cell = 0.0
    raw_cell = r.d.get("coverage_cell_m", "auto")
    if area is not None:
        x0, y0, x1, y1 = area.bounds
        side = max(x1 - x0, y1 - y0)
        if raw_cell == "auto":  # a quarter of the swath, at most 4096 cells a side
            from cosim.coverage import swath_m

            sw = swath_m(alt, camera.hfov_deg) if camera is not None else side
            cell = max(MIN_CELL_M, min(side / AUTO_CELLS_SIDE, sw / 4.0), side / 4096.0)
        else:
            cell = r.num("coverage_cell_m", lo=MIN_CELL_M, hi=10_000.0) or 0.0
            if cell and ((x1 - x0) / cell + 1) * ((y1 - y0) / cell + 1) > MAX_CELLS:
                info.err(path + ("coverage_cell_m",),
                         f"{cell:g} m cells make a map of more than {MAX_CELLS} cells over "
                         f"this area; use larger cells")
    cov_hz = r.num("coverage_hz", 1.0, lo=0.01, hi=info.rates.control_hz)
    cov_every = 0
    if cov_hz is not None:
        cov_every = round(info.rates.physics_hz / cov_hz)
        if abs(info.rates.physics_hz / cov_hz - cov_every) > 1e-9 \
                or cov_every % info.rates.control_every:
            info.err(path + ("coverage_hz",),
                     f"coverage steps must fall on exchanges: coverage_hz {cov_hz:g} is not "
                     f"control_hz {info.rates.control_hz:g} divided by a whole number")
            cov_every = 0
    if None in (v_kt, bank, flown, overlap, step) or not cov_every or camera is None \
            or area is None or not rows:
        return None
    if det.image:
        if not cameras_for(info.sections, info.rates.control_every, tuple(rows)):
            info.err(path + ("detection", "image"),
                     "the image detector needs a camera (cameras:) on a search aircraft, "
                     "not on a gimbal, with frames on exchanges (rate_hz: control_hz divided "
                     "by a whole number)")
    _check_aircraft(info, rows, path)
    spec = SearchSpec(area_ne=area_pts or (), no_fly_ne=zone_pts, base_ne=base,
                      rows=tuple(rows), airspeed_kt=v_kt, bank_deg=bank,
                      flown_bank_deg=flown or bank, alt_agl_m=alt,
                      alt_auto=alt_auto, overlap=overlap, sweep_deg=sweep, camera=camera,
                      fires=fires, detection=det, cell_m=cell, coverage_every=cov_every,
                      turn_step_m=step,
                      lane_overrun_m=overrun)
    if not info.problems:  # the plan, made once here: what cannot be flown is said now
        _check_plan(info, spec, path)
    return spec


def _check_aircraft(info: Any, rows: list[int], path: P) -> None:
    """Every search aircraft must fly missions and be on MAVLink."""
    from cosim.mavlink.scenario import mavlink_rows
    from cosim.vehicles import get_class

    for r in rows:
        p = get_class(info.vehicles[r].vehicle_class).mavlink
        if p is None or p.auto_mode is None or not p.autopilot:
            info.err(path + ("aircraft",), f"vehicle {info.ids[r]} (class "
                                           f"{info.vehicles[r].vehicle_class}) flies no "
                                           f"missions: it cannot fly a search plan")
            return
    on = mavlink_rows(info.mavlink, info.ids)
    off = [info.ids[r] for r in rows if on is not None and r not in on]
    if off:
        info.err(path + ("aircraft",), f"{', '.join(off[:5])}{' ...' if len(off) > 5 else ''}"
                                       f" not on MAVLink (mavlink.vehicles leaves them out): "
                                       f"search plans are flown as MAVLink missions")


def _check_plan(info: Any, spec: SearchSpec, path: P) -> None:
    """Make the plan (``cosim.search.mission``) and each aircraft's mission;
    report what stops either."""
    from cosim.mavlink.mission import MAX_ITEMS
    from cosim.search.mission import ACCEPT_M, mission_waypoints, plan_search

    frame = info.origin.frame
    starts = []
    for r in spec.rows:
        v = info.vehicles[r]
        n, e, _ = frame.geodetic_to_ned(v.lat_deg, v.lon_deg, frame.alt_m)
        starts.append((float(n), float(e), v.heading_deg))
    try:
        plan = plan_search(spec, starts)
    except ValueError as e:
        info.err(path, f"cannot plan the search: {e}")
        return
    overrun = spec.lane_overrun_m if spec.lane_overrun_m is not None else ACCEPT_M
    for k, a in enumerate(plan.aircraft):
        try:
            mission_waypoints(a, spec.turn_step_m, overrun, MAX_ITEMS)
        except ValueError as e:
            info.err(path, f"{info.ids[spec.rows[k]]}'s plan: {e}")
            return


def fire_targets(spec: SearchSpec) -> tuple[Any, ...]:
    """The search's fires as targets of the world (kind ``fire``), so cameras
    draw them and detections are scored against them."""
    from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

    color = TARGET_DEFAULTS["fire"][3]
    return tuple(TargetSpec(id=f.id, kind="fire", north_m=f.north_m, east_m=f.east_m,
                            lat_deg=None, lon_deg=None, heading_deg=0.0, length_m=f.size_m,
                            width_m=f.size_m, height_m=f.height_m, color_rgb=color,
                            growth_m_per_s=f.growth_m_per_s) for f in spec.fires)


def cameras_for(sections: dict[str, Any], control_every: int, rows: tuple[int, ...]
                ) -> list[Any]:
    """The ``cameras:`` views the image detector can use: on search aircraft,
    frames on exchanges (every ``control_every`` ticks), not on a gimbal."""
    cams = sections.get("cameras")
    return [c for c in (cams.views if cams is not None else ())
            if set(c.vehicles) & set(rows) and c.frame_every % control_every == 0
            and c.mount != "gimbal"]
