"""Target shadows (cosim.renderer.shadows): a target whose shadow cannot reach
the view is skipped, and skipping changes no pixel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, Pose, camera_pose, intrinsics
from cosim.renderer import shadows
from cosim.renderer.shadows import draw_shadows, shade_table
from cosim.world.targets import TARGET_DEFAULTS, TargetSpec


def _scene(elevation_deg: float) -> tuple[CameraSpec, Pose, np.ndarray, np.ndarray]:
    cam = CameraSpec("c", (0,), "nadir", -90.0, False, 60.0, 46.8, 320, 240, 10.0, 12)
    pose = camera_pose(cam, 37.0, -122.0, 110.0, 0.0, 0.0, 0.0, 10.0)  # 100 m up
    e, a = math.radians(elevation_deg), math.radians(120.0)
    sun_l = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), -math.sin(e)])
    return cam, pose, sun_l, shade_table(elevation_deg)


def _trucks(n: int, seed: int) -> tuple[list[TargetSpec], np.ndarray]:
    """``n`` trucks round the edge of the view (58 m east and west, 43 m north and
    south of the nadir point at 100 m), some in it, some out, their shadows
    reaching in or not."""
    length, width, height, colour = TARGET_DEFAULTS["truck"]
    rng = np.random.default_rng(seed)
    specs = [TargetSpec(f"t{k}", "truck", 0.0, 0.0, None, None, float(rng.uniform(0, 360)),
                        length, width, height, colour) for k in range(n)]
    ang = rng.uniform(0, 2 * math.pi, n)
    rad = rng.uniform(0.8, 1.6, n)
    origins = np.column_stack([43 * rad * np.cos(ang), 58 * rad * np.sin(ang), np.zeros(n)])
    return specs, origins


@pytest.mark.parametrize("elevation_deg", [15.0, 40.0, 75.0])
def test_skipping_shadows_out_of_view_changes_no_pixel(elevation_deg: float,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    cam, pose, sun_l, table = _scene(elevation_deg)
    K = intrinsics(cam)
    specs, origins = _trucks(60, 1)
    base = np.full((240, 320, 4), 200, np.uint8)
    culled = base.copy()
    draw_shadows(K, pose, specs, origins, sun_l, 0.0, 1, culled, table)
    skipped = sum(not shadows.may_reach_view(t, origins[k], sun_l, K, pose, 320, 240)
                  for k, t in enumerate(specs))
    monkeypatch.setattr(shadows, "may_reach_view", lambda *a: True)
    whole = base.copy()
    draw_shadows(K, pose, specs, origins, sun_l, 0.0, 1, whole, table)
    assert np.array_equal(culled, whole)
    assert 5 < skipped < 55, skipped  # some skipped, some drawn
    assert (whole != base).any()


def test_a_target_far_out_of_view_costs_no_shadow(monkeypatch: pytest.MonkeyPatch) -> None:
    """hulls_on_ground (about 0.25 ms a target) runs for the target in view only."""
    cam, pose, sun_l, table = _scene(40.0)
    length, width, height, colour = TARGET_DEFAULTS["truck"]
    truck = TargetSpec("t", "truck", 0.0, 0.0, None, None, 30.0, length, width, height, colour)
    origins = np.array([[0.0, 0.0, 0.0], [500.0, 300.0, 0.0]])
    made = []
    hulls = shadows.hulls_on_ground

    def counted(t: TargetSpec, o: np.ndarray, *a: object) -> list[np.ndarray]:
        made.append(tuple(o))
        return hulls(t, o, *a)  # type: ignore[arg-type]

    monkeypatch.setattr(shadows, "hulls_on_ground", counted)
    img = np.full((240, 320, 4), 200, np.uint8)
    draw_shadows(intrinsics(cam), pose, [truck, truck], origins, sun_l, 0.0, 1, img, table)
    assert made == [(0.0, 0.0, 0.0)]
