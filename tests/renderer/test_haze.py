"""Haze (the ``atmosphere:`` section): Koschmieder's law on rendered frames,
the ground's tiles against the exact per-pixel transmittance, the section's
checks, and the same frames in and out of render worker processes."""

from __future__ import annotations

import copy
import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose, ground_homography
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.haze import LEVELS
from cosim.scenario import parse_scenario
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.ground import GroundSpec
from cosim.world.targets import TargetSpec
from tests.renderer.test_renderer import _fly

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0
W = np.array([0.0722, 0.7152, 0.2126])  # Rec. 709 weights, BGR order


def _cam(mount: str, pitch: float, w: int = 320, h: int = 240, hfov: float = 60.0
         ) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec("c", (0,), mount, pitch, False, hfov, vfov, w, h, 10.0, 12)


def _lum(px: np.ndarray) -> float:
    """Mean relative luminance of BGR(A) pixels (gamma 2.2, as the ground truth)."""
    lin = (px[:, :3].astype(np.float64) / 255.0) ** 2.2
    return float((lin @ W).mean())


def test_apparent_contrast_falls_as_koschmieder() -> None:
    """A light square slab (1 m tall, 0.2 d a side) seen from straight above at
    distances d of 0.25 to 2 km through air of V = 5 km. Haze turns a colour L0 into
    L0 t + A (1 - t), so the target's luminance Y_t and the ground's around it
    Y_b (at about the same distance, hence the same t) become
    Y_t t + Y_A (1 - t) and Y_b t + Y_A (1 - t): their difference scales by
    exactly t = exp(-3.912 d / V), whatever the airlight (the Weber contrast
    (Y_t - Y_b) / Y_b does not: its denominator gains airlight too). So the
    hazy frame's difference over the clear frame's (same pose, same ground)
    must be t within 5 %; with d the slab's top's distance (the ring of
    ground lies 1 m lower and a little off the axis: under 1 % in t)."""
    v_km = 5.0
    cam = _cam("nadir", -90.0, 320, 240, 40.0)
    ratios = []
    for d_m in (250.0, 500.0, 1000.0, 2000.0):
        slab = TargetSpec(id="slab", kind="truck", north_m=0.0, east_m=0.0, lat_deg=None,
                          lon_deg=None, heading_deg=0.0, length_m=0.2 * d_m,
                          width_m=0.2 * d_m, height_m=1.0, color_rgb=(230, 230, 230))
        pose = camera_pose(cam, LAT0, LON0, GROUND_M + d_m + 1.0, 0.0, 0.0, 0.0, GROUND_M)
        diffs = []
        for air in (None, AtmosphereSpec(v_km)):
            world = World(WorldSpec(LAT0, LON0, GROUND_M, 4, 120.0, GroundSpec(), (slab,),
                                    atmosphere=air))
            img, rows = render_frame(world, cam, pose, 0)
            r = rows[0]
            x0, y0 = math.ceil(r["bbox_x0_px"]) + 2, math.ceil(r["bbox_y0_px"]) + 2
            x1, y1 = math.floor(r["bbox_x1_px"]) - 2, math.floor(r["bbox_y1_px"]) - 2
            assert x1 - x0 >= 8 and y1 - y0 >= 8  # enough of the slab to average
            inner = img[y0:y1, x0:x1].reshape(-1, 4)
            ring = np.zeros(img.shape[:2], bool)  # ground 6 to 30 px outside the slab
            ring[y0 - 32:y1 + 32, x0 - 32:x1 + 32] = True
            ring[y0 - 8:y1 + 8, x0 - 8:x1 + 8] = False
            diffs.append(_lum(inner) - _lum(img[ring]))
        t = math.exp(-3.912 * d_m / (1000.0 * v_km))
        ratios.append(diffs[1] / diffs[0] / t)
        assert diffs[1] / diffs[0] == pytest.approx(t, rel=0.05), (d_m, diffs, t)
    assert max(ratios) - min(ratios) < 0.05, ratios


