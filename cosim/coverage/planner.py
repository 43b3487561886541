"""Coverage plans for a fixed-wing fleet over a search area.

The area (a polygon in the scenario's local frame, metres north and east of
the origin) is split across the sweep direction into one strip per aircraft,
each of the same area (cut positions found by bisection on the clipped
area). Each strip is flown as a lawnmower (boustrophedon): parallel lanes
along the sweep direction, spaced no wider than the camera's swath less the
overlap, each lane as long as the strip's band around it so that the swaths
cover the strip to its edges; consecutive lanes are joined by the shortest
turns a fixed-wing can fly (``dubins``, radius ``v^2 / (g tan(bank))``),
and the aircraft's transit from the base to its first lane is counted.
Lanes closer together than a U-turn (twice the radius) are flown
interleaved (0, k, 1, k + 1, ...) when that makes the flight shorter, so
the turns need not loop.

No-fly zones (polygons; holes of the area count as zones too) are cut out
of the area first: the strips share the searchable rest equally. No flown
point (lane, turn, transit or detour) comes nearer a zone than a margin
(``no_fly_margin_m``, a tenth of the turn radius unless told). Lanes are
cut where they would enter the margin, and a lane end is pulled back (or
run on, when that is clear) until a turn of the radius to either side is
clear of the zones; the rows of lane pieces are grouped into cells
(consecutive rows of one piece each, as in a boustrophedon decomposition),
each flown as a lawnmower, the cells in order of the nearest. What the
pulled-back ends leave unseen (in front of a zone's side) is flown again
across the sweep, and what that leaves along a zone's side, along it. A
join whose shortest turn would touch a zone is flown by the next shortest
Dubins word that keeps clear, or else becomes a detour: the shortest path
over the corners of the zones' convex hulls inflated by more than the turn
radius (a visibility graph), flown as Dubins paths from corner to corner,
so that no turn is tighter than the radius; a detour is checked against
the zones like every other join. A zone that encloses part of the area or
the base, or leaves nothing to search, is refused with a ``ValueError``,
as is a join no detour can fly. Planning is bounded: at most 100 zones of
at most 1000 vertices each.

Everything here is geometry: no simulation, no MAVLink. Geometry is done in
a right-handed plane (x east, y north); the public values carry
``north_m``/``east_m``.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import LineString, MultiPolygon, Point, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from cosim.coverage.dubins import DubinsChain, DubinsPath, Flight, candidates, shortest
from cosim.guidance.commands import min_turn_radius_m

_BISECT_TOL = 1e-9  # relative area error of a cut
MAX_NO_FLY_ZONES = 100
MAX_ZONE_VERTICES = 1000

Pose = tuple[float, float, float]
Lane = tuple[tuple[float, float], tuple[float, float]]
Piece = tuple[float, float, float]  # a lane in a rotated frame: u_start, u_end, v


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
    zones = _zones(area, no_fly)
    outer = Polygon(area.exterior)
    base = (base_ne[1], base_ne[0])
    air: _Airspace | None = None
    searchable: BaseGeometry = outer
    if zones:
        air = _Airspace(zones, turn_radius, margin, swath_width_m)
        searchable = air.searchable(outer, base)
    course = _longest_axis_course(outer) if sweep_deg is None else float(sweep_deg)
    theta = math.radians(90.0 - course)  # the lanes' direction, counter-clockwise from east
    # rotate so that the lanes run along +u; v across them
    rot = affinity.rotate(searchable, -theta, origin=(0, 0), use_radians=True)
    spacing = swath_width_m * (1.0 - overlap)
    shares = _shares(rot, n_aircraft, spacing, tiles=air is None)
    # rows apart for a plain U-turn; with interleave=False, one after another
    jump = math.ceil(2.0 * turn_radius / spacing) + 1 if interleave else 1
    out = []
    for k, (strip_r, v0, v1) in enumerate(shares):
        strip = affinity.rotate(strip_r, theta, origin=(0, 0), use_radians=True)
        rows = _lanes(strip_r, v0, v1, spacing)
        if air is None:
            cells = [_unrotate(c, theta) for c in _cells(rows)]
        else:
            rows = air.fly_rows(rows, theta)
            cells = [_unrotate(c, theta) for c in _cells(rows)]
            cells += air.fill_cells(strip_r, rows, theta, spacing)
        lanes, joins = _route(cells, base, turn_radius, jump)
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


def _zones(area: Polygon, no_fly: Sequence[Polygon]) -> list[Polygon]:
    """The zones to avoid, checked: the area's holes, then ``no_fly``."""
    zones = [Polygon(r) for r in area.interiors]
    given = list(no_fly)
    if len(zones) + len(given) > MAX_NO_FLY_ZONES:
        raise ValueError(f"at most {MAX_NO_FLY_ZONES} no-fly zones (the area's holes "
                         f"included) are planned around, got {len(zones) + len(given)}")
    for i, z in enumerate(given):
        if not isinstance(z, Polygon):
            raise ValueError(f"no_fly[{i}] must be a shapely Polygon in (east, north) "
                             f"metres, got {type(z).__name__}")
        n = len(z.exterior.coords) - 1 + sum(len(r.coords) - 1 for r in z.interiors)
        if n > MAX_ZONE_VERTICES:
            raise ValueError(f"no_fly[{i}] has {n} vertices, more than the "
                             f"{MAX_ZONE_VERTICES} planned around: simplify it first "
                             f"(shapely's simplify)")
        if not z.is_valid or z.area <= 0:
            raise ValueError(f"no_fly[{i}] must be a simple polygon of positive area "
                             "(its edges must not cross)")
        zones.append(Polygon(z.exterior))
    return zones


