"""The camera's sensor and lens (cosim.renderer.sensor) against their formulas."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, SensorSpec
from cosim.errors import ConfigError
from cosim.renderer.sensor import GAMMA, MID_GREY, READ_SIGNAL, Sensor, noise_model, snr_of_iso
from cosim.scenario import parse_scenario


def _cam(w: int = 640, h: int = 480, hfov: float = 70.0, **sensor: float) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec(name="belly", vehicles=(0,), mount="nadir", pitch_deg=-90.0,
                      stabilised=False, hfov_deg=hfov, vfov_deg=vfov, width_px=w, height_px=h,
                      rate_hz=10.0, frame_every=12, sensor=SensorSpec(**sensor))


def _flat(cam: CameraSpec, value: int) -> np.ndarray:
    img = np.full((cam.height_px, cam.width_px, 4), value, np.uint8)
    img[..., 3] = 255
    return img


def _lin(v: np.ndarray) -> np.ndarray:
    out: np.ndarray = (v.astype(np.float64) / 255.0) ** GAMMA
    return out


@pytest.mark.parametrize("strength", [1.0, 2.5])
def test_vignetting_corner_to_centre_is_cos4_of_the_off_axis_angle(strength: float) -> None:
    cam = _cam(hfov=80.0, vignetting=strength)
    s = cam.sensor
    assert s is not None
    img = Sensor(cam, s, seed=1, vehicle_row=0).apply(_flat(cam, 250), 0)
    assert (img[..., 3] == 255).all()
    f = cam.fx_px
    # the top-left pixel centre's angle off the axis, from the field of view alone
    theta = math.atan(math.hypot((cam.width_px - 1) / 2, (cam.height_px - 1) / 2) / f)
    want = math.cos(theta) ** (4 * strength)
    got = _lin(img[0, 0, :3]) / _lin(np.array([250]))
    # one 8-bit step of the corner's value, in linear light
    step = GAMMA * (1 / float(img[0, 0, 0])) * want
    assert np.allclose(got, want, atol=step), (got, want)
    cy, cx = cam.height_px // 2, cam.width_px // 2
    assert abs(int(img[cy, cx, 0]) - 250) <= 1  # the centre barely dims


def test_noise_variance_is_read_plus_shot_noise_in_linear_light() -> None:
    """A flat field at two levels: the recorded values' variance in linear light
    is a + b L (plus the 8-bit rounding's, (dL/dv)^2 / 12 of a step), within
    five standard errors of a sample variance."""
    cam = _cam(snr_db=20.0)
    s = cam.sensor
    assert s is not None
    sensor = Sensor(cam, s, seed=7, vehicle_row=2)
    a, b = noise_model(20.0)
    assert a == pytest.approx(b * READ_SIGNAL)
    # the ratio at mid-grey is the one asked for
    assert 20 * math.log10(MID_GREY / math.sqrt(a + b * MID_GREY)) == pytest.approx(20.0)
    for frame_no, value in enumerate((60, 200)):  # far from black, where the clip biases it
        level = float(_lin(np.array([value]))[0])
        out = sensor.apply(_flat(cam, value), frame_no)
        assert (out[..., 3] == 255).all()
        v = out[..., :3].astype(np.float64)
        lin = _lin(v)
        n = lin.size
        rounding = float(np.mean((GAMMA * (v / 255) ** (GAMMA - 1) / 255) ** 2)) / 12
        want = a + b * level
        assert float(lin.var()) - rounding == pytest.approx(want, rel=5 * math.sqrt(2 / n)), \
            (value, float(lin.var()), rounding, want)
        assert float(lin.mean()) == pytest.approx(level, abs=5 * math.sqrt(want / n))


def test_noise_is_a_function_of_seed_vehicle_camera_and_frame() -> None:
    cam = _cam(w=64, h=48, snr_db=25.0)
    s = cam.sensor
    assert s is not None

    def frame(seed: int, row: int, frame_no: int) -> bytes:
        return Sensor(cam, s, seed, row).apply(_flat(cam, 120), frame_no).tobytes()

    assert frame(3, 0, 5) == frame(3, 0, 5)
    assert len({frame(3, 0, 5), frame(4, 0, 5), frame(3, 1, 5), frame(3, 0, 6)}) == 4


def test_the_compiled_pass_is_gain_then_table_look_up_per_value() -> None:
    """sensor_pass against numpy: each colour value times its pixel's gain
    (fixed point, rounded half up, clipped), then the table at value * 256 +
    its level; alpha kept; the levels splitmix64's bytes (a plain Python
    splitmix64 here)."""
    from cosim.renderer.sensor_pass import GAIN_BITS, fill_levels, gain_fixed, gain_noise

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (6, 10, 4), dtype=np.uint8)
    gain = gain_fixed(rng.uniform(0.3, 1.6, (6, 10)))  # above 1 too: the clip
    table = rng.integers(0, 256, 65536, dtype=np.uint8)
    key, mask = 0xDEADBEEF12345, (1 << 64) - 1
    want_words = []
    for j in range(1, 24):
        z = (key + j * 0x9E3779B97F4A7C15) & mask
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        want_words.append(z ^ (z >> 31))
    levels = fill_levels(np.empty(23, np.uint64), key)
    assert levels.view(np.uint64).tolist() == want_words
    v = img[..., :3].astype(np.int64)
    g = gain.reshape(6, 10, 1).astype(np.int64)
    lit = np.minimum((v * g + (1 << (GAIN_BITS - 1))) >> GAIN_BITS, 255)
    want = img.copy()
    want[..., :3] = table[lit * 256 + levels[:180].reshape(6, 10, 3)]
    got = gain_noise(img.copy(), gain, table, levels)
    assert np.array_equal(got, want)
    assert np.array_equal(gain_noise(img.copy(), gain, None, None)[..., :3], lit)
    with pytest.raises(ValueError, match="a level for each colour value"):
        gain_noise(img.copy(), None, table, levels[:179])


def test_iso_maps_to_3_db_less_per_doubling() -> None:
    assert snr_of_iso(100) == pytest.approx(40.0)
    assert snr_of_iso(200) == pytest.approx(40.0 - 10 * math.log10(2))
    assert snr_of_iso(6400) == pytest.approx(40.0 - 10 * math.log10(64))


SCENARIO = """\
schema_version: 1
origin: {lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 10}
rates: {physics_hz: 120, control_hz: 30}
duration_s: 1
vehicles:
  - {id: u1, model: uav700, init: {alt_agl_m: 100, airspeed_kt: 100}}
