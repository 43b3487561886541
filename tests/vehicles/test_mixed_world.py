"""Three classes in one run on MAVLink: each vehicle's heartbeat (in its tlog)
carries its own class's type, autopilot and starting mode."""

from __future__ import annotations

from pathlib import Path

from cosim.mavlink import MavlinkConfig
from cosim.scenario import parse_scenario
from cosim.sync import run_scenario

BODY = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
duration_s: 3
vehicles:
  - {id: plane, model: uav700, init: {north_m: -2000, east_m: 0, alt_agl_m: 300,
     heading_deg: 0, airspeed_kt: 100}}
  - {id: quad, model: F450, init: {north_m: 0, east_m: 0, alt_agl_m: 20}}
  - {id: car, class: ground, init: {north_m: 0, east_m: 30}}
"""


def test_a_ground_station_sees_three_types_with_their_own_modes(tmp_path: Path) -> None:
    from pymavlink import mavutil

    ML = mavutil.mavlink
    scn = parse_scenario(BODY, str(tmp_path / "mixed.yaml"), check_properties=False)
    res = run_scenario(scn, tmp_path / "run", backend="inline", mavlink=MavlinkConfig(url=None))
    assert res.stop_reason == "completed", res.error
    seen = {}
    for name in ("plane", "quad", "car"):
        log = mavutil.mavlink_connection(str(tmp_path / "run" / f"{name}.tlog"),
                                         dialect="ardupilotmega")
        hb = log.recv_match(type="HEARTBEAT")
        seen[name] = (hb.type, hb.autopilot, mavutil.mode_string_v10(hb))
    assert seen == {
        "plane": (ML.MAV_TYPE_FIXED_WING, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, seen["plane"][2]),
        "quad": (ML.MAV_TYPE_QUADROTOR, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, "LOITER"),
        "car": (ML.MAV_TYPE_GROUND_ROVER, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, "HOLD")}
    assert seen["plane"][2] in ("MANUAL", "FBWA", "GUIDED", "CRUISE", "LOITER", "AUTO")
