"""Renderer: projection against an independent pinhole model, a level pass's
time in view, determinism across render workers, video read-back, config errors."""

from __future__ import annotations

import csv
import math
import textwrap
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from cosim.conspicuity.visibility import passes, read_ground_truth
from cosim.core.camera import CameraSpec, camera_pose, footprint
from cosim.core.geo import LocalFrame
from cosim.core.state import N_STATE, STATE_INDEX
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.renderer import video
from cosim.renderer.frame import OBSTACLE_RGB, World, WorldSpec, render_frame
from cosim.renderer.ground import GroundTexture
from cosim.renderer.participant import CameraParticipant
from cosim.renderer.targets import lambert
from cosim.renderer.video import have_pyav
from cosim.scenario import parse_scenario
from cosim.sync.participants import RunContext
from cosim.world.ground import GroundSpec
from cosim.world.obstacles import Obstacle
from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0


def _cam(mount: str, pitch: float, w: int = 320, h: int = 240, hfov: float = 60.0,
         yaw: float = 0.0) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec("c", (0,), mount, pitch, False, hfov, vfov, w, h, 10.0, 12, yaw_deg=yaw)


def _analytic_uv(cam: CameraSpec, pts_ned: np.ndarray, cam_ned: np.ndarray, roll: float,
                 pitch: float, yaw: float) -> np.ndarray:
    """Pixel of NED points: the textbook 3-2-1 direction cosine matrix, camera
    axes written out for the mount, u = cx + f x/z."""
    ph, th, ps = (math.radians(a) for a in (roll, pitch, yaw))
    cph, sph, cth, sth, cps, sps = (math.cos(ph), math.sin(ph), math.cos(th), math.sin(th),
                                    math.cos(ps), math.sin(ps))
    # rows: body x, y, z axes expressed in NED
    bx = np.array([cth * cps, cth * sps, -sth])
    by = np.array([sph * sth * cps - cph * sps, sph * sth * sps + cph * cps, sph * cth])
    bz = np.array([cph * sth * cps + sph * sps, cph * sth * sps - sph * cps, cph * cth])
    # gimbal: turned by yaw gy about the body's down axis, then its nose pitched by g
    gy = math.radians(cam.yaw_deg)
    fwd, right = math.cos(gy) * bx + math.sin(gy) * by, -math.sin(gy) * bx + math.cos(gy) * by
    g = math.radians(cam.pitch_deg)
    axis = math.cos(g) * fwd - math.sin(g) * bz
    down_img = math.sin(g) * fwd + math.cos(g) * bz  # image "down" direction
    f = cam.width_px / 2 / math.tan(math.radians(cam.hfov_deg) / 2)
    d = pts_ned - cam_ned
    x, y, z = d @ right, d @ down_img, d @ axis
    return np.stack([(cam.width_px - 1) / 2 + f * x / z, (cam.height_px - 1) / 2 + f * y / z],
                    axis=1)


def _target(kind: str, n: float, e: float, heading: float = 0.0, tid: str = "t") -> TargetSpec:
    L, W, H, c = TARGET_DEFAULTS[kind]
    return TargetSpec(tid, kind, n, e, None, None, heading, L, W, H, c)


