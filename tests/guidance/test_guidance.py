"""Fixed-wing commands and guidance, flown in JSBSim and judged from the
logged ground truth only."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest

from cosim.core.units import KT_TO_MPS
from cosim.errors import ConfigError
from cosim.guidance import min_turn_radius_m
from cosim.logs import read_states
from cosim.scenario import load_scenario, parse_scenario
from cosim.sync import run_scenario
from tests.helpers import same_states

HEAD = """
schema_version: 1
origin: {lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 20}
duration_s: DURATION
vehicles:
  - id: a
    model: c172p
    init: {north_m: 0, east_m: 0, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 100}
  - id: b
    model: c172p
    init: {north_m: 0, east_m: 3000, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 100}
schedule:
"""


def _fly(write_scenario, tmp_path: Path, schedule: str, duration: float = 200.0,
         backend: str = "inline", **kw):
    text = HEAD.replace("DURATION", str(duration)) + schedule
    scn = load_scenario(write_scenario(text))
    res = run_scenario(scn, tmp_path / "out", backend=backend, **kw)
    assert res.ok, res.summary
    events = [json.loads(x) for x in (res.out_dir / "events.jsonl").read_text().splitlines()]
    return read_states(res.out_dir), events


def _veh(t, vid: str) -> dict[str, np.ndarray]:
    s = t.filter(pc.equal(t["vehicle"].cast("string"), vid))
    cols = {c: s[c].to_numpy() for c in s.column_names if c not in ("vehicle", "command")}
    cols["command"] = np.asarray(s["command"].cast("string").to_pylist())
    return cols


@pytest.mark.integration
def test_goto_5_km_is_reached_then_loitered(write_scenario, tmp_path: Path) -> None:
    t, ev = _fly(write_scenario, tmp_path, """
  - at_s: 0
    vehicles: a
    command: {goto: {north_m: 3000, east_m: 4000, loiter_radius_m: 500}}
""", duration=260)
    reached = [e for e in ev if e["event"] == "goal_reached"]
    assert len(reached) == 1 and reached[0]["vehicle"] == "a"
    a = _veh(t, "a")
    d = np.hypot(a["north_m"] - 3000, a["east_m"] - 4000)
    late = a["time_s"] > reached[0]["time_s"] + 60  # settled on the circle
    assert late.sum() > 100
    assert np.all(np.abs(d[late] - 500) < 60), (d[late].min(), d[late].max())
    # it circles: the bearing from the target sweeps through every quadrant
    ang = np.degrees(np.arctan2(a["east_m"][late] - 4000, a["north_m"][late] - 3000))
    assert np.histogram(ang, bins=4, range=(-180, 180))[0].min() > 0
    assert set(a["command"][late]) == {"loiter (goto reached)"}
    # b had no command: the autopilot stayed off
    b = _veh(t, "b")
    assert set(b["ap_engaged"]) == {0} and set(a["ap_engaged"][1:]) == {1}


@pytest.mark.integration
def test_waypoint_square_flown_in_order(write_scenario, tmp_path: Path) -> None:
    pts = [(2000, 3000), (2000, 5000), (0, 5000), (0, 3000)]
    wps = ", ".join(f"{{north_m: {n}, east_m: {e}}}" for n, e in pts)
    t, ev = _fly(write_scenario, tmp_path, f"""
  - at_s: 0
    vehicles: b
    command: {{waypoints: [{wps}]}}
""", duration=220)
    reached = [e for e in ev if e["event"] == "waypoint_reached"]
    assert [e["index"] for e in reached] == [0, 1, 2]
    assert all(e["vehicle"] == "b" for e in reached)
    assert [e["event"] for e in ev if e["vehicle"] == "b"][-1] == "goal_reached"
    b = _veh(t, "b")
    v = 100 * KT_TO_MPS
    accept = max(0.5 * min_turn_radius_m(v, 45), 50)
    closest = []
    for n, e in pts[:3]:
        d = np.hypot(b["north_m"] - n, b["east_m"] - e)
        assert d.min() < accept + 30, (n, e, d.min())
        closest.append(b["time_s"][np.argmin(d)])
    assert closest == sorted(closest)


@pytest.mark.integration
def test_heading_altitude_speed_holds_and_bank_limit(write_scenario, tmp_path: Path) -> None:
    t, _ = _fly(write_scenario, tmp_path, """
  - at_s: 0
    vehicles: a
    command: {heading_deg: 250, alt_agl_m: 700, airspeed_kt: 90}
  - at_s: 0
    vehicles: b
    command: {heading_deg: 180, bank_limit_deg: 25}
