"""Stills from the ``camera`` command: exactly the asked number at the asked
times (interval) or spacing (distance), the same pixels and ground truth as
the video frame they were taken at, the states unchanged, bad values
refused, and a vehicle without a camera ignoring the command."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.logs import read_states
from cosim.scenario import parse_scenario
from cosim.sync import run_scenario

BODY = """\
schema_version: 1
origin: {lat_deg: 37.4150, lon_deg: -122.0480, ground_alt_m: 10}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 8
seed: 7
vehicles:
  - {id: uav1, model: uav700, init: {north_m: -300, east_m: 0, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}
  - {id: uav2, model: uav700, init: {north_m: -300, east_m: 300, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}
schedule:
SCHEDULE
ground: {texture: procedural}
targets:
  - {id: truck1, kind: truck, north_m: 0, east_m: 0, heading_deg: 20}
cameras:
  render_workers: WORKERS
  views:
    - {name: belly, vehicles: uav1, mount: nadir, vfov_deg: 40, width_px: 160,
       height_px: 120, rate_hz: 10}
"""


def _run(tmp_path: Path, schedule: str, workers: int = 0, name: str = "r") -> Path:
    body = BODY.replace("SCHEDULE", schedule).replace("WORKERS", str(workers))
    scn = parse_scenario(body, str(tmp_path / f"{name}.yaml"))
    res = run_scenario(scn, tmp_path / name, backend="inline")
    assert res.stop_reason == "completed", res.error
    return tmp_path / name


def _stills(out: Path) -> list[dict]:
    path = out / "stills" / "stills.jsonl"
    return [json.loads(x) for x in path.read_text().splitlines()] if path.exists() else []


@pytest.fixture(scope="module")
def interval_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("stills")
    return _run(tmp, "  - {at_s: 4, vehicles: uav1, command: {camera: {interval_s: 1.5, "
                     "count: 3}}}\n  - {at_s: 2, vehicles: uav2, command: {camera: {shoot: true}}}",
                workers=1)


def test_an_interval_takes_exactly_its_count_at_its_times(interval_run: Path) -> None:
    stills = _stills(interval_run)
    assert [s["time_s"] for s in stills] == pytest.approx([4.0, 5.5, 7.0])
    assert [s["file"] for s in stills] == [f"stills/uav1_belly_{k:04d}.png" for k in (1, 2, 3)]
    events = [json.loads(x) for x in (interval_run / "events.jsonl").read_text().splitlines()]
    assert [e["time_s"] for e in events if e["event"] == "still"] == pytest.approx(
        [4.0, 5.5, 7.0])
    summary = json.loads((interval_run / "summary.json").read_text())
    assert summary["cameras"]["stills"]["taken"] == 3


def test_a_still_is_its_video_frame_with_the_same_ground_truth(interval_run: Path) -> None:
    gt: dict[int, dict[str, str]] = {}
    with open(interval_run / "cameras" / "uav1_belly.gt.csv") as f:
        for row in csv.DictReader(f):
            gt[int(row["frame"])] = row
    seen_in_view = False
    for s in _stills(interval_run):
        img = cv2.imread(str(interval_run / s["file"]))
        assert img is not None and img.shape == (120, 160, 3)
        row = gt[s["frame"]]
        t, = s["targets"]
        assert t["target"] == row["target"] == "truck1"
        assert str(t["in_view"]) == row["in_view"]
        for col in ("eccentricity_deg", "range_m", "pixels_on_target"):
            if row[col]:
                assert float(row[col]) == pytest.approx(float(t[col]), abs=1e-3)
        seen_in_view |= row["in_view"] == "1"
        states = read_states(interval_run)
        i = [k for k, (v, ts) in enumerate(zip(states["vehicle"].to_pylist(),
                                                 states["time_s"].to_pylist()))
             if v == "uav1" and abs(ts - s["time_s"]) < 1e-9]
        if i:
            assert states["lat_deg"][i[0]].as_py() == pytest.approx(s["pose"]["lat_deg"])
    assert seen_in_view  # the truck is under the aircraft in some still


def test_a_vehicle_without_a_camera_ignores_the_command(interval_run: Path) -> None:
    assert not any(s["vehicle"] == "uav2" for s in _stills(interval_run))


def test_distance_triggering_spaces_stills_by_the_distance(tmp_path: Path) -> None:
    out = _run(tmp_path, "  - {at_s: 1, vehicles: uav1, command: {camera: {distance_m: 20}}}\n"
                         "  - {at_s: 6, vehicles: uav1, command: {camera: {stop: true}}}")
    stills = _stills(out)
    assert 12 <= len(stills) <= 14  # about 51 m/s for 5 s: 255 m, one at the start
    pos = np.array([(s["pose"]["lat_deg"], s["pose"]["lon_deg"]) for s in stills])
    d = np.hypot(np.diff(pos[:, 0]) * 111_320.0,
                 np.diff(pos[:, 1]) * 111_320.0 * math.cos(math.radians(37.415)))
    frame_travel = 52.0 / 10  # one frame's travel at the speed flown
    assert np.all(np.abs(d - 20.0) <= frame_travel + 1.0), d
    assert max(s["time_s"] for s in stills) < 6.0 + 0.1  # stopped


@pytest.mark.integration
def test_stills_never_change_the_states(tmp_path: Path, interval_run: Path) -> None:
    plain = _run(tmp_path, "  - {at_s: 4, vehicles: uav1, command: {camera: {stop: true}}}\n"
                           "  - {at_s: 2, vehicles: uav2, command: {camera: {stop: true}}}",
                 workers=1, name="plain")
    assert not _stills(plain)
    a, b = read_states(interval_run), read_states(plain)
    for col in ("lat_deg", "lon_deg", "alt_msl_m", "yaw_deg"):
        assert a[col].to_pylist() == b[col].to_pylist()


@pytest.mark.parametrize("camera, message", [
    ("{interval_s: 0}", "camera"),
    ("{shoot: true, interval_s: 2}", "exactly one of"),
    ("{distance_m: 50, count: 0}", "count"),
    ("{stop: 1}", "expected true"),
    ("{burst: 3}", "unknown key 'burst'")])
def test_bad_camera_commands_are_refused_with_their_line(tmp_path: Path, camera: str,
                                                         message: str) -> None:
    body = BODY.replace("SCHEDULE", f"  - {{at_s: 1, vehicles: uav1, command: {{camera: "
                                    f"{camera}}}}}").replace("WORKERS", "0")
    with pytest.raises(ConfigError) as e:
        parse_scenario(body, str(tmp_path / "bad.yaml"))
    assert message in str(e.value) and "bad.yaml:12" in str(e.value)
