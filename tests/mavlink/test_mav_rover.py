"""The ground vehicle's ArduRover personality through the MAVLink services:
its heartbeat, its modes by ArduRover's numbers, and a waypoint mission
driven in AUTO as one ``waypoints`` command."""

from __future__ import annotations

from mavtest import S, mavutil, of_type, start_of
from test_mav_commands import heartbeat
from test_mav_mission import ack_result, set_mode, upload

from cosim.vehicles.ground import GROUND
from cosim.vehicles.ground.mavlink import ArduRover

ML = mavutil.mavlink
WP = ML.MAV_CMD_NAV_WAYPOINT
G = ML.MAV_FRAME_GLOBAL_INT
LAT0, LON0 = start_of(0)


def test_a_rover_drives_its_mission_in_auto_and_holds_in_hold(rig) -> None:
    r = rig(1, personality=ArduRover(), safety=GROUND.safety_problems)
    hb = heartbeat(r)
    assert (hb.type, hb.autopilot, hb.custom_mode) == (
        ML.MAV_TYPE_GROUND_ROVER, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, 4)
    proto, _, _ = upload(r, [(G, WP, 0, 0, 0, 0, LAT0 + 0.001, LON0, 0.0),
                             (G, ML.MAV_CMD_DO_CHANGE_SPEED, 1, 3.5, -1, 0, 0.0, 0.0, 0.0),
                             (G, WP, 0, 0, 0, 0, LAT0 + 0.001, LON0 + 0.002, 0.0),
                             (G, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0.0, 0.0, 0.0)])
    assert proto[-1] == ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    cmds, replies = set_mode(r, 10)
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    goto, speed = (vc.command for vc in cmds)  # the speed item runs as item 1 starts
    assert goto.nav == "goto" and (goto.points[0].a, goto.points[0].b) == (LAT0 + 0.001, LON0)
    assert goto.alt_m is None and speed.airspeed_mps == 3.5
    assert heartbeat(r).custom_mode == 10
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = LAT0 + 0.001, LON0
    c = r.step(4)[0].command
    assert (c.points[0].b, c.airspeed_mps) == (LON0 + 0.002, 3.5)
    cmds, replies = set_mode(r, 4)
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    assert cmds[0].command.nav == "loiter" and heartbeat(r).custom_mode == 4
    cmds, replies = set_mode(r, 0)  # MANUAL: no driver
    assert ack_result(replies) == ML.MAV_RESULT_FAILED and not cmds
    assert any("no driver" in t.text for t in of_type(replies, "STATUSTEXT"))
    assert heartbeat(r).custom_mode == 4