@pytest.mark.parametrize("mount,pitch,att,offset_ne,yaw", [
    ("nadir", -90.0, (4.0, -3.0, 30.0), (12.0, -7.0), 0.0),
    ("forward", 0.0, (3.0, -20.0, 10.0), (120.0, 30.0), 0.0),
    ("gimbal", -45.0, (-6.0, 2.0, -40.0), (70.0, -40.0), 0.0),
    ("gimbal", -50.0, (5.0, -4.0, 20.0), (45.0, 65.0), 70.0),
    ("gimbal", -90.0, (2.0, 3.0, 0.0), (20.0, 5.0), -90.0),
])
def test_projected_corners_match_an_analytic_pinhole(mount: str, pitch: float,
                                                      att: tuple[float, float, float],
                                                      offset_ne: tuple[float, float],
                                                      yaw: float) -> None:
    t = _target("truck", *offset_ne, heading=25.0)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (t,)))
    cam = _cam(mount, pitch, yaw=yaw)
    alt_agl = 100.0
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + alt_agl, *att, ground_alt_m=GROUND_M)
    _, rows = render_frame(world, cam, pose, 0)
    # the target's corners in the frame anchored under the camera (= scenario frame here)
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    la, lo = frame.place(*offset_ne, GROUND_M)
    base = np.array(frame.geodetic_to_ned(la, lo, GROUND_M), dtype=float)
    a = math.radians(t.heading_deg)
    fwd, rgt = np.array([math.cos(a), math.sin(a), 0]), np.array([-math.sin(a), math.cos(a), 0])
    corners = np.array([base + sx * t.length_m / 2 * fwd + sy * t.width_m / 2 * rgt
                        - np.array([0, 0, hz]) for sx in (-1, 1) for sy in (-1, 1)
                        for hz in (0.0, t.height_m)])
    uv = _analytic_uv(cam, corners, np.array([0.0, 0.0, -alt_agl]), *att)
    r = rows[0]
    assert r["in_view"] == 1 and r["fully_in_view"] == 1
    got = [r["bbox_x0_px"], r["bbox_y0_px"], r["bbox_x1_px"], r["bbox_y1_px"]]
    want = [uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()]
    assert np.allclose(got, want, atol=0.5), (got, want)
    assert r["pixels_on_target"] > 0


@pytest.mark.parametrize("mount,pitch,att,cam_ne,offset_ne", [
    ("nadir", -90.0, (4.0, -3.0, 30.0), (14000.0, 14000.0), (12.0, -7.0)),
    ("gimbal", -45.0, (-6.0, 2.0, -40.0), (-25000.0, 9000.0), (70.0, -40.0)),
])
def test_projection_far_from_the_origin_matches_an_independent_pinhole(
        mount: str, pitch: float, att: tuple[float, float, float],
        cam_ne: tuple[float, float], offset_ne: tuple[float, float]) -> None:
    """A camera 20-27 km from the scenario origin, where the scenario's tangent
    plane is 30-60 m above the ground: corners built on the ellipsoid at the
    target (its own local level frame) and seen from the camera's local level
    frame, both through exact WGS-84; the renderer must agree within 0.5 px."""
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    n_t, e_t = cam_ne[0] + offset_ne[0], cam_ne[1] + offset_ne[1]
    t = _target("truck", n_t, e_t, heading=25.0)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (t,)))
    cam = _cam(mount, pitch)
    alt_agl = 100.0
    la_c, lo_c = frame.place(*cam_ne, GROUND_M + alt_agl)
    pose = camera_pose(cam, float(la_c), float(lo_c), GROUND_M + alt_agl, *att,
                       ground_alt_m=GROUND_M)
    _, rows = render_frame(world, cam, pose, 0)
    la_t, lo_t = frame.place(n_t, e_t, GROUND_M)
    at_target = LocalFrame(float(la_t), float(lo_t), GROUND_M)
    a = math.radians(t.heading_deg)
    fwd, rgt = np.array([math.cos(a), math.sin(a), 0]), np.array([-math.sin(a), math.cos(a), 0])
    local = np.array([sx * t.length_m / 2 * fwd + sy * t.width_m / 2 * rgt
                      - np.array([0, 0, hz]) for sx in (-1, 1) for sy in (-1, 1)
                      for hz in (0.0, t.height_m)])
    geo = at_target.ned_to_geodetic(local[:, 0], local[:, 1], local[:, 2])
    at_camera = LocalFrame(float(la_c), float(lo_c), GROUND_M + alt_agl)
    corners = np.stack(at_camera.geodetic_to_ned(*geo), axis=1)
    uv = _analytic_uv(cam, corners, np.zeros(3), *att)
    r = rows[0]
    assert r["in_view"] == 1 and r["fully_in_view"] == 1
    got = [r["bbox_x0_px"], r["bbox_y0_px"], r["bbox_x1_px"], r["bbox_y1_px"]]
    want = [uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()]
    assert np.allclose(got, want, atol=0.5), (got, want)