cameras:
  views:
    - name: belly
      sensor: %s
"""


def test_sensor_keys_parse() -> None:
    scn = parse_scenario(SCENARIO % "{vignetting: cos4, iso: 400}", "s.yaml",
                         check_properties=False)
    cam = scn.sections["cameras"].views[0]
    assert cam.sensor == SensorSpec(vignetting=1.0, snr_db=snr_of_iso(400))
    scn = parse_scenario(SCENARIO % "{vignetting: 0.5, snr_db: 30}", "s.yaml",
                         check_properties=False)
    assert scn.sections["cameras"].views[0].sensor == SensorSpec(vignetting=0.5, snr_db=30.0)
    scn = parse_scenario(SCENARIO % "{distortion: {k1: -0.2, k2: 0.05}}", "s.yaml",
                         check_properties=False)
    assert scn.sections["cameras"].views[0].sensor == SensorSpec(k1=-0.2, k2=0.05)
    plain = parse_scenario(SCENARIO.replace("      sensor: %s\n", ""), "s.yaml",
                           check_properties=False)
    assert plain.sections["cameras"].views[0].sensor is None


@pytest.mark.parametrize("sensor, message", [
    ("{snr_db: 90}", r"s.yaml:10: cameras.views\[0\].sensor.snr_db: must be <= 80, got 90"),
    ("{iso: 10}", r"s.yaml:10: cameras.views\[0\].sensor.iso: must be >= 25, got 10"),
    ("{snr_db: 20, iso: 100}", r"s.yaml:10: cameras.views\[0\].sensor: give only one of "
                               r"snr_db / iso"),
    ("{vignetting: strong}", r"s.yaml:10: cameras.views\[0\].sensor.vignetting: expected cos4, "
                             r"true, false or a strength 0 to 4"),
    ("{vignetting: 5}", r"s.yaml:10: cameras.views\[0\].sensor.vignetting: must be <= 4"),
    ("{exposure_ms: 150}", r"s.yaml:10: cameras.views\[0\].sensor.exposure_ms: must be "
                           r"<= 100, got 150"),
    ("{grain: 1}", r"s.yaml:10: cameras.views\[0\].sensor.grain: unknown key 'grain'"),
    ("[1, 2]", r"s.yaml:10: cameras.views\[0\].sensor: expected a mapping"),
    ("{distortion: {k1: -0.9}}", r"s.yaml:10: cameras.views\[0\].sensor.distortion: k1 -0.9, "
                                 r"k2 0 fold the image: the distorted radius stops growing at "
                                 r"r = 0.60\d, inside the image's corner at r = 0.722"),
    ("{distortion: {k1: 0.1, k2: 1.5}}", r"s.yaml:10: cameras.views\[0\].sensor.distortion.k2: "
                                         r"must be <= 1, got 1.5"),
    ("{distortion: {k3: 0.1}}", r"s.yaml:10: cameras.views\[0\].sensor.distortion.k3: unknown "
                                r"key 'k3'"),
])
def test_bad_sensor_keys_are_refused_with_their_place(sensor: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_scenario(SCENARIO % sensor, "s.yaml", check_properties=False)


def _sensor_run(tmp_path: Path, name: str, workers: int) -> list[str]:
    """The frames' sha256 of a plain belly camera and the same with a sensor."""
    from tests.renderer.test_renderer import _fly

    more = textwrap.indent("- {name: sensed, vehicles: u1, mount: nadir, vfov_deg: 40, "
                           "width_px: 160, height_px: 120, rate_hz: 10, "
                           "sensor: {vignetting: 3, iso: 3200, exposure_ms: 30, "
                           "distortion: {k1: -0.2}}}\n", "    ")
    summary, _ = _fly(tmp_path, name, rate=10.0, dur=0.5, more=more, workers=workers)
    return [s["frames_sha256"] for s in summary["streams"]]


