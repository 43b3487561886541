"""A fixed-wing's ``land``: on a 3-degree glide path to the point (at the end
of a goto or a route, or straight ahead), a gentle touchdown near the point
that is a landing and not an impact, then a roll-out to a stop on the ground,
on skids (the uav700) and on wheels with brakes (JSBSim's c172p)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cosim.logs import read_states
from cosim.scenario import parse_scenario
from cosim.sync import run_scenario
from cosim.vehicles.fixed_wing.guidance import GLIDE_DEG

SCENARIO = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 150
vehicles:
  - {id: goto, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 100, airspeed_kt: 70}}
  - {id: ahead, model: uav700,
     init: {north_m: 0, east_m: 3000, alt_agl_m: 60, airspeed_kt: 70, heading_deg: 90}}
  - {id: route, model: uav700, init: {north_m: 0, east_m: -3000, alt_agl_m: 100, airspeed_kt: 70}}
  - {id: cessna, model: c172p, init: {north_m: 0, east_m: 6000, alt_agl_m: 100, airspeed_kt: 90}}
schedule:
  - {at_s: 1, vehicles: goto,
     command: {goto: {north_m: 3000, east_m: 500}, airspeed_kt: 60, land: true}}
  - {at_s: 1, vehicles: ahead, command: {land: true, airspeed_kt: 60}}
  - {at_s: 100, vehicles: ahead, command: {heading_deg: 0, alt_agl_m: 100}}
  - {at_s: 1, vehicles: cessna,
     command: {goto: {north_m: 3000, east_m: 6500}, airspeed_kt: 65, land: true}}
  - {at_s: 1, vehicles: route, command: {airspeed_kt: 60, land: true, waypoints: [
      {north_m: 1000, east_m: -3000}, {north_m: 1000, east_m: -2000},
      {north_m: 3000, east_m: -2000}]}}
"""
#: where each lands: the goto's point, the route's last point
POINTS = {"goto": (3000.0, 500.0), "route": (3000.0, -2000.0), "cessna": (3000.0, 6500.0)}
ALL = ["goto", "ahead", "route", "cessna"]


pytestmark = pytest.mark.integration  # landings flown to the ground


@pytest.fixture(scope="module")
def landed(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, list[dict]]:
    out = tmp_path_factory.mktemp("land") / "run"
    scn = parse_scenario(SCENARIO, str(out.parent / "land.yaml"), check_properties=False)
    res = run_scenario(scn, out, backend="inline")
    assert res.stop_reason == "completed", res.error
    t = read_states(out)
    who = np.array(t["vehicle"].to_pylist())
    cols = {v: {k: np.asarray(t[k].to_pylist())[who == v] for k in t.column_names
                if k != "vehicle"} for v in ALL}
    events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    return cols, events


def _touchdown_row(c: dict) -> int:
    return int(np.argmax(c["contact_force_n"] > 0.0))


@pytest.mark.parametrize("vehicle", ["goto", "route", "cessna"])
def test_it_touches_down_at_the_point_gently(landed, vehicle: str) -> None:
    """Skids (the uav700) or wheels (the c172p) on the ground within 30 m of
    the point, sinking slower than 2 m/s, with level wings."""
    cols, events = landed
    c = cols[vehicle]
    i = _touchdown_row(c)
    assert c["contact_force_n"][i] > 0.0 and c["time_s"][i] > 30.0
    assert np.all(c["contact_force_n"][:i] == 0.0)
    pn, pe = POINTS[vehicle]
    assert math.hypot(c["north_m"][i] - pn, c["east_m"][i] - pe) < 30.0
    if vehicle == "route":  # its last leg runs north along east = -2000 m
        assert abs(c["east_m"][i] - pe) < 5.0
    [td] = [e for e in events if e["event"] == "touchdown" and e["vehicle"] == vehicle]
    assert -30.0 < td["distance_m"] < 30.0
    assert 0.0 < td["sink_mps"] < 2.0
    assert abs(c["roll_deg"][i]) < 5.0


