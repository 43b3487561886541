"""The ground vehicle class: a batched kinematic bicycle checked against the
circle it must drive, its limits, obstacles it never enters (the model's
hard rule and the guidance's routes around them), lockstep bit-identity
across backends, scenario errors, and its ArduRover personality."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.logs import read_states
from cosim.scenario import parse_scenario
from cosim.sync import run_scenario
from cosim.vehicles.ground.model import SPEED_CMD, STEER_CMD, BicycleModel
from cosim.vehicles.registry import state_layout
from cosim.world.obstacles import inflate, inside, plan_route, segment_clear
from tests.helpers import same_states

BARN = [[40, -20], [40, 15], [55, 15], [55, -20]]
SHED = [[90, -5], [90, 30], [100, 30], [100, -5]]
WALL = [[50, 50], [50, 70], [52, 70], [52, 50]]


def _scenario(tmp_path: Path, body: str, name: str = "g") -> object:
    text = f"""\
schema_version: 1
name: {name}
origin: {{lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}}
rates: {{physics_hz: 120, control_hz: 30, log_hz: 30}}
{body}"""
    return parse_scenario(text, str(tmp_path / f"{name}.yaml"), check_properties=False)


ROUTE = f"""\
duration_s: 30
vehicles:
  - {{id: car, class: ground, max_speed_mps: 10, init: {{north_m: 0, east_m: 0}}}}
  - {{id: rammer, class: ground, init: {{north_m: 0, east_m: 60}}}}
obstacles:
  - {{id: barn, polygon: {BARN}}}
  - {{id: shed, polygon: {SHED}}}
  - {{id: wall, polygon: {WALL}}}
schedule:
  - {{at_s: 0, vehicles: car, command: {{airspeed_mps: 8, goto: {{north_m: 130, east_m: 0}}}}}}
  - {{at_s: 0, vehicles: rammer, command: {{airspeed_mps: 6, heading_deg: 0}}}}