# --- runs through the participant, with synthetic straight and level poses -------------

SCENARIO = """\
schema_version: 1
origin: {{lat_deg: {lat}, lon_deg: {lon}, ground_alt_m: {g}}}
rates: {{physics_hz: 120, control_hz: 30}}
duration_s: {dur}
seed: 3
vehicles:
  - id: u1
    model: uav700
    init: {{north_m: 0, east_m: 0, alt_agl_m: 100, heading_deg: 0, airspeed_kt: 100}}
targets:
  - {{id: truck1, kind: truck, north_m: 0, east_m: 0}}
  - {{id: fire1, kind: fire, north_m: 40, east_m: 30}}
cameras:
  render_workers: {workers}
  digest: true
  codec: {codec}
  operator_view: {op}
  views:
    - {{name: belly, vehicles: u1, mount: nadir, vfov_deg: 40, width_px: {w}, height_px: {h},
       rate_hz: {rate}}}
{more}"""
MORE_VIEWS = """\
    - {name: fwd, vehicles: u1, mount: forward, hfov_deg: 60, width_px: 96, height_px: 64,
       rate_hz: 10}
    - {name: tilt, vehicles: u1, mount: {pitch_deg: -45}, hfov_deg: 50, width_px: 96,
       height_px: 64, rate_hz: 10}
"""


def _fly(tmp_path: Path, name: str, *, workers: int = 0, rate: float = 30.0, dur: float = 4.0,
         w: int = 160, h: int = 120, alt_agl_m: float = 100.0, v_mps: float = 51.4,
         codec: str = "mp4v", op: bool = False, more: str = "") -> tuple[dict[str, Any], Path]:
    """Fly u1 north at v_mps and alt_agl_m, passing over the truck at mid-run."""
    text = SCENARIO.format(lat=LAT0, lon=LON0, g=GROUND_M, dur=dur, workers=workers, w=w, h=h,
                           rate=rate, codec=codec, op=str(op).lower(), more=more)
    scn = parse_scenario(text, str(tmp_path / f"{name}.yaml"), check_properties=False)
    out = tmp_path / name
    out.mkdir()
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    part = CameraParticipant(scn)
    ctx = RunContext(scn, out, ["u1"], frame, np.zeros((1, 3)), 120.0, 4, None, None, 1)
    part.start(ctx)
    states = np.zeros((1, N_STATE))
    for tick in range(0, scn.total_ticks, 4):
        north = -v_mps * dur / 2 + v_mps * tick / 120.0
        la, lo = frame.place(north, 0.0, GROUND_M + alt_agl_m)
        states[0, STATE_INDEX["lat_deg"]], states[0, STATE_INDEX["lon_deg"]] = la, lo
        states[0, STATE_INDEX["alt_msl_m"]] = GROUND_M + alt_agl_m
        states[0, STATE_INDEX["vn_mps"]] = v_mps
        part.on_exchange(tick, states)
    summary = part.finish(scn.total_ticks, "completed")
    assert summary is not None
    return summary, out


def _rows(out: Path, target: str) -> list[dict[str, str]]:
    with open(out / "cameras/u1_belly.gt.csv") as f:
        return [r for r in csv.DictReader(f) if r["target"] == target]


def test_level_pass_time_in_view_matches_the_field_of_view(tmp_path: Path) -> None:
    h, v, rate = 100.0, 51.4, 30.0
    summary, out = _fly(tmp_path, "pass", rate=rate, alt_agl_m=h, v_mps=v, dur=6.0)
    rows = _rows(out, "truck1")
    assert len(rows) == summary["streams"][0]["frames"] == 180
    seen = sum(int(r["in_view"]) for r in rows) / rate
    want = (2 * h * math.tan(math.radians(40.0) / 2) + 10.0) / v  # truck 10 m long
    assert abs(seen - want) <= 1 / rate, (seen, want)
    full = [r for r in rows if r["fully_in_view"] == "1"]
    assert full and all(float(r["contrast"]) != 0 for r in full)
    mid = min(rows, key=lambda r: float(r["eccentricity_px"] or 1e9))
    assert float(mid["range_m"]) == pytest.approx(h - 3.5 / 2, abs=0.5)