class _Airspace:
    """The no-fly zones, and what flying around them needs: which lane
    pieces can be flown, whether a flight keeps clear, detours."""

    def __init__(self, zones: list[Polygon], radius: float, margin: float,
                 swath: float) -> None:
        self.zones = zones
        self.radius = radius
        self.margin = margin
        self.swath = swath
        self.union = unary_union(zones)
        self.keep_out = self.union.buffer(margin, quad_segs=8) if margin > 0 else self.union
        # a flight is checked against the zones grown by half the margin, its
        # samples close enough that a chord strays from the arc by far less
        self._touch = self.union.buffer(0.5 * margin, quad_segs=8) if margin > 0 else self.union
        shapely.prepare(self._touch)
        self._step = max(min(margin, radius / 10.0), radius / 1000.0)
        self._rotated: dict[float, BaseGeometry] = {}
        self._obstacles: dict[float, tuple[np.ndarray, list[Polygon], BaseGeometry]] = {}
        # where a turn of the radius to either side of a lane end goes: the
        # two half-discs ahead of it (turning circles left and right; a
        # U-turn onto a lane 2R away or more), and the loop of a U-turn onto
        # a lane nearer than that (Dubins' CCC: its middle circle as far as
        # sqrt(3) R ahead)
        ahead = box(0.0, -2.0 * radius, (1.0 + math.sqrt(3.0)) * radius, 2.0 * radius)
        discs = unary_union([Point(0.0, radius).buffer(radius, quad_segs=8),
                             Point(0.0, -radius).buffer(radius, quad_segs=8),
                             Point(math.sqrt(3.0) * radius, 0.0).buffer(radius, quad_segs=8)])
        self._ahead = discs.convex_hull.intersection(ahead)
        self._behind = affinity.scale(self._ahead, -1.0, 1.0, origin=(0, 0))

    def searchable(self, outer: Polygon, base: tuple[float, float]) -> BaseGeometry:
        """``outer`` less the zones; refused if nothing is left, or if zones
        enclose the base or any of it."""
        rest = outer.difference(self.union)
        if rest.area <= 1e-9 * outer.area:
            raise ValueError("the no-fly zones cover the whole search area: nothing is left "
                             "to search")
        where = f"(north {base[1]:.0f} m, east {base[0]:.0f} m)"
        for i, z in enumerate(self.zones):
            if z.buffer(self.margin).contains(Point(base)):
                raise ValueError(f"the base {where} lies inside no-fly zone {i} (or within "
                                 f"its {self.margin:.0f} m margin): no aircraft can take off")
        for poly in _polygons(self.union):
            for ring in poly.interiors:
                pocket = Polygon(ring)
                if pocket.contains(Point(base)):
                    raise ValueError(f"the base {where} is enclosed by no-fly zones: no "
                                     "aircraft can leave it")
                lost = pocket.intersection(rest).area
                if lost > 0:
                    c = pocket.representative_point()
                    raise ValueError(f"{lost:.0f} m2 of the search area (around north "
                                     f"{c.y:.0f} m, east {c.x:.0f} m) is enclosed by no-fly "
                                     "zones: no aircraft can reach it")
        return rest

    def _keep_out_in(self, phi: float) -> BaseGeometry:
        """The zones with their margin in the frame rotated by ``-phi``."""
        if phi not in self._rotated:
            g = affinity.rotate(self.keep_out, -phi, origin=(0, 0), use_radians=True)
            shapely.prepare(g)
            self._rotated[phi] = g
        return self._rotated[phi]

    def fly_rows(self, rows: list[tuple[int, list[Piece]]], phi: float
                 ) -> list[tuple[int, list[Piece]]]:
        """The lane pieces (frame rotated by ``-phi``) as they can be flown:
        cut where they would enter a zone's margin, each end pulled back (or
        run on, up to four radii, where the line is clear) until a turn of
        the radius to either side of it is clear."""
        ko = self._keep_out_in(phi)
        ext = 4.0 * self.radius
        step = self.radius / 8.0
        out = []
        for i, pieces in rows:
            flown: list[Piece] = []
            for c0, c1, v in pieces:
                for p, q in _clear(ko, c0 - ext, c1 + ext, v):
                    lo, hi = max(p, c0), min(q, c1)
                    if hi < lo:
                        continue  # a clear stretch beyond the lane, not on it
                    b = self._end(ko, self._ahead, v, hi, min(q, hi + ext) if hi >= c1 else hi,
                                  lo, step)
                    a = self._end(ko, self._behind, v, lo, max(p, lo - ext) if lo <= c0 else lo,
                                  b if b is not None else hi, step)
                    if a is not None and b is not None and b - a > 1e-6 * self.radius:
                        flown.append((a, b, v))
            if flown:
                out.append((i, flown))
        return out

    def _end(self, ko: BaseGeometry, shape: BaseGeometry, v: float, at: float, far: float,
             near: float, step: float) -> float | None:
        """Where a lane end meant for ``at`` can be: ``at``, else the nearest
        of on towards ``far`` or back towards ``near`` where a turn beyond it
        (``shape``) is clear; None if none is."""
        def ok(u: float) -> bool:
            return not ko.intersects(affinity.translate(shape, u, v))

        if ok(at):
            return at
        sign = 1.0 if at >= near else -1.0  # on: away from the lane's other end
        n_on = int(abs(far - at) / step)
        n_back = int(abs(at - near) / step)
        for k in range(1, max(n_on, n_back) + 1):
            if k <= n_on and ok(at + sign * k * step):
                return at + sign * k * step
            if k <= n_back and ok(at - sign * k * step):
                return at - sign * k * step
        return None

    def fill_cells(self, strip_r: BaseGeometry, rows: list[tuple[int, list[Piece]]],
                   phi: float, spacing: float) -> list[list[Lane]]:
        """Cells of lanes over what the lanes ``rows`` leave unseen of
        ``strip_r`` (frame rotated by ``-phi``): in front of zones, where the
        lanes had to stop short to turn, lanes across the sweep; then, along
        sides of zones oblique to both, lanes along those sides."""
        seen = unary_union([LineString([(a, v), (b, v)]).buffer(self.swath / 2.0,
                                                               cap_style="flat")
                            for _, pieces in rows for a, b, v in pieces])
        left = strip_r.difference(seen) if not seen.is_empty else strip_r
        cells: list[list[Lane]] = []
        cross = self._sweep(left, math.pi / 2.0, phi, spacing, cells)
        # what is still unseen lies along zones' sides oblique to both ways:
        # sweep it along each side (of the zone's hull) in turn
        left = left.difference(cross) if not cross.is_empty else left
        if left.area <= spacing * spacing:
            return cells
        for z in self.zones:
            hull = affinity.rotate(z.convex_hull, -phi, origin=(0, 0), use_radians=True)
            if hull.distance(left) > 2.0 * spacing:
                continue
            xy = list(hull.exterior.coords)
            for p, q in zip(xy, xy[1:]):
                if math.dist(p, q) < spacing:
                    continue
                band = LineString([p, q]).buffer(2.0 * spacing, cap_style="flat")
                part = left.intersection(band)
                if part.area > spacing * spacing:
                    seen_side = self._sweep(part, math.atan2(q[1] - p[1], q[0] - p[0]), phi,
                                            spacing, cells, side=p)
                    left = left.difference(seen_side) if not seen_side.is_empty else left
        return cells

    def _sweep(self, region: BaseGeometry, psi: float, phi: float, spacing: float,
               cells: list[list[Lane]], side: tuple[float, float] | None = None
               ) -> BaseGeometry:
        """Add to ``cells`` lanes along ``psi`` (counter-clockwise from +u
        of the frame rotated by ``-phi``) over the pieces of ``region``
        larger than a lane spacing squared; what their swaths see. With
        ``side`` (a point of a zone's side along ``psi``) the first lane
        runs just outside the zone's margin, the others a spacing apart
        outwards, rather than in equal bands."""
        parts = [g for g in _polygons(region) if g.area > spacing * spacing]
        parts.sort(key=lambda g: (round(g.bounds[1], 6), round(g.bounds[0], 6)))
        frame = phi + psi
        seen: list[BaseGeometry] = []
        for part in parts:
            turned = affinity.rotate(part, -psi, origin=(0, 0), use_radians=True)
            _, v0, _, v1 = turned.bounds
            if side is None:
                rows = _lanes(turned, v0, v1, spacing)
            else:
                rows = _side_rows(turned, _rot(side, -psi)[1], 1.05 * self.margin, spacing,
                                  self.swath)
            rows = self.fly_rows(rows, frame)
            cells += [_unrotate(c, frame) for c in _cells(rows)]
            seen += [affinity.rotate(LineString([(a, v), (b, v)]).buffer(
                self.swath / 2.0, cap_style="flat"), psi, origin=(0, 0), use_radians=True)
                for _, pieces in rows for a, b, v in pieces]
        return unary_union(seen) if seen else Polygon()

    def clear(self, flight: Flight) -> bool:
        pts = flight.sample(self._step)[:, :2]
        return not self._touch.intersects(LineString(pts))

    def _leg(self, a: Pose, b: Pose) -> DubinsPath | None:
        """The shortest Dubins path from ``a`` to ``b`` clear of the zones
        (the shortest word, else the next ...); None if none is."""
        for path in candidates(a, b, self.radius):
            if self.clear(path):
                return path
        return None

    def join(self, a: Pose, b: Pose) -> Flight:
        """The shortest turn from ``a`` to ``b`` that keeps clear of the
        zones, else the shortest detour found that does."""
        path = self._leg(a, b)
        if path is not None:
            return path
        for f in (1.25, 1.6, 2.2, 3.0):
            detour = self._detour(a, b, f * self.radius + self.margin)
            if detour is not None:
                return detour
        raise ValueError(
            f"cannot fly from (north {a[1]:.0f} m, east {a[0]:.0f} m) to (north {b[1]:.0f} m, "
            f"east {b[0]:.0f} m) around the no-fly zones turning no tighter than "
            f"{self.radius:.0f} m with a {self.margin:.0f} m margin: the way between zones, "
            "or between a zone and a lane, is too narrow; try a smaller turn radius or "
            "margin, or another sweep_deg")

    def obstacles(self, d: float) -> tuple[np.ndarray, list[Polygon], BaseGeometry]:
        """The zones' convex hulls inflated by ``d``: the corners a detour may
        turn at; the hulls inflated a little less (by piece, and as one
        prepared geometry) that a detour's legs must miss."""
        if d not in self._obstacles:
            hulls = [z.convex_hull.simplify(0.02 * d) for z in self.zones]
            big = unary_union([h.buffer(d, quad_segs=4) for h in hulls])
            nodes = np.array([xy for poly in _polygons(big)
                              for xy in poly.exterior.coords[:-1]], dtype=float)
            small = unary_union([h.buffer(0.95 * d, quad_segs=4) for h in hulls])
            shapely.prepare(small)
            self._obstacles[d] = (nodes, _polygons(small), small)
        return self._obstacles[d]

    def _detour(self, a: Pose, b: Pose, d: float) -> DubinsChain | None:
        """From ``a`` to ``b`` by the shortest way over the corners of the
        hulls inflated by ``d`` (never straight: that failed already), flown
        as Dubins paths through those corners, each headed half way between
        its legs, each the shortest clear of the zones; None if there is no
        way, or a leg cannot keep clear."""
        nodes, pieces, small = self.obstacles(d)
        pa, pb = Point(a[0], a[1]), Point(b[0], b[1])
        # the legs from a and to b may cross the inflated hull they start in
        # (a lane ends within it), not the zone with its margin
        ends = unary_union([self.keep_out] + [p for p in pieces
                                              if not p.contains(pa) and not p.contains(pb)])
        shapely.prepare(ends)
        pts = np.vstack([[a[:2], b[:2]], nodes]) if len(nodes) else np.array([a[:2], b[:2]])
        n = len(pts)
        dist = np.full(n, np.inf)
        prev = np.full(n, -1)
        done = np.zeros(n, dtype=bool)
        dist[0] = 0.0
        heap = [(float(np.hypot(*(pts[0] - pts[1]))), 0)]
        while heap:
            _, i = heapq.heappop(heap)
            if done[i]:
                continue
            done[i] = True
            if i == 1:
                break
            cand = np.flatnonzero(~done)
            if i == 0:
                cand = cand[cand != 1]
            if not len(cand):
                continue
            segs = np.stack([np.broadcast_to(pts[i], (len(cand), 2)), pts[cand]], axis=1)
            lines = shapely.linestrings(segs)
            blocked = np.empty(len(cand), dtype=bool)
            to_end = (cand == 1) | (i == 0)
            if to_end.any():
                blocked[to_end] = shapely.intersects(lines[to_end], ends)
            if (~to_end).any():
                blocked[~to_end] = shapely.intersects(lines[~to_end], small)
            for j in cand[~blocked]:
                nd = dist[i] + float(np.hypot(*(pts[j] - pts[i])))
                if nd < dist[j]:
                    dist[j], prev[j] = nd, i
                    heapq.heappush(heap, (nd + float(np.hypot(*(pts[j] - pts[1]))), int(j)))
        if not np.isfinite(dist[1]):
            return None
        way = [1]
        while way[-1] != 0:
            way.append(int(prev[way[-1]]))
        way.reverse()
        poses: list[Pose] = [a]
        for k in range(1, len(way) - 1):
            p0, p1, p2 = pts[way[k - 1]], pts[way[k]], pts[way[k + 1]]
            u = (p1 - p0) / max(np.hypot(*(p1 - p0)), 1e-12)
            w = (p2 - p1) / max(np.hypot(*(p2 - p1)), 1e-12)
            h = u + w
            poses.append((float(p1[0]), float(p1[1]), math.atan2(h[1], h[0])))
        poses.append(b)
        legs = []
        for p, q in zip(poses, poses[1:]):
            leg = self._leg(p, q)
            if leg is None:
                return None
            legs.append(leg)
        return DubinsChain(tuple(legs))