"""


def _columns(out: Path, vehicle: str) -> dict[str, np.ndarray]:
    t = read_states(out)
    m = np.array([v == vehicle for v in t["vehicle"].to_pylist()])
    return {k: np.asarray(t[k].to_pylist())[m] for k in t.column_names if k != "vehicle"}


def test_a_routed_car_reaches_its_goal_around_obstacles_and_a_rammer_stops_short(
        tmp_path: Path) -> None:
    res = run_scenario(_scenario(tmp_path, ROUTE), tmp_path / "run", backend="inline")
    assert res.stop_reason == "completed", res.error
    car, rammer = _columns(res.out_dir, "car"), _columns(res.out_dir, "rammer")
    polys = [np.array(p, dtype=float) for p in (BARN, SHED, WALL)]
    for c in (car, rammer):  # never inside, at any logged tick (30 Hz)
        pts = np.stack([c["north_m"], c["east_m"]], axis=1)
        for poly in polys:
            assert not inside(poly, pts).any()
        assert np.all(c["alt_agl_m"] == 0.0) and np.all(c["status"] == 0)
    # the goal: stopped within 1 m of it
    assert math.hypot(car["north_m"][-1] - 130, car["east_m"][-1]) < 1.0
    assert car["airspeed_mps"][-1] < 0.05
    events = [json.loads(x) for x in (res.out_dir / "events.jsonl").read_text().splitlines()]
    goal = [e for e in events if e["event"] == "goal_reached"]
    assert [e["vehicle"] for e in goal] == ["car"]
    assert sum(e["event"] == "waypoint_reached" for e in events) >= 2  # around, not through
    # the rammer drove straight at the wall and stopped 0.5 m short (STOP_SHORT_M), +-0.3 m
    assert 50 - 0.8 < rammer["north_m"].max() < 50 - 0.2
    assert rammer["airspeed_mps"][-1] < 0.05
    # limits: speed, acceleration (logged at 30 Hz), steering
    for c, top in ((car, 8.0), (rammer, 6.0)):
        v = c["airspeed_mps"]
        assert v.max() <= top + 1e-9
        dv = np.diff(v) * 30.0
        assert dv.max() <= 2.0 + 1e-6 and dv.min() >= -4.0 - 1e-6
        assert np.abs(c["steer_deg"]).max() <= 35.0 + 1e-9


class _Spec:
    def __init__(self, params: dict, heading: float = 0.0, speed: float = 0.0) -> None:
        self.class_params = params
        self.heading_deg = heading
        self.airspeed_mps = speed
        self.terrain_alt_m = 400.0
        self.vehicle_class = "ground"


def _params(**kw: float) -> dict:
    p = {"wheelbase_m": 2.5, "max_speed_mps": 15.0, "accel_mps2": 2.0, "brake_mps2": 4.0,
         "max_steer_deg": 35.0, "steer_rate_dps": 60.0, "margin_m": 2.0,
         "origin": (47.0, 8.0, 400.0), "obstacles": (), "start_ne": (0.0, 0.0)}
    p.update(kw)
    return p


def _model(specs: list[_Spec]) -> BicycleModel:
    cols = [f.name for f in state_layout([type("S", (), {"vehicle_class": "ground"})()])]
    return BicycleModel(specs, 1 / 120, (SPEED_CMD, STEER_CMD), cols)


def _circle_error(hz: int) -> tuple[float, float]:
    """Worst distance from the circle over one full turn, and from the start after it."""
    m = _model([_Spec(_params(), heading=0.0, speed=5.0)])
    m.dt = 1 / hz
    delta = 20.0
    m.v_cmd[:] = 5.0
    m.delta[:] = math.radians(delta)
    m.delta_cmd[:] = math.radians(delta)
    r = 2.5 / math.tan(math.radians(delta))
    worst = 0.0
    for _ in range(round(2 * math.pi * r / 5.0 * hz)):
        m.step(1)
        worst = max(worst, abs(math.hypot(m.n[0], m.e[0] - r) - r))
    return worst, math.hypot(m.n[0], m.e[0])


def test_held_steering_drives_the_bicycle_circle() -> None:
    """With delta held the rear axle drives a circle of radius L / tan(delta)
    (6.87 m here), centred that far to the right; explicit Euler leaves it
    by an error of first order in dt: 2 cm over a turn at 120 Hz, half that
    at 240 Hz (L / sin(delta), the front axle's radius, would be 44 cm off)."""
    e120, back = _circle_error(120)
    e240, _ = _circle_error(240)
    assert e120 < 0.03 and back < 0.2
    assert 0.4 < e240 / e120 < 0.6


def test_the_model_stops_at_an_obstacle_it_is_driven_into() -> None:
    """No guidance: full speed straight at a wall; the model itself keeps the
    vehicle out, stopped at the boundary (within one substep's travel)."""
    wall = ((20.0, -5.0), (20.0, 5.0), (22.0, 5.0), (22.0, -5.0))
    m = _model([_Spec(_params(obstacles=(wall,)), heading=0.0, speed=10.0)])
    m.v_cmd[:] = 10.0
    for _ in range(10 * 120):
        m.step(1)
        assert not inside(np.array(wall), np.stack([m.n, m.e], axis=1)).any()
    assert 20.0 - 10.0 / 120 - 1e-9 <= m.n[0] < 20.0
    assert m.v[0] == 0.0 and m.blocked[0] == 1.0


def test_a_vehicles_state_does_not_depend_on_its_batch() -> None:
    """Elementwise: a car stepped alone equals the same car stepped with others."""
    specs = [_Spec(_params(start_ne=(i * 7.0, -3.0 * i)), heading=17.0 * i, speed=i * 1.3)
             for i in range(7)]
    together = _model(specs)
    alone = _model([specs[3]])
    for m in (together, alone):
        m.v_cmd[:] = 6.0
        m.delta_cmd[:] = math.radians(12.0)
        m.step(600)
    assert (together.n[3], together.e[3], together.psi[3]) == (alone.n[0], alone.e[0],
                                                               alone.psi[0])


def test_routes_keep_clear_of_grown_obstacles() -> None:
    polys = [inflate(np.array(p, dtype=float), 2.0) for p in (BARN, SHED)]
    path = plan_route(np.array([0.0, 0.0]), np.array([130.0, 0.0]), polys)
    assert path is not None and len(path) >= 2
    at = np.array([0.0, 0.0])
    length = 0.0
    for p in path:
        assert segment_clear(at, p, polys)
        length += float(np.hypot(*(p - at)))
        at = p
    assert 130.0 < length < 200.0
    # a goal inside an obstacle has no route
    assert plan_route(np.array([0.0, 0.0]), np.array([47.0, 0.0]), polys) is None


@pytest.mark.integration
def test_the_mixed_world_is_identical_on_every_backend(tmp_path: Path) -> None:
    """Cars, quadrotors and a fixed-wing in one clock: the same states, bit for
    bit, inline and on 2 or 3 worker processes."""
    body = f"""\
duration_s: 8
vehicles:
  - {{id: car, class: ground, count: 5, formation: {{type: line, spacing_m: 15}},
     init: {{north_m: 0, east_m: -30, heading_deg: 90}}}}
  - {{id: uav, model: uav700, init: {{north_m: -2000, east_m: 0, alt_agl_m: 300,
     heading_deg: 0, airspeed_kt: 100}}}}
  - {{id: quad, model: F450, count: 2, formation: {{type: line, spacing_m: 10}},
     init: {{north_m: 0, east_m: -60, alt_agl_m: 0}}}}
obstacles:
  - {{id: barn, polygon: {BARN}}}
schedule:
  - {{at_s: 0, vehicles: "car*", command: {{airspeed_mps: 7, goto: {{north_m: 80, east_m: 5}}}}}}
  - {{at_s: 0.5, vehicles: "quad*", command: {{takeoff_agl_m: 15}}}}
  - {{at_s: 4, vehicles: "quad*", command: {{goto: {{north_m: 20, east_m: -40}}}}}}
"""
    scn = _scenario(tmp_path, body, "mixed")
    ref = None
    for backend, workers in (("inline", None), ("process", 2), ("process", 3)):
        res = run_scenario(scn, tmp_path / f"{backend}{workers}", backend=backend,
                           workers=workers)
        assert res.stop_reason == "completed", res.error
        t = read_states(res.out_dir)
        if ref is None:
            ref = t
        assert same_states(t, ref), f"{backend} x{workers} differs from inline"


@pytest.mark.parametrize("obstacles,start,msg", [
    ("[{id: a, polygon: [[0, 0], [1, 1]]}]", "", "expected a list of 3 to 64"),
    ("[{id: a, polygon: [[0, 0], [10, 10], [10, 0], [0, 10]]}]", "", "edges cross"),
    ("[{id: a, polygon: [[0, 0], [1, 1], [2, 2]]}]", "", "no area"),
    ("[{id: a, polygon: [[-5, -5], [-5, 5], [5, 5], [5, -5]]}]", "", "starts inside obstacle"),
    ("[{id: a, polygon: [[0, 0], [0, 1], [1, 1]]}, {id: a, polygon: [[5, 5], [5, 6], [6, 6]]}]",
     "", "repeats"),
    ("[]", ", wheelbase_m: 0", "wheelbase_m"),
])
def test_scenario_errors_name_the_line(tmp_path: Path, obstacles: str, start: str,
                                       msg: str) -> None:
    body = f"""\
duration_s: 2
vehicles:
  - {{id: car, class: ground, init: {{north_m: 0.5, east_m: 0.5}}{start}}}
obstacles: {obstacles}
"""
    with pytest.raises(ConfigError) as ei:
        _scenario(tmp_path, body, "bad")
    assert any(msg in p and "bad.yaml:" in p for p in ei.value.problems), ei.value.problems


def test_it_is_an_ardurover_on_mavlink(tmp_path: Path) -> None:
    """HEARTBEAT type GROUND_ROVER starting in HOLD; modes by ArduRover's numbers
    (GUIDED 15, RTL 11, HOLD 4 accepted; MANUAL 0 refused); DO_REPOSITION
    drives it to a point in GUIDED; a plane beside it stays a plane."""
    from pymavlink import mavutil

    from cosim.core.state import N_STATE, STATE_INDEX
    from cosim.mavlink import MavlinkConfig, MavlinkEndpoint, mav_specs
    from cosim.mavlink.adapter import make_message
    from cosim.vehicles import get_class

    ML = mavutil.mavlink
    body = """\
duration_s: 2
vehicles:
  - {id: car, class: ground, init: {north_m: 0, east_m: 0}}
  - {id: uav, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0,
     airspeed_kt: 100}}
"""
    scn = _scenario(tmp_path, body, "mav")
    ep = MavlinkEndpoint(mav_specs(scn.vehicles, get_class), 120.0, MavlinkConfig(url=None))
    try:
        states = np.zeros((2, N_STATE))
        states[:, STATE_INDEX["lat_deg"]] = 47.0
        states[:, STATE_INDEX["lon_deg"]] = 8.0
        states[:, STATE_INDEX["alt_msl_m"]] = [400.0, 700.0]
        ep.exchange(0, states)
        car = ep.vehicles[0]
        assert (car.personality.mav_type, car.mode) == (ML.MAV_TYPE_GROUND_ROVER, 4)
        assert ep.vehicles[1].personality.mav_type == ML.MAV_TYPE_FIXED_WING

        def mode(number: int) -> list:
            ep.inject(make_message("SET_MODE", target_system=1,
                                   base_mode=ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                   custom_mode=number))
            return ep.exchange(0, states)

        for number, name in ((15, "GUIDED"), (11, "RTL"), (4, "HOLD")):
            mode(number)
            assert car.mode == number and car.personality.mode_name(number) == name
        assert mode(0) == [] and car.mode == 4  # MANUAL: no driver
        ep.inject(make_message("COMMAND_INT", target_system=1, target_component=1,
                               frame=ML.MAV_FRAME_GLOBAL_INT, command=ML.MAV_CMD_DO_REPOSITION,
                               current=0, autocontinue=0, param1=4.0, param2=1.0, param3=0,
                               param4=0, x=470001000, y=80000000, z=400.0))
        cmds = ep.exchange(0, states)
        assert car.mode == 15
        [c] = [c for c in cmds if c.row == 0]
        assert c.command.nav == "goto" and c.command.airspeed_mps == 4.0
        assert c.command.points[0].a == pytest.approx(47.0001)
    finally:
        ep.close()


def test_a_cars_camera_sits_on_its_roof(tmp_path: Path) -> None:
    """The forward camera is 1.5 m up (``camera_height_m``): a truck 15-25 m
    ahead on flat ground has its near bottom edge f * 1.5 / 15 px below the
    horizon (at the road surface it would be on the horizon)."""
    import csv

    body = """\
duration_s: 0.5
vehicles:
  - {id: car, class: ground, init: {north_m: 0, east_m: 0}}
targets:
  - {id: truck, kind: truck, north_m: 20, east_m: 0, heading_deg: 0}
cameras:
  render_workers: 0
  views:
    - {name: front, vehicles: car, hfov_deg: 60, width_px: 320, height_px: 240, rate_hz: 10}
"""
    res = run_scenario(_scenario(tmp_path, body, "cam"), tmp_path / "cam", backend="inline")
    assert res.stop_reason == "completed", res.error
    with open(res.out_dir / "cameras/car_front.gt.csv") as f:
        row = next(r for r in csv.DictReader(f) if r["target"] == "truck")
    f_px = 320 / 2 / math.tan(math.radians(30.0))
    assert float(row["bbox_y1_px"]) == pytest.approx((240 - 1) / 2 + f_px * 1.5 / 15.0, abs=1.0)


def test_obstacle_discovered_names_the_scout_by_its_id(tmp_path: Path) -> None:
    """The event says which vehicle's camera saw the obstacle by the vehicle's
    id (as every event names vehicles), not by its row in the state array."""
    body = f"""\
duration_s: 0.5
vehicles:
  - {{id: car, class: ground, knows_obstacles: false, scout: look,
     init: {{north_m: 0, east_m: 0}}}}
  - {{id: quad, model: F450, init: {{north_m: 45, east_m: 0, alt_agl_m: 30}}}}
obstacles:
  - {{id: barn, polygon: {BARN}}}
cameras:
  render_workers: 0
  views:
    - {{name: look, vehicles: quad, mount: nadir, vfov_deg: 60, width_px: 32, height_px: 24,
       rate_hz: 5}}
"""
    res = run_scenario(_scenario(tmp_path, body, "scout"), tmp_path / "scout", backend="inline")
    assert res.stop_reason == "completed", res.error
    events = [json.loads(x) for x in (res.out_dir / "events.jsonl").read_text().splitlines()]
    found = [e for e in events if e["event"] == "obstacle_discovered"]
    assert [(e["vehicle"], e["obstacle"], e["by"]) for e in found] == [("car", "barn", "quad")]
