"""Targets as shaded bodies: every part inside the ground-truth box, wheels
seen from the side, and the parts under others never painted over them."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose, project, to_camera
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.targets import (
    WHEEL_RGB,
    bounding_part,
    hidden_faces,
    lambert,
    parts_of,
    to_local,
)
from cosim.world.ground import GroundSpec
from cosim.world.targets import TARGET_DEFAULTS, TARGET_KINDS, TargetSpec

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0


def _target(kind: str, scale: tuple[float, float, float] = (1.0, 1.0, 1.0),
            heading_deg: float = 0.0) -> TargetSpec:
    L, W, H, c = TARGET_DEFAULTS[kind]
    return TargetSpec("t", kind, 0.0, 0.0, None, None, heading_deg, L * scale[0], W * scale[1],
                      H * scale[2], c)


@pytest.mark.parametrize("kind", TARGET_KINDS)
@pytest.mark.parametrize("scale", [(1.0, 1.0, 1.0), (0.3, 2.0, 1.0), (3.0, 0.5, 4.0),
                                   (0.01, 0.01, 0.01), (100.0, 40.0, 0.2)])
def test_every_part_lies_inside_the_ground_truth_box(kind: str,
                                                     scale: tuple[float, float, float]) -> None:
    t = _target(kind, scale)
    lo, hi = np.array(bounding_part(t)[0]), np.array(bounding_part(t)[1])
    for time_s, seed in ((0.0, 3), (0.37, 11), (5.0, 12), (2.2, 40), (7.9, 41)):
        for p in parts_of(t, time_s, seed):
            assert (np.array(p.lo) <= np.array(p.hi)).all(), p
            assert (np.array(p.lo) >= lo - 1e-9).all() and (np.array(p.hi) <= hi + 1e-9).all(), (
                kind, scale, p, lo, hi)


def test_vehicles_have_wheels_and_people_skin_and_hair() -> None:
    for kind in ("truck", "fire_truck", "car"):
        parts = parts_of(_target(kind))
        wheels = [p for p in parts if p.color_rgb == WHEEL_RGB]
        assert len(wheels) >= 2, kind
        assert all(p.hi[2] == 0.0 for p in wheels), kind  # on the ground
        assert all(hidden_faces(tuple(parts))[parts.index(p), 4] for p in wheels), kind
    person = parts_of(dataclasses.replace(_target("person"), color_rgb=(10, 200, 30)))
    assert {(190, 150, 120), (60, 45, 35), (10, 200, 30)} <= {p.color_rgb for p in person}
    assert len(person) == 7  # two legs, torso, two arms, head, hair


def _view(t: TargetSpec, cam: CameraSpec, back_m: float, up_m: float, yaw_deg: float,
          pitch_deg: float = 0.0) -> tuple[np.ndarray, World, object]:
    """Render ``t`` (at the origin) from ``back_m`` away along -``yaw_deg``."""
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (t,)))
    a = math.radians(yaw_deg)
    lat, lon = world.frame.place(-back_m * math.cos(a), -back_m * math.sin(a), GROUND_M)
    pose = camera_pose(cam, float(lat), float(lon), GROUND_M + up_m, 0.0, 0.0, yaw_deg,
                       ground_alt_m=GROUND_M)
    img, _ = render_frame(world, cam, pose, 0)
    return img, world, pose


def test_a_side_view_shows_dark_wheels_under_the_body_and_ground_between() -> None:
    """A truck broadside, 25 m away, the camera 1 m up: the pixel at the middle
    of each axle's side is the wheels' dark; halfway between the front and
    the middle axle, at the same height, the ground shows under the body."""
    t = _target("truck")
    cam = CameraSpec("c", (0,), "forward", 0.0, False, 40.0, 30.6, 640, 480, 10.0, 12)
    img, world, pose = _view(t, cam, 25.0, 1.0, 90.0)  # looking east at its left side
    origin = world.targets.origins_in(pose.local, pose.local_ecef_m)[0]  # type: ignore[attr-defined]
    L, W, H = t.length_m, t.width_m, t.height_m
    clear = 0.25 * H

    def pixel(x_m: float) -> np.ndarray:
        pt_l = to_local(t, origin, np.array([[x_m, -W / 2, -clear / 2]]))
        uv = project(world.view(cam).K, to_camera(pose, pt_l))[0]  # type: ignore[arg-type]
        return img[int(round(uv[1])), int(round(uv[0])), :3].astype(int)

    for x_m in (0.38 * L, -0.17 * L, -0.28 * L):
        assert pixel(x_m).max() < 50, (x_m, pixel(x_m))
    between = pixel(0.1 * L)
    assert between.max() > 70, between


def test_parts_under_others_are_painted_before_them() -> None:
    """Seen from ahead and above, 30 deg down, no pixel of a car or truck has
    the colour of an axle's top (it lies under the body): were it painted by
    its centre's depth it would cover the front of the body."""
    cam = CameraSpec("c", (0,), "gimbal", -30.0, False, 40.0, 30.6, 320, 240, 10.0, 12)
    top = np.array([min(255, int(c * lambert(np.array([0.0, 0.0, -1.0]))))
                    for c in WHEEL_RGB[::-1]])
    for kind in ("car", "fire_truck", "truck"):
        t = _target(kind, heading_deg=235.0)
        r = 2.2 * t.length_m
        img, _, _ = _view(t, cam, r * math.cos(math.radians(30)),
                          t.height_m / 2 + r * math.sin(math.radians(30)), 0.0)
        assert (img[..., :3] == WHEEL_RGB[::-1]).all(axis=-1).sum() == 0  # sanity: shaded
        wheels = (np.abs(img[..., :3].astype(int) - WHEEL_RGB[::-1]) < 25).all(axis=-1)
        assert wheels.sum() > 20, kind  # the wheels' sides are seen
        assert (img[..., :3] == top).all(axis=-1).sum() == 0, kind
