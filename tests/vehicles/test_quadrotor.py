"""The quadrotor class (the F450 with its controller as a JSBSim system):
take-off, hover and landing hold their position, a goto stops on its
point at its speed, headings and velocity setpoints are flown, and the
fixed-wing refuses what only a hovering vehicle can do."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.logs import read_states
from cosim.scenario import load_scenario, parse_scenario
from cosim.sync import run_scenario

REPO = Path(__file__).resolve().parent.parent.parent


def _columns(out: Path, vehicle: str) -> dict[str, np.ndarray]:
    t = read_states(out)
    m = np.array([v == vehicle for v in t["vehicle"].to_pylist()])
    return {k: np.asarray(t[k].to_pylist())[m] for k in t.column_names if k != "vehicle"}


@pytest.fixture(scope="module")
def hover_goto(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, np.ndarray], list]:
    out = tmp_path_factory.mktemp("quad") / "run"
    res = run_scenario(load_scenario(REPO / "scenarios/quadrotor/hover_goto.yaml"), out,
                       backend="inline")
    assert res.stop_reason == "completed", res.error
    events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    return _columns(out, "quad"), events


def test_take_off_and_hover_hold_position(hover_goto) -> None:
    """Take-off at 1 s to 20 m: straight up, within 0.2 m of the start; the
    height closes on 20 m with the altitude loop's 1 s time constant (within
    0.25 m half a second before the goto at 10 s)."""
    c, _ = hover_goto
    t = c["time_s"]
    climb = (t >= 1.0) & (t < 10.0)
    assert np.hypot(c["north_m"][climb], c["east_m"][climb]).max() < 0.2
    assert c["alt_agl_m"][t < 1.0].max() < 0.2  # on its legs until then
    hover = (t >= 9.5) & (t < 10.0)
    assert np.abs(c["alt_agl_m"][hover] - 20.0).max() < 0.25
    assert np.all(c["status"] == 0)


def test_a_goto_stops_on_its_point_at_its_speed(hover_goto) -> None:
    c, events = hover_goto
    t = c["time_s"]
    leg = (t >= 10.0) & (t < 28.0)
    speed = np.hypot(c["vn_mps"][leg], c["ve_mps"][leg])
    assert 5.5 < speed.max() <= 6.05  # the commanded 6 m/s, less drag's share
    [goal] = [e for e in events if e["event"] == "goal_reached"]
    after = t >= goal["time_s"]
    d = np.hypot(c["north_m"][after & (t < 28)] - 40.0, c["east_m"][after & (t < 28)] - 45.0)
    assert d.max() < 1.0  # stopped on it (overshoot included)
    hold = (t >= 26.0) & (t < 28.0)
    assert np.hypot(c["vn_mps"][hold], c["ve_mps"][hold]).max() < 0.3
    turned = (t >= 31.0) & (t < 32.0)  # heading 270 at 28 s
    assert np.abs(c["yaw_deg"][turned] - 270.0).max() < 2.0


def test_landing_holds_position_and_stops_the_motors(hover_goto) -> None:
    c, events = hover_goto
    t = c["time_s"]
    down = t >= 32.0
    assert np.hypot(c["north_m"][down] - 40.0, c["east_m"][down] - 45.0).max() < 0.3
    vd = c["vd_mps"][down & (c["alt_agl_m"] > 1.0)]
    assert vd.max() <= 1.5 * 1.12  # the sink limit (the climb loop overshoots it by 8%)
    assert [e["vehicle"] for e in events if e["event"] == "landed"] == ["quad"]
    assert c["alt_agl_m"][-1] < 0.2 and abs(c["vd_mps"][-1]) < 0.05


def test_velocity_setpoints_are_flown(tmp_path: Path) -> None:
    body = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 30}
duration_s: 12
vehicles:
  - {id: q, model: F450, init: {north_m: 0, east_m: 0, alt_agl_m: 30}}
schedule:
  - {at_s: 1, vehicles: q, command: {velocity: {north_mps: -3, east_mps: 4}}}
"""
    scn = parse_scenario(body, str(tmp_path / "v.yaml"), check_properties=False)
    res = run_scenario(scn, tmp_path / "v", backend="inline")
    assert res.stop_reason == "completed", res.error
    c = _columns(res.out_dir, "q")
    late = c["time_s"] > 8.0
    assert np.abs(c["vn_mps"][late] + 3.0).max() < 0.3
    assert np.abs(c["ve_mps"][late] - 4.0).max() < 0.3
    assert np.abs(c["alt_agl_m"][late] - 30.0).max() < 0.5
    assert c["command"][-1] == "velocity -3 4"


def test_a_fixed_wing_refuses_what_only_a_hovering_vehicle_does(tmp_path: Path) -> None:
    body = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
duration_s: 5
vehicles:
  - {id: uav, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}
  - {id: q, model: F450, init: {north_m: 0, east_m: 0, alt_agl_m: 30}}
schedule:
  - {at_s: 1, vehicles: uav, command: {takeoff_agl_m: 50}}
  - {at_s: 1, vehicles: q, command: {airspeed_mps: 40, goto: {north_m: 10, east_m: 0}}}
  - {at_s: 1, vehicles: q, command: {throttle: 0.5}}
"""
    with pytest.raises(ConfigError) as ei:
        parse_scenario(body, str(tmp_path / "bad.yaml"), check_properties=False)
    msgs = "\n".join(ei.value.problems)
    assert "a fixed-wing cannot take off vertically" in msgs
    assert "a quadrotor flies at 0..15 m/s, not 40" in msgs
    assert "throttle, bank limits and stall protection are for fixed-wings" in msgs


def test_a_loiter_with_a_radius_orbits_the_centre(tmp_path: Path) -> None:
    """A loiter with radius 20 m at 4 m/s: after closing on the circle, the
    quadrotor stays within 2 m of it and goes round clockwise (its bearing
    from the centre grows) at close to 4 m/s: one turn in about 2 pi 20 / 4 s."""
    body = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 75
vehicles:
  - {id: quad, model: F450, init: {north_m: 0, east_m: 0, alt_agl_m: 15}}
schedule:
  - {at_s: 2, vehicles: quad, command: {airspeed_mps: 4,
     loiter: {center: {north_m: 30, east_m: 0}, radius_m: 20}}}
"""
    scn = parse_scenario(body, str(tmp_path / "o.yaml"), check_properties=False)
    res = run_scenario(scn, tmp_path / "o", backend="inline")
    assert res.stop_reason == "completed", res.error
    c = _columns(tmp_path / "o", "quad")
    t = c["time_s"]
    on = t >= 30.0
    dn, de = c["north_m"][on] - 30.0, c["east_m"][on]
    assert np.abs(np.hypot(dn, de) - 20.0).max() < 2.0
    bearing = np.unwrap(np.arctan2(de, dn))
    assert np.all(np.diff(bearing) > 0)  # clockwise seen from above
    turns = (bearing[-1] - bearing[0]) / (2 * np.pi)
    expected = 4.0 * (t[on][-1] - t[on][0]) / (2 * np.pi * 20.0)
    assert turns == pytest.approx(expected, rel=0.15)
