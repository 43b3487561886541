"""Buildings: the obstacles' roof and colour keys and their checks, the
roofs' geometry against the formulas, and rendered roofs where the pinhole
and the sun put them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose
from cosim.errors import ConfigError
from cosim.renderer.buildings import BuildingSet, building
from cosim.renderer.frame import World, WorldSpec, _scenario_to_l, render_frame
from cosim.renderer.targets import lambert
from cosim.scenario import load_scenario, parse_scenario
from cosim.world.ground import GroundSpec
from cosim.world.obstacles import WALL_RGB, Obstacle
from cosim.world.sun import SunSpec

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0
#: 20 m north-south by 10 m east-west, centred on the origin
HOUSE = ((-10.0, -5.0), (-10.0, 5.0), (10.0, 5.0), (10.0, -5.0))


def _scenario(tmp_path: Path, obstacles: str) -> object:
    text = f"""\
schema_version: 1
name: b
origin: {{lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}}
rates: {{physics_hz: 120, control_hz: 30, log_hz: 30}}
duration_s: 2
vehicles:
  - {{id: car, class: ground, init: {{north_m: -100, east_m: -100}}}}
obstacles:
{obstacles}"""
    return parse_scenario(text, str(tmp_path / "b.yaml"), check_properties=False)


def test_roof_and_colour_keys_are_read(tmp_path: Path) -> None:
    scn = _scenario(tmp_path, """\
  - {id: a, height_m: 8, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof: gable,
     roof_height_m: 3, color: "#c8b496", roof_color: [150, 40, 30]}
  - {id: b, height_m: 8, polygon: [[30, 0], [30, 10], [40, 10], [40, 0]], roof: hip}
  - {id: c, polygon: [[50, 0], [50, 10], [60, 5]]}
""")
    a, b, c = scn.world.obstacles  # type: ignore[attr-defined]
    assert (a.roof, a.roof_height_m, a.color_rgb, a.roof_rgb) == \
        ("gable", 3.0, (200, 180, 150), (150, 40, 30))
    assert (b.roof, b.roof_height_m, b.roof_rgb) == ("hip", 4.0, WALL_RGB)  # half of height_m
    assert (c.roof, c.roof_height_m, c.height_m, c.color_rgb) == ("flat", 0.0, 3.0, WALL_RGB)


@pytest.mark.parametrize("obstacle,msg", [
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10]], roof: gable}",
     r"b\.yaml:9: obstacles\[0\]\.roof: a gable roof needs a convex polygon of 4 corners, "
     r"got 3 corners; give roof: flat"),
    ("{id: a, polygon: [[0, 0], [0, 10], [3, 5], [10, 5]], roof: hip}",
     r"obstacles\[0\]\.roof: a hip roof needs a convex polygon of 4 corners, got 4 corners not "
     r"convex"),
    ("{id: a, height_m: 6, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof: hip, "
     "roof_height_m: 6}", r"obstacles\[0\]\.roof_height_m: must be below height_m \(6, the roof's "
                          r"top: the walls end at height_m - roof_height_m\), got 6"),
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof_height_m: 2}",
     r"obstacles\[0\]\.roof_height_m: a flat roof has no height: give roof: gable or hip"),
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof: dome}",
     r"obstacles\[0\]\.roof: expected one of: flat, gable, hip; got 'dome'"),
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof: gable, roof_height_m: -1}",
     r"obstacles\[0\]\.roof_height_m: must be > 0, got -1"),
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], color: red}",
     r"obstacles\[0\]\.color: expected a colour as '#rrggbb' or \[r, g, b\] \(0-255\)"),
    ("{id: a, polygon: [[0, 0], [0, 10], [20, 10], [20, 0]], roof_color: [1, 2, 300]}",
     r"obstacles\[0\]\.roof_color: expected a colour"),
])
def test_bad_roof_keys_are_refused_with_file_line_and_path(tmp_path: Path, obstacle: str,
                                                          msg: str) -> None:
    with pytest.raises(ConfigError, match=msg):
        _scenario(tmp_path, f"  - {obstacle}\n")


def _faces(o: Obstacle) -> list[tuple[np.ndarray, np.ndarray, tuple[int, int, int]]]:
    b = building(o)
    return [(b.points[idx], n, c) for idx, n, c in b.faces]


def test_gable_roof_geometry() -> None:
    """Walls up to height - roof height; the ridge along the long axis at the
    top, over the short edges' midpoints; two slopes tilted atan(rise / half
    width) and two upright gable ends in the walls' colour."""
    o = Obstacle("h", HOUSE, 9.0, "gable", 4.0, (200, 180, 150), (150, 40, 30))
    faces = _faces(o)
    walls = [f for f in faces if f[2] == o.color_rgb and len(f[0]) == 4]
    assert len(walls) == 4 and all(sorted(-f[0][:, 2]) == [0, 0, 5, 5] for f in walls)
    slopes = [f for f in faces if f[2] == o.roof_rgb]
    assert len(slopes) == 2  # each one planar quad
    tilt = math.degrees(math.atan2(4.0, 5.0))
    for v, n, _ in slopes:
        assert math.degrees(math.acos(-n[2])) == pytest.approx(tilt)
        assert n[0] == pytest.approx(0.0, abs=1e-12)  # facing east or west
        ridge = v[np.isclose(v[:, 2], -9.0)]
        assert sorted(map(tuple, ridge[:, :2])) == [(-10.0, 0.0), (10.0, 0.0)]
    ends = [f for f in faces if f[2] == o.color_rgb and len(f[0]) == 3]
    assert len(ends) == 2 and all(abs(f[1][0]) == 1.0 for f in ends)  # facing north, south