def _polygons(g: BaseGeometry) -> list[Polygon]:
    if isinstance(g, Polygon):
        return [g] if not g.is_empty else []
    if isinstance(g, MultiPolygon):
        return [p for p in g.geoms if not p.is_empty]
    return [p for p in getattr(g, "geoms", []) if isinstance(p, Polygon) and not p.is_empty]


def _clear(ko: BaseGeometry, u0: float, u1: float, v: float) -> list[tuple[float, float]]:
    """The stretches of the line ``v`` from ``u0`` to ``u1`` outside ``ko``."""
    seg = LineString([(u0, v), (u1, v)])
    if not ko.intersects(seg):
        return [(u0, u1)]
    hit = seg.intersection(ko)
    blocked = sorted((g.bounds[0], g.bounds[2]) for g in getattr(hit, "geoms", [hit])
                     if not g.is_empty)
    out, at = [], u0
    for b0, b1 in blocked:
        if b0 > at:
            out.append((at, b0))
        at = max(at, b1)
    if at < u1:
        out.append((at, u1))
    return out


def _flown(index: int, strip: BaseGeometry, lanes: list[Lane], joins: list[DubinsPath | None],
           base: tuple[float, float], radius: float, air: _Airspace | None) -> AircraftPlan:
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
                        (x0, y0, _heading(lanes[0])), None)
    for a, b, path in zip(lanes, lanes[1:], joins):
        plan.turns.append(join((a[1][0], a[1][1], _heading(a)),
                               (b[0][0], b[0][1], _heading(b)), path))
    return plan


