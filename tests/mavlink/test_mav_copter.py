"""The quadrotor's ArduCopter personality through the MAVLink services: its
heartbeat, its modes by ArduCopter's numbers, NAV_TAKEOFF and NAV_LAND, and
a take-off, waypoint and land mission flown in AUTO item by item, and
DO_ORBIT in CIRCLE."""

from __future__ import annotations

from mavtest import S, mavutil, of_type, start_of
from test_mav_commands import heartbeat, long, one_ack
from test_mav_mission import ack_result, set_mode, upload

from cosim.vehicles.quadrotor import QUADROTOR
from cosim.vehicles.quadrotor.mavlink import ArduCopter

ML = mavutil.mavlink
REL = ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
LAT0, LON0 = start_of(0)


def test_copter_modes_takeoff_land_and_a_mission(rig) -> None:
    r = rig(1, personality=ArduCopter(), safety=QUADROTOR.safety_problems)
    hb = heartbeat(r)
    assert (hb.type, hb.autopilot, hb.custom_mode) == (
        ML.MAV_TYPE_QUADROTOR, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, 5)
    for number, nav in ((4, "loiter"), (9, None), (6, "goto"), (5, "loiter")):
        cmds, replies = set_mode(r, number)
        assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED, number
        assert heartbeat(r).custom_mode == number
        c = cmds[0].command
        assert c.nav == nav and c.land == (number in (6, 9))
    cmds, replies = set_mode(r, 0)  # STABILIZE: no pilot
    assert ack_result(replies) == ML.MAV_RESULT_FAILED and not cmds
    _, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196)  # forced
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == ML.MAV_RESULT_ACCEPTED
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 25.0)
    assert one_ack(replies, ML.MAV_CMD_NAV_TAKEOFF) == ML.MAV_RESULT_FAILED  # disarmed
    assert not cmds and any("arm first" in t.text for t in of_type(replies, "STATUSTEXT"))
    _, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == ML.MAV_RESULT_ACCEPTED
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 25.0)
    assert one_ack(replies, ML.MAV_CMD_NAV_TAKEOFF) == ML.MAV_RESULT_ACCEPTED
    assert cmds[0].command.takeoff_agl_m == 25.0 and heartbeat(r).custom_mode == 4
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_LAND)
    assert cmds[0].command.land and heartbeat(r).custom_mode == 9
    proto, _, _ = upload(r, [(REL, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0.0, 0.0, 30.0),
                             (REL, ML.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, LAT0 + 0.001, LON0, 30.0),
                             (REL, ML.MAV_CMD_NAV_LAND, 0, 0, 0, 0, LAT0 + 0.001,
                              LON0 + 0.001, 0.0)])
    assert proto[-1] == ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    cmds, replies = set_mode(r, 3)
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    take, goto = (vc.command for vc in cmds)  # in the air above 30 m: take-off done
    assert take.takeoff_agl_m == 30.0
    assert (goto.nav, goto.points[0].a, goto.points[0].b) == ("goto", LAT0 + 0.001, LON0)
    assert not of_type(replies, "STATUSTEXT")
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = LAT0 + 0.001, LON0
    land = r.step(4)[0].command
    assert land.land and (land.points[0].a, land.points[0].b) == (LAT0 + 0.001, LON0 + 0.001)
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = LAT0 + 0.001, LON0 + 0.001
    r.states[0, [S["alt_agl_m"], S["vd_mps"], S["vn_mps"], S["ve_mps"]]] = 0.1, 0.0, 0.0, 0.0
    r.step(4)
    reached = [m.seq for m in of_type(r.gcs.drain(wait_s=0.5), "MISSION_ITEM_REACHED")]
    assert reached == [2, 3] and not r.ep.vehicles[0].armed  # landed: disarmed


def test_copter_orbits_in_circle_mode(rig) -> None:
    r = rig(1, personality=ArduCopter(), safety=QUADROTOR.safety_problems)
    cmds, replies = r.request(lambda: r.gcs.mav.command_int_send(
        1, 1, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ML.MAV_CMD_DO_ORBIT, 0, 0, -25, 3, 0, 0,
        round((LAT0 + 0.001) * 1e7), round(LON0 * 1e7), 40.0))
    assert one_ack(replies, ML.MAV_CMD_DO_ORBIT) == ML.MAV_RESULT_ACCEPTED
    c = cmds[0].command
    assert (c.nav, c.loiter_radius_m, c.loiter_cw, c.airspeed_mps) == ("loiter", 25, False, 3)
    assert heartbeat(r).custom_mode == 7  # CIRCLE