def test_hip_roof_geometry_and_a_square_ones_pyramid() -> None:
    """The ridge cut short by half the width at each end: every slope rises
    the roof's height over half the width; over a square, a pyramid."""
    o = Obstacle("h", HOUSE, 9.0, "hip", 4.0)
    slopes = [f for f in _faces(o) if f[1][2] < -1e-9]
    assert len(slopes) == 4
    tilt = math.degrees(math.atan2(4.0, 5.0))
    assert all(math.degrees(math.acos(-n[2])) == pytest.approx(tilt) for _, n, _ in slopes)
    ridge = {tuple(p[:2]) for v, _, _ in slopes for p in v if p[2] == -9.0}
    assert ridge == {(-5.0, 0.0), (5.0, 0.0)}
    square = Obstacle("s", ((0.0, 0.0), (0.0, 8.0), (8.0, 8.0), (8.0, 0.0)), 6.0, "hip", 2.0)
    slopes = [f for f in _faces(square) if f[1][2] < -1e-9]
    assert len(slopes) == 4 and all(len(v) == 3 for v, _, _ in slopes)
    assert {tuple(p) for v, _, _ in slopes for p in v if p[2] == -6.0} == {(4.0, 4.0, -6.0)}


def test_a_slope_that_is_not_planar_is_drawn_as_two_triangles() -> None:
    """A gable over a trapezoid: its slopes' corners do not lie in one plane."""
    o = Obstacle("t", ((0.0, 0.0), (0.0, 10.0), (20.0, 8.0), (20.0, 2.0)), 8.0, "gable", 3.0)
    b = building(o)
    for idx, n, _ in b.faces:
        v = b.points[idx]
        assert np.abs((v - v[0]) @ n).max() < 1e-9  # every face planar, its normal true
    assert sum(1 for idx, n, _ in b.faces if n[2] < -1e-9) == 4


def _cam(w: int = 320, h: int = 240, hfov: float = 60.0) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec("c", (0,), "nadir", -90.0, False, hfov, vfov, w, h, 10.0, 12)


