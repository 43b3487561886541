"""The ground truth's ``visible_fraction``: a target's visible pixels over
those its faces would cover with nothing in front of them, within the image."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
import pytest

from cosim.core.camera import SHIFT, CameraSpec, camera_pose
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.truth import GT_COLUMNS, unoccluded_pixels
from cosim.world.ground import GroundSpec
from cosim.world.obstacles import Obstacle
from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0


def _target(kind: str, n: float, e: float, tid: str = "t") -> TargetSpec:
    L, W, H, c = TARGET_DEFAULTS[kind]
    return TargetSpec(tid, kind, n, e, None, None, 0.0, L, W, H, c)


def _cam(mount: str, pitch: float, w: int, h: int, hfov: float) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec("c", (0,), mount, pitch, False, hfov, vfov, w, h, 10.0, 12)


def _row(targets: tuple[TargetSpec, ...], obstacles: tuple[Obstacle, ...], cam: CameraSpec,
         alt_agl_m: float) -> dict[str, Any]:
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), targets, obstacles))
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + alt_agl_m, 0.0, 0.0, 0.0,
                       ground_alt_m=GROUND_M)
    _, rows = render_frame(world, cam, pose, 0)
    return rows[0]


def test_it_is_the_last_ground_truth_column() -> None:
    assert GT_COLUMNS[-2:] == ("contrast", "visible_fraction")


def test_a_target_with_nothing_in_front_is_wholly_visible() -> None:
    row = _row((_target("truck", 10.0, 5.0),), (), _cam("nadir", -90.0, 320, 240, 60.0), 80.0)
    assert row["fully_in_view"] == 1 and row["pixels_on_target"] > 100
    assert row["visible_fraction"] == 1.0


def test_a_building_hiding_the_left_half_of_a_target_leaves_half_visible() -> None:
    """A forward camera 1.5 m up looks north at a car 60 m away, straight
    ahead and square on (its outline is symmetric about the image's centre
    column); a 30 m high building 30 m ahead reaches from the line of sight
    (east 0, which projects onto the centre column at every range) 20 m to
    the west: it hides the car's left half, whatever the car's outline."""
    car = _target("car", 60.0, 0.0)
    wall = Obstacle("w", ((30.0, -20.0), (30.0, 0.0), (32.0, 0.0), (32.0, -20.0)), 30.0)
    cam = _cam("forward", 0.0, 640, 480, 20.0)
    bare = _row((car,), (), cam, 1.5)
    row = _row((car,), (wall,), cam, 1.5)
    assert bare["visible_fraction"] == 1.0 and bare["pixels_on_target"] > 1000
    assert row["in_view"] == 1
    assert row["visible_fraction"] == pytest.approx(0.5, abs=0.03)
    assert row["pixels_on_target"] == pytest.approx(bare["pixels_on_target"] / 2, rel=0.06)


def test_a_target_hidden_whole_is_zero_and_one_out_of_view_is_empty() -> None:
    car = _target("car", 60.0, 0.0)
    wall = Obstacle("w", ((30.0, -20.0), (30.0, 20.0), (32.0, 20.0), (32.0, -20.0)), 30.0)
    cam = _cam("forward", 0.0, 640, 480, 20.0)
    row = _row((car,), (wall,), cam, 1.5)
    assert row["in_view"] == 1 and row["pixels_on_target"] == 0
    assert row["visible_fraction"] == 0.0
    behind = _row((_target("car", -60.0, 0.0),), (), cam, 1.5)
    assert behind["in_view"] == 0 and behind["visible_fraction"] is None


def test_the_part_of_a_target_outside_the_image_is_not_counted_as_hidden() -> None:
    """A nadir camera 40 m up, a truck straddling the image's right edge:
    part of it is out of view, none of it hidden."""
    cam = _cam("nadir", -90.0, 320, 240, 60.0)
    half_w_m = 40.0 * math.tan(math.radians(30.0))  # ground half-width under the camera
    row = _row((_target("truck", 0.0, half_w_m),), (), cam, 40.0)
    assert row["in_view"] == 1 and row["fully_in_view"] == 0 and row["pixels_on_target"] > 0
    assert row["visible_fraction"] == 1.0


def test_unoccluded_pixels_counts_an_overlap_once_and_only_inside_the_image() -> None:
    """Squares filled into a mask over their bounding rectangle count the
    pixels the same fill covers in the whole image: overlaps once, the
    parts off the image not at all."""
    def square(x: float, y: float, side: float = 10.3) -> np.ndarray:
        return np.round(np.array([[x, y], [x + side, y], [x + side, y + side], [x, y + side]])
                        * 16).astype(np.int32)

    def whole(polys: list[np.ndarray]) -> int:
        img = np.zeros((100, 120), np.uint8)
        for p in polys:
            cv2.fillConvexPoly(img, p, 1, cv2.LINE_8, SHIFT)
        return int(img.sum())

    mask = np.zeros((100, 120), np.uint8)
    for polys in ([square(20.2, 20.7)], [square(20.2, 20.7), square(25.6, 23.1)],
                  [square(114.4, 50.2)], [square(-5.3, -4.8)], [square(-20.0, 30.0)],
                  [square(30.0, 95.5, 30.0), square(-3.0, 2.0, 130.0)]):
        assert unoccluded_pixels(polys, mask) == whole(polys)
        assert not mask.any()  # left all zero
    assert 0 < unoccluded_pixels([square(114.4, 50.2)], mask) < \
        unoccluded_pixels([square(50.0, 50.2)], mask)
    assert unoccluded_pixels([square(-20.0, 30.0)], mask) == 0


def test_a_long_wall_hides_the_car_behind_it_and_not_the_car_before_it() -> None:
    """A forward camera 1.5 m up looking north. A 4 m wall across the view
    20 m ahead, 85 m long, its centre 42 m off: a car 24 m ahead, behind it,
    is hidden though nearer than the wall's centre. A 4 m wall along the view
    3 m to the right, from 5 to 60 m ahead (centre 32.6 m off): a car 40 m
    ahead beside it, on the camera's side of it, is not hidden though
    farther than the wall's centre (by centre distances alone: 0.56)."""
    cam = _cam("forward", 0.0, 640, 480, 60.0)
    across = Obstacle("a", ((20.0, -5.0), (20.0, 80.0), (21.0, 80.0), (21.0, -5.0)), 4.0)
    along = Obstacle("b", ((5.0, 3.0), (5.0, 4.0), (60.0, 4.0), (60.0, 3.0)), 4.0)
    behind = _row((_target("car", 24.0, 0.0),), (across,), cam, 1.5)
    assert behind["in_view"] == 1 and behind["visible_fraction"] == 0.0
    beside = _row((_target("car", 40.0, 2.0),), (along,), cam, 1.5)
    assert beside["pixels_on_target"] == _row((_target("car", 40.0, 2.0),), (), cam,
                                              1.5)["pixels_on_target"]
    assert beside["visible_fraction"] == 1.0