def test_a_run_records_the_sensor_frames(tmp_path: Path) -> None:
    """The render pool applies the camera's sensor before the frame is written."""
    sha = _sensor_run(tmp_path, "inline", 0)
    assert sha[0] != sha[1]  # the same view through a lens, dimmed, blurred and noisy


@pytest.mark.integration
def test_sensor_frames_are_the_same_for_any_render_worker_count(tmp_path: Path) -> None:
    assert _sensor_run(tmp_path, "w0", 0) == _sensor_run(tmp_path, "w2", 2)


def test_the_search_camera_refuses_a_sensor() -> None:
    """The search's camera sees by geometry: a sensor there would be ignored."""
    repo = Path(__file__).resolve().parents[2]
    path = repo / "scenarios/xprize/search.yaml"
    text = path.read_text().replace("camera: {hfov_deg: 60,", "camera: {sensor: {iso: 800}, "
                                    "hfov_deg: 60,")
    with pytest.raises(ConfigError, match=r"search.yaml:\d+: search.camera.sensor: the search "
                                          r"camera sees by geometry"):
        parse_scenario(text, str(path), check_properties=False)



# --- lens distortion -------------------------------------------------------------------


def _brown(cam: CameraSpec, k1: float, k2: float, u: np.ndarray, v: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """The formula written out: x_d = x (1 + k1 r^2 + k2 r^4), normalised by f."""
    f, cx, cy = cam.fx_px, (cam.width_px - 1) / 2, (cam.height_px - 1) / 2
    x, y = (u - cx) / f, (v - cy) / f
    r2 = x * x + y * y
    g = 1 + k1 * r2 + k2 * r2 * r2
    return cx + f * x * g, cy + f * y * g


@pytest.mark.parametrize("k1, k2", [(-0.2, 0.05), (0.15, 0.0)])
def test_a_straight_line_bends_as_brown_distortion_says(k1: float, k2: float) -> None:
    cam = _cam(w=320, h=240, hfov=60.0, k1=k1, k2=k2)
    s = cam.sensor
    assert s is not None
    img = _flat(cam, 0)
    u0 = 300
    img[:, u0, :3] = 255  # a vertical line, one pixel wide
    out = Sensor(cam, s, 1, 0).apply(img, 0)
    # where the formula puts the line, row by row of the recorded image
    v_src = np.linspace(-40.0, cam.height_px + 40.0, 20001)
    u_d, v_d = _brown(cam, k1, k2, np.full_like(v_src, u0), v_src)
    rows = np.arange(cam.height_px)
    seen = np.interp(rows, v_d, v_src)  # the rows whose line the render holds
    rows = rows[(seen >= 1) & (seen <= cam.height_px - 2)]
    assert len(rows) > 0.9 * cam.height_px
    want = np.interp(rows, v_d, u_d)
    lum = out[rows, :, 0].astype(np.float64)
    cols = np.arange(cam.width_px)
    near = np.abs(cols[None, :] - want[:, None]) < 4
    got = (lum * near * cols).sum(axis=1) / (lum * near).sum(axis=1)
    assert np.abs(got - want).max() < 0.25, np.abs(got - want).max()
    assert np.ptp(want) > 3  # it does bend: a straight line would not pass


def test_ground_truth_box_and_centre_are_where_the_distorted_frame_shows_the_target() -> None:
    """A truck off the image centre, rendered with and without it: the pixels
    that change in the distorted frames lie within the ground truth's box
    (within a pixel), and the truth's centre is the ideal one through the
    formula."""
    from cosim.core.camera import camera_pose
    from cosim.core.geo import LocalFrame
    from cosim.renderer.frame import World, WorldSpec, render_frame
    from cosim.world.ground import GroundSpec
    from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

    k1, k2 = -0.25, 0.04
    lat, lon, g_m = 37.0, -122.0, 10.0
    length, width, height, colour = TARGET_DEFAULTS["truck"]
    truck = TargetSpec("t", "truck", 14.0, 20.0, None, None, 30.0, length, width, height, colour)
    cam = _cam(w=320, h=240, hfov=60.0, k1=k1, k2=k2)
    ideal = _cam(w=320, h=240, hfov=60.0)
    ideal = CameraSpec(**{**ideal.__dict__, "sensor": None})
    la, lo = LocalFrame(lat, lon, g_m).place(0.0, 0.0, g_m + 60)
    pose = camera_pose(cam, float(la), float(lo), g_m + 60, 0.0, 0.0, 0.0, g_m)
    frames, rows = [], []
    for targets in ((truck,), ()):
        world = World(WorldSpec(lat, lon, g_m, 1, 120.0, GroundSpec(), targets))
        img, got = render_frame(world, cam, pose, 0)
        rows.append(got)
        s = cam.sensor
        assert s is not None
        frames.append(Sensor(cam, s, 1, 0).apply(img.copy(), 0).astype(int))
    changed = np.argwhere(np.abs(frames[0] - frames[1]).max(axis=2) > 0)
    (fy0, fx0), (fy1, fx1) = changed.min(axis=0), changed.max(axis=0)
    r = rows[0][0]
    assert r["in_view"] == 1 and r["fully_in_view"] == 1
    box = np.array([r["bbox_x0_px"], r["bbox_y0_px"], r["bbox_x1_px"], r["bbox_y1_px"]])
    assert np.abs(box - [fx0, fy0, fx1, fy1]).max() <= 1.0, (box, (fx0, fy0, fx1, fy1))
    world = World(WorldSpec(lat, lon, g_m, 1, 120.0, GroundSpec(), (truck,)))
    _, [plain] = render_frame(world, ideal, pose, 0)
    cu, cv = _brown(cam, k1, k2, np.array(plain["center_x_px"]), np.array(plain["center_y_px"]))
    assert (r["center_x_px"], r["center_y_px"]) == pytest.approx((float(cu), float(cv)))
    # far enough off centre for the lens to move it: an undistorted truth would fail
    assert math.hypot(cu - plain["center_x_px"], cv - plain["center_y_px"]) > 3
    assert plain["bbox_x1_px"] - box[2] > 3
    assert r["pixels_on_target"] == plain["pixels_on_target"]  # measured on the ideal frame


def test_a_barrel_lens_sees_scene_in_its_corners_and_its_truth_box_holds(tmp_path: Path
                                                                         ) -> None:
    """Through the render worker, a barrel lens (k1 -0.25, k2 0.04) records
    ground in its corners (the rays there pass outside the pinhole's field:
    they were black), and a truck near a corner, partly outside the pinhole's
    field, is drawn whole: the pixels it changes lie within its ground truth's
    box (within a pixel), fully in view."""
    import cv2

    from cosim.core.geo import LocalFrame
    from cosim.renderer.frame import WorldSpec
    from cosim.renderer.outputs import Stream
    from cosim.renderer.render_pool import RenderWorker
    from cosim.world.ground import GroundSpec
    from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

    lat, lon, g_m = 37.0, -122.0, 10.0
    length, width, height, colour = TARGET_DEFAULTS["truck"]
    truck = TargetSpec("t", "truck", 22.0, -30.0, None, None, 30.0, length, width, height,
                       colour)
    cam = _cam(w=320, h=240, hfov=60.0, k1=-0.25, k2=0.04)
    la, lo = LocalFrame(lat, lon, g_m).place(0.0, 0.0, g_m + 60)
    pose6 = (float(la), float(lo), g_m + 60, 0.0, 0.0, 0.0)
    frames, rows = [], []
    for k, targets in enumerate(((truck,), ())):
        out = tmp_path / str(k)
        out.mkdir()
        stream = Stream(0, "u1", 0, cam, "v.avi", "v.gt.csv", None)
        worker = RenderWorker(WorldSpec(lat, lon, g_m, 1, 120.0, GroundSpec(), targets),
                              [stream], out, "mjpg", False)
        _, truth = worker.render(0, 0, 0, pose6, still="still.png")
        worker.close()
        frames.append(cv2.imread(str(out / "still.png")).astype(int))
        rows.append(truth)
    ground = frames[1]
    for y, x in ((0, 0), (0, 319), (239, 0), (239, 319)):
        assert ground[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].sum(axis=2).min() > 30, (y, x)
    changed = np.argwhere(np.abs(frames[0] - frames[1]).max(axis=2) > 0)
    (fy0, fx0), (fy1, fx1) = changed.min(axis=0), changed.max(axis=0)
    first = rows[0]
    assert first is not None
    r = first[0]
    assert r["in_view"] == 1 and r["fully_in_view"] == 1 and r["pixels_on_target"] > 0
    box = np.array([r["bbox_x0_px"], r["bbox_y0_px"], r["bbox_x1_px"], r["bbox_y1_px"]])
    assert np.abs(box - [fx0, fy0, fx1, fy1]).max() <= 1.0, (box, (fx0, fy0, fx1, fy1))
    assert box[1] < 3  # its top: the pinhole's field reaches row 11 there, black above


def test_a_lens_near_folding_renders_at_most_twice_the_frame() -> None:
    """k1 -1 at 46 deg barely keeps from folding at the corner: its corners would
    ask for a render 1796 x 1348 for a 640 x 480 frame; it gets half the frame
    more on each side at most, and what lies past that stays black."""
    cam = _cam(hfov=46.0, k1=-1.0)
    s = cam.sensor
    assert s is not None
    sensor = Sensor(cam, s, 1, 0)
    assert (sensor.source.width_px, sensor.source.height_px) == (1280, 960)
    assert sensor.source.fx_px == pytest.approx(cam.fx_px)
    img = np.full((960, 1280, 4), 200, np.uint8)
    out = sensor.apply(img, 0)
    assert (out[0, 0, :3] == 0).all() and (out[240, 320, :3] == 200).all()
    mild = _cam(hfov=60.0, k1=-0.1)
    assert mild.sensor is not None
    src = Sensor(mild, mild.sensor, 1, 0).source
    assert 640 < src.width_px < 800 and 480 < src.height_px < 600


# --- motion blur -----------------------------------------------------------------------


def _nadir_pose(cam: CameraSpec, alt_agl_m: float) -> tuple[tuple[float, ...], object]:
    from cosim.core.camera import camera_pose

    lat, lon, g_m = 37.0, -122.0, 10.0
    pose6 = (lat, lon, g_m + alt_agl_m, 0.0, 0.0, 0.0)
    return pose6, camera_pose(cam, *pose6, g_m)


def test_motion_blur_smears_a_bright_square_by_v_t_over_gsd_along_the_flight() -> None:
    """Level flight north at 40 m/s, 60 m up, a 40 ms exposure: the ground moves
    v T / GSD pixels (GSD = h / f at the centre) down the image of a nadir
    camera (image top toward the nose); a bright square is smeared that far
    back toward the image top, its centroid by half of it."""
    v_mps, h_m, t_ms = 40.0, 60.0, 40.0
    cam = _cam(w=320, h=240, hfov=50.0, exposure_ms=t_ms)
    s = cam.sensor
    assert s is not None
    sensor = Sensor(cam, s, 1, 0)
    pose6, pose = _nadir_pose(cam, h_m)
    smear = sensor.smear_px(pose6, (v_mps, 0.0, 0.0, 0.0, 0.0, 0.0), None, pose, 10.0)
    assert smear is not None
    want_px = v_mps * t_ms / 1000 / (h_m / cam.fx_px)
    assert want_px > 8  # long enough to tell from a square at rest
    assert smear == pytest.approx((0.0, want_px), abs=1e-6)
    img = _flat(cam, 0)
    img[150:154, 200:204, :3] = 255  # a 4 x 4 px bright square
    out = sensor.apply(img, 0, smear)[..., 0].astype(np.float64)
    ys, xs = np.nonzero(out)
    w = out[ys, xs]
    assert (xs.min(), xs.max()) == (200, 203)  # across the flight: untouched
    assert (153 - ys.min()) - 3 == pytest.approx(want_px, abs=1.0)  # along it: v T / GSD
    assert ys.max() == 153  # where the square is now: the smear trails behind it
    assert float((w * ys).sum() / w.sum()) - 151.5 == pytest.approx(-want_px / 2, abs=0.2)
    assert float(w.sum()) == pytest.approx(16 * 255, rel=0.02)  # light spread, not lost


def test_motion_blur_of_a_pitch_rate_is_focal_length_times_angle() -> None:
    """Hovering, pitching up at 10 deg/s, a 20 ms exposure: the centre's ground
    point moves f tan(rate T) pixels along the image's vertical."""
    cam = _cam(w=320, h=240, hfov=50.0, exposure_ms=20.0)
    s = cam.sensor
    assert s is not None
    pose6, pose = _nadir_pose(cam, 80.0)
    smear = Sensor(cam, s, 1, 0).smear_px(pose6, (0.0, 0.0, 0.0, 0.0, 10.0, 0.0), None, pose,
                                          10.0)
    assert smear is not None
    want = cam.fx_px * math.tan(math.radians(10.0 * 0.020))
    assert abs(smear[0]) < 1e-6 and abs(smear[1]) == pytest.approx(want, rel=1e-3)
    assert Sensor(cam, s, 1, 0).smear_px(pose6, None, None, pose, 10.0) is None


def test_a_run_blurs_frames_by_the_vehicle_s_motion(tmp_path: Path) -> None:
    """exposure_ms through a run: the participant hands the velocity down, the
    frames differ from the sharp ones, and not at all with the shutter at 0."""
    from tests.renderer.test_renderer import _fly

    def run(name: str, sensor: str) -> list[str]:
        more = textwrap.indent("- {name: blur, vehicles: u1, mount: nadir, vfov_deg: 40, "
                               "width_px: 160, height_px: 120, rate_hz: 10, "
                               f"sensor: {sensor}}}\n", "    ")
        summary, _ = _fly(tmp_path, name, rate=10.0, dur=0.5, more=more)
        return [s["frames_sha256"] for s in summary["streams"]]

    sharp = run("sharp", "{exposure_ms: 0}")
    assert sharp[0] == sharp[1]
    blurred = run("blurred", "{exposure_ms: 20}")
    assert blurred[0] == sharp[0] and blurred[1] != sharp[1]


@pytest.mark.parametrize("dx, dy", [(13.5, 13.5), (-20.3, 7.1), (4.0, -30.0), (0.0, 13.5)])
def test_a_long_diagonal_smear_in_pieces_is_the_whole_kernel(dx: float, dy: float) -> None:
    """smear_frame cuts a kernel too big for OpenCV's tap-by-tap filter into
    pieces: the pieces sum to the whole kernel, and the frame equals one
    filter2D with it within one 8-bit step, away from the image's edges."""
    import cv2

    from cosim.renderer.sensor import line_kernel, smear_frame

    whole, (ax, ay) = line_kernel(dx, dy)
    assert float(whole.sum()) == pytest.approx(1.0, abs=1e-5)
    r = math.ceil(max(abs(dx), abs(dy))) + 1
    total = np.zeros((2 * r + 1, 2 * r + 1))
    for i in range(3):
        part, (px, py) = line_kernel(dx, dy, i, 3)
        total[r - py:r - py + part.shape[0], r - px:r - px + part.shape[1]] += part
    placed = np.zeros_like(total)
    placed[r - ay:r - ay + whole.shape[0], r - ax:r - ax + whole.shape[1]] = whole
    assert np.allclose(total, placed, atol=1e-6)
    img = np.random.default_rng(2).integers(0, 256, (120, 160, 4), np.uint8)
    img[..., 3] = 255
    want = cv2.filter2D(img, -1, whole, anchor=(ax, ay), borderType=cv2.BORDER_REPLICATE)
    got = smear_frame(img.copy(), dx, dy)
    m = r + 1
    assert np.abs(got.astype(int) - want.astype(int))[m:-m, m:-m].max() <= 1
    assert (got[..., 3] == 255).all()


def test_a_rendered_bright_square_is_smeared_by_v_t_over_gsd(tmp_path: Path) -> None:
    """The render worker's whole path: a 0.8 m white square on a black picture
    ground, seen from 60 m by a nadir camera flying north at 40 m/s with a 40
    ms exposure (a still, lossless): against the same frame without the
    exposure, its light moves v T / GSD / 2 toward the image top (the smear
    trails behind it), not sideways, and its streak is v T / GSD longer."""
    import cv2

    from cosim.core.geo import LocalFrame
    from cosim.renderer.frame import WorldSpec
    from cosim.renderer.outputs import Stream
    from cosim.renderer.render_pool import RenderWorker
    from cosim.world.ground import GroundSpec

    picture = np.zeros((800, 800, 3), np.uint8)
    picture[396:404, 396:404] = 255  # 0.8 m at 0.1 m/px, at the origin
    cv2.imwrite(str(tmp_path / "ground.png"), picture)
    ground = GroundSpec(kind="image", image=str(tmp_path / "ground.png"),
                        origin_ne_m=(40.0, -40.0), m_per_px=0.1)
    lat, lon, g_m, h_m, v_mps, t_ms = 37.0, -122.0, 10.0, 60.0, 40.0, 40.0
    ws = WorldSpec(lat, lon, g_m, 1, 120.0, ground, ())
    la, lo = LocalFrame(lat, lon, g_m).place(0.0, 0.0, g_m + h_m)
    pose6 = (float(la), float(lo), g_m + h_m, 0.0, 0.0, 0.0)
    light = []
    for exposure in (0.0, t_ms):
        cam = _cam(w=320, h=240, hfov=50.0, exposure_ms=exposure)
        out = tmp_path / f"e{exposure:g}"
        (out / "cameras").mkdir(parents=True)
        s = Stream(0, "u1", 0, cam, "cameras/b.avi", "cameras/b.gt.csv", None)
        w = RenderWorker(ws, [s], out, "mjpg", False)
        w.render(0, 0, 0, pose6, None, "still.png", (v_mps, 0.0, 0.0, 0.0, 0.0, 0.0))
        w.close()
        light.append(cv2.imread(str(out / "still.png"))[..., 1].astype(np.float64))
    want_px = v_mps * t_ms / 1000 / (h_m / _cam(w=320, h=240, hfov=50.0).fx_px)
    assert want_px > 8

    def centroid(img: np.ndarray) -> tuple[float, float]:
        ys, xs = np.nonzero(img)
        return float((img[ys, xs] * xs).sum() / img.sum()), float((img[ys, xs] * ys).sum()
                                                                  / img.sum())

    (x0, y0), (x1, y1) = centroid(light[0]), centroid(light[1])
    assert x1 - x0 == pytest.approx(0.0, abs=0.2)
    assert y1 - y0 == pytest.approx(-want_px / 2, abs=0.3)
    rows = [np.flatnonzero(img.max(axis=1) > 0) for img in light]
    assert len(rows[1]) - len(rows[0]) == pytest.approx(want_px, abs=1.0)