def test_a_gable_roof_seen_from_above_is_where_the_pinhole_puts_it_and_sun_shaded() -> None:
    """A nadir camera 30 m up over the ridge of a north-south gable house (9 m
    top, walls 5 m), the sun low in the east: the roof spans f * 5 m / 25 m
    either side of the image's centre column (its eaves, at the walls' top),
    the east slope in lambert(its normal) of the roof colour, the west slope
    in its own, the ridge between them on the centre column (eaves at 9 m
    would be f * 5 m / 21 m out, 11 px more a side)."""
    o = Obstacle("h", HOUSE, 9.0, "gable", 4.0, (200, 180, 150), (150, 40, 30))
    sun = SunSpec(azimuth_deg=90.0, elevation_deg=30.0)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (), (o,), sun))
    cam = _cam()
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 30.0, 0.0, 0.0, 0.0, ground_alt_m=GROUND_M)
    img, _ = render_frame(world, cam, pose, 0)
    sun_l = sun.to_sun_ned()
    shade = {}
    for side, e in (("east", 1.0), ("west", -1.0)):
        n = np.array([0.0, e * 4.0, -5.0]) / math.hypot(4.0, 5.0)
        k = lambert(n, sun_l)
        shade[side] = np.array([min(255, int(c * k)) for c in o.roof_rgb[::-1]])
    assert (shade["east"] > shade["west"]).all()
    row = img[120, :, :3]  # the image's middle row: east is to the right (nose north)
    is_e = (row == shade["east"]).all(axis=1)
    is_w = (row == shade["west"]).all(axis=1)
    cx = (320 - 1) / 2
    half_px = cam.fx_px * 5.0 / 25.0
    east, west = np.flatnonzero(is_e), np.flatnonzero(is_w)
    # OpenCV's fill takes in the pixels an edge touches: up to a pixel more a side
    assert abs(east.min() - cx) <= 1.5 and abs(west.max() - cx) <= 1.5
    assert east.max() == pytest.approx(cx + half_px, abs=1.5)
    assert west.min() == pytest.approx(cx - half_px, abs=1.5)
    assert len(east) + len(west) == pytest.approx(2 * half_px, abs=2.0)


@pytest.mark.parametrize("roof,roof_h,far_e_m", [
    ("flat", 0.0, -5.0 - 9.0 / math.tan(math.radians(30.0))),  # the roof's west edge, 9 m up
    ("gable", 4.0, -9.0 / math.tan(math.radians(30.0))),  # the ridge over e = 0, 9 m up
])
def test_a_buildings_shadow_reaches_as_far_as_h_over_tan_elevation(roof: str, roof_h: float,
                                                                  far_e_m: float) -> None:
    """The sun 30 deg up in the east; a nadir camera 100 m over the house: the
    ground the shadow darkens (against the same frame without shadows) ends
    west of the house where its highest point lands, h / tan(30 deg) west of
    it, within a pixel or two; there is no shadow east of it."""
    o = Obstacle("h", HOUSE, 9.0, roof, roof_h)
    cam = _cam()
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, ground_alt_m=GROUND_M)
    frames = []
    for shadows in (False, True):
        sun = SunSpec(azimuth_deg=90.0, elevation_deg=30.0, shadows=shadows)
        world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (), (o,), sun))
        frames.append(render_frame(world, cam, pose, 0)[0].copy())
    dark = (frames[0] != frames[1]).any(axis=2)
    cx = (320 - 1) / 2
    for r in (110, 120, 130):  # rows a few metres either side of the middle
        cols = np.flatnonzero(dark[r])
        want = cx + cam.fx_px * far_e_m / 100.0
        assert abs(cols.min() - want) <= 2.0, (r, cols.min(), want)
        assert cols.max() <= cx - cam.fx_px * 5.0 / (100.0 - 9.0 + roof_h) + 2  # under the eaves


def test_buildings_out_of_view_are_culled_but_not_a_shadow_reaching_into_it() -> None:
    """A nadir camera 100 m up sees the ground within 57.7 m east and west
    (60 deg lens): a 12 m tower 70 m east, the sun 30 deg up in the east,
    casts its shadow 20.8 m west, into the view; one 300 m east does not."""
    cam = _cam()
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, ground_alt_m=GROUND_M)
    tower = ((-3.0, 67.0), (-3.0, 73.0), (3.0, 73.0), (3.0, 67.0))
    far = tuple((n, e + 230.0) for n, e in tower)
    frames, near = [], []
    for obstacles in ((), (Obstacle("t", tower, 12.0), Obstacle("f", far, 12.0))):
        sun = SunSpec(azimuth_deg=90.0, elevation_deg=30.0, shadows=True)
        world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (), obstacles, sun))
        frames.append(render_frame(world, cam, pose, 0)[0].copy())
        rot, shift = _scenario_to_l(world, pose)
        near.append(world.buildings.in_view(rot, shift, pose, world.view(cam).planes))
    assert near == [[], [0]]
    dark = np.flatnonzero((frames[0] != frames[1]).any(axis=2).any(axis=0))
    edge = (320 - 1) / 2 + cam.fx_px * (67.0 - 12.0 / math.tan(math.radians(30.0))) / 100.0
    assert abs(dark.min() - edge) <= 2.0 and dark.max() == 319  # the shadow, to the edge