def test_contrast_is_the_weber_contrast_of_relative_luminance() -> None:
    """pixels_on_target and contrast (truth module docstring) against the definition
    written out: target pixels vs a ring around the box (the box grown by half its
    size, at least 4 px) without the box and without other targets' pixels; Y from
    linearised sRGB (gamma 2.2) with Rec. 709 weights."""
    from cosim.renderer.truth import _pixels

    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (120, 160, 4), np.uint8)
    img[..., 3] = 255
    ids = np.zeros((120, 160), np.uint16)
    ids[40:60, 50:90] = 1  # the target (its box)
    ids[44:50, 60:66] = 0  # a hole: ground seen through it is not target
    ids[30:38, 95:110] = 2  # another target inside the ring: excluded from it
    row: dict[str, Any] = {}
    _pixels(row, img, ids, 1, 50.0, 40.0, 89.0, 59.0)

    def lum(px: np.ndarray) -> np.ndarray:
        lin = (px[:, :3].astype(np.float64) / 255.0) ** 2.2
        out: np.ndarray = lin @ np.array([0.0722, 0.7152, 0.2126])
        return out

    target = ids == 1
    box = np.zeros_like(target)
    box[40:60, 50:90] = True  # the pixels floor(x0)..ceil(x1), floor(y0)..ceil(y1)
    m = max(4, int(0.5 * 40))
    ring = np.zeros_like(target)
    ring[40 - m:60 + m, 50 - m:90 + m] = True
    ring &= ~box & (ids == 0)
    y_t, y_b = lum(img[target]).mean(), lum(img[ring]).mean()
    assert row["pixels_on_target"] == int(target.sum()) == 20 * 40 - 36
    assert row["contrast"] == pytest.approx((y_t - y_b) / y_b, rel=1e-5, abs=1e-6)
    img[target] = (40, 40, 40, 255)  # a dark target on the same ground: negative
    _pixels(row, img, ids, 1, 50.0, 40.0, 89.0, 59.0)
    assert row["contrast"] == pytest.approx(((40 / 255) ** 2.2 - y_b) / y_b, rel=1e-5)
    assert row["contrast"] < 0


@pytest.mark.integration
def test_frames_identical_whatever_the_render_worker_count(tmp_path: Path) -> None:
    # three streams (nadir, forward, a -45 deg gimbal), so 2 and 3 workers really
    # split them (a worker count is capped at the number of streams)
    digests = []
    for n in (0, 1, 2, 3):
        summary, out = _fly(tmp_path, f"w{n}", workers=n, rate=10.0, dur=1.5, op=n == 3,
                            more=MORE_VIEWS)
        assert [s["camera"] for s in summary["streams"]] == ["belly", "fwd", "tilt"]
        digests.append([s["frames_sha256"] for s in summary["streams"]])
    assert digests[0] == digests[1] == digests[2] == digests[3]
    assert len(set(digests[0])) == 3  # three different views
    cap = cv2.VideoCapture(str(out / "cameras/u1_belly.mp4"))
    n_read = 0
    while True:
        ok, img = cap.read()
        if not ok:
            break
        assert img.shape == (120, 160, 3)
        n_read += 1
    assert n_read == 15 == summary["streams"][0]["frames"]
    assert summary["operator"]["frames"] == 15


def test_mjpg_video_reads_back(tmp_path: Path) -> None:
    summary, out = _fly(tmp_path, "mj", codec="mjpg", rate=10.0, dur=1.0)
    cap = cv2.VideoCapture(str(out / summary["streams"][0]["video"]))
    assert summary["streams"][0]["video"].endswith(".avi")
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 10
    assert (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))) \
        == (160, 120)


