"""Trees in 3-D (``ground: {trees: 3d}``, cosim/renderer/canopy.py): a crown's
parallax and its shadow against their formulas on rendered frames, targets
hidden under crowns, every tree in view drawn whole, the ground's tiles, and
the key's checks."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, Pose, camera_pose, project, to_camera
from cosim.errors import ConfigError
from cosim.renderer import canopy, frame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.texture import ProceduralTiles
from cosim.scenario import parse_scenario
from cosim.world.ground import GroundSpec
from cosim.world.sun import DEFAULT, SunSpec
from cosim.world.targets import TargetSpec
from tests.renderer.test_haze import SCENARIO as AIR

LAT0, LON0, GROUND_M, SEED = 37.4150, -122.0480, 10.0, 7  # the flyover's


def _cam(pitch_deg: float = -90.0, w: int = 320, h: int = 240, hfov: float = 60.0
         ) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    mount = "nadir" if pitch_deg == -90.0 else "gimbal"
    return CameraSpec("c", (0,), mount, pitch_deg, False, hfov, vfov, w, h, 10.0, 12)


def _world(trees: str = "3d", sun: SunSpec = DEFAULT,
           targets: tuple[TargetSpec, ...] = ()) -> World:
    return World(WorldSpec(LAT0, LON0, GROUND_M, SEED, 120.0, GroundSpec(trees=trees), targets,
                           (), sun))


def _one(north_m: float, east_m: float, radius_m: float, crown_m: float, top_m: float
         ) -> canopy.Trees:
    return canopy.Trees(*(np.array([v]) for v in (north_m, east_m, radius_m, crown_m, top_m,
                                                  1.0)))


def _placed(monkeypatch: pytest.MonkeyPatch, world: World, cam: CameraSpec, pose: Pose,
            tree: canopy.Trees) -> tuple[np.ndarray, np.ndarray]:
    """The frame with only ``tree`` (L axes) standing, and without it."""
    got = []
    for trees in (tree, tree.take(np.zeros(0, int))):
        monkeypatch.setattr(canopy, "in_view", lambda *a, t=trees: t)
        got.append(render_frame(world, cam, pose, 0)[0][..., :3].astype(int))
    return got[0], got[1]


@pytest.mark.parametrize("east_m", [30.0, 45.0])
def test_a_crown_top_h_up_lands_h_tan_t_from_its_foot(monkeypatch: pytest.MonkeyPatch,
                                                      east_m: float) -> None:
    # a slender tree (0.1 m crown radius, 5 to 15 m up) east of a nadir camera 100 m
    # up: its top is seen at off-nadir angle t = atan(east / (100 - 15)), displaced
    # 15 tan t on the ground from its foot, 15 tan t / gsd pixels in the image
    cam, height_m, top_m = _cam(), 100.0, 15.0
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + height_m, 0.0, 0.0, 0.0, GROUND_M)
    world = _world()
    K = world.view(cam).K
    with_tree, without = _placed(monkeypatch, world, cam, pose,
                                 _one(0.0, east_m, 0.1, 5.0, top_m))
    cols = np.flatnonzero((with_tree != without).any(axis=2).any(axis=0))
    foot, top = project(K, to_camera(pose, np.array([[0.0, east_m, 0.0],
                                                     [0.0, east_m, -top_m]])))
    assert abs(cols.min() - foot[0]) <= 1.0 and abs(cols.max() - top[0]) <= 1.5
    gsd_m = height_m / K[0, 0]
    tan_t = east_m / (height_m - top_m)
    assert cols.max() - cols.min() == pytest.approx(top_m * tan_t / gsd_m, abs=2.0)
    assert top_m * tan_t / gsd_m > 10  # a parallax a flat crown would not show


@pytest.mark.parametrize("az_deg, el_deg", [(90.0, 40.0), (180.0, 30.0), (225.0, 55.0)])
def test_a_crowns_shadow_falls_h_over_tan_elevation_away_from_the_sun(
        monkeypatch: pytest.MonkeyPatch, az_deg: float, el_deg: float) -> None:
    # a crown 4 to 12 m up, 2 m across, straight under a nadir camera 100 m up; its
    # shadow (the frame with shadows against the frame without) reaches, away from
    # the sun, the shadow of its centre (8 m up: 8 / tan(el)) plus the ellipsoid's
    # half extent along the sun's rays: sqrt(r^2 + c^2 / tan(el)^2), c = 4 m
    cam, height_m = _cam(), 100.0
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + height_m, 0.0, 0.0, 0.0, GROUND_M)
    tree = _one(0.0, 0.0, 2.0, 4.0, 12.0)
    frames = []
    for shadows in (True, False):
        monkeypatch.setattr(canopy, "in_view", lambda *a: tree)
        world = _world(sun=SunSpec(az_deg, el_deg, shadows=shadows))
        frames.append(render_frame(world, cam, pose, 0)[0][..., :3].astype(int))
    dark = (frames[0] < frames[1]).any(axis=2)
    rows, cols = np.nonzero(dark)
    K = world.view(cam).K
    px_per_m = K[0, 0] / height_m
    az, tan_el = math.radians(az_deg), math.tan(math.radians(el_deg))
    # away from the sun: north -cos az, east -sin az; in the image east is right, north up
    away = np.array([-math.sin(az), math.cos(az)])
    along = (np.column_stack([cols, rows]) - K[:2, 2]) @ away / px_per_m
    reach_m = 8.0 / tan_el + math.hypot(2.0, 4.0 / tan_el)
    assert along.max() == pytest.approx(reach_m, abs=1.5 / px_per_m)
    across = (np.column_stack([cols, rows]) - K[:2, 2]) @ np.array([away[1], -away[0]])
    assert abs(across.mean()) < 0.5  # straight away from the sun
    assert across.max() / px_per_m == pytest.approx(2.0, abs=1.5 / px_per_m)  # its width


def _wood_tree() -> tuple[float, float, float]:
    """A wood's tree by the flyover's track (north, east of its foot, crown radius)."""
    t = canopy.standing(SEED, 380.0, 420.0, -40.0, 40.0)
    k = int(np.argmax(t.crown_m))
    return float(t.north_m[k]), float(t.east_m[k]), float(t.radius_m[k])


def test_a_target_under_a_crown_is_hidden_and_one_in_the_open_is_not() -> None:
    n, e, r = _wood_tree()
    person = TargetSpec("p", "person", n + 0.3, e, None, None, 0.0, 0.5, 0.5, 1.8,
                        (220, 30, 30))
    cam = _cam(hfov=20.0)
    lat, lon = World(WorldSpec(LAT0, LON0, GROUND_M, SEED, 120.0, GroundSpec(), ())) \
        .frame.place(n, e, GROUND_M)[:2]
    pose = camera_pose(cam, float(lat), float(lon), GROUND_M + 60.0, 0.0, 0.0, 0.0, GROUND_M)
    seen = {mode: render_frame(_world(mode, targets=(person,)), cam, pose, 0)[1][0]
            for mode in ("flat", "3d")}
    assert seen["flat"]["pixels_on_target"] > 20
    assert seen["3d"]["pixels_on_target"] == 0
    assert seen["3d"]["in_view"]  # hidden, not out of view
    # the flyover's truck stands in a field, no tree within 10 m: as visible either way
    assert not len(canopy.standing(SEED, -10.0, 10.0, -10.0, 10.0))
    truck = TargetSpec("t", "truck", 0.0, 0.0, None, None, 20.0, 8.0, 2.5, 3.0, (200, 200, 200))
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, GROUND_M)
    px = [render_frame(_world(mode, targets=(truck,)), cam, pose, 0)[1][0]["pixels_on_target"]
          for mode in ("flat", "3d")]
    assert px[0] == px[1] > 50


def test_every_tree_whose_crown_is_in_view_is_drawn() -> None:
    # an oblique view over a wood whose trees' tables lie in two blocks (east 0 m);
    # every band of rows sees ground finer than the flat trees' levels, so every
    # tree whose crown reaches into the image must be drawn, its foot in view or not
    cam = _cam(-45.0)
    world = _world()
    lat, lon = world.frame.place(370.0, 0.0, GROUND_M)[:2]
    pose = camera_pose(cam, float(lat), float(lon), GROUND_M + 40.0, 0.0, 0.0, 0.0, GROUND_M)
    view = world.view(cam)
    img = np.empty((cam.height_px, cam.width_px, 4), np.uint8)
    H, _, _, levels = frame._draw_ground(world, cam, pose, view, img, None)
    assert all(0 <= lv < canopy.FLAT_FROM_LEVEL for lv in levels)
    drawn = frame._trees_in_view(world, pose, view, H, levels, cam.width_px)
    every = canopy.standing(SEED, 250.0, 550.0, -150.0, 150.0)
    a_inv = np.linalg.inv(frame._l_to_scenario_ne(world, pose))
    n, e = a_inv[:2, :2] @ np.stack([every.north_m, every.east_m]) + a_inv[:2, 2:3]
    every = canopy.Trees(n, e, every.radius_m, every.crown_m, every.top_m, every.tone)
    crown = canopy.outlines(every, pose.c_l, world.sun_l)[0]
    uv = project(view.K, ((crown - pose.c_l) @ pose.R_cl.T).reshape(-1, 3)).reshape(
        len(every), -1, 2)
    inside = ((uv[..., 0] > 0) & (uv[..., 0] < cam.width_px - 1) & (uv[..., 1] > 0)
              & (uv[..., 1] < cam.height_px - 1)).any(axis=1)
    want = {(round(a, 6), round(b, 6)) for a, b in zip(n[inside], e[inside])}
    got = {(round(a, 6), round(b, 6)) for a, b in zip(drawn.north_m, drawn.east_m)}
    assert len(want) > 30 and want <= got
    feet_out = project(view.K, to_camera(pose, np.column_stack([n, e, 0 * n])))[inside]
    assert (feet_out[:, 1] > cam.height_px).any()  # some feet below the image, crowns in it


def test_3d_ground_tiles_show_the_ground_under_the_trees_and_flat_ones_further() -> None:
    flat, three = ProceduralTiles(SEED, 0.05, 256), ProceduralTiles(SEED, 0.05, 256,
                                                                    canopy.FLAT_FROM_LEVEL)
    tile = np.empty((256, 256, 4), np.uint8)
    other = np.empty_like(tile)
    # the wood at north 380-420 m: level 4 (0.8 m a pixel) tile row 3, column 0
    lv = canopy.FLAT_FROM_LEVEL
    assert np.array_equal(flat.make(lv, 1, 0, tile), three.make(lv, 1, 0, other))
    # level 2 (0.2 m a pixel): the wood's trees gone, the rest of the tile the same
    ti = -int(400.0 / (0.2 * 256)) - 1
    a, b = flat.make(2, ti, 0, tile).astype(int), three.make(2, ti, 0, other).astype(int)
    changed = (a != b).any(axis=2)
    assert 0.1 < changed.mean() < 0.9
    # where they differ, the flat tile shows a dark crown over the lighter ground
    assert (a[changed].sum(axis=1) < b[changed].sum(axis=1)).mean() > 0.95


SCENARIO = AIR.replace("atmosphere:\n", "ground:\n")  # its body from line 9


def test_the_trees_key(tmp_path: Path) -> None:
    f = str(tmp_path / "g.yaml")

    def ground(body: str) -> GroundSpec:
        spec: GroundSpec = parse_scenario(SCENARIO.format(body=body), f,
                                          check_properties=False).world.ground
        return spec

    assert ground("  texture: procedural\n") == ground("  trees: flat\n") == GroundSpec(
        image_folders=ground("  trees: flat\n").image_folders)
    assert ground("  trees: 3d\n").trees == "3d" and ground("  trees: none\n").trees == "none"
    for body, problem in (("  trees: 4d\n", "expected one of: flat, 3d, none; got '4d'"),
                          ("  trees: [3d]\n", "expected a string, got a list")):
        with pytest.raises(ConfigError, match=f"{f}:9: ground.trees: {problem}"):
            ground(body)


def test_the_compiled_fill_covers_every_pixel_a_polygon_reaches_into() -> None:
    from cosim.renderer.canopy_pass import fill_polygons

    rng = np.random.default_rng(5)
    h, w = 60, 80
    for _ in range(200):
        n = int(rng.integers(3, 12))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        centre, radius = rng.uniform([-10, -10], [w + 10, h + 10]), rng.uniform(0.2, 30.0, 2)
        poly = centre + np.column_stack([np.cos(ang), np.sin(ang)]) * radius
        img, ids = np.zeros((h, w, 4), np.uint8), np.full((h, w), 7, np.uint16)
        fill_polygons(img, ids, poly[None], np.array([n]), np.array([[1, 2, 3]], np.uint8),
                      np.array([True]), 0, 1)
        got = img[..., 0] == 1
        assert np.array_equal(got, ids == 0) and (img[..., 3] == 0).all()
        # every pixel whose centre is inside is filled; none is more than a pixel away
        ys, xs = np.mgrid[0:h, 0:w]
        inside = np.ones((h, w), bool)
        near = np.ones((h, w), bool)
        for (ax, ay), (bx, by) in zip(poly, np.roll(poly, -1, axis=0)):
            cross = (bx - ax) * (ys - ay) - (by - ay) * (xs - ax)
            edge = math.hypot(bx - ax, by - ay)
            inside &= cross >= 0
            near &= cross >= -0.75 * edge  # within 0.75 px (a pixel's half diagonal)
        assert (got[inside]).all() and not (got & ~near).any()


def test_a_target_in_front_of_a_crown_stays_whole() -> None:
    # a person 6 m south of a tree on the wood's southern edge (no tree within 15 m
    # south of it, 8 m either side), seen from 20 m south of it and 2 m up: the
    # tree's trunk rises behind the person, who keeps every pixel it has with flat
    # trees (the trunk drawn over it, it would lose some); 6 m north of the tree,
    # behind the trunk, it loses some (here all: the trunk is as wide as it, nearer)
    t = canopy.standing(SEED, 360.0, 430.0, -60.0, 90.0)
    edge = [k for k in np.argsort(t.north_m) if not ((t.north_m < t.north_m[k])
            & (t.north_m > t.north_m[k] - 15.0) & (abs(t.east_m - t.east_m[k]) < 8.0)).any()]
    n, e = float(t.north_m[edge[0]]), float(t.east_m[edge[0]])
    cam = _cam(-5.0, hfov=20.0)
    px = {}
    for dn in (-6.0, 6.0):
        lat, lon = _world().frame.place(n + dn - 20.0, e, GROUND_M)[:2]
        pose = camera_pose(cam, float(lat), float(lon), GROUND_M + 2.0, 0.0, 0.0, 0.0,
                           GROUND_M)
        person = TargetSpec("p", "person", n + dn, e, None, None, 0.0, 0.5, 0.5, 1.8,
                            (220, 30, 30))
        px[dn] = [render_frame(_world(mode, targets=(person,)), cam, pose, 0)[1][0]
                  ["pixels_on_target"] for mode in ("flat", "3d")]
    assert px[-6.0][0] == px[-6.0][1] > 50
    assert px[6.0][1] < px[6.0][0]


def test_the_compiled_outlines_are_numpys() -> None:
    from cosim.renderer.canopy_pass import outline_pixels

    rng = np.random.default_rng(11)
    n = 300
    trees = canopy.Trees(rng.uniform(-60, 60, n), rng.uniform(-60, 60, n),
                         rng.uniform(1.6, 2.8, n), rng.uniform(2.5, 5.0, n),
                         rng.uniform(6.0, 16.0, n), np.ones(n))
    cam, world = _cam(-30.0), _world()
    K = world.view(cam).K
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 9.0, 0.0, 0.0, 30.0, GROUND_M)
    centre, semi = canopy._axes(trees)
    out, counts, depth, state = outline_pixels(centre, semi, world.sun_l, pose.c_l, pose.R_cl,
                                               K, canopy._COS, canopy._SIN, canopy.LIT,
                                               canopy.TRUNK_M, 0.05)
    crown, cap, trunk, outside = canopy.outlines(trees, pose.c_l, world.sun_l)
    assert np.array_equal(state == 2, ~outside)
    front = state == 0
    assert front.sum() > 100 and (state == 1).sum() > 5  # some across the near plane
    for part, polys in ((0, trunk), (1, crown), (2, cap)):
        uv = project(K, ((polys[front] - pose.c_l) @ pose.R_cl.T).reshape(-1, 3))
        got = out[front, part, :polys.shape[1]].reshape(-1, 2)
        assert np.allclose(got, uv, atol=1e-6)
    mid = ((crown[front] - pose.c_l) @ pose.R_cl.T).mean(axis=1)
    assert np.allclose(depth[front], np.linalg.norm(mid, axis=1))
    # a trunk is left out where its foot lies inside the crown's inscribed circle
    ring = out[front, 1, :canopy.SIDES]
    centre_px = ring.mean(axis=1)
    inner = np.linalg.norm(ring - centre_px[:, None], axis=2).min(axis=1) * math.cos(
        math.pi / canopy.SIDES)
    foot = out[front, 0, :2].mean(axis=1)
    bare = np.linalg.norm(foot - centre_px, axis=1) > inner
    assert np.array_equal(counts[front, 0], np.where(bare, 4, 0))
    assert (counts[front, 1:] == canopy.SIDES).all()


@pytest.mark.integration
def test_3d_trees_are_the_same_inline_and_in_worker_processes(tmp_path: Path) -> None:
    from tests.renderer.test_renderer import _fly

    # ten 160 x 120 frames 80 m apart along a line north, 60 m up (0.36 m a pixel:
    # ground finer than the flat trees' levels), hedgerows and woods in view
    digests = []
    for n in (0, 1):
        summary, _ = _fly(tmp_path, f"w{n}", workers=n, rate=10.0, dur=1.0, v_mps=800.0,
                          alt_agl_m=60.0, more="ground: {texture: procedural, trees: 3d}\n")
        digests.append([s["frames_sha256"] for s in summary["streams"]])
    flat, _ = _fly(tmp_path, "flat", workers=0, rate=10.0, dur=1.0, v_mps=800.0,
                   alt_agl_m=60.0)
    assert digests[0] == digests[1]
    assert digests[0] != [s["frames_sha256"] for s in flat["streams"]]  # trees in view