def _exact_t(view_K_inv: np.ndarray, pose: object, max_r: float, w: int, h_px: int,
             v_km: float) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's own exp(-3.912 d / V) (d: camera to where its ray meets the
    ground plane, from the textbook ray-plane intersection; a ray meeting it
    beyond the ground's range counts at that range) and where it meets it."""
    u, v = np.meshgrid(np.arange(float(w)), np.arange(float(h_px)))
    rays_c = np.stack([u, v, np.ones_like(u)], axis=-1) @ view_K_inv.T
    rays_l = rays_c @ pose.R_cl  # type: ignore[attr-defined]  # camera -> L
    down = rays_l[..., 2]
    ground = down > 1e-9
    h = pose.height_m  # type: ignore[attr-defined]
    with np.errstate(divide="ignore", invalid="ignore"):
        horiz = h * np.hypot(rays_l[..., 0], rays_l[..., 1]) / down
    horiz = np.where(ground & (horiz <= max_r), horiz, max_r)
    return np.exp(-3.912 * np.hypot(horiz, h) / (1000.0 * v_km)), ground


def _drawn_t(haze: object, img_shape: tuple[int, int], H: np.ndarray, pose: object,
             max_r: float, bands: list[tuple[int, int]]) -> np.ndarray:
    """The transmittance step Haze.ground gives each pixel, read back: with
    tables that turn every value into their step's number, a frame hazed
    holds each pixel's step (its middle returned as t)."""
    h_px, w = img_shape
    probe = copy.copy(haze)
    probe.tables3 = np.repeat(np.arange(LEVELS, dtype=np.uint8)[:, None, None],  # type: ignore[attr-defined]
                              256 * 4, axis=1).reshape(LEVELS, 256, 4)
    img = np.zeros((h_px, w, 4), np.uint8)
    probe.ground(img, H, pose, max_r, bands)  # type: ignore[attr-defined]
    out: np.ndarray = (img[..., 0].astype(float) + 0.5) / LEVELS
    return out


@pytest.mark.parametrize("mount,pitch,alt_m,hfov", [
    ("nadir", -90.0, 100.0, 60.0), ("gimbal", -20.0, 100.0, 60.0),
    ("forward", 0.0, 300.0, 90.0), ("gimbal", -45.0, 1500.0, 30.0)])
def test_every_ground_pixel_has_its_own_transmittance(mount: str, pitch: float, alt_m: float,
                                                      hfov: float) -> None:
    """Every ground pixel is hazed with a t within 0.007 of its own ray's
    exp(-3.912 d / V) (half a step of 1/128 and the interpolation's error), for
    V = 2 km, and neighbouring pixels are at most two steps apart: no edge of a
    tile to see (tiles of 4 x 32 pixels of one transmittance each were up to
    0.027 off and five steps apart in the oblique view)."""
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (),
                            atmosphere=AtmosphereSpec(2.0)))
    assert world.haze is not None
    cam = _cam(mount, pitch, 320, 240, hfov)
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + alt_m, 2.0, 3.0, 30.0, GROUND_M)
    view = world.view(cam)
    H = ground_homography(view.K_inv, pose)
    max_r = world.spec.ground.max_range_m
    want, ground = _exact_t(view.K_inv, pose, max_r, 320, 240, 2.0)
    got = _drawn_t(world.haze, (240, 320), H, pose, max_r, [(0, 240)])
    err = np.abs(got - want)[ground]
    assert ground.any() and err.max() < 0.007, float(err.max())
    steps = max(float(np.abs(np.diff(got, axis=a)).max()) for a in (0, 1))
    assert steps * LEVELS <= 2.0 + 1e-9, steps * LEVELS


