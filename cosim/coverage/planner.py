"""Coverage plans for a fixed-wing fleet over a search area.

The area (a polygon in the scenario's local frame, metres north and east of
the origin) is split among the aircraft and each one's share laid out as a
lawnmower of lanes (``lanes``: equal-area strips, rows of lanes, cells and
their order), joined by the shortest turns a fixed-wing can fly
(``dubins``, radius ``v^2 / (g tan(bank))``); the aircraft's transit from
the base to its first lane is counted. No-fly zones are flown around
(``airspace``): no flown point comes nearer a zone than a margin
(``no_fly_margin_m``, a tenth of the turn radius unless told); every join
and the transit is checked against the zones, and a join that would touch
one detours. ``min_fleet`` finds the smallest fleet that covers the area
before a deadline.

This module owns the plan (``AircraftPlan``, ``CoveragePlan``), its
arguments' checks and the sweep direction; the geometry of lanes and zones
is the other modules'. Everything here is geometry: no simulation, no
MAVLink. Geometry is done in a right-handed plane (x east, y north); the
public values carry ``north_m``/``east_m``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from shapely import affinity
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from cosim.coverage.airspace import Airspace, checked_zones
from cosim.coverage.dubins import DubinsChain, DubinsPath, Flight, shortest
from cosim.coverage.lanes import (
    Lane,
    Pose,
    group_cells,
    heading,
    lane_rows,
    route,
    strip_shares,
    unrotate,
)
from cosim.guidance.commands import min_turn_radius_m


def turn_radius_m(airspeed_mps: float, bank_deg: float) -> float:
    """The tightest level turn: ``v^2 / (g tan(bank))``."""
    if not 0 < bank_deg < 90:
        raise ValueError(f"bank_deg must be in (0, 90), got {bank_deg}")
    return min_turn_radius_m(airspeed_mps, bank_deg)


def swath_m(alt_agl_m: float, hfov_deg: float) -> float:
    """The ground width a nadir camera sees across track from ``alt_agl_m``."""
    return 2.0 * alt_agl_m * math.tan(math.radians(hfov_deg) / 2.0)


def max_alt_for_detection_m(target_size_m: float, min_px: float, width_px: int,
                            hfov_deg: float) -> float:
    """The highest altitude at which a target ``target_size_m`` across still
    spans ``min_px`` pixels of a ``width_px`` nadir image (``hfov_deg``)."""
    return target_size_m * width_px / (min_px * 2.0 * math.tan(math.radians(hfov_deg) / 2.0))


@dataclass
class AircraftPlan:
    """One aircraft's share: its strip, its lanes in flying order, the path."""

    index: int
    strip: BaseGeometry  # in (east, north) metres: a polygon, or several pieces

    #: lanes in flying order: ((east, north) start, (east, north) end)
    lanes: list[Lane]
    transit: Flight | None  # base to the first lane
    #: ``turns[i]`` joins ``lanes[i]`` to ``lanes[i + 1]``: a Dubins path, or a
    #: chain of them where the join detours around a no-fly zone
    turns: list[Flight] = field(default_factory=list)

    @property
    def area_m2(self) -> float:
        return float(self.strip.area)

    @property
    def survey_m(self) -> float:
        return float(sum(math.dist(a, b) for a, b in self.lanes))

    @property
    def turns_m(self) -> float:
        return float(sum(t.length_m for t in self.turns))

    @property
    def transit_m(self) -> float:
        return self.transit.length_m if self.transit is not None else 0.0

    @property
    def detour_m(self) -> float:
        """The length of the joins (and the transit) that detour around a
        no-fly zone; already counted in ``turns_m`` and ``transit_m``."""
        flights = [*self.turns, *([self.transit] if self.transit is not None else [])]
        return float(sum(t.length_m for t in flights if isinstance(t, DubinsChain)))

    @property
    def length_m(self) -> float:
        return self.transit_m + self.survey_m + self.turns_m

    def waypoints_ne(self, turn_step_m: float) -> list[tuple[float, float]]:
        """The flight as waypoints ``(north_m, east_m)`` for path following:
        the transit and the turns sampled every ``turn_step_m`` at most, each
        lane its two ends (the base itself left out)."""
        out: list[tuple[float, float]] = []

        def add(points: np.ndarray) -> None:
            out.extend((float(y), float(x)) for x, y in points[:, :2])

        if self.transit is not None:
            add(self.transit.sample(turn_step_m)[1:-1])
        for i, (a, b) in enumerate(self.lanes):
            out += [(a[1], a[0]), (b[1], b[0])]
            if i < len(self.turns):
                add(self.turns[i].sample(turn_step_m)[1:-1])
        return out

    def path(self, step_m: float = 10.0) -> np.ndarray:
        """The whole flight, transit first, as ``(k, 3)`` points ``east_m,
        north_m, heading_rad`` (heading counter-clockwise from east) at most
        ``step_m`` apart."""
        parts: list[np.ndarray] = []
        if self.transit is not None:
            parts.append(self.transit.sample(step_m))
        for i, (a, b) in enumerate(self.lanes):
            h = math.atan2(b[1] - a[1], b[0] - a[0])
            n = max(1, math.ceil(math.dist(a, b) / step_m))
            s = np.linspace(0.0, 1.0, n + 1)[:, None]
            lane = np.hstack([np.array(a) + s * (np.array(b) - np.array(a)),
                              np.full((n + 1, 1), h)])
            parts.append(lane)
            if i < len(self.turns):
                parts.append(self.turns[i].sample(step_m))
        return np.vstack(parts) if parts else np.zeros((0, 3))


