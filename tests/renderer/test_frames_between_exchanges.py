"""A camera faster than the exchange: its aircraft's states are gathered at
the frame rate inside each exchange, and the frames are exactly those of a
run exchanging at the frame rate (nothing else in these scenarios depends
on the exchange rate: no commands, no guidance)."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from cosim.errors import ConfigError
from cosim.scenario import load_scenario
from cosim.sync import Run
from tests.helpers import same_states

SCENARIO = """\
schema_version: 1
origin: {{lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 20}}
rates: {{physics_hz: 120, control_hz: {control}, log_hz: 10}}
duration_s: 2
seed: 5
vehicles:
  - {{id: cam, {cam}model: uav700, init: {{north_m: -60, east_m: 0, alt_agl_m: 120,
     heading_deg: 10, airspeed_kt: 100}}}}
  - {{id: other, {other}model: uav700, init: {{north_m: 0, east_m: 900, alt_agl_m: 300,
     heading_deg: 200, airspeed_kt: 90}}}}
targets:
  - {{id: truck1, kind: truck, north_m: 0, east_m: 0}}
cameras:
  render_workers: 0
  digest: true
  views:
    - {{name: belly, vehicles: {vehicles}, mount: nadir, vfov_deg: 40, width_px: 96,
       height_px: 72, rate_hz: 30}}
{more}"""


def _run(tmp_path: Path, name: str, control: int, backend: str = "inline",
         vehicles: str = "cam", other: str = "", more: str = "", cam: str = "") -> Path:
    f = tmp_path / f"{name}.yaml"
    f.write_text(SCENARIO.format(control=control, vehicles=vehicles, other=other, more=more,
                                 cam=cam))
    res = Run(load_scenario(f), tmp_path / name, backend=backend).run()
    assert res.ok, res.error
    return tmp_path / name


def _same_frames(at30: Path, at10: Path) -> list[str]:
    """The belly camera's frames, ground truth and the states of the two
    runs are the same; the ground truth's lines."""
    s30, s10 = (json.loads((d / "summary.json").read_text())["cameras"] for d in (at30, at10))
    (a,), (b,) = s30["streams"], s10["streams"]
    assert a["frames"] == b["frames"] == 60
    assert a["frames_sha256"] == b["frames_sha256"]
    gt = "cameras/cam_belly.gt.csv"
    lines = (at30 / gt).read_text().splitlines()
    assert len(lines) > 60 and lines == (at10 / gt).read_text().splitlines()
    assert same_states(pq.read_table(at30 / "states.parquet"),
                       pq.read_table(at10 / "states.parquet"))
    return lines


def test_frames_between_exchanges_are_those_of_a_run_at_the_frame_rate(tmp_path: Path) -> None:
    at30 = _run(tmp_path, "at30", 30)
    at10 = _run(tmp_path, "at10", 10, backend="process")  # two of every three in between
    _same_frames(at30, at10)


GIMBAL = """\
    - {name: turret, vehicles: cam, mount: {pitch_deg: -60, yaw_deg: 0}, hfov_deg: 50,
       width_px: 96, height_px: 72, rate_hz: 30}
schedule:
  - {at_s: 1, vehicles: [cam], command: {gimbal: {pitch_deg: -90, yaw_deg: 45}}}
"""


def test_a_gimbal_moved_at_an_exchange_moves_from_that_tick_on(tmp_path: Path) -> None:
    at30 = _run(tmp_path, "g30", 30, more=GIMBAL)
    at10 = _run(tmp_path, "g10", 10, more=GIMBAL)
    gt = "cameras/cam_turret.gt.csv"
    lines = (at30 / gt).read_text().splitlines()
    assert len(lines) > 60 and lines == (at10 / gt).read_text().splitlines()
    s30, s10 = (json.loads((d / "summary.json").read_text())["cameras"]["streams"]
                for d in (at30, at10))
    assert [x["frames_sha256"] for x in s30] == [x["frames_sha256"] for x in s10]


def test_a_rigid_body_aircraft_has_frames_between_exchanges(tmp_path: Path) -> None:
    """The rigid-body tier is batched but can step its batch a frame at a
    time while a camera watches one of its aircraft: the same frames and
    states as a run exchanging at the frame rate, beside a JSBSim aircraft."""
    rigid = "class: fixed_wing_rigid, "
    at30 = _run(tmp_path, "r30", 30, cam=rigid)
    at10 = _run(tmp_path, "r10", 10, backend="process", cam=rigid)
    lines = _same_frames(at30, at10)
    assert any(",truck1,1," in x for x in lines)  # it flew over the truck


def test_a_batched_aircraft_cannot_have_frames_between_exchanges(tmp_path: Path) -> None:
    with pytest.raises(AssertionError, match="stepped with its class's other vehicles"):
        _run(tmp_path, "batched", 10, vehicles="other", other="class: fixed_wing_batched, ")
    # on exchanges it can
    _run(tmp_path, "batched30", 30, vehicles="other", other="class: fixed_wing_batched, ")


def test_the_config_error_names_the_rates_that_fit(tmp_path: Path) -> None:
    f = tmp_path / "bad.yaml"
    f.write_text(SCENARIO.format(control=10, vehicles="cam", other="", more="", cam="").replace(
        "rate_hz: 30", "rate_hz: 24"))
    with pytest.raises(ConfigError, match=r"rate_hz 24: a frame every 5 ticks neither falls on "
                                          r"exchanges nor divides one .* use one of 40, 30, 20, "
                                          r"10, 5"):
        load_scenario(f)


def test_a_failed_build_finishes_no_participant_that_never_started(tmp_path: Path) -> None:
    """The cameras are made before the pool (they ask for their watch), but a
    pool that cannot be built leaves them out of the run: one error, its own."""
    import dataclasses

    f = tmp_path / "stall.yaml"
    f.write_text(SCENARIO.format(control=10, vehicles="cam", other="", more="", cam=""))
    scn = load_scenario(f)
    # a start no trim reaches (a scenario's envelope check would refuse it)
    slow = dataclasses.replace(scn.vehicles[0], airspeed_mps=2.0)
    scn = dataclasses.replace(scn, vehicles=(slow, *scn.vehicles[1:]))
    res = Run(scn, tmp_path / "run", backend="inline").run()
    assert not res.ok and "could not trim" in str(res.error)
    events = [json.loads(x) for x in (tmp_path / "run" / "events.jsonl").read_text().splitlines()]
    errors = [e for e in events if e["event"] == "error"]
    assert len(errors) == 1 and "could not trim" in errors[0]["message"], errors
    assert "cameras" not in res.summary
