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

Everything here is geometry: no simulation, no MAVLink. Geometry is done in
a right-handed plane (x east, y north); the public values carry
``north_m``/``east_m``.

Not planned yet: no-fly zones inside the area (a polygon with holes is
refused with a clear message).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from shapely import affinity
from shapely.geometry import Polygon, box
from shapely.geometry.base import BaseGeometry

from cosim.coverage.dubins import DubinsPath, shortest

G_MPS2 = 9.80665
_BISECT_TOL = 1e-9  # relative area error of a cut


def turn_radius_m(airspeed_mps: float, bank_deg: float) -> float:
    """The tightest level turn: ``v^2 / (g tan(bank))``."""
    if not 0 < bank_deg < 90:
        raise ValueError(f"bank_deg must be in (0, 90), got {bank_deg}")
    return airspeed_mps ** 2 / (G_MPS2 * math.tan(math.radians(bank_deg)))


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
    lanes: list[tuple[tuple[float, float], tuple[float, float]]]
    transit: DubinsPath | None  # base to the first lane
    turns: list[DubinsPath] = field(default_factory=list)

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


def area_polygon(points_ne: Sequence[tuple[float, float]]) -> Polygon:
    """A search area from its corners, ``(north_m, east_m)`` in order."""
    poly = Polygon([(e, n) for n, e in points_ne])
    if not poly.is_valid or poly.area <= 0:
        raise ValueError("the search area must be a simple polygon of positive area "
                         "(its edges must not cross)")
    return poly


def plan_coverage(area: Polygon, n_aircraft: int, swath_width_m: float, turn_radius: float,
                  base_ne: tuple[float, float] = (0.0, 0.0), overlap: float = 0.1,
                  sweep_deg: float | None = None, interleave: bool = True) -> CoveragePlan:
    """Split ``area`` (east, north metres) among ``n_aircraft`` and plan each
    one's lanes; ``sweep_deg`` (a course, clockwise from north) defaults to
    the area's longest axis, so that strips are long and turns few;
    ``interleave=False`` flies the lanes strictly one after another."""
    if n_aircraft < 1:
        raise ValueError(f"n_aircraft must be >= 1, got {n_aircraft}")
    if not swath_width_m > 0 or not turn_radius > 0:
        raise ValueError("swath_width_m and turn_radius must be > 0")
    if not 0 <= overlap < 1:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    if list(area.interiors):
        raise ValueError("no-fly zones inside the search area are not planned yet: give the "
                         "area without holes")
    course = _longest_axis_course(area) if sweep_deg is None else float(sweep_deg)
    theta = math.radians(90.0 - course)  # the lanes' direction, counter-clockwise from east
    # rotate so that the lanes run along +u; v across them
    rot = affinity.rotate(area, -theta, origin=(0, 0), use_radians=True)
    cuts = _equal_area_cuts(rot, n_aircraft)
    spacing = swath_width_m * (1.0 - overlap)
    base = (base_ne[1], base_ne[0])
    out = []
    for k in range(n_aircraft):
        strip_r = _clip_v(rot, cuts[k], cuts[k + 1])
        lanes_r = _lanes(strip_r, cuts[k], cuts[k + 1], spacing)
        strip = affinity.rotate(strip_r, theta, origin=(0, 0), use_radians=True)
        # lanes row after row, or interleaved so that turns need no loops: the shorter
        jump = math.ceil(2.0 * turn_radius / spacing) + 1  # rows apart for a plain U-turn
        options = [_flown(k, strip, [(_rot(a, theta), _rot(b, theta))
                                     for a, b in _order(lanes_r, base, theta, seq)],
                          base, turn_radius)
                   for seq in _sequences(lanes_r, jump if interleave else 1)]
        out.append(min(options, key=lambda p: p.length_m))
    return CoveragePlan(area, course % 360.0, spacing, turn_radius, out)


def completion_s(plan: CoveragePlan, airspeed_mps: float) -> float:
    """When the last aircraft finishes its plan (transit, lanes and turns) at
    ``airspeed_mps``, taking off together."""
    return max(a.length_m for a in plan.aircraft) / airspeed_mps


