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
    ("{grain: 1}", r"s.yaml:10: cameras.views\[0\].sensor.grain: unknown key 'grain'"),
    ("[1, 2]", r"s.yaml:10: cameras.views\[0\].sensor: expected a mapping"),
])
def test_bad_sensor_keys_are_refused_with_their_place(sensor: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_scenario(SCENARIO % sensor, "s.yaml", check_properties=False)


def _sensor_run(tmp_path: Path, name: str, workers: int) -> list[str]:
    """The frames' sha256 of a plain belly camera and the same with a sensor."""
    from tests.renderer.test_renderer import _fly

    more = textwrap.indent("- {name: sensed, vehicles: u1, mount: nadir, vfov_deg: 40, "
                           "width_px: 160, height_px: 120, rate_hz: 10, "
                           "sensor: {vignetting: 3, iso: 3200}}\n", "    ")
    summary, _ = _fly(tmp_path, name, rate=10.0, dur=0.5, more=more, workers=workers)
    return [s["frames_sha256"] for s in summary["streams"]]


def test_a_run_records_the_sensor_frames(tmp_path: Path) -> None:
    """The render pool applies the camera's sensor before the frame is written."""
    sha = _sensor_run(tmp_path, "inline", 0)
    assert sha[0] != sha[1]  # the same view, dimmed at the edges and noisy


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

