"""The gimbal's ``look_at``: a gimbal camera keeps a point in its image's
centre while its aircraft flies and banks past it (checked against the
renderer's own ground truth of a target placed at the point: its box centre's
angle off the optical axis), within the gimbal's limits; its parsing."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose, look_at_angles, project, to_camera
from cosim.core.geo import LocalFrame
from cosim.errors import ConfigError
from cosim.guidance.commands import Command, parse_command
from cosim.scenario import load_scenario
from cosim.sync import Run

TRUCK_HALF_HEIGHT_M = 1.75  # the box centre of a default truck (3.5 m tall)

SCENARIO = """\
schema_version: 1
origin: {{lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 20}}
rates: {{physics_hz: 120, control_hz: {control}, log_hz: 10}}
duration_s: {dur}
seed: 5
vehicles:
  - {{id: cam, model: uav700, init: {{north_m: -260, east_m: 0, alt_agl_m: 120,
     heading_deg: 0, airspeed_kt: 100}}}}
targets:
  - {{id: truck1, kind: truck, north_m: -150, east_m: 90}}
cameras:
  render_workers: {workers}
  digest: true
  views:
    - {{name: turret, vehicles: cam, mount: gimbal, stabilised: {stab}, hfov_deg: 40,
       width_px: 96, height_px: 72, rate_hz: 30}}
