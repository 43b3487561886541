"""The sky: its colour follows each ray's elevation (whatever the camera's
attitude) and the sun, and hazy ground meets it without a seam."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.core.camera import camera_pose, intrinsics
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.sky import (
    E0_DEG,
    GLOW_RGB,
    HORIZON_RGB,
    ZENITH_RGB,
    Sky,
    brightness,
    horizon_rgb,
)
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.ground import GroundSpec
from cosim.world.sun import DEFAULT, SunSpec
from tests.renderer.test_haze import _cam

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0


def _ray(elev_deg: float, az_deg: float) -> np.ndarray:
    e, a = math.radians(elev_deg), math.radians(az_deg)
    return np.array([[math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), -math.sin(e)]])


def test_colour_against_elevation() -> None:
    """horizon + (zenith - horizon)(1 - exp(-e / E0)); below the horizon as on it."""
    sky = Sky(DEFAULT)
    hor, zen = np.array(HORIZON_RGB[::-1]), np.array(ZENITH_RGB[::-1])
    for e in (0.0, E0_DEG, 30.0, 89.0):
        want = hor + (zen - hor) * (1.0 - math.exp(-e / E0_DEG))
        np.testing.assert_allclose(sky.colours(_ray(e, 10.0))[0], want, atol=1e-3)
    np.testing.assert_allclose(sky.colours(_ray(-5.0, 10.0))[0], hor, atol=1e-3)


def test_sun_sets_brightness_and_glow() -> None:
    """Full brightness from 30 deg up, 0.6 + 0.4 sin(el)/sin(30) below; a low
    sun warms the sky toward it and not away from it; the default airlight
    is the horizon's colour under the sun."""
    assert brightness(DEFAULT) == 1.0
    low = SunSpec(azimuth_deg=90.0, elevation_deg=5.0)
    b = 0.6 + 0.4 * math.sin(math.radians(5.0)) / 0.5
    assert brightness(low) == pytest.approx(b)
    assert horizon_rgb(low) == tuple(round(c * b) for c in HORIZON_RGB)
    sky = Sky(low)
    toward, away = sky.colours(_ray(5.0, 90.0))[0], sky.colours(_ray(5.0, 270.0))[0]
    hor = np.array(HORIZON_RGB[::-1]) * b
    zen = np.array(ZENITH_RGB[::-1]) * b
    plain = hor + (zen - hor) * (1.0 - math.exp(-5.0 / E0_DEG))
    np.testing.assert_allclose(away, plain, atol=1e-3)  # cos < 0: no glow
    cos_g = float(_ray(5.0, 90.0)[0] @ low.to_sun_ned())
    w = 0.5 * (1.0 - 5.0 / 40.0) * cos_g ** 8
    np.testing.assert_allclose(toward, plain + (np.array(GLOW_RGB[::-1]) - plain) * w,
                               atol=1e-3)
    assert toward[2] > away[2] + 20  # redder toward the sun


@pytest.mark.parametrize("roll_deg", [0.0, 25.0])
def test_drawn_sky_follows_each_pixels_elevation(roll_deg: float) -> None:
    """A forward camera rolled or not: each sky pixel has the colour of its own
    ray's elevation (computed from the pixel's ray independently), within 3
    levels (the grid's interpolation, steepest along the horizon); the
    horizon is tilted with the roll."""
    cam = _cam("forward", 0.0, 320, 240, 70.0)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0,
                            GroundSpec(max_range_m=500.0), ()))
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 50.0, roll_deg, 8.0, 0.0, GROUND_M)
    img, _ = render_frame(world, cam, pose, 0)
    u, v = np.meshgrid(np.arange(320.0), np.arange(240.0))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(intrinsics(cam)).T
    rays_l = rays @ pose.R_cl
    up = -rays_l[..., 2] / np.linalg.norm(rays_l, axis=-1)
    sky = up > 0.01  # above the horizon: never ground
    want = Sky(DEFAULT).colours(rays_l[sky].reshape(-1, 3))
    err = np.abs(img[..., :3][sky].astype(float) - want)
    assert sky.sum() > 5000 and err.max() <= 3.0, float(err.max())


def test_hazy_ground_meets_the_sky_without_a_seam() -> None:
    """In thick haze the far ground takes the airlight's colour, which is the
    sky's at the horizon: the rows just above and below the horizon differ
    by at most 3 levels (a vertical gradient fixed to the image's rows
    differed by tens)."""
    cam = _cam("forward", -5.0, 320, 240, 70.0)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(max_range_m=5000.0),
                            (), atmosphere=AtmosphereSpec(0.4)))
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, GROUND_M)
    img, _ = render_frame(world, cam, pose, 0)
    # the horizon's row: a level camera pitched 5 deg down sees it 5 deg above the centre
    f = intrinsics(cam)[1, 1]
    y_h = intrinsics(cam)[1, 2] - f * math.tan(math.radians(5.0))
    above = img[int(y_h) - 1, :, :3].astype(float).mean(axis=0)
    below = img[int(y_h) + 2, :, :3].astype(float).mean(axis=0)
    assert np.abs(above - below).max() <= 3.0, (above, below)