def test_the_village_example_validates() -> None:
    """examples/village/village.yaml, the README's runnable village."""
    scn = load_scenario(Path(__file__).resolve().parents[2] / "examples/village/village.yaml",
                        check_properties=False)
    roofs = [(o.id, o.roof) for o in scn.world.obstacles]
    assert roofs == [("house1", "gable"), ("house2", "hip"), ("barn", "gable"),
                     ("shed", "flat")]
    assert scn.world.sun.shadows and len(scn.world.targets) == 2


def test_a_target_in_a_buildings_shadow_is_lit_by_the_sky_alone() -> None:
    """The sun 30 deg up in the east behind a 10 m block (east 5 m to -5 m):
    its shadow reaches 22.3 m west. A person 10 m west of its middle (its
    ray toward the sun meets the wall 3.8 m up) shows only the ambient share
    of its colours, 0.45 (targets.lambert with no sun); one 30 m west, past
    the shadow, is sunlit, as both are without the block."""
    from cosim.renderer.targets import AMBIENT, parts_of
    from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

    L, W, H, c = TARGET_DEFAULTS["person"]
    people = tuple(TargetSpec(f"p{e:g}", "person", 0.0, e, None, None, 0.0, L, W, H, c)
                   for e in (-10.0, -30.0))
    block = Obstacle("b", ((-5.0, -5.0), (-5.0, 5.0), (5.0, 5.0), (5.0, -5.0)), 10.0)
    cam = _cam()
    la, lo = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), ())).frame.place(
        0.0, -20.0, GROUND_M)
    pose = camera_pose(cam, float(la), float(lo), GROUND_M + 40.0, 0.0, 0.0, 0.0,
                       ground_alt_m=GROUND_M)
    ambient = {tuple(min(255, int(v * AMBIENT)) for v in p.color_rgb[::-1])
               for p in parts_of(people[0])}
    sun = SunSpec(azimuth_deg=90.0, elevation_deg=30.0, shadows=True)
    for obstacles, want in (((block,), (True, False)), ((), (False, False))):
        world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), people, obstacles,
                                sun))
        img, rows = render_frame(world, cam, pose, 0)
        ids = world.last_ids(cam.height_px, cam.width_px)
        for k in range(2):
            assert rows[k]["fully_in_view"] == 1 and rows[k]["pixels_on_target"] > 10
            colours = {tuple(int(v) for v in px) for px in img[ids == k + 1][:, :3]}
            assert (colours <= ambient) == want[k], (k, colours, ambient)


def test_what_lies_in_a_gable_houses_shadow_follows_its_roof() -> None:
    """The sun 30 deg up in the east, the north-south gable house (walls 5 m,
    ridge 9 m over east 0): a ray toward the sun from 0.5 m up rises
    tan(30 deg) a metre. From 1 m west of the west wall it meets the wall;
    from 8 m it clears the eaves (5.12 m) but meets the roof, steeper than
    the ray; from 12 m it passes over the ridge (10.3 m at east 0), which a
    flat roof at 9 m would stop."""
    sun = SunSpec(azimuth_deg=90.0, elevation_deg=30.0).to_sun_ned()
    pts = np.array([[0.0, -6.0, -0.5], [0.0, -13.0, -0.5], [0.0, -17.0, -0.5],
                    [15.0, -6.0, -0.5]])  # the last north of the house
    gable = BuildingSet((Obstacle("h", HOUSE, 9.0, "gable", 4.0),), sun, True)
    assert gable.in_shadow(pts, sun, [0]).tolist() == [True, True, False, False]
    flat = BuildingSet((Obstacle("h", HOUSE, 9.0),), sun, True)
    assert flat.in_shadow(pts, sun, [0]).tolist() == [True, True, True, False]
