"""The coverage planner against independent computations: areas (shapely's),
curvature measured on the flown path, the camera's geometry."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from shapely.geometry import LineString, Polygon
from shapely.ops import unary_union

from cosim.coverage import (
    DubinsChain,
    area_polygon,
    max_alt_for_detection_m,
    no_fly_polygon,
    plan_coverage,
    shortest,
    swath_m,
    turn_radius_m,
)

SQUARE = [(0, 0), (0, 32_000), (32_000, 32_000), (32_000, 0)]  # 1024 km2, (north, east)
L_SHAPE = [(0, 0), (0, 9_000), (3_000, 9_000), (3_000, 3_000), (8_000, 3_000), (8_000, 0)]
SLANTED = [(0, 0), (1_500, 7_000), (6_500, 8_000), (9_000, 2_500), (4_000, -1_000)]
# 20 x 16 km with a square hole inside and a zone over its north-east corner
WIDE = [(0, 0), (0, 20_000), (16_000, 20_000), (16_000, 0)]
HOLE = [(6_000, 7_000), (6_000, 9_500), (8_500, 9_500), (8_500, 7_000)]
EDGE = [(12_000, 17_000), (12_000, 23_000), (18_000, 23_000), (18_000, 17_000)]
SLANTED_HOLE = [(3_000, 2_500), (5_500, 4_000), (4_500, 5_500), (2_500, 4_500)]


def test_turn_radius_swath_and_detection_altitude_from_their_equations() -> None:
    assert turn_radius_m(100.0, 45.0) == pytest.approx(100.0 ** 2 / 9.80665)
    assert turn_radius_m(60.0, 30.0) == pytest.approx(3600.0 / (9.80665 * math.tan(math.pi / 6)))
    assert swath_m(300.0, 90.0) == pytest.approx(600.0)
    alt = max_alt_for_detection_m(10.0, 8.0, 1920, 60.0)
    gsd = swath_m(alt, 60.0) / 1920  # metres per pixel at that altitude
    assert 10.0 / gsd == pytest.approx(8.0)
    with pytest.raises(ValueError, match="bank_deg"):
        turn_radius_m(50.0, 90.0)


def _curvatures(path: np.ndarray) -> np.ndarray:
    """1 / the radius of the circle through consecutive points of a path with
    their headings (a chord c turning the heading by d: 2 sin(d / 2) / c)."""
    ds = np.hypot(np.diff(path[:, 0]), np.diff(path[:, 1]))
    dh = np.abs(np.remainder(np.diff(path[:, 2]) + np.pi, 2 * np.pi) - np.pi)
    keep = ds > 1e-9
    return 2 * np.sin(dh[keep] / 2) / ds[keep]


def test_dubins_paths_end_at_the_goal_and_turn_no_tighter_than_the_radius() -> None:
    rng = random.Random(4)
    for _ in range(300):
        r = rng.uniform(50, 1500)
        s = (rng.uniform(-5e3, 5e3), rng.uniform(-5e3, 5e3), rng.uniform(-4, 4))
        g = (rng.uniform(-5e3, 5e3), rng.uniform(-5e3, 5e3), rng.uniform(-4, 4))
        p = shortest(s, g, r)
        pts = p.sample(5.0)
        assert np.allclose(pts[0], s)
        assert math.dist(pts[-1][:2], g[:2]) < 1e-3
        assert abs(math.remainder(pts[-1][2] - g[2], 2 * math.pi)) < 1e-6
        assert p.length_m >= math.dist(s[:2], g[:2]) - 1e-6
        assert _curvatures(pts).max() <= 1.0 / r * (1 + 1e-6)
        steps = np.hypot(np.diff(pts[:, 0]), np.diff(pts[:, 1]))
        assert steps.max() <= 5.0 + 1e-6
    # known cases: straight ahead; a U-turn onto the lane 2R away
    assert shortest((0, 0, 0), (1000, 0, 0), 100).length_m == pytest.approx(1000)
    assert shortest((0, 0, 0), (0, 200, math.pi), 100).length_m == pytest.approx(math.pi * 100)


@pytest.mark.parametrize("corners", [SQUARE, L_SHAPE, SLANTED], ids=["square", "L", "slanted"])
@pytest.mark.parametrize("n", [1, 3, 7])
def test_strips_cover_the_area_exactly_once_in_equal_shares(corners, n: int) -> None:
    area = area_polygon(corners)
    plan = plan_coverage(area, n, swath_width_m=400.0, turn_radius=600.0,
                         base_ne=(-1_000.0, -1_000.0))
    strips = [a.strip for a in plan.aircraft]
    assert len(strips) == n
    for s in strips:
        assert s.area == pytest.approx(area.area / n, rel=1e-6)
    assert sum(s.area for s in strips) == pytest.approx(area.area, rel=1e-9)
    assert unary_union(strips).symmetric_difference(area).area < 1e-6 * area.area
    for i in range(n):
        for j in range(i + 1, n):
            assert strips[i].intersection(strips[j]).area < 1e-6 * area.area


def _assert_flyable_and_clear(plan, radius: float, base_en: tuple[float, float]) -> None:
    """Every aircraft's flight: continuous from the base, no turn tighter than
    ``radius``, never inside a no-fly zone, its length all its parts."""
    for a in plan.aircraft:
        path = a.path(step_m=10.0)
        assert _curvatures(path).max() <= 1.0 / radius * (1 + 1e-6)
        steps = np.hypot(np.diff(path[:, 0]), np.diff(path[:, 1]))
        assert steps.max() <= 10.0 + 1e-6  # one continuous flight
        # the transit is part of it: from the base to the first lane
        assert np.allclose(path[0, :2], base_en)
        assert a.transit_m >= math.dist(base_en, a.lanes[0][0]) - 1e-6
        assert a.length_m == pytest.approx(a.transit_m + a.survey_m + a.turns_m)
        assert a.detour_m <= a.transit_m + a.turns_m + 1e-6
        assert len(a.turns) == len(a.lanes) - 1
        flown = LineString(path[:, :2])
        for i, zone in enumerate(plan.no_fly):
            assert flown.intersection(zone).length < 1e-6, (a.index, i)
            assert flown.distance(zone) >= 0.5 * plan.no_fly_margin_m, (a.index, i)


@pytest.mark.parametrize("corners", [SQUARE, L_SHAPE, SLANTED], ids=["square", "L", "slanted"])
def test_the_swaths_cover_every_strip_and_every_turn_is_flyable(corners) -> None:
    area = area_polygon(corners)
    swath, radius = 350.0, turn_radius_m(102.9, 45.0)  # 200 kt at 45 degrees: 1080 m
    plan = plan_coverage(area, 4, swath_width_m=swath, turn_radius=radius,
                         base_ne=(-2_000.0, 500.0))
    assert plan.lane_spacing_m <= swath
    for a in plan.aircraft:
        seen = unary_union([LineString(lane).buffer(swath / 2, cap_style="flat")
                            for lane in a.lanes])
        missed = a.strip.difference(seen).area
        assert missed < 1e-6 * a.strip.area, (a.index, missed)
    _assert_flyable_and_clear(plan, radius, (500.0, -2_000.0))


@pytest.mark.parametrize("corners, zones, n", [
    (WIDE, [HOLE, EDGE], 4),
    (WIDE, [HOLE, EDGE], 1),
    (SLANTED, [SLANTED_HOLE], 3),
], ids=["hole-and-edge-4", "hole-and-edge-1", "slanted-hole-3"])
def test_with_no_fly_zones_the_swaths_cover_the_searchable_area_from_outside_the_zones(
        corners, zones, n: int) -> None:
    area = area_polygon(corners)
    no_fly = [no_fly_polygon(z) for z in zones]
    swath, radius = 350.0, turn_radius_m(102.9, 45.0)
    plan = plan_coverage(area, n, swath_width_m=swath, turn_radius=radius,
                         base_ne=(-2_000.0, 500.0), no_fly=no_fly)
    searchable = area.difference(unary_union(no_fly))
    assert plan.searchable is not None
    assert plan.searchable.symmetric_difference(searchable).area < 1e-6 * searchable.area
    # equal shares of the searchable area, and nothing else
    strips = [a.strip for a in plan.aircraft]
    assert sum(s.area for s in strips) == pytest.approx(searchable.area, rel=1e-6)
    for s in strips:
        assert s.area == pytest.approx(searchable.area / n, rel=1e-6)
        for z in no_fly:
            assert s.intersection(z).area < 1e-6 * searchable.area
    # the swaths (which may overhang the zones) see the searchable area
    seen = unary_union([LineString(lane).buffer(swath / 2, cap_style="flat")
                        for a in plan.aircraft for lane in a.lanes])
    assert searchable.intersection(seen).area >= 0.995 * searchable.area
    _assert_flyable_and_clear(plan, radius, (500.0, -2_000.0))
    # lanes that would cross the hole are flown in pieces either side of it
    if HOLE in zones:
        hole = no_fly_polygon(HOLE)
        west = [lane for a in plan.aircraft for lane in a.lanes
                if max(lane[0][0], lane[1][0]) < hole.bounds[0]
                and hole.bounds[1] < lane[0][1] < hole.bounds[3]]
        east = [lane for a in plan.aircraft for lane in a.lanes
                if min(lane[0][0], lane[1][0]) > hole.bounds[2]
                and hole.bounds[1] < lane[0][1] < hole.bounds[3]]
        assert west and east


def test_a_hole_in_the_area_is_a_no_fly_zone() -> None:
    area = area_polygon(WIDE)
    holed = Polygon(area.exterior.coords, [no_fly_polygon(HOLE).exterior.coords])
    kw = dict(swath_width_m=350.0, turn_radius=800.0, base_ne=(-2_000.0, 500.0))
    by_hole = plan_coverage(holed, 2, **kw)
    by_zone = plan_coverage(area, 2, no_fly=[no_fly_polygon(HOLE)], **kw)
    assert len(by_hole.no_fly) == 1
    assert [a.lanes for a in by_hole.aircraft] == [a.lanes for a in by_zone.aircraft]
    assert [a.length_m for a in by_hole.aircraft] == [a.length_m for a in by_zone.aircraft]


def test_a_zone_between_the_base_and_the_area_is_flown_around_and_counted() -> None:
    area = area_polygon([(0, 0), (0, 6_000), (4_000, 6_000), (4_000, 0)])
    wall = no_fly_polygon([(-3_000, -1_000), (-3_000, 7_000), (-2_000, 7_000),
                           (-2_000, -1_000)])  # south of the area, wider than it
    radius = 600.0
    base = (-6_000.0, 3_000.0)
    plain = plan_coverage(area, 2, 300.0, radius, base_ne=base)
    plan = plan_coverage(area, 2, 300.0, radius, base_ne=base, no_fly=[wall])
    _assert_flyable_and_clear(plan, radius, (3_000.0, -6_000.0))
    for p, a in zip(plain.aircraft, plan.aircraft):
        assert isinstance(a.transit, DubinsChain)
        assert a.detour_m == pytest.approx(a.transit_m)
        assert a.transit_m > p.transit_m  # the way round is longer ...
        assert a.length_m == pytest.approx(a.transit_m + a.survey_m + a.turns_m)  # ... and counted
    # deterministic: the same plan again
    again = plan_coverage(area, 2, 300.0, radius, base_ne=base, no_fly=[wall])
    assert [a.path(50.0).tolist() for a in again.aircraft] == \
        [a.path(50.0).tolist() for a in plan.aircraft]


def test_interleaved_lanes_shorten_the_flight_when_lanes_are_closer_than_a_u_turn() -> None:
    area = area_polygon(SQUARE)
    radius = turn_radius_m(102.9, 45.0)  # 1080 m: lanes 312 m apart cannot be turned plainly
    kw = dict(swath_width_m=swath_m(300.0, 60.0), turn_radius=radius, base_ne=(-2e3, -2e3))
    plain = plan_coverage(area, 8, interleave=False, **kw)
    best = plan_coverage(area, 8, **kw)
    for p, b in zip(plain.aircraft, best.aircraft):
        def key(lanes):  # each lane whichever way it is flown, to the millimetre
            return sorted(tuple(sorted((round(x, 3), round(y, 3)) for x, y in lane))
                          for lane in lanes)

        assert key(p.lanes) == key(b.lanes)  # the same lanes, another order
        assert b.survey_m == pytest.approx(p.survey_m)
        assert b.turns_m < 0.7 * p.turns_m, (b.turns_m, p.turns_m)


def test_the_sweep_follows_the_long_axis_unless_told() -> None:
    long_east = area_polygon([(0, 0), (0, 20_000), (2_000, 20_000), (2_000, 0)])
    assert plan_coverage(long_east, 1, 300.0, 500.0).sweep_deg == pytest.approx(90.0)
    long_north = area_polygon([(0, 0), (0, 2_000), (20_000, 2_000), (20_000, 0)])
    assert plan_coverage(long_north, 1, 300.0, 500.0).sweep_deg % 180 == pytest.approx(0.0)
    assert plan_coverage(long_north, 1, 300.0, 500.0, sweep_deg=45.0).sweep_deg == 45.0


def test_bad_input_is_refused_with_what_was_expected() -> None:
    with pytest.raises(ValueError, match="simple polygon"):
        area_polygon([(0, 0), (10, 10), (0, 10), (10, 0)])  # edges cross
    square = area_polygon(SQUARE)
    with pytest.raises(ValueError, match="n_aircraft must be >= 1"):
        plan_coverage(square, 0, 300.0, 500.0)
    with pytest.raises(ValueError, match="overlap"):
        plan_coverage(square, 1, 300.0, 500.0, overlap=1.0)
    with pytest.raises(ValueError, match="simple polygon"):
        no_fly_polygon([(0, 0), (10, 10), (0, 10), (10, 0)])


def _square(n0: float, e0: float, size: float) -> list[tuple[float, float]]:
    return [(n0, e0), (n0, e0 + size), (n0 + size, e0 + size), (n0 + size, e0)]


def test_zones_that_leave_nothing_reachable_or_are_too_many_are_refused() -> None:
    area = area_polygon(_square(0, 0, 10_000))
    zone = no_fly_polygon

    def plan(no_fly, base_ne=(-1_000.0, -1_000.0)):
        return plan_coverage(area, 2, 300.0, 500.0, base_ne=base_ne, no_fly=no_fly)

    with pytest.raises(ValueError, match="nothing is left to search"):
        plan([zone(_square(-100, -100, 10_200))])
    with pytest.raises(ValueError, match="the base .* lies inside no-fly zone 0"):
        plan([zone(_square(2_000, 2_000, 1_000))], base_ne=(2_500.0, 2_500.0))
    # a ring of four zones round the middle of the area: what is inside is unreachable
    ring = [zone([(3_000, 3_000), (3_000, 7_000), (3_500, 7_000), (3_500, 3_000)]),
            zone([(6_500, 3_000), (6_500, 7_000), (7_000, 7_000), (7_000, 3_000)]),
            zone([(3_000, 3_000), (3_000, 3_500), (7_000, 3_500), (7_000, 3_000)]),
            zone([(3_000, 6_500), (3_000, 7_000), (7_000, 7_000), (7_000, 6_500)])]
    with pytest.raises(ValueError, match="enclosed by no-fly zones: no aircraft can reach it"):
        plan(ring)
    with pytest.raises(ValueError, match="is enclosed by no-fly zones: no aircraft can leave"):
        plan(ring, base_ne=(5_000.0, 5_000.0))
    with pytest.raises(ValueError, match="at most 100 no-fly zones"):
        plan([zone(_square(100.0 * i, -5_000, 50)) for i in range(101)])
    many = Polygon([(2_000 + 500 * math.cos(t), 2_000 + 500 * math.sin(t))
                    for t in np.linspace(0, 2 * math.pi, 1_002)[:-1]])
    with pytest.raises(ValueError, match="no_fly.0. has 1001 vertices"):
        plan([many])
    with pytest.raises(ValueError, match="no_fly.0. must be a shapely Polygon"):
        plan([LineString([(0, 0), (1, 1)])])


@pytest.mark.integration
def test_min_fleet_is_the_smallest_that_finishes_before_the_deadline() -> None:
    from cosim.coverage import completion_s, min_fleet

    area = area_polygon([(0, 0), (0, 12_000), (8_000, 12_000), (8_000, 0)])  # 96 km2
    v, bank, swath, deadline = 60.0, 45.0, 400.0, 600.0
    plan = min_fleet(area, v, bank, swath, deadline, base_ne=(4_000.0, 6_000.0))
    n = len(plan.aircraft)
    assert completion_s(plan, v) <= deadline
    fewer = plan_coverage(area, n - 1, swath, turn_radius_m(v, bank), (4_000.0, 6_000.0))
    assert completion_s(fewer, v) > deadline
    # a deadline shorter than the transit to the farthest corner: no fleet will do
    with pytest.raises(ValueError, match="cannot cover the area"):
        min_fleet(area, v, bank, swath, 60.0, base_ne=(4_000.0, 6_000.0), max_aircraft=64)
    # with a zone: the plan avoids it and still meets the deadline
    zone = no_fly_polygon([(3_000, 2_000), (3_000, 4_000), (5_000, 4_000), (5_000, 2_000)])
    zoned = min_fleet(area, v, bank, swath, deadline, base_ne=(4_000.0, 6_000.0), no_fly=[zone])
    assert zoned.no_fly and completion_s(zoned, v) <= deadline


def test_more_aircraft_than_lanes_across_share_the_lanes_along_their_length() -> None:
    """Past one lane per aircraft, strips would only get narrower than a lane
    (their swaths overlapping): each lane row is cut along its length
    instead, into equal areas, and the search ends sooner the more aircraft
    fly it."""
    from cosim.coverage import completion_s

    area = area_polygon([(0, 0), (0, 16_000), (4_000, 16_000), (4_000, 0)])  # 4 rows of lanes
    v, swath = 102.9, 1_120.0  # lanes 1,008 m apart: 4 across
    radius = turn_radius_m(v, 45.0)
    done = []
    for n in (4, 8, 16):
        plan = plan_coverage(area, n, swath_width_m=swath, turn_radius=radius,
                             base_ne=(2_000.0, 8_000.0))
        shares = [a.strip for a in plan.aircraft]
        assert len(shares) == n
        for s in shares:
            assert s.area == pytest.approx(area.area / n, rel=1e-6)
        assert unary_union(shares).symmetric_difference(area).area < 1e-6 * area.area
        for a in plan.aircraft:
            seen = unary_union([LineString(lane).buffer(swath / 2, cap_style="flat")
                                for lane in a.lanes])
            assert a.strip.difference(seen).area < 1e-6 * a.strip.area
            assert a.survey_m <= 16_000.0 * 4 / n * 1.001  # its share of the lanes only
        done.append(completion_s(plan, v))
    assert done[0] > done[1] > done[2], done