@dataclass
class CoveragePlan:
    area: Polygon
    sweep_deg: float  # lanes' direction, degrees clockwise from north (a course)
    lane_spacing_m: float
    turn_radius_m: float
    aircraft: list[AircraftPlan]
    #: the zones avoided (the area's holes among them), (east, north) metres
    no_fly: list[Polygon] = field(default_factory=list)
    #: the area less the zones: what the strips share (None: the whole area)
    searchable: BaseGeometry | None = None
    no_fly_margin_m: float = 0.0  # no flown point comes nearer a zone


def area_polygon(points_ne: Sequence[tuple[float, float]]) -> Polygon:
    """A search area from its corners, ``(north_m, east_m)`` in order."""
    return _polygon(points_ne, "the search area")


def no_fly_polygon(points_ne: Sequence[tuple[float, float]]) -> Polygon:
    """A no-fly zone from its corners, ``(north_m, east_m)`` in order (for
    ``plan_coverage(..., no_fly=[...])``)."""
    return _polygon(points_ne, "a no-fly zone")


def _polygon(points_ne: Sequence[tuple[float, float]], what: str) -> Polygon:
    poly = Polygon([(e, n) for n, e in points_ne])
    if not poly.is_valid or poly.area <= 0:
        raise ValueError(f"{what} must be a simple polygon of positive area "
                         "(its edges must not cross)")
    return poly


def plan_coverage(area: Polygon, n_aircraft: int, swath_width_m: float, turn_radius: float,
                  base_ne: tuple[float, float] = (0.0, 0.0), overlap: float = 0.1,
                  sweep_deg: float | None = None, interleave: bool = True,
                  no_fly: Sequence[Polygon] = (),
                  no_fly_margin_m: float | None = None) -> CoveragePlan:
    """Split ``area`` (east, north metres) among ``n_aircraft`` and plan each
    one's lanes; ``sweep_deg`` (a course, clockwise from north) defaults to
    the area's longest axis, so that strips are long and turns few;
    ``interleave=False`` flies the lanes strictly one after another.

    ``no_fly``: polygons (east, north metres; at most 100, each of at most
    1000 vertices; a zone's own holes are not flown into) that no part of the
    flight may enter or come nearer than ``no_fly_margin_m`` (default: a
    tenth of ``turn_radius``); they may lie inside the area, cut its edge or
    lie outside it. Holes of ``area`` are no-fly zones too. The strips share
    the area less the zones equally."""
    if n_aircraft < 1:
        raise ValueError(f"n_aircraft must be >= 1, got {n_aircraft}")
    if not swath_width_m > 0 or not turn_radius > 0:
        raise ValueError("swath_width_m and turn_radius must be > 0")
    if not 0 <= overlap < 1:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    margin = 0.1 * turn_radius if no_fly_margin_m is None else float(no_fly_margin_m)
    if not margin >= 0:
        raise ValueError(f"no_fly_margin_m must be >= 0, got {no_fly_margin_m}")
    zones = checked_zones(area, no_fly)
    outer = Polygon(area.exterior)
    base = (base_ne[1], base_ne[0])
    air: Airspace | None = None
    searchable: BaseGeometry = outer
    if zones:
        air = Airspace(zones, turn_radius, margin, swath_width_m)
        searchable = air.searchable(outer, base)
    course = _longest_axis_course(outer) if sweep_deg is None else float(sweep_deg)
    theta = math.radians(90.0 - course)  # the lanes' direction, counter-clockwise from east
    # rotate so that the lanes run along +u; v across them
    rot = affinity.rotate(searchable, -theta, origin=(0, 0), use_radians=True)
    spacing = swath_width_m * (1.0 - overlap)
    shares = strip_shares(rot, n_aircraft, spacing, tiles=air is None)
    # rows apart for a plain U-turn; with interleave=False, one after another
    jump = math.ceil(2.0 * turn_radius / spacing) + 1 if interleave else 1
    out = []
    for k, (strip_r, v0, v1) in enumerate(shares):
        strip = affinity.rotate(strip_r, theta, origin=(0, 0), use_radians=True)
        rows = lane_rows(strip_r, v0, v1, spacing)
        if air is None:
            cells = [unrotate(c, theta) for c in group_cells(rows)]
        else:
            rows = air.fly_rows(rows, theta)
            cells = [unrotate(c, theta) for c in group_cells(rows)]
            cells += air.fill_cells(strip_r, rows, theta, spacing)
        lanes, joins = route(cells, base, turn_radius, jump)
        out.append(_flown(k, strip, lanes, joins, base, turn_radius, air))
    return CoveragePlan(area, course % 360.0, spacing, turn_radius, out, zones,
                        searchable, margin if zones else 0.0)