def _sequences(m: int, jump: int) -> list[list[int]]:
    """Orders of ``m`` rows to try: one after another; and, where lanes are
    closer than a U-turn, interleaved in blocks of ``2 * jump`` rows (0,
    jump, 1, jump + 1, ...: every turn but one a block spans ``jump`` or
    ``jump - 1`` rows, wide enough not to loop)."""
    out = [list(range(m))]
    if jump > 1 and m > 2:
        seq: list[int] = []
        for b in range(0, m, 2 * jump):
            size = min(2 * jump, m - b)
            h = (size + 1) // 2
            low, high = range(b, b + h), range(b + h, b + size)
            for i in range(h):
                seq.append(low[i])
                if i < len(high):
                    seq.append(high[i])
        out.append(seq)
    return out


def _heading(lane: Lane) -> float:
    (x0, y0), (x1, y1) = lane
    return math.atan2(y1 - y0, x1 - x0)


def _longest_axis_course(area: Polygon) -> float:
    """The course (clockwise from north) of the long side of the area's
    smallest enclosing rectangle."""
    rect = area.minimum_rotated_rectangle
    xs, ys = rect.exterior.coords.xy
    sides = [((xs[i + 1] - xs[i]), (ys[i + 1] - ys[i])) for i in range(2)]
    dx, dy = max(sides, key=lambda s: math.hypot(*s))
    return math.degrees(math.atan2(dx, dy)) % 180.0