""", duration=120)
    a, b = _veh(t, "a"), _veh(t, "b")
    late = a["time_s"] > 80
    assert np.all(np.abs(((a["yaw_deg"][late] - 250 + 180) % 360) - 180) < 1.0)
    assert np.all(np.abs(a["alt_agl_m"][late] - 700) < 3.0)
    assert np.all(np.abs(a["airspeed_mps"][late] / KT_TO_MPS - 90) < 2.0)
    assert np.abs(a["roll_deg"]).max() <= 45 + 2
    assert np.abs(b["roll_deg"]).max() <= 25 + 2
    assert np.abs(b["roll_deg"]).max() > 20  # it did bank towards the limit
    assert set(b["bank_limit_deg"][1:]) == {25.0} and set(a["bank_limit_deg"]) == {45.0}
    assert np.all(np.abs(((b["yaw_deg"][late] - 180 + 180) % 360) - 180) < 1.0)


@pytest.mark.integration
def test_goto_relative_to_each_start(write_scenario, tmp_path: Path) -> None:
    t, ev = _fly(write_scenario, tmp_path, """
  - at_s: 0
    vehicles: all
    command: {goto: {frame: start, north_m: 2500, east_m: 0, loiter_radius_m: 450}}
""", duration=120)
    goals = {e["vehicle"]: (e["north_m"], e["east_m"]) for e in ev
             if e["event"] == "goal_reached"}
    assert goals["a"] == pytest.approx((2500, 0), abs=1e-6)
    assert goals["b"] == pytest.approx((2500, 3000), abs=0.05)  # b started 3000 m east


@pytest.mark.integration
def test_guided_flight_is_deterministic_across_backends(write_scenario, tmp_path: Path
                                                        ) -> None:
    sched = """
  - at_s: 0
    vehicles: all
    command: {goto: {frame: start, north_m: 2000, east_m: 1000}, airspeed_kt: 95}
"""
    a, _ = _fly(write_scenario, tmp_path / "i", sched, duration=40)
    b, _ = _fly(write_scenario, tmp_path / "p", sched, duration=40, backend="process",
                workers=2)
    assert same_states(a, b)


def test_stall_with_protection_off_and_protected_without(write_scenario, tmp_path: Path
                                                          ) -> None:
    t, ev = _fly(write_scenario, tmp_path, """
  - at_s: 0
    vehicles: a
    command: {stall_protection: false, throttle: 0}
  - at_s: 0
    vehicles: b
    command: {throttle: 0}
""", duration=90)
    stalls = [e for e in ev if e["event"] == "stall"]
    assert stalls and stalls[0]["vehicle"] == "a" and stalls[0]["phase"] == "onset"
    assert not [e for e in stalls if e["vehicle"] == "b"]
    prot = [e for e in ev if e["event"] == "stall_protection"]
    assert prot and {e["vehicle"] for e in prot} == {"b"} and prot[0]["phase"] == "active"
    a = _veh(t, "a")
    onset = a["time_s"] >= stalls[0]["time_s"]
    assert a["stalled"][onset][0] == 1
    assert a["vd_mps"][onset].max() > 5  # the stalled wing drops the aircraft


SCHEMA = """
schema_version: 1
origin: {lat_deg: 37.4, lon_deg: -122.0}
duration_s: 100
vehicles:
  - {id: a, model: c172p, init: {alt_msl_m: 600, airspeed_kt: 100}}
  - {id: f, model: f16, init: {north_m: 5000, alt_msl_m: 3000, airspeed_kt: 400}}
schedule:
"""


@pytest.mark.parametrize("vehicles,cmd,message", [
    ("a", "{headng_deg: 5}",
     r"s\.yaml:\d+: schedule\[0\]\.command\.headng_deg: unknown command 'headng_deg'"),
    ("a", "{airspeed_kt: 200}",
     r"airspeed 200\.0 kt is outside the envelope of c172p \(55\.\.140 kt TAS\)"),
    ("a", "{loiter: {radius_m: 200}}",
     r"loiter radius 200 m is below the minimum turn radius of a \(\d+ m at 100 kt and a 45 "
     r"deg bank limit\)"),
    ("a", "{bank_limit_deg: 20, goto: {north_m: 0, loiter_radius_m: 400}}",
     r"below the minimum turn radius of a \(\d+ m at 100 kt and a 20 deg bank limit\)"),
    ("f", "{heading_deg: 5}", r"model f16 \(class jsbsim\) takes no commands"),
    ("a", "{goto: {north_m: 1}, heading_deg: 3}", r"heading_deg and goto conflict"),
    ("a", "{goto: {frame: start, lat_deg: 37, lon_deg: -122}}",
     r"frame: start takes north_m/east_m offsets"),
    ("a", "{throttle: 1.5}", r"command\.throttle: must be 0\.\.1"),
    ("a", "{throttle: 0.5, airspeed_kt: 90}", r"throttle \(manual\) and an airspeed hold"),
])
def test_bad_commands_are_rejected_at_validation(vehicles: str, cmd: str, message: str) -> None:
    text = SCHEMA + f"  - at_s: 1\n    vehicles: {vehicles}\n    command: {cmd}\n"
    with pytest.raises(ConfigError, match=message):
        parse_scenario(text, "s.yaml")


def test_min_turn_radius_is_the_design_equation() -> None:
    v = 200 * KT_TO_MPS
    assert min_turn_radius_m(v, 45) == pytest.approx(v * v / 9.80665)
    assert min_turn_radius_m(v, 45) == pytest.approx(1079.5, abs=0.5)  # docs/physics.md: ~1.08 km
    assert min_turn_radius_m(v, 30) == pytest.approx(v * v / (9.80665 * math.tan(math.pi / 6)))