schedule:
{schedule}"""

LOOK_ONLY = ("  - {at_s: 0, vehicles: cam, command: {gimbal: {look_at: "
             "{north_m: -150, east_m: 90, alt_agl_m: 1.75}}}}\n")
LOOK = LOOK_ONLY.replace("command: {", "command: {heading_deg: 40, ")


def _run(tmp_path: Path, name: str, *, control: int = 10, stab: bool = False,
         schedule: str = LOOK, dur: float = 2.0, workers: int = 0) -> Path:
    f = tmp_path / f"{name}.yaml"
    f.write_text(SCENARIO.format(control=control, stab=str(stab).lower(), schedule=schedule,
                                 dur=dur, workers=workers))
    res = Run(load_scenario(f), tmp_path / name).run()
    assert res.ok, res.error
    return tmp_path / name


def _truck(out: Path) -> list[dict[str, str]]:
    with open(out / "cameras/cam_turret.gt.csv") as f:
        return [r for r in csv.DictReader(f) if r["target"] == "truck1"]


def _events(out: Path, kind: str) -> list[dict[str, Any]]:
    lines = (out / "events.jsonl").read_text().splitlines()
    return [e for e in map(json.loads, lines) if e["event"] == kind]


@pytest.mark.parametrize("stab", [False, True])
def test_a_gimbal_looking_at_a_point_keeps_it_in_the_image_centre(tmp_path: Path,
                                                                  stab: bool) -> None:
    """The aircraft turns (banks) past the truck, exchanging at 10 Hz with
    frames at 30 Hz (two of every three between exchanges): in every frame
    the truck's box centre is on the optical axis, the image's centre, while
    the angles the gimbal takes swing through tens of degrees."""
    out = _run(tmp_path, "look", stab=stab)
    rows = _truck(out)
    assert len(rows) == 60
    for r in rows:
        assert r["in_view"] == "1", r["frame"]
        assert float(r["eccentricity_deg"]) < 0.05, r
        assert float(r["eccentricity_px"]) < 0.1, r
    [ev] = _events(out, "gimbal")
    assert ev["tick"] == 0 and ev["look_at"] == {"north_m": -150.0, "east_m": 90.0,
                                                 "alt_msl_m": 20.0 + TRUCK_HALF_HEIGHT_M}
    assert ev["source"] == "schedule" and -90.0 <= ev["pitch_deg"] < -30.0
    # the truck was east-south-east of the nose at the start: the yaw is right, ahead
    assert 30.0 < ev["yaw_deg"] < 90.0
    # the aircraft banks into its turn: a gimbal that follows the body sees it roll
    rolls = [abs(float(r["roll_deg"])) for r in _states(out)]
    assert max(rolls) > 10.0


def _states(out: Path) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    t = pq.read_table(out / "states.parquet").to_pylist()
    return [r for r in t if r["vehicle"] == "cam"]


def test_tracking_is_the_same_at_any_exchange_rate_and_ends_at_an_angle_command(
        tmp_path: Path) -> None:
    """The angles come from each frame's pose, so exchanging at 30 Hz or 10 Hz
    (and rendering inline or in a render worker) gives the same frames; a
    later angle command ends tracking (pitch only:
    the yaw stays where tracking left it) and the truck leaves the centre."""
    sched = LOOK_ONLY + "  - {at_s: 1, vehicles: cam, command: {gimbal: {pitch_deg: -60}}}\n"
    at30 = _run(tmp_path, "g30", control=30, schedule=sched)
    at10 = _run(tmp_path, "g10", control=10, schedule=sched, workers=1)
    gt = "cameras/cam_turret.gt.csv"
    assert (at30 / gt).read_text() == (at10 / gt).read_text()
    s30, s10 = (json.loads((d / "summary.json").read_text())["cameras"]["streams"]
                for d in (at30, at10))
    assert [x["frames_sha256"] for x in s30] == [x["frames_sha256"] for x in s10]
    rows = _truck(at10)
    assert all(float(r["eccentricity_px"]) < 0.1 for r in rows[:30])
    assert all(float(r["eccentricity_px"]) > 2.0 for r in rows[31:])
    tracked, fixed = _events(at10, "gimbal")
    assert fixed["tick"] == 120 and fixed["pitch_deg"] == -60.0 and "look_at" not in fixed
    assert fixed["yaw_deg"] == pytest.approx(_yaw_to_truck(at10, 120), abs=0.01)
    assert tracked["tick"] == 0


@pytest.mark.parametrize("point", [
    "{frame: start, north_m: 110, east_m: 90, alt_msl_m: 21.75}",  # cam starts at -260, 0
    "{lat_deg: 37.398648467984756, lon_deg: -121.99898356909104, alt_agl_m: 1.75}",
])
def test_look_at_takes_goto_s_other_points(tmp_path: Path, point: str) -> None:
    """The same truck, as an offset from the aircraft's start or by latitude
    and longitude: the same point, kept in the centre."""
    sched = f"  - {{at_s: 0, vehicles: cam, command: {{gimbal: {{look_at: {point}}}}}}}\n"
    out = _run(tmp_path, "other", schedule=sched, dur=0.5)
    assert all(float(r["eccentricity_px"]) < 0.1 for r in _truck(out))
    [ev] = _events(out, "gimbal")
    assert ev["look_at"] == {"north_m": -150.0, "east_m": 90.0, "alt_msl_m": 21.75}


def test_a_hold_stops_tracking_at_the_angles_of_that_tick(tmp_path: Path) -> None:
    """``look_at: null`` (MAVLink's DO_SET_ROI_NONE): the gimbal stays at the
    angles that pointed at the truck at the command's tick; the aircraft
    flies on, so the truck drifts off the centre."""
    sched = LOOK_ONLY + "  - {at_s: 1, vehicles: cam, command: {gimbal: {look_at: null}}}\n"
    out = _run(tmp_path, "hold", schedule=sched)
    rows = _truck(out)
    assert all(float(r["eccentricity_px"]) < 0.1 for r in rows[:31])  # frame 30: tick 120
    assert all(float(r["eccentricity_px"]) > 1.0 for r in rows[34:])
    _, held = _events(out, "gimbal")
    assert held["tick"] == 120 and "look_at" not in held
    assert held["yaw_deg"] == pytest.approx(_yaw_to_truck(out, 120), abs=1e-6)


def _yaw_to_truck(out: Path, tick: int) -> float:
    """The yaw that points at the truck from the logged state at ``tick``,
    worked out on its own (a level frame: a non-stabilised gimbal's yaw also
    holds the body's roll and pitch, so use the camera's own model)."""
    [r] = [s for s in _states(out) if s["tick"] == tick]
    cam = CameraSpec("c", (0,), "gimbal", -90.0, False, 40.0, 30.0, 96, 72, 30.0, 4)
    at = LocalFrame(37.4, -122.0, 20.0).place(-150.0, 90.0, 20.0 + TRUCK_HALF_HEIGHT_M)
    pitch, yaw = look_at_angles(cam, r["lat_deg"], r["lon_deg"], r["alt_msl_m"], r["roll_deg"],
                                r["pitch_deg"], r["yaw_deg"], 20.0, float(at[0]), float(at[1]),
                                20.0 + TRUCK_HALF_HEIGHT_M)
    pose = camera_pose(cam, r["lat_deg"], r["lon_deg"], r["alt_msl_m"], r["roll_deg"],
                       r["pitch_deg"], r["yaw_deg"], 20.0, (pitch, yaw))
    n, e, d = pose.local.geodetic_to_ned(float(at[0]), float(at[1]), 20.0 + TRUCK_HALF_HEIGHT_M)
    K = np.array([[cam.fx_px, 0.0, 47.5], [0.0, cam.fx_px, 35.5], [0.0, 0.0, 1.0]])
    [(u, v)] = project(K, to_camera(pose, np.array([[float(n), float(e), float(d)]])))
    assert (u, v) == pytest.approx((47.5, 35.5), abs=1e-6)  # the angles are the exact aim
    return yaw


@pytest.mark.parametrize("att", [(0.0, 0.0, 0.0), (12.0, -5.0, 33.0), (-25.0, 8.0, -140.0)])
@pytest.mark.parametrize("stab", [False, True])
@pytest.mark.parametrize("offset", [(80.0, 30.0, 0.0), (-60.0, -90.0, 5.0), (0.0, 0.0, 0.0),
                                    (300.0, -20.0, 40.0)])
def test_look_at_angles_put_the_point_on_the_optical_axis(
        att: tuple[float, float, float], stab: bool, offset: tuple[float, float, float]) -> None:
    """From any attitude, the angles turn the camera (``camera_pose``, the
    renderer's) onto the point: its projection is the principal point."""
    cam = CameraSpec("c", (0,), "gimbal", -90.0, stab, 40.0, 30.0, 96, 72, 30.0, 4)
    ground = LocalFrame(37.4, -122.0, 20.0)
    lat, lon = (float(x) for x in ground.place(10.0, -5.0, 140.0))
    n, e, h = offset
    at_lat, at_lon = (float(x) for x in ground.place(10.0 + n, -5.0 + e, 20.0 + h))
    pitch, yaw = look_at_angles(cam, lat, lon, 140.0, *att, 20.0, at_lat, at_lon, 20.0 + h)
    pose = camera_pose(cam, lat, lon, 140.0, *att, 20.0, (pitch, yaw))
    p_l = np.array([[float(x) for x in pose.local.geodetic_to_ned(at_lat, at_lon, 20.0 + h)]])
    c = to_camera(pose, p_l)
    assert c[0, 2] > 0  # in front
    K = np.array([[cam.fx_px, 0.0, 47.5], [0.0, cam.fx_px, 35.5], [0.0, 0.0, 1.0]])
    assert project(K, c)[0] == pytest.approx((47.5, 35.5), abs=1e-6)
    if stab or att == (0.0, 0.0, 0.0):  # level: the textbook elevation and bearing
        dist = math.hypot(n, e)
        assert pitch == pytest.approx(-math.degrees(math.atan2(120.0 - h, dist)), abs=0.01)
        if dist:
            assert yaw == pytest.approx(
                math.remainder(math.degrees(math.atan2(e, n)) - att[2], 360.0), abs=0.01)


def test_a_point_above_the_gimbal_s_reach_clamps_its_pitch(tmp_path: Path) -> None:
    """A point 1000 m up, 100 m ahead: 84 deg above the horizon; the gimbal
    stops at its upper limit (30) with the yaw still toward it."""
    sched = ("  - {at_s: 0, vehicles: cam, command: {gimbal: {look_at: "
             "{north_m: -160, east_m: 0, alt_agl_m: 1000}}}}\n")
    out = _run(tmp_path, "up", schedule=sched, dur=0.5, stab=True)
    [ev] = _events(out, "gimbal")
    assert ev["pitch_deg"] == 30.0
    assert abs(ev["yaw_deg"]) < 2.0


def _parse(d: Any) -> tuple[Command | None, list[str]]:
    problems: list[str] = []
    cmd = parse_command(d, ("command",), lambda p, m: problems.append(
        f"{'.'.join(map(str, p))}: {m}"))
    return cmd, problems


def test_look_at_parses_as_goto_s_point() -> None:
    cmd, problems = _parse({"gimbal": {"look_at": {"lat_deg": 37.4, "lon_deg": -122.0,
                                                   "alt_msl_m": 25}}})
    assert not problems and cmd is not None
    assert cmd.points_gimbal and not cmd.flies
    p = cmd.gimbal_look_at
    assert p is not None and (p.frame, p.a, p.b, p.alt_m, p.alt_agl) == (
        "geodetic", 37.4, -122.0, 25.0, False)
    assert cmd.label() == "gimbal look at 37.4,-122 (lat/lon)"
    cmd, problems = _parse({"gimbal": {"look_at": {"north_m": 120, "east_m": -40}}})
    assert not problems and cmd is not None and cmd.label() == "gimbal look at 120,-40"
    cmd, problems = _parse({"gimbal": {"look_at": None}})
    assert not problems and cmd is not None and cmd.gimbal_hold and cmd.points_gimbal
    assert cmd.label() == "gimbal hold" and cmd.gimbal_look_at is None


@pytest.mark.parametrize("gimbal,match", [
    ({"look_at": {"north_m": 1}, "pitch_deg": -45},
     r"command\.gimbal: give look_at or angles \(pitch_deg\), not both"),
    ({"look_at": None, "yaw_deg": 5, "pitch_deg": 0},
     r"command\.gimbal: give look_at or angles \(pitch_deg / yaw_deg\), not both"),
    ({"look_at": {"north_m": 1, "airspeed_kt": 50}},
     r"command\.gimbal\.look_at\.airspeed_kt: unknown key 'airspeed_kt'"),
    ({"look_at": 5}, r"command\.gimbal\.look_at: expected a point"),
    ({"look_at": {"alt_msl_m": 5}}, r"command\.gimbal\.look_at: missing the position"),
    ({"look_at": {"north_m": 1, "lat_deg": 3}}, r"give lat_deg/lon_deg or north_m/east_m"),
    ({"look_at": {"north_m": 1, "alt_msl_m": 1, "alt_agl_m": 2}},
     r"give only one of alt_msl_m / alt_agl_m"),
    ({"look_at": {"north_m": 1e12}}, r"look_at\.north_m: must be"),
    ({"aim": 3}, r"command\.gimbal\.aim: unknown key 'aim'; expected pitch_deg, yaw_deg, "
                 r"look_at"),
])
def test_bad_look_at_specs_are_refused(gimbal: dict[str, Any], match: str) -> None:
    _, problems = _parse({"gimbal": gimbal})
    with pytest.raises(ValueError, match=match):
        if problems:
            raise ValueError("; ".join(problems))


def test_the_schedule_refuses_a_bad_look_at_with_its_line(tmp_path: Path) -> None:
    f = tmp_path / "bad.yaml"
    f.write_text(SCENARIO.format(control=10, stab="false", dur=1, workers=0, schedule=(
        "  - {at_s: 0, vehicles: cam, command: {gimbal: {look_at: {north_m: 5}, "
        "yaw_deg: 10}}}\n")))
    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+: schedule\[0\]\.command\.gimbal: "
                                          r"give look_at or angles \(yaw_deg\), not both"):
        load_scenario(f)