def test_the_goto_lands_on_its_own_track(landed) -> None:
    """The approach is the goto's leg: at touchdown the aircraft is within 5 m
    of the line from where the leg began through the point."""
    c = landed[0]["goto"]
    i = _touchdown_row(c)
    a = np.array([c["north_m"][0], c["east_m"][0]])  # the goto began here (at 1 s, close)
    b = np.array(POINTS["goto"])
    u = (b - a) / np.hypot(*(b - a))
    p = np.array([c["north_m"][i], c["east_m"][i]]) - b
    assert abs(p[0] * u[1] - p[1] * u[0]) < 5.0


@pytest.mark.parametrize("vehicle", ALL)
def test_the_descent_follows_the_glide_path(landed, vehicle: str) -> None:
    """In the middle of the descent (60 % down to 20 % of its height), the
    flight path angle is the glide path's 3 degrees within one degree."""
    c = landed[0][vehicle]
    i = _touchdown_row(c)
    top = float(c["alt_agl_m"][:i].max()) if vehicle == "ahead" else 100.0
    mid = (np.arange(len(c["time_s"])) < i) & (c["alt_agl_m"] < 0.6 * top) \
        & (c["alt_agl_m"] > 0.2 * top)
    assert mid.sum() > 50
    gamma = np.degrees(np.arctan2(c["vd_mps"][mid], np.hypot(c["vn_mps"][mid], c["ve_mps"][mid])))
    assert abs(float(np.median(gamma)) - GLIDE_DEG) < 1.0


@pytest.mark.parametrize("vehicle", ALL)
def test_it_rolls_to_a_stop_and_is_never_an_impact(landed, vehicle: str) -> None:
    cols, events = landed
    c = cols[vehicle]
    assert np.all(c["status"] == 0)  # no impact, no crash, at any time
    assert not any(e["event"] in ("impact", "crash") and e.get("vehicle") == vehicle
                   for e in events)
    [stop] = [e for e in events if e["event"] == "landed" and e["vehicle"] == vehicle]
    after = c["time_s"] >= stop["time_s"]
    assert after.sum() > 10
    assert np.hypot(c["vn_mps"][after], c["ve_mps"][after]).max() < 0.5
    assert np.all(c["contact_force_n"][after] > 0.0)  # on the ground
    assert np.ptp(c["alt_agl_m"][after]) < 0.05
    assert c["command"][-1] == "landed"


def test_land_alone_lands_straight_ahead(landed) -> None:
    """No point given: it keeps its heading (east) and lands where the glide
    path from its height meets the ground."""
    c = landed[0]["ahead"]
    i = _touchdown_row(c)
    assert abs(c["north_m"][i]) < 10.0
    expected = 3000.0 + 60.0 / math.tan(math.radians(GLIDE_DEG))
    assert abs(c["east_m"][i] - expected) < 0.1 * expected


def test_on_the_ground_it_stays_there(landed) -> None:
    """After the touchdown no stall or stall-protection events (alpha means
    nothing at rest), and a command to fly on is ignored with an event: a
    fixed-wing does not take off again."""
    cols, events = landed
    for v in ALL:
        [td] = [e for e in events if e["event"] == "touchdown" and e["vehicle"] == v]
        assert not [e for e in events if e.get("vehicle") == v and e["time_s"] > td["time_s"]
                    and e["event"] in ("stall", "stall_protection")]
    [ign] = [e for e in events if e["event"] == "command_ignored"]
    assert (ign["vehicle"], ign["time_s"]) == ("ahead", 100.0)
    assert "take off" in ign["reason"]
    c = cols["ahead"]
    late = c["time_s"] > 100.0
    assert np.hypot(c["vn_mps"][late], c["ve_mps"][late]).max() < 0.5
    assert np.all(c["throttle"][late] == 0.0)