def min_fleet(area: Polygon, airspeed_mps: float, bank_deg: float, swath_width_m: float,
              deadline_s: float, base_ne: tuple[float, float] = (0.0, 0.0),
              overlap: float = 0.1, max_aircraft: int = 10_000) -> CoveragePlan:
    """The plan of the smallest fleet that covers ``area`` before
    ``deadline_s``: fewer aircraft than the lanes' length needs at that speed
    cannot, so the search starts there, doubles until a fleet is fast enough,
    then bisects (completion time falls with every aircraft added, up to the
    transit, which a larger fleet does not shorten). ``ValueError`` if even
    ``max_aircraft`` cannot (the transit alone may be too long)."""
    radius = turn_radius_m(airspeed_mps, bank_deg)

    def plan(n: int) -> CoveragePlan:
        return plan_coverage(area, n, swath_width_m, radius, base_ne, overlap)

    def fast(n: int) -> bool:
        return completion_s(plan(n), airspeed_mps) <= deadline_s

    survey = area.area / (swath_width_m * (1.0 - overlap))  # the lanes' length, about
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


def _flown(index: int, strip: BaseGeometry,
           lanes: list[tuple[tuple[float, float], tuple[float, float]]],
           base: tuple[float, float], radius: float) -> AircraftPlan:
    """The plan flying ``lanes`` in order: the transit to the first, turns between."""
    plan = AircraftPlan(index, strip, lanes, None)
    if lanes:
        (x0, y0), (x1, y1) = lanes[0]
        plan.transit = shortest((base[0], base[1], math.atan2(y0 - base[1], x0 - base[0])),
                                (x0, y0, math.atan2(y1 - y0, x1 - x0)), radius)
        for a, b in zip(lanes, lanes[1:]):
            plan.turns.append(shortest((a[1][0], a[1][1], _heading(a)),
                                       (b[0][0], b[0][1], _heading(b)), radius))
    return plan


def _sequences(rows: list[list[tuple[float, float, float]]], jump: int) -> list[list[int]]:
    """Orders of the rows to try: one after another; and, where every row is
    one piece and lanes are closer than a U-turn, interleaved in blocks of
    ``2 * jump`` rows (0, jump, 1, jump + 1, ...: every turn but one a block
    spans ``jump`` or ``jump - 1`` rows, wide enough not to loop)."""
    m = len(rows)
    out = [list(range(m))]
    if jump > 1 and m > 2 and all(len(r) == 1 for r in rows):
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


def _heading(lane: tuple[tuple[float, float], tuple[float, float]]) -> float:
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


def _clip_v(poly: Polygon, v0: float, v1: float) -> BaseGeometry:
    minx, _, maxx, _ = poly.bounds
    return poly.intersection(box(minx - 1.0, v0, maxx + 1.0, v1))


def _equal_area_cuts(poly: Polygon, n: int) -> list[float]:
    """v positions splitting ``poly`` into ``n`` bands of equal area."""
    _, miny, _, maxy = poly.bounds
    total = poly.area
    cuts = [miny]
    for k in range(1, n):
        want = total * k / n
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
           ) -> list[list[tuple[float, float, float]]]:
    """Per lane row (v ascending), the lane pieces ``(u_start, u_end, v)``:
    rows centred in equal sub-bands no wider than ``spacing``; each piece
    spans its sub-band's part of the strip, so the swaths reach its edges."""
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
            rows.append([(u0, u1, (a + b) / 2.0) for u0, u1 in pieces])
    return rows


def _order(rows: list[list[tuple[float, float, float]]], base: tuple[float, float],
           theta: float, seq: list[int]) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The rows in the order ``seq`` (or its reverse), alternating direction;
    of the four ways (either end of ``seq``, starting either way along the
    lanes) the one whose first lane starts nearest the base."""
    best: list[tuple[tuple[float, float], tuple[float, float]]] = []
    best_d = math.inf
    bu = _rot(base, -theta)
    for order in (seq, seq[::-1]):
        for forward in (True, False):
            lanes = []
            fwd = forward
            for r in order:
                row = rows[r]
                pieces = row if fwd else [(u1, u0, v) for u0, u1, v in reversed(row)]
                lanes += [((u0, v), (u1, v)) for u0, u1, v in pieces]
                fwd = not fwd
            if lanes:
                d = math.dist(bu, lanes[0][0])
                if d < best_d:
                    best, best_d = lanes, d
    return best


def _rot(p: tuple[float, float], a: float) -> tuple[float, float]:
    c, s = math.cos(a), math.sin(a)
    return (c * p[0] - s * p[1], s * p[0] + c * p[1])
