"""Commands: exactly one COMMAND_ACK each, the right result, and the right
``Command`` (checked through real ``FixedWingGuidance`` where it matters)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mavtest import HOME_ALT_M, START_ALT_M, S, mavutil, of_type, start_of, state_rows

from cosim.core.geo import LocalFrame
from cosim.mavlink.adapter import make_message
from cosim.vehicles.fixed_wing.guidance import AP_CHANNELS, FixedWingGuidance
from cosim.vehicles.fixed_wing.mav_modes import PlaneMode

ML = mavutil.mavlink
ACCEPTED, DENIED, UNSUPPORTED, FAILED = (ML.MAV_RESULT_ACCEPTED, ML.MAV_RESULT_DENIED,
                                         ML.MAV_RESULT_UNSUPPORTED, ML.MAV_RESULT_FAILED)
ORIGIN = LocalFrame(47.0, 8.0, HOME_ALT_M)


def long(r, target: int, cmd: int, *params: float):
    p = list(params) + [0.0] * (7 - len(params))
    return r.request(lambda: r.gcs.mav.command_long_send(target, 1, cmd, 0, *p))


def cint(r, target: int, cmd: int, frame: int, p1: float = 0, p2: float = 0, p3: float = 0,
         p4: float = 0, x: int = 0, y: int = 0, z: float = 0):
    return r.request(lambda: r.gcs.mav.command_int_send(target, 1, frame, cmd, 0, 0, p1, p2, p3,
                                                        p4, x, y, z))


def one_ack(replies, cmd: int, src: int = 1):
    acks = of_type(replies, "COMMAND_ACK")
    assert len(acks) == 1, f"expected exactly one COMMAND_ACK, got {acks}"
    a = acks[0]
    assert a.command == cmd and a.get_srcSystem() == src
    assert (a.target_system, a.target_component) == (255, 190)
    return a.result


def heartbeat(r, sysid: int = 1):
    r.step(120)
    hb, = of_type(r.gcs.drain(wait_s=1.0), "HEARTBEAT", sysid)
    return hb


def guidance_for(n: int) -> tuple[FixedWingGuidance, np.ndarray]:
    lat = [start_of(i)[0] for i in range(n)]
    lon = [start_of(i)[1] for i in range(n)]
    start_ne = np.stack(ORIGIN.geodetic_to_ned(lat, lon, [START_ALT_M] * n)[:2], axis=1)
    g = FixedWingGuidance(n, ORIGIN, start_ne, {c: i for i, c in enumerate(AP_CHANNELS)})
    return g, np.zeros((n, len(AP_CHANNELS)))


# -- modes -----------------------------------------------------------------
def test_set_mode_message_acks_and_shows_in_the_next_heartbeat(rig) -> None:
    r = rig(3)
    cmds, replies = r.request(lambda: r.gcs.mav.set_mode_send(
        2, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PlaneMode.LOITER))
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE, src=2) == ACCEPTED
    assert len(cmds) == 1 and cmds[0].row == 1
    c = cmds[0].command
    assert c.nav == "loiter" and c.loiter_here
    assert heartbeat(r, 2).custom_mode == PlaneMode.LOITER
    assert heartbeat(r, 1).custom_mode == PlaneMode.GUIDED


def test_mavutil_set_mode_by_name_works(rig) -> None:
    """What MAVProxy's ``mode RTL`` does: pymavlink's ArduPilot mode mapping."""
    r = rig(1)
    r.gcs.conn.target_system, r.gcs.conn.target_component = 1, 1
    assert r.gcs.conn.mode_mapping()["RTL"] == PlaneMode.RTL  # it sees an ArduPlane
    cmds, replies = r.request(lambda: r.gcs.conn.set_mode("RTL"))
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == ACCEPTED
    assert heartbeat(r).custom_mode == PlaneMode.RTL


def test_do_set_mode_rtl_flies_home_at_the_rtl_altitude(rig) -> None:
    r = rig(2)
    cmds, replies = long(r, 2, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                         PlaneMode.RTL)
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE, 2) == ACCEPTED
    c = cmds[0].command
    assert c.nav == "goto"
    p = c.points[0]
    assert (p.frame, p.a, p.b) == ("geodetic", *start_of(1))
    assert c.alt_m == pytest.approx(HOME_ALT_M + 100.0) and not c.alt_agl  # ALT_HOLD_RTL
    assert c.airspeed_mps == 25.0  # AIRSPEED_CRUISE
    assert heartbeat(r, 2).custom_mode == PlaneMode.RTL


@pytest.mark.parametrize("mode, why", [(PlaneMode.AUTO, "mission"), (PlaneMode.MANUAL, "pilot"),
                                       (PlaneMode.FBWA, "not supported"), (99, "not supported")])
def test_modes_cosim_cannot_fly_fail_with_a_reason(rig, mode: int, why: str) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                         mode)
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == FAILED
    assert not cmds
    text, = of_type(replies, "STATUSTEXT")
    assert why in text.text
    assert heartbeat(r).custom_mode == PlaneMode.GUIDED


def test_set_mode_without_the_custom_flag_is_denied(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_SET_MODE, 0, PlaneMode.LOITER)
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == DENIED and not cmds


def test_vehicle_without_autopilot_is_manual_and_refuses_guided(rig) -> None:
    r = rig(1, has_autopilot=False)
    assert heartbeat(r).custom_mode == PlaneMode.MANUAL
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                         PlaneMode.GUIDED)
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == FAILED and not cmds


# -- arming ----------------------------------------------------------------
def test_disarm_in_flight_needs_force_then_arm_restores_cruise(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == FAILED and not cmds
    assert heartbeat(r).base_mode & ML.MAV_MODE_FLAG_SAFETY_ARMED

    cmds, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == ACCEPTED
    assert cmds[0].command.throttle == 0.0
    hb = heartbeat(r)
    assert not hb.base_mode & ML.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == ML.MAV_STATE_STANDBY

    # disarmed: no speed changes (the engine is off)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 30)
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == FAILED and not cmds

    cmds, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == ACCEPTED
    assert cmds[0].command.airspeed_mps == 25.0
    assert heartbeat(r).base_mode & ML.MAV_MODE_FLAG_SAFETY_ARMED


def test_arming_check_refuses_a_crashed_vehicle_unless_disabled(rig) -> None:
    r = rig(1)
    r.states[0, S["status"]] = 1  # ground impact: frozen on the ground
    r.step(4)
    assert one_ack(long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 0)[1],
                   ML.MAV_CMD_COMPONENT_ARM_DISARM) == ACCEPTED  # not flying: no force needed
    cmds, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == FAILED
    assert "PreArm" in of_type(replies, "STATUSTEXT")[0].text
    r.request(lambda: r.gcs.mav.param_set_send(1, 1, b"ARMING_CHECK", 0,
                                               ML.MAV_PARAM_TYPE_INT32))
    cmds, replies = long(r, 1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert one_ack(replies, ML.MAV_CMD_COMPONENT_ARM_DISARM) == ACCEPTED


# -- navigation ------------------------------------------------------------
@pytest.mark.parametrize("frame, alt_m, agl", [
    (ML.MAV_FRAME_GLOBAL_INT, 850.0, False),
    (ML.MAV_FRAME_GLOBAL, 850.0, False),
    (ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, HOME_ALT_M + 450.0, False),
    (ML.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, 450.0, True),
])
def test_do_reposition_goes_to_the_point_in_each_altitude_frame(rig, frame: int, alt_m: float,
                                                                agl: bool) -> None:
    r = rig(3)
    lat, lon = 47.0203, 8.0456
    z = 850.0 if frame in (ML.MAV_FRAME_GLOBAL_INT, ML.MAV_FRAME_GLOBAL) else 450.0
    cmds, replies = cint(r, 3, ML.MAV_CMD_DO_REPOSITION, frame, p1=-1,
                         p2=ML.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, p3=400, p4=1,
                         x=round(lat * 1e7), y=round(lon * 1e7), z=z)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION, 3) == ACCEPTED
    vc, = cmds
    assert vc.row == 2 and "DO_REPOSITION" in vc.origin
    c = vc.command
    assert c.nav == "goto"
    p = c.points[0]
    assert p.frame == "geodetic" and p.a == pytest.approx(lat, abs=1e-9)
    assert p.b == pytest.approx(lon, abs=1e-9)
    assert (c.alt_m, c.alt_agl) == (pytest.approx(alt_m), agl)
    assert c.loiter_radius_m == 400 and c.loiter_cw is False  # param4 = 1: counter-clockwise
    assert c.airspeed_mps is None  # -1: no change
    # guidance flies to exactly that point
    g, sp = guidance_for(3)
    g.command([2], c, r.states, sp)
    n, e, _ = ORIGIN.geodetic_to_ned(lat, lon, HOME_ALT_M)
    assert g.b[2] == pytest.approx([float(n), float(e)], abs=1e-6)
    assert sp[2, AP_CHANNELS.index("cosim/ap/alt-mode")] == (1.0 if agl else 0.0)


def test_do_reposition_speed_limits_and_guided_requirement(rig) -> None:
    r = rig(1)
    x, y = round(47.01 * 1e7), round(8.01 * 1e7)
    long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PlaneMode.LOITER)
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_REPOSITION, ML.MAV_FRAME_GLOBAL_INT, x=x, y=y, z=900)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == FAILED and not cmds  # not GUIDED
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_REPOSITION, ML.MAV_FRAME_GLOBAL_INT, p1=500,
                         p2=1, x=x, y=y, z=900)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == DENIED and not cmds  # > AIRSPEED_MAX
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_REPOSITION, ML.MAV_FRAME_GLOBAL_INT, p1=30, p2=1,
                         x=x, y=y, z=900)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == ACCEPTED
    assert cmds[0].command.airspeed_mps == 30 and cmds[0].command.loiter_cw
    assert heartbeat(r).custom_mode == PlaneMode.GUIDED


@pytest.mark.parametrize("kw", [dict(frame=ML.MAV_FRAME_LOCAL_NED, x=0, y=0, z=100),
                                dict(frame=ML.MAV_FRAME_GLOBAL_INT, x=round(95e7), y=0, z=100)])
def test_do_reposition_with_a_bad_frame_or_position_is_denied(rig, kw) -> None:
    r = rig(1)
    frame = kw.pop("frame")
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_REPOSITION, frame, **kw)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == DENIED and not cmds


def test_do_reposition_as_command_long_uses_relative_altitude(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_REPOSITION, -1, 1, 0, 0, 47.01, 8.02, 300)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == ACCEPTED
    c = cmds[0].command
    assert (c.points[0].a, c.points[0].b) == (pytest.approx(47.01), pytest.approx(8.02))
    assert c.alt_m == pytest.approx(HOME_ALT_M + 300)


def test_change_speed(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 31.5, -1)
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == ACCEPTED
    assert cmds[0].command.airspeed_mps == 31.5 and cmds[0].command.nav is None
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 5, -1)  # < AIRSPEED_MIN
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == DENIED and not cmds
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, -1, 70)
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == ACCEPTED
    assert cmds[0].command.throttle == pytest.approx(0.7)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 2, 3, -1)  # climb speed: no
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == DENIED and not cmds


def test_loiter_unlim_here_and_at_a_point(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, -300)
    assert one_ack(replies, ML.MAV_CMD_NAV_LOITER_UNLIM) == ACCEPTED
    c = cmds[0].command
    assert c.nav == "loiter" and c.loiter_here and c.loiter_radius_m == 300
    assert c.loiter_cw is False and c.alt_m is None
    assert heartbeat(r).custom_mode == PlaneMode.LOITER
    cmds, replies = cint(r, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, ML.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
                         x=round(47.005e7), y=round(8.003e7), z=250)
    assert one_ack(replies, ML.MAV_CMD_NAV_LOITER_UNLIM) == ACCEPTED
    c = cmds[0].command
    assert not c.loiter_here and c.points[0].frame == "geodetic"
    assert (c.points[0].a, c.points[0].b) == (pytest.approx(47.005), pytest.approx(8.003))
    assert (c.alt_m, c.alt_agl) == (250, True)


def test_return_to_launch(rig) -> None:
    r = rig(2)
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert one_ack(replies, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    c = cmds[0].command
    assert c.nav == "goto" and (c.points[0].a, c.points[0].b) == start_of(0)
    assert heartbeat(r).custom_mode == PlaneMode.RTL
    # again: already in RTL, nothing new to do
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert one_ack(replies, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED and not cmds


def test_takeoff_climbs_to_the_requested_height_above_home(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 800)
    assert one_ack(replies, ML.MAV_CMD_NAV_TAKEOFF) == ACCEPTED
    c = cmds[0].command
    assert c.nav == "loiter" and c.loiter_here and c.alt_m == HOME_ALT_M + 800
    assert heartbeat(r).custom_mode == PlaneMode.TAKEOFF
    # already above the takeoff altitude: loiter without descending
    long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PlaneMode.GUIDED)
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 100)
    assert one_ack(replies, ML.MAV_CMD_NAV_TAKEOFF) == ACCEPTED
    assert cmds[0].command.alt_m is None


# -- requests --------------------------------------------------------------
def test_request_message_home_version_and_extended_state(rig) -> None:
    r = rig(2)
    cmds, replies = long(r, 2, ML.MAV_CMD_REQUEST_MESSAGE, ML.MAVLINK_MSG_ID_HOME_POSITION)
    assert one_ack(replies, ML.MAV_CMD_REQUEST_MESSAGE, 2) == ACCEPTED and not cmds
    assert [m.get_type() for m in replies] == ["COMMAND_ACK", "HOME_POSITION"]  # ACK first
    home = replies[1]
    assert (home.latitude, home.longitude) == tuple(round(v * 1e7) for v in start_of(1))
    assert home.altitude == round(HOME_ALT_M * 1000)
    assert home.z == pytest.approx(START_ALT_M - HOME_ALT_M)

    _, replies = long(r, 1, ML.MAV_CMD_REQUEST_MESSAGE, ML.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert one_ack(replies, ML.MAV_CMD_REQUEST_MESSAGE) == ACCEPTED
    av, = of_type(replies, "AUTOPILOT_VERSION")
    assert av.capabilities & ML.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert av.capabilities & ML.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    assert av.flight_sw_version >> 24 == 4 and av.uid == 1

    _, replies = long(r, 1, ML.MAV_CMD_REQUEST_MESSAGE, ML.MAVLINK_MSG_ID_EXTENDED_SYS_STATE)
    ext, = of_type(replies, "EXTENDED_SYS_STATE")
    assert ext.landed_state == ML.MAV_LANDED_STATE_IN_AIR

    _, replies = long(r, 1, ML.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    assert one_ack(replies, ML.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES) == ACCEPTED
    assert of_type(replies, "AUTOPILOT_VERSION")

    _, replies = long(r, 1, ML.MAV_CMD_REQUEST_MESSAGE, ML.MAVLINK_MSG_ID_RC_CHANNELS)
    assert one_ack(replies, ML.MAV_CMD_REQUEST_MESSAGE) == DENIED
    assert [m.get_type() for m in replies] == ["COMMAND_ACK"]


def test_set_and_get_message_interval(rig) -> None:
    r = rig(1)
    att = ML.MAVLINK_MSG_ID_ATTITUDE
    _, replies = long(r, 1, ML.MAV_CMD_SET_MESSAGE_INTERVAL, att, 50_000)  # 20 Hz
    assert one_ack(replies, ML.MAV_CMD_SET_MESSAGE_INTERVAL) == ACCEPTED
    _, replies = long(r, 1, ML.MAV_CMD_GET_MESSAGE_INTERVAL, att)
    assert one_ack(replies, ML.MAV_CMD_GET_MESSAGE_INTERVAL) == ACCEPTED
    assert of_type(replies, "MESSAGE_INTERVAL")[0].interval_us == 50_000
    got = []
    for _ in range(240):  # 2 s at 120 Hz, exchanging every tick
        r.step(1)
        got += of_type(r.gcs.drain(), "ATTITUDE")
    got += of_type(r.gcs.drain(wait_s=0.3), "ATTITUDE")
    assert len(got) == 40
    _, replies = long(r, 1, ML.MAV_CMD_SET_MESSAGE_INTERVAL, att, -1)  # off
    assert one_ack(replies, ML.MAV_CMD_SET_MESSAGE_INTERVAL) == ACCEPTED
    for _ in range(5):
        r.step(120)
    assert not of_type(r.gcs.drain(wait_s=0.3), "ATTITUDE")
    _, replies = long(r, 1, ML.MAV_CMD_SET_MESSAGE_INTERVAL, ML.MAVLINK_MSG_ID_RC_CHANNELS, 1e5)
    assert one_ack(replies, ML.MAV_CMD_SET_MESSAGE_INTERVAL) == DENIED


def test_unknown_command_gets_one_unsupported_ack(rig) -> None:
    r = rig(2)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_DIGICAM_CONTROL, 1)
    assert one_ack(replies, ML.MAV_CMD_DO_DIGICAM_CONTROL) == UNSUPPORTED and not cmds
    assert r.ep.counters()["unsupported_commands"] == 1


def test_broadcast_command_is_acked_once_by_every_vehicle(rig) -> None:
    r = rig(4)
    cmds, replies = long(r, 0, ML.MAV_CMD_NAV_LOITER_UNLIM)
    acks = of_type(replies, "COMMAND_ACK")
    assert sorted(a.get_srcSystem() for a in acks) == [1, 2, 3, 4]
    assert {a.result for a in acks} == {ACCEPTED}
    assert sorted(c.row for c in cmds) == [0, 1, 2, 3]


def test_unknown_target_system_is_ignored_and_counted(rig) -> None:
    r = rig(2)
    cmds, replies = long(r, 77, ML.MAV_CMD_NAV_LOITER_UNLIM)
    assert not cmds and not of_type(replies, "COMMAND_ACK")
    assert r.ep.counters()["unknown_target_system"] == 1
    cmds, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, ML.MAV_COMP_ID_CAMERA, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, 0, 0, 0, 0, 0, 0))
    assert not cmds and not of_type(replies, "COMMAND_ACK")
    assert r.ep.counters()["other_component"] == 1


# -- position targets --------------------------------------------------------
_POS_ONLY = 0b0000_1111_1111_1000  # ignore velocity, acceleration, yaw, yaw rate


def test_set_position_target_global_int_in_guided(rig) -> None:
    r = rig(1)
    cmds, replies = r.request(lambda: r.gcs.mav.set_position_target_global_int_send(
        0, 1, 1, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, _POS_ONLY, round(47.03e7),
        round(8.04e7), 500, 0, 0, 0, 0, 0, 0, 0, 0))
    assert not of_type(replies, "COMMAND_ACK")  # no ACK for these, as in ArduPilot
    c = cmds[0].command
    assert c.nav == "goto" and (c.points[0].a, c.points[0].b) == (pytest.approx(47.03),
                                                                  pytest.approx(8.04))
    assert c.alt_m == pytest.approx(HOME_ALT_M + 500)
    # altitude only
    cmds, _ = r.request(lambda: r.gcs.mav.set_position_target_global_int_send(
        0, 1, 1, ML.MAV_FRAME_GLOBAL_INT, _POS_ONLY | 0b11, 0, 0, 1234, 0, 0, 0, 0, 0, 0, 0, 0))
    assert cmds[0].command.nav is None and cmds[0].command.alt_m == 1234
    # outside GUIDED it is ignored (ArduPlane), and counted
    long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PlaneMode.LOITER)
    cmds, _ = r.request(lambda: r.gcs.mav.set_position_target_global_int_send(
        0, 1, 1, ML.MAV_FRAME_GLOBAL_INT, _POS_ONLY, round(47.03e7), round(8.04e7), 900,
        0, 0, 0, 0, 0, 0, 0, 0))
    assert not cmds and r.ep.counters()["position_targets_ignored"] == 1


def test_set_position_target_local_ned_is_relative_to_the_start(rig) -> None:
    r = rig(3)
    x, y, z = 1500.0, -700.0, -250.0  # 1.5 km north, 700 m west, 250 m above the start
    cmds, _ = r.request(lambda: r.gcs.mav.set_position_target_local_ned_send(
        0, 3, 1, ML.MAV_FRAME_LOCAL_NED, _POS_ONLY, x, y, z, 0, 0, 0, 0, 0, 0, 0, 0))
    vc, = cmds
    c = vc.command
    assert vc.row == 2 and c.nav == "goto"
    assert (c.points[0].frame, c.points[0].a, c.points[0].b) == ("start", x, y)
    assert c.alt_m == START_ALT_M - z
    g, sp = guidance_for(3)
    g.command([2], c, r.states, sp)
    assert g.b[2] == pytest.approx(g.start_ne[2] + [x, y], abs=1e-9)


@pytest.mark.parametrize("frame", ["LOCAL_OFFSET_NED", "BODY_OFFSET_NED"])
def test_set_position_target_offsets_from_the_current_position(rig, frame: str) -> None:
    r = rig(1)
    fr = getattr(ML, f"MAV_FRAME_{frame}")
    cmds, _ = r.request(lambda: r.gcs.mav.set_position_target_local_ned_send(
        0, 1, 1, fr, _POS_ONLY, 800.0, 300.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0))
    c = cmds[0].command
    row = r.states[0]
    here = LocalFrame(row[S["lat_deg"]], row[S["lon_deg"]], row[S["alt_msl_m"]])
    n, e, _ = here.geodetic_to_ned(c.points[0].a, c.points[0].b, row[S["alt_msl_m"]])
    if frame == "BODY_OFFSET_NED":  # x forward, y right of the nose
        psi = math.radians(row[S["yaw_deg"]])
        n, e = (n * math.cos(psi) + e * math.sin(psi), -n * math.sin(psi) + e * math.cos(psi))
    assert (float(n), float(e)) == (pytest.approx(800.0, abs=1e-6), pytest.approx(300.0,
                                                                                 abs=1e-6))
    assert c.alt_m == pytest.approx(row[S["alt_msl_m"]])


def test_velocity_only_targets_are_unsupported_and_counted(rig) -> None:
    r = rig(1)
    vel_only = 0b0000_1111_1100_0111
    cmds, _ = r.request(lambda: r.gcs.mav.set_position_target_local_ned_send(
        0, 1, 1, ML.MAV_FRAME_LOCAL_NED, vel_only, 0, 0, 0, 10, 0, 0, 0, 0, 0, 0, 0))
    assert not cmds and r.ep.counters()["position_targets_unsupported"] == 1


# -- in-process clients ------------------------------------------------------
def test_injected_messages_take_the_same_path_as_network_ones(rig) -> None:
    r = rig(2)
    net, _ = long(r, 2, ML.MAV_CMD_DO_REPOSITION, -1, 1, 0, 0, 47.01, 8.02, 300)
    r.ep.inject(make_message("COMMAND_LONG", target_system=2, target_component=1,
                             command=ML.MAV_CMD_DO_REPOSITION, param1=-1, param2=1,
                             param5=47.01, param6=8.02, param7=300))
    local = r.step()
    assert [c.command for c in local] == [c.command for c in net]
    assert local[0].origin.endswith("in-process")
    # its ACK goes out like any other (to the ground stations listening)
    assert one_ack(r.gcs.drain(wait_s=1.0), ML.MAV_CMD_DO_REPOSITION, 2) == ACCEPTED


def test_states_are_read_from_each_vehicles_own_row(rig) -> None:
    r = rig(3)
    r.states = state_rows(3)[::-1].copy()  # rows swapped: vehicle 1 now reads row 0
    r.step(120)
    gp, = of_type(r.gcs.drain(wait_s=1.0), "GLOBAL_POSITION_INT", 1)
    assert gp.lat == round(r.states[0, S["lat_deg"]] * 1e7)


def test_schedule_commands_take_the_vehicle_state_path(rig) -> None:
    """A schedule item's command goes through the same vehicle state as a
    station's: steering puts the vehicle in GUIDED (the heartbeat shows it),
    a setting leaves the mode alone, and the command reaches guidance as is."""
    from cosim.guidance.commands import parse_command

    r = rig(2)
    long(r, 2, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PlaneMode.LOITER)
    assert heartbeat(r, 2).custom_mode == PlaneMode.LOITER

    def cmd(d: dict):
        c = parse_command(d, ("command",), lambda p, m: pytest.fail(m))
        assert c is not None
        return c

    speed = cmd({"airspeed_kt": 90})
    assert r.ep.local_command(1, speed) is speed
    assert heartbeat(r, 2).custom_mode == PlaneMode.LOITER  # a setting: mode unchanged
    goto = cmd({"goto": {"north_m": 1000, "east_m": 0, "frame": "start"}})
    assert r.ep.local_command(1, goto) is goto
    assert heartbeat(r, 2).custom_mode == PlaneMode.GUIDED
    assert heartbeat(r, 1).custom_mode == PlaneMode.GUIDED
    loiter = cmd({"loiter": {"radius_m": 400}})
    r.ep.local_command(1, loiter)
    assert heartbeat(r, 2).custom_mode == PlaneMode.LOITER  # a scheduled loiter: LOITER
    hdg = cmd({"heading_deg": 90})
    r.ep.local_command(1, hdg)
    assert heartbeat(r, 2).custom_mode == PlaneMode.GUIDED


@pytest.mark.parametrize("vehicle_class, personality, kinds", [
    ("quadrotor", "cosim.vehicles.quadrotor.mavlink:ArduCopter",
     [({"takeoff_agl_m": 10}, 4), ({"loiter": {}}, 5), ({"land": True}, 9),
      ({"goto": {"north_m": 10, "east_m": 0}}, 4), ({"velocity": {"north_mps": 1,
                                                                  "east_mps": 0}}, 4)]),
    ("ground", "cosim.vehicles.ground.mavlink:ArduRover",
     [({"loiter": {}}, 4), ({"goto": {"north_m": 10, "east_m": 0}}, 15)])])
def test_every_class_reports_the_mode_of_what_it_was_told(rig, vehicle_class: str,
                                                          personality: str, kinds) -> None:
    import importlib

    from cosim.guidance.commands import parse_command
    from cosim.vehicles import get_class

    mod, name = personality.split(":")
    r = rig(1, personality=getattr(importlib.import_module(mod), name)(),
            safety=get_class(vehicle_class).safety_problems)
    for d, mode in kinds:
        c = parse_command(d, ("command",), lambda p, m: pytest.fail(m))
        r.ep.local_command(0, c)
        assert heartbeat(r, 1).custom_mode == mode, d


def test_do_orbit_is_a_loiter_with_radius_and_direction(rig) -> None:
    r = rig(1)
    lat, lon = start_of(0)
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_ORBIT, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                         -400, 30, 0, 0, round((lat + 0.01) * 1e7), round(lon * 1e7), 200.0)
    assert one_ack(replies, ML.MAV_CMD_DO_ORBIT) == ACCEPTED
    c = cmds[0].command
    assert (c.nav, c.loiter_radius_m, c.loiter_cw, c.airspeed_mps) == ("loiter", 400, False, 30)
    assert (c.points[0].a, c.alt_m) == (pytest.approx(lat + 0.01), HOME_ALT_M + 200.0)
    assert heartbeat(r).custom_mode == PlaneMode.LOITER
    _, replies = cint(r, 1, ML.MAV_CMD_DO_ORBIT, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0)
    assert one_ack(replies, ML.MAV_CMD_DO_ORBIT) == DENIED


@pytest.mark.parametrize("mode", list(PlaneMode))
def test_do_set_mode_answers_every_mode_of_the_table(rig, mode: PlaneMode) -> None:
    """Each mode is entered, or refused as FAILED with a STATUSTEXT saying why
    (AUTO without a mission, a pilot's mode); never silently."""
    r = rig(1)
    _, replies = long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)
    res = one_ack(replies, ML.MAV_CMD_DO_SET_MODE)
    if mode in (PlaneMode.GUIDED, PlaneMode.LOITER, PlaneMode.RTL, PlaneMode.TAKEOFF,
                PlaneMode.CIRCLE):
        assert res == ACCEPTED and heartbeat(r).custom_mode == mode
    else:
        assert res == FAILED and of_type(replies, "STATUSTEXT"), mode.name