def test_ground_tiles_from_the_disk_cache_are_the_generated_ones(
        ground_cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    keys = [(0, 3, -2), (2, -1, 0), (4, 0, 0)]
    cold = GroundTexture(GroundSpec(), frame, 5)
    made = [cold.tile(*k) for k in keys]
    assert (cold.tiles_made, cold.tiles_loaded) == (3, 0)
    files = sorted(ground_cache.rglob("*.bgr"))
    assert len(files) == 3
    files[0].write_bytes(files[0].read_bytes()[:1000])  # a partial file is not used
    warm = GroundTexture(GroundSpec(), frame, 5)
    assert all(np.array_equal(a, warm.tile(*k)) for a, k in zip(made, keys))
    assert (warm.tiles_made, warm.tiles_loaded) == (1, 2)
    assert files[0].stat().st_size == 256 * 256 * 3  # written anew
    other_seed = GroundTexture(GroundSpec(), frame, 6)
    assert not np.array_equal(made[1], other_seed.tile(*keys[1]))
    assert other_seed.tiles_loaded == 0
    monkeypatch.setenv("COSIM_GROUND_CACHE", "off")
    off = GroundTexture(GroundSpec(), frame, 5)
    assert all(np.array_equal(a, off.tile(*k)) for a, k in zip(made, keys))
    assert off.tiles_loaded == 0 and len(list(ground_cache.rglob("*.bgr"))) == 4


def _decoded(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            return frames
        frames.append(img)


@pytest.mark.skipif(not have_pyav(), reason="PyAV not installed")
def test_pyav_and_opencv_mp4v_and_h264_read_back_alike(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """mp4v through PyAV and through the OpenCV fallback, and h264: the right frame
    count and size, and the same picture (the YUV planes' range and order are right)."""
    s_av, out_av = _fly(tmp_path, "av", rate=10.0, dur=1.0)
    s_264, out_264 = _fly(tmp_path, "x264", rate=10.0, dur=1.0, codec="h264")
    monkeypatch.setattr(video, "have_pyav", lambda: False)
    s_cv, out_cv = _fly(tmp_path, "cv", rate=10.0, dur=1.0)
    assert s_264["streams"][0]["video"].endswith(".mp4")
    assert s_av["streams"][0]["frames_sha256"] == s_cv["streams"][0]["frames_sha256"]
    ref = _decoded(out_cv / s_cv["streams"][0]["video"])
    for out, s in ((out_av, s_av), (out_264, s_264)):
        got = _decoded(out / s["streams"][0]["video"])
        assert len(got) == len(ref) == 10
        assert all(g.shape == (120, 160, 3) for g in got)
        assert min(cv2.PSNR(g, r) for g, r in zip(got, ref)) > 28.0


@pytest.mark.skipif(not have_pyav(), reason="PyAV not installed")
@pytest.mark.parametrize("codec,wrap", [("mp4v", True), ("h264", True), ("mp4v", False)])
def test_each_encoded_frame_is_its_own_picture(tmp_path: Path, codec: str, wrap: bool) -> None:
    """The writer reuses one YUV buffer for every frame: each decoded frame must
    match the picture written at its place, not a later one written into the
    same buffer (an encoder holding on to its input past encode() would); also
    through the copy into PyAV's own planes (``wrap`` off, older PyAV)."""
    rng = np.random.default_rng(3)
    base = cv2.GaussianBlur(rng.integers(0, 256, (96, 128, 3), np.uint8), (0, 0), 2.0)
    pics = [np.ascontiguousarray(np.roll(base, 9 * k, axis=1)) for k in range(12)]
    path = str(tmp_path / f"v.{video.EXTENSIONS[codec]}")
    w = video.open_video(path, codec, 10.0, 128, 96)
    if not wrap:
        w.wrap = None  # type: ignore[attr-defined]
    for p in pics:
        w.write(p)
    w.release()
    got = _decoded(Path(path))
    assert len(got) == len(pics)
    for k, g in enumerate(got):
        scores = [cv2.PSNR(g, p) for p in pics]
        assert int(np.argmax(scores)) == k and scores[k] > 30.0, (k, scores)


def test_odd_frame_size_mp4v_reads_back(tmp_path: Path) -> None:
    summary, out = _fly(tmp_path, "odd", rate=10.0, dur=1.0, w=161, h=121)
    got = _decoded(out / summary["streams"][0]["video"])
    assert len(got) == 10 == summary["streams"][0]["frames"]


def test_h264_without_pyav_is_a_config_error(tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "av" else real(name, *a))
    text = SCENARIO.format(lat=LAT0, lon=LON0, g=GROUND_M, dur=1, workers=0, w=160, h=120,
                           rate=10, codec="h264", op="false", more="")
    f = str(tmp_path / "h264.yaml")
    with pytest.raises(ConfigError, match=r"h264.yaml:\d+: cameras.codec: h264 needs PyAV"):
        parse_scenario(text, f, check_properties=False)


def test_config_errors_carry_file_and_line(tmp_path: Path) -> None:
    text = textwrap.dedent("""\
        schema_version: 1
        origin: {lat_deg: 37, lon_deg: -122}
        rates: {physics_hz: 120, control_hz: 30}
        duration_s: 2
        vehicles:
          - {id: u1, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 100,
             heading_deg: 0, airspeed_kt: 100}}
        targets:
          - {kind: tank, north_m: 0, east_m: 0}
          - {kind: truck, north_m: 0, east_m: 0, color: purple}
        cameras:
          views:
            - {name: a, mount: sideways, rate_hz: 10}
            - {name: b, rate_hz: 7}
            - {name: c, rate_hz: 40}
            - {name: d, vehicles: nobody}
            - {name: e, mount: {pitch_deg: -90, yaw_deg: 200}}
        schedule:
          - {at_s: 1, command: {gimbal: {pitch_deg: 45}}}
          - {at_s: 1, command: {gimbal: {roll_deg: 5}}}
        """)
    f = str(tmp_path / "bad.yaml")
    with pytest.raises(ConfigError) as ei:
        parse_scenario(text, f, check_properties=False)
    msgs = ei.value.problems
    assert any(m.startswith(f"{f}:9: targets[0].kind: expected one of") for m in msgs)
    assert any(m.startswith(f"{f}:10: targets[1].color: expected a colour") for m in msgs)
    assert any(m.startswith(f"{f}:13: cameras.views[0].mount: expected nadir") for m in msgs)
    assert any(m.startswith(f"{f}:14: cameras.views[1].rate_hz: rate_hz 7 must divide "
                            "physics_hz 120") for m in msgs)
    assert any(m.startswith(f"{f}:15: cameras.views[2].rate_hz: rate_hz 40: a frame every 3 "
                            "ticks neither falls on exchanges nor divides one") for m in msgs)
    assert any(m.startswith(f"{f}:16: cameras.views[3].vehicles") for m in msgs)
    assert f"{f}:17: cameras.views[4].mount.yaw_deg: must be <= 180, got 200" in msgs
    assert f"{f}:19: schedule[0].command.gimbal.pitch_deg: must be -90..30, got 45" in msgs
    assert any(m.startswith(f"{f}:20: schedule[1].command.gimbal.roll_deg: unknown key")
               for m in msgs)


class _Events:
    def __init__(self) -> None:
        self.got: list[tuple[str, int, dict[str, Any]]] = []

    def emit(self, kind: str, tick: int, **fields: Any) -> None:
        self.got.append((kind, tick, fields))


class _Commander:
    def __init__(self) -> None:
        self.observers: list[Any] = []


def _fly_gimbal(tmp_path: Path, name: str, mount: str, turn_at: int | None
                ) -> tuple[list[dict[str, str]], _Events]:
    """u1 flies north over the truck with a gimbal camera; a gimbal command
    (yaw 90) through the run's command observers at tick ``turn_at``."""
    view = (f"    - {{name: belly, vehicles: u1, mount: {mount}, vfov_deg: 40, width_px: 160,"
            f" height_px: 120, rate_hz: 30}}\n")
    text = SCENARIO.format(lat=LAT0, lon=LON0, g=GROUND_M, dur=4.0, workers=0, w=160, h=120,
                           rate=30, codec="mp4v", op="false", more="")
    text = text[:text.index("  views:\n") + len("  views:\n")] + view
    scn = parse_scenario(text, str(tmp_path / f"{name}.yaml"), check_properties=False)
    out = tmp_path / name
    out.mkdir()
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    part = CameraParticipant(scn)
    events, commander = _Events(), _Commander()
    ctx = RunContext(scn, out, ["u1"], frame, np.zeros((1, 3)), 120.0, 4, events, None, 1,
                     commander)
    part.start(ctx)
    states = np.zeros((1, N_STATE))
    for tick in range(0, scn.total_ticks, 4):
        if tick == turn_at:
            for observe in commander.observers:
                observe(0, Command(gimbal_yaw_deg=90.0), "schedule")
        la, lo = frame.place(-100.0 + 50.0 * tick / 120.0, 0.0, GROUND_M + 100.0)
        states[0, STATE_INDEX["lat_deg"]], states[0, STATE_INDEX["lon_deg"]] = la, lo
        states[0, STATE_INDEX["alt_msl_m"]] = GROUND_M + 100.0
        part.on_exchange(tick, states)
    part.finish(scn.total_ticks, "completed")
    with open(out / "cameras/u1_belly.gt.csv") as f:
        return [r for r in csv.DictReader(f) if r["target"] == "truck1"], events


@pytest.mark.integration
def test_a_gimbal_command_turns_the_camera_from_that_frame_on(tmp_path: Path) -> None:
    """Turned 90 deg right, a nadir gimbal sees what was ahead (image up) on
    the image's left; the frames after the command are those of a camera
    mounted so from the start, those before it those of a plain nadir one."""
    fixed, _ = _fly_gimbal(tmp_path, "nadir", "nadir", None)
    turned, _ = _fly_gimbal(tmp_path, "turned", "{pitch_deg: -90, yaw_deg: 90}", None)
    cmd, events = _fly_gimbal(tmp_path, "cmd", "gimbal", 240)  # 2 s: frame 60
    assert len(fixed) == len(turned) == len(cmd) == 120
    seen = [i for i, r in enumerate(fixed) if r["in_view"] == "1"]
    assert seen
    cx, cy = (160 - 1) / 2, (120 - 1) / 2
    for i in seen:  # (dx, dy) -> (dy, -dx): a quarter turn of the image
        a, b = fixed[i], turned[i]
        dx, dy = float(a["center_x_px"]) - cx, float(a["center_y_px"]) - cy
        assert float(b["center_x_px"]) - cx == pytest.approx(dy, abs=0.6)
        assert float(b["center_y_px"]) - cy == pytest.approx(-dx, abs=0.6)
    # ahead of the nose comes in at the top, or on the left once turned
    for name, way in (("nadir", "down"), ("turned", "right")):
        rows = read_ground_truth(tmp_path / name / "cameras/u1_belly.gt.csv")
        [p] = passes(rows[("u1", "belly", "truck1")], 1 / 30)
        assert p.screen_direction == way
    assert cmd[:60] == fixed[:60] and cmd[60:] == turned[60:]
    assert cmd[60] != fixed[60]
    assert [e for e in events.got if e[0] == "gimbal"] == [
        ("gimbal", 240, {"vehicle": "u1", "camera": "belly", "pitch_deg": -90.0,
                         "yaw_deg": 90.0, "source": "schedule"})]


@pytest.mark.integration
def test_a_fixed_mount_ignores_gimbal_commands(tmp_path: Path) -> None:
    fixed, _ = _fly_gimbal(tmp_path, "nadir", "nadir", None)
    cmd, events = _fly_gimbal(tmp_path, "cmd", "nadir", 240)
    assert cmd == fixed and not [e for e in events.got if e[0] == "gimbal"]


@pytest.mark.parametrize("yaw,gimbal_yaw", [(0.0, 0.0), (30.0, 0.0), (0.0, 90.0),
                                            (-120.0, 45.0)])
def test_a_level_nadir_footprint_is_the_field_of_view_turned_by_the_heading(
        yaw: float, gimbal_yaw: float) -> None:
    """At height h, level: a rectangle 2 h tan(hfov/2) across the image by
    2 h tan(vfov/2) along it, image top toward heading + gimbal yaw."""
    cam = _cam("gimbal", -90.0, w=320, h=240, hfov=60.0, yaw=gimbal_yaw)
    h = 120.0
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + h, 0.0, 0.0, yaw, ground_alt_m=GROUND_M)
    got = footprint(cam, pose)
    half_x = h * math.tan(math.radians(cam.hfov_deg) / 2)  # the image edges, not pixel centres
    half_y = h * math.tan(math.radians(cam.vfov_deg) / 2)
    a = math.radians(yaw + gimbal_yaw)
    up, right = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    want = np.array([half_y * up - half_x * right, half_y * up + half_x * right,
                     -half_y * up + half_x * right, -half_y * up - half_x * right])
    assert np.allclose(got, want, atol=0.05), (got, want)


def test_a_footprint_reaching_over_the_horizon_is_cut_at_the_range() -> None:
    cam = _cam("forward", 0.0)
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0,
                       ground_alt_m=GROUND_M)
    got = footprint(cam, pose, max_range_m=800.0)
    # the top corners look above the horizon: cut at 800 m in their direction
    tx = math.tan(math.radians(cam.hfov_deg) / 2)
    ty = math.tan(math.radians(cam.vfov_deg) / 2)
    top = 800.0 * np.array([[1.0, -tx], [1.0, tx]]) / math.hypot(1.0, tx)
    # the bottom ones meet the ground where the ray (x, y, 1) has come down 100 m
    bottom = 100.0 / ty * np.array([[1.0, tx], [1.0, -tx]])
    assert np.allclose(got, np.vstack([top, bottom]), atol=1e-6), got


def test_obstacles_are_drawn_as_prisms_that_hide_what_is_behind_them() -> None:
    """A nadir camera 100 m above a 10 m block: its roof fills the square the
    pinhole puts it at (f * 10 m / 90 m around the centre), in the roof's
    shade, and the truck under it is in view with no pixel of it seen."""
    block = Obstacle("block", ((-10.0, -10.0), (-10.0, 10.0), (10.0, 10.0), (10.0, -10.0)), 10.0)
    t = _target("truck", 0.0, 0.0)
    cam = _cam("nadir", -90.0, w=320, h=240, hfov=60.0)
    pose = camera_pose(cam, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, ground_alt_m=GROUND_M)
    bare, rows_bare = render_frame(World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(),
                                                   (t,))), cam, pose, 0)
    img, rows = render_frame(World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, GroundSpec(), (t,),
                                             (block,))), cam, pose, 0)
    assert rows_bare[0]["pixels_on_target"] > 0
    assert rows[0]["in_view"] == 1 and rows[0]["pixels_on_target"] == 0
    half = cam.fx_px * 10.0 / 90.0  # the roof's half side in pixels
    cx, cy = (320 - 1) / 2, (240 - 1) / 2
    k = lambert(np.array([0.0, 0.0, -1.0]))
    roof = np.array([min(255, int(c * k)) for c in OBSTACLE_RGB[::-1]])
    inner = img[int(cy - half + 2):int(cy + half - 1), int(cx - half + 2):int(cx + half - 1), :3]
    assert (inner == roof).all()
    for x, y in ((cx - half - 2, cy), (cx + half + 2, cy), (cx, cy - half - 2),
                 (cx, cy + half + 2)):
        assert (img[int(round(y)), int(round(x)), :3] != roof).any()