def _clip_v(poly: BaseGeometry, v0: float, v1: float) -> BaseGeometry:
    minx, _, maxx, _ = poly.bounds
    return poly.intersection(box(minx - 1.0, v0, maxx + 1.0, v1))


def _shares(rot: BaseGeometry, n: int, spacing: float, tiles: bool
            ) -> list[tuple[BaseGeometry, float, float]]:
    """Each aircraft's share of ``rot`` (lanes along u) as (polygon, v0, v1)
    of equal area: strips across v, or, when there are more aircraft than
    lanes across the area (and ``tiles``), a strip per lane row cut along the
    lanes into as many pieces as aircraft share it, so that a large fleet
    flies shorter lanes rather than narrower strips (which only overlap)."""
    _, vmin, _, vmax = rot.bounds
    rows = max(1, math.ceil((vmax - vmin) / spacing - 1e-9))
    if not tiles or n <= rows:
        cuts = _equal_area_cuts(rot, n)
        return [(_clip_v(rot, cuts[k], cuts[k + 1]), cuts[k], cuts[k + 1]) for k in range(n)]
    per = [n // rows + (1 if s < n % rows else 0) for s in range(rows)]
    cuts = _equal_area_cuts(rot, rows, weights=per)
    out = []
    for s, k in enumerate(per):
        strip = _clip_v(rot, cuts[s], cuts[s + 1])
        # cut along u: the same bisection on the strip turned a quarter turn
        turned = affinity.rotate(strip, 90.0, origin=(0, 0))  # (u, v) -> (-v, u)
        ucuts = _equal_area_cuts(turned, k)
        for j in range(k):
            piece = affinity.rotate(_clip_v(turned, ucuts[j], ucuts[j + 1]), -90.0,
                                    origin=(0, 0))
            out.append((piece, cuts[s], cuts[s + 1]))
    return out


def _equal_area_cuts(poly: BaseGeometry, n: int, weights: Sequence[int] | None = None
                     ) -> list[float]:
    """v positions splitting ``poly`` into ``n`` bands of equal area (or of
    areas in proportion to ``weights``)."""
    _, miny, _, maxy = poly.bounds
    total = poly.area
    share = [1] * n if weights is None else list(weights)
    cuts = [miny]
    for k in range(1, n):
        want = total * sum(share[:k]) / sum(share)
        lo, hi = cuts[-1], maxy
        for _ in range(200):
            mid = (lo + hi) / 2.0
            if _clip_v(poly, miny, mid).area < want:
                lo = mid
            else:
                hi = mid
            if hi - lo <= _BISECT_TOL * max(1.0, maxy - miny):
                break
        cuts.append((lo + hi) / 2.0)
    cuts.append(maxy)
    return cuts


def _lanes(strip: BaseGeometry, v0: float, v1: float, spacing: float
           ) -> list[tuple[int, list[Piece]]]:
    """Per lane row (v ascending; with its index, empty rows left out), the
    lane pieces ``(u_start, u_end, v)``: rows centred in equal sub-bands no
    wider than ``spacing``; each piece spans its sub-band's part of the
    strip, so the swaths reach its edges."""
    if strip.is_empty or v1 <= v0:
        return []
    m = max(1, math.ceil((v1 - v0) / spacing - 1e-9))
    width = (v1 - v0) / m
    minx, _, maxx, _ = strip.bounds
    rows = []
    for i in range(m):
        a, b = v0 + i * width, v0 + (i + 1) * width
        band = strip.intersection(box(minx - 1.0, a, maxx + 1.0, b))
        parts = list(band.geoms) if hasattr(band, "geoms") else [band]
        pieces = sorted((p.bounds[0], p.bounds[2]) for p in parts
                        if not p.is_empty and p.area > 0)
        if pieces:
            rows.append((i, [(u0, u1, (a + b) / 2.0) for u0, u1 in pieces]))
    return rows


def _side_rows(region: BaseGeometry, v_side: float, offset: float, spacing: float,
               swath: float) -> list[tuple[int, list[Piece]]]:
    """Rows of lanes along a zone's side at ``v = v_side`` over ``region``
    (on one side of it): the first ``offset`` from the side, then a
    ``spacing`` apart until the swaths reach across ``region``; each lane
    spans the part of ``region`` its band holds."""
    minx, v0, maxx, v1 = region.bounds
    up = (v0 + v1) / 2.0 >= v_side
    far = (v1 - v_side) if up else (v_side - v0)
    rows = []
    i = 0
    while offset + i * spacing - swath / 2.0 < far and i < 1000:
        d = offset + i * spacing
        v = v_side + d if up else v_side - d
        band = region.intersection(box(minx - 1.0, v - spacing / 2.0, maxx + 1.0,
                                       v + spacing / 2.0))
        parts = [g for g in getattr(band, "geoms", [band]) if not g.is_empty and g.area > 0]
        if parts:
            rows.append((i, sorted((g.bounds[0], g.bounds[2], v) for g in parts)))
        i += 1
    return rows


def _cells(rows: list[tuple[int, list[Piece]]]) -> list[list[Piece]]:
    """The pieces grouped into cells: a piece continues the cell of the one
    piece of the row before that it overlaps along the lanes, when that one
    overlaps no other (a boustrophedon decomposition); each cell one piece
    a row, rows consecutive."""
    cells: list[list[Piece]] = []
    prev: list[tuple[int, Piece]] = []
    prev_i = None
    for i, pieces in rows:
        cur = []
        for p in pieces:
            cid = None
            if prev_i == i - 1:
                over = [(c, q) for c, q in prev if q[0] < p[1] and p[0] < q[1]]
                if len(over) == 1:
                    q = over[0][1]
                    if sum(1 for r in pieces if q[0] < r[1] and r[0] < q[1]) == 1:
                        cid = over[0][0]
            if cid is None:
                cells.append([])
                cid = len(cells) - 1
            cells[cid].append(p)
            cur.append((cid, p))
        prev, prev_i = cur, i
    return cells


def _unrotate(cell: list[Piece], phi: float) -> list[Lane]:
    """A cell's pieces as lanes (each its +u way) in the (east, north) frame."""
    return [(_rot((u0, v), phi), _rot((u1, v), phi)) for u0, u1, v in cell]


def _route(cells: list[list[Lane]], start: tuple[float, float], radius: float, jump: int
           ) -> tuple[list[Lane], list[DubinsPath | None]]:
    """The cells' lanes in flying order, and the turns between them (None
    between cells): from ``start``, the cell with the nearest end next; each
    cell flown in the row order (plain or interleaved) and way that is
    shortest from where the aircraft is."""
    left = list(range(len(cells)))
    lanes: list[Lane] = []
    joins: list[DubinsPath | None] = []
    pos = start
    while left:
        gaps = [_gap(cells[c], pos) for c in left]
        ci = left[gaps.index(min(gaps))]
        left.remove(ci)
        best: tuple[float, list[Lane], list[DubinsPath]] | None = None
        for seq in _sequences(len(cells[ci]), jump):
            ls = _orient(cells[ci], seq, pos)
            ts = [shortest((a[1][0], a[1][1], _heading(a)), (b[0][0], b[0][1], _heading(b)),
                           radius) for a, b in zip(ls, ls[1:])]
            cost = math.dist(pos, ls[0][0]) + sum(t.length_m for t in ts)
            if best is None or cost < best[0]:
                best = (cost, ls, ts)
        assert best is not None
        if lanes:
            joins.append(None)
        lanes += best[1]
        joins += best[2]
        pos = lanes[-1][1]
    return lanes, joins


def _gap(cell: list[Lane], at: tuple[float, float]) -> float:
    """How far ``at`` is from the nearest end of a cell's first or last lane."""
    return min(math.dist(at, p) for p in (*cell[0], *cell[-1]))


def _orient(cell: list[Lane], seq: list[int], pos: tuple[float, float]) -> list[Lane]:
    """The cell's lanes in the order ``seq`` (or its reverse), alternating
    direction; of the four ways (either end of ``seq``, starting either way
    along the lanes) the one whose first lane starts nearest ``pos``."""
    best: list[Lane] = []
    best_d = math.inf
    for order in (seq, seq[::-1]):
        for forward in (True, False):
            lanes = []
            fwd = forward
            for r in order:
                a, b = cell[r]
                lanes.append((a, b) if fwd else (b, a))
                fwd = not fwd
            d = math.dist(pos, lanes[0][0])
            if d < best_d:
                best, best_d = lanes, d
    return best


def _rot(p: tuple[float, float], a: float) -> tuple[float, float]:
    c, s = math.cos(a), math.sin(a)
    return (c * p[0] - s * p[1], s * p[0] + c * p[1])