def completion_s(plan: CoveragePlan, airspeed_mps: float) -> float:
    """When the last aircraft finishes its plan (transit, lanes, turns and
    detours) at ``airspeed_mps``, taking off together."""
    return max(a.length_m for a in plan.aircraft) / airspeed_mps


def min_fleet(area: Polygon, airspeed_mps: float, bank_deg: float, swath_width_m: float,
              deadline_s: float, base_ne: tuple[float, float] = (0.0, 0.0),
              overlap: float = 0.1, max_aircraft: int = 10_000,
              no_fly: Sequence[Polygon] = (),
              no_fly_margin_m: float | None = None) -> CoveragePlan:
    """The plan of the smallest fleet that covers ``area`` (less the
    ``no_fly`` zones, as in ``plan_coverage``) before ``deadline_s``: fewer
    aircraft than the lanes' length needs at that speed cannot, so the search
    starts there, doubles until a fleet is fast enough, then bisects
    (completion time falls with every aircraft added, up to the transit,
    which a larger fleet does not shorten). ``ValueError`` if even
    ``max_aircraft`` cannot (the transit alone may be too long)."""
    radius = turn_radius_m(airspeed_mps, bank_deg)

    def plan(n: int) -> CoveragePlan:
        return plan_coverage(area, n, swath_width_m, radius, base_ne, overlap,
                             no_fly=no_fly, no_fly_margin_m=no_fly_margin_m)

    def fast(n: int) -> bool:
        return completion_s(plan(n), airspeed_mps) <= deadline_s

    searchable = area.area
    if no_fly:
        searchable = Polygon(area.exterior).difference(unary_union(list(no_fly))).area
    survey = searchable / (swath_width_m * (1.0 - overlap))  # the lanes' length, about
    lo = max(1, math.floor(survey / (airspeed_mps * deadline_s)))
    if fast(lo):
        hi = lo
        lo = 0
    else:
        hi = min(lo * 2, max_aircraft)
        while not fast(hi):
            if hi >= max_aircraft:
                raise ValueError(f"even {max_aircraft} aircraft cannot cover the area within "
                                 f"{deadline_s:g} s at {airspeed_mps:g} m/s (the transit "
                                 f"from the base may be too long)")
            lo, hi = hi, min(hi * 2, max_aircraft)
    while hi - lo > 1:  # fast(hi), not fast(lo) (or lo = 0)
        mid = (lo + hi) // 2
        if fast(mid):
            hi = mid
        else:
            lo = mid
    return plan(hi)


def _flown(index: int, strip: BaseGeometry, lanes: list[Lane], joins: list[DubinsPath | None],
           base: tuple[float, float], radius: float, air: Airspace | None) -> AircraftPlan:
    """The plan flying ``lanes`` in order: the transit to the first, the
    ``joins`` between (None: to be found), each checked against the zones."""
    plan = AircraftPlan(index, strip, lanes, None)
    if not lanes:
        return plan

    def join(a: Pose, b: Pose, path: DubinsPath | None) -> Flight:
        if air is None:
            return path if path is not None else shortest(a, b, radius)
        if path is not None and air.clear(path):
            return path
        return air.join(a, b)

    (x0, y0), _ = lanes[0]
    plan.transit = join((base[0], base[1], math.atan2(y0 - base[1], x0 - base[0])),
                        (x0, y0, heading(lanes[0])), None)
    for a, b, path in zip(lanes, lanes[1:], joins):
        plan.turns.append(join((a[1][0], a[1][1], heading(a)),
                               (b[0][0], b[0][1], heading(b)), path))
    return plan


def _longest_axis_course(area: Polygon) -> float:
    """The course (clockwise from north) of the long side of the area's
    smallest enclosing rectangle."""
    rect = area.minimum_rotated_rectangle
    xs, ys = rect.exterior.coords.xy
    sides = [((xs[i + 1] - xs[i]), (ys[i + 1] - ys[i])) for i in range(2)]
    dx, dy = max(sides, key=lambda s: math.hypot(*s))
    return math.degrees(math.atan2(dx, dy)) % 180.0