@pytest.mark.parametrize("masked", [False, True])
def test_the_ground_haze_keeps_to_its_bands_and_mask(masked: bool) -> None:
    """Only the rows of the bands change, and with a mask only the pixels it
    marks; alpha never. An oblique view whose bands stop short of the image."""
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (),
                            atmosphere=AtmosphereSpec(2.0)))
    haze = world.haze
    assert haze is not None
    cam = _cam("gimbal", -20.0, 320, 240, 60.0)
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 300.0, 2.0, 3.0, 30.0, GROUND_M)
    H = ground_homography(world.view(cam).K_inv, pose)
    max_r = world.spec.ground.max_range_m
    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (240, 320, 4), dtype=np.uint8)
    bands = [(10, 101), (130, 238)]
    mask = (rng.random((240, 320)) < 0.7).astype(np.uint8) * 255 if masked else None
    got = img.copy()
    haze.ground(got, H, pose, max_r, bands, mask)
    changed = (got != img).any(axis=2)
    in_bands = np.zeros(240, bool)
    for y0, y1 in bands:
        in_bands[y0:y1] = True
    assert changed[in_bands].mean() > 0.5 * (0.7 if masked else 1.0)
    assert not changed[~in_bands].any()
    if mask is not None:
        assert not changed[mask == 0].any()
    assert np.array_equal(got[..., 3], img[..., 3])


SCENARIO = """\
schema_version: 1
origin: {{lat_deg: 37, lon_deg: -122}}
rates: {{physics_hz: 120, control_hz: 30}}
duration_s: 2
vehicles:
  - {{id: u1, model: uav700, init: {{north_m: 0, east_m: 0, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}}}
atmosphere:
{body}"""


@pytest.mark.parametrize("body,problem", [
    ("  visibility_km: 0.04\n", r":9: atmosphere.visibility_km: must be >= 0.05, got 0.04"),
    ("  visibility_km: 1001\n", r":9: atmosphere.visibility_km: must be <= 1000, got 1001"),
    ("  visibility_km: far\n", r":9: atmosphere.visibility_km: expected a number, got"),
    ("  visibility_km: .nan\n", r":9: atmosphere.visibility_km: expected a number, got"),
    ("  visibility_km: 5\n  color: grey\n", r":10: atmosphere.color: expected a colour"),
    ("  visibility_km: 5\n  color: [1, 2, 300]\n", r":10: atmosphere.color: expected a colour"),
    ("  visibility_km: 5\n  fog: true\n",
     r":10: atmosphere.fog: unknown key 'fog'; expected one of: visibility_km, color"),
    ("  color: '#ffffff'\n", r":8: atmosphere: missing required key 'visibility_km'"),
    ("  - 5\n", r":8: atmosphere: expected a mapping, got a list"),
])
def test_the_section_refuses_bad_values_with_file_and_line(tmp_path: Path, body: str,
                                                           problem: str) -> None:
    f = str(tmp_path / "air.yaml")
    with pytest.raises(ConfigError, match=f"{f}{problem}"):
        parse_scenario(SCENARIO.format(body=body), f, check_properties=False)


def test_the_section_reaches_the_world(tmp_path: Path) -> None:
    f = str(tmp_path / "air.yaml")
    body = "  visibility_km: 2.5\n  color: [200, 210, 220]\n"
    scn = parse_scenario(SCENARIO.format(body=body), f, check_properties=False)
    assert scn.world.atmosphere == AtmosphereSpec(2.5, (200, 210, 220))
    assert scn.world.atmosphere.transmittance(2500.0) == pytest.approx(math.exp(-3.912))
    text = SCENARIO.format(body="").replace("atmosphere:\n", "")
    assert parse_scenario(text, f, check_properties=False).world.atmosphere is None


@pytest.mark.integration
def test_hazy_frames_are_the_same_inline_and_in_worker_processes(tmp_path: Path) -> None:
    more = textwrap.dedent("""\
        atmosphere: {visibility_km: 1.5}
        """)
    digests = []
    for n in (0, 1):
        summary, _ = _fly(tmp_path, f"w{n}", workers=n, rate=10.0, dur=1.0, more=more)
        digests.append([s["frames_sha256"] for s in summary["streams"]])
    clear, _ = _fly(tmp_path, "clear", workers=0, rate=10.0, dur=1.0)
    assert digests[0] == digests[1]
    assert digests[0] != [s["frames_sha256"] for s in clear["streams"]]
