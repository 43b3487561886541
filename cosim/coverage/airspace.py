"""The airspace a coverage plan flies in: no-fly zones and flying around them.

No-fly zones (polygons; holes of the area count as zones too) are checked
(at most 100 zones of at most 1000 vertices each) and cut out of the area
first, so that the strips share the searchable rest. No flown point (lane,
turn, transit or detour) comes nearer a zone than a margin. Lanes are cut
where they would enter the margin, and a lane end is pulled back (or run
on, when that is clear) until a turn of the radius to either side is clear
of the zones. What the pulled-back ends leave unseen (in front of a zone's
side) is flown again across the sweep, and what that leaves along a zone's
side, along it. A join whose shortest turn would touch a zone is flown by
the next shortest Dubins word that keeps clear, or else becomes a detour:
the shortest path over the corners of the zones' convex hulls inflated by
more than the turn radius (a visibility graph), flown as Dubins paths from
corner to corner, so that no turn is tighter than the radius; a detour is
checked against the zones like every other join. A zone that encloses part
of the area or the base, or leaves nothing to search, is refused with a
``ValueError``, as is a join no detour can fly.

It owns the zones and the checks against them; the strips, rows and cells
themselves are ``lanes``' (used here on what the zones leave), and the plan
the ``planner``'s: this module never builds a plan.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import LineString, MultiPolygon, Point, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from cosim.coverage.dubins import DubinsChain, DubinsPath, Flight, candidates
from cosim.coverage.lanes import (
    Lane,
    Piece,
    Pose,
    group_cells,
    lane_rows,
    rotate_xy,
    side_rows,
    unrotate,
)

MAX_NO_FLY_ZONES = 100
MAX_ZONE_VERTICES = 1000


def checked_zones(area: Polygon, no_fly: Sequence[Polygon]) -> list[Polygon]:
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


class Airspace:
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
                rows = lane_rows(turned, v0, v1, spacing)
            else:
                rows = side_rows(turned, rotate_xy(side, -psi)[1], 1.05 * self.margin, spacing,
                                  self.swath)
            rows = self.fly_rows(rows, frame)
            cells += [unrotate(c, frame) for c in group_cells(rows)]
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
