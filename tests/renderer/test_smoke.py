"""A fire's smoke: lit by the sun as a Lambertian sphere, and casting its
puffs' shadows on the ground where the sun's geometry puts them."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose, fixed, intrinsics, project
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.smoke import lit_sphere, shadow_outlines
from cosim.renderer.targets import smoke_puffs, to_local
from cosim.world.ground import GroundSpec
from cosim.world.sun import SunSpec
from cosim.world.targets import TargetSpec

FIRE = TargetSpec("f", "fire", 0.0, 0.0, None, None, 0.0, 6.0, 6.0, 3.0, (230, 90, 20))


@pytest.mark.parametrize("phase_deg", [0.0, 40.0, 90.0, 135.0, 180.0])
def test_lit_sphere_is_the_mean_lambert_light_over_the_visible_disc(phase_deg: float) -> None:
    """Against a direct average of max(0, n . s) over a 2000 x 2000 grid of the
    sphere's disc seen along z (n the surface normal there)."""
    a = math.radians(phase_deg)
    x, y = np.meshgrid(np.linspace(-1, 1, 2000), np.linspace(-1, 1, 2000))
    inside = x * x + y * y < 1.0
    nz = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, 1.0))
    light = np.maximum(x * math.sin(a) + nz * math.cos(a), 0.0)
    assert lit_sphere(a) == pytest.approx(float(light[inside].mean()), abs=2e-3)


def test_a_puffs_shadow_is_the_spheres() -> None:
    """Each outline is an ellipse centred hc / tan(elevation) from the puff's
    foot away from the sun, r across and r / sin(elevation) along."""
    az, el = 120.0, 35.0
    sun = SunSpec(az, el).to_sun_ned()
    origin = np.array([5.0, -3.0, 0.0])
    puffs = smoke_puffs(FIRE, 4.0, 7)
    outlines = shadow_outlines(FIRE, origin, sun, 4.0, 7)
    assert len(outlines) == len(puffs) > 3
    away = np.array([math.cos(math.radians(az + 180)), math.sin(math.radians(az + 180))])
    for (poly, alpha), (centre_t, r, a) in zip(outlines, puffs):
        c_l = to_local(FIRE, origin, centre_t[None, :])[0]
        hc = -c_l[2]
        want = c_l[:2] + hc / math.tan(math.radians(el)) * away
        np.testing.assert_allclose(poly[:, :2].mean(axis=0), want, atol=1e-9)
        d = poly[:, :2] - want
        along, across = d @ away, d @ np.array([-away[1], away[0]])
        assert np.abs(along).max() == pytest.approx(r / math.sin(math.radians(el)))
        assert np.abs(across).max() == pytest.approx(r, rel=1e-2)
        assert alpha == a and (poly[:, 2] == 0.0).all()


def test_the_drawn_smoke_shadow_covers_its_outlines_and_nothing_else() -> None:
    """Nadir, 120 m up, sun at 40 deg: the ground darkened by the shadows
    (frames with shadows on and off) lies within the puffs' projected
    outlines (1 px margin) and covers the inside (2 px in) of every puff's
    outline at least 0.2 opaque, except where the flames stand."""
    cam = CameraSpec("c", (0,), "gimbal", -90.0, False, 60.0, 46.8, 400, 300, 10.0, 12)
    pose = camera_pose(cam, 47.0, 8.0, 520.0, 0.0, 0.0, 0.0, ground_alt_m=400.0)
    frames = []
    for shadows in (False, True):
        ws = WorldSpec(47.0, 8.0, 400.0, 3, 120.0, GroundSpec(), (FIRE,), (),
                       SunSpec(250.0, 40.0, "", shadows))
        world = World(ws)
        frames.append(render_frame(world, cam, pose, 600)[0][..., :3].astype(int))
    flames = world.last_ids(300, 400) != 0
    darker = (frames[1] < frames[0]).any(axis=2)
    assert not (frames[1] > frames[0]).any()
    origin = world.targets.origins_in(pose.local, pose.local_ecef_m)[0]
    outline = np.zeros(darker.shape, np.uint8)
    strong = np.zeros(darker.shape, np.uint8)
    K = intrinsics(cam)
    for poly, alpha in shadow_outlines(FIRE, origin, world.sun_l, 600 / 120.0, 3):
        uv = fixed(project(K, (poly - pose.c_l) @ pose.R_cl.T))
        cv2.fillConvexPoly(outline, uv, 1, cv2.LINE_8, 4)
        if alpha >= 0.2:
            cv2.fillConvexPoly(strong, uv, 1, cv2.LINE_8, 4)
    grown = cv2.dilate(outline, np.ones((3, 3), np.uint8)).astype(bool)
    core = cv2.erode(strong, np.ones((5, 5), np.uint8)).astype(bool) & ~flames
    assert darker.sum() > 200 and core.sum() > 200
    assert not (darker & ~grown).any()
    assert darker[core].mean() > 0.99
