"""The ArduPilot mission items beyond waypoints, flown item by item from
synthetic state rows: DO_JUMP with its repeat count, the loiters with an end
(turns, time, altitude), CONDITION_DELAY and CONDITION_DISTANCE holding back
the DO items after them, DO_SET_HOME, DO_SET_ROI (the gimbal follows the
point), fence and rally lists (a breach switches to RTL with an event; RTL
goes to the nearest rally point), and what AUTOPILOT_VERSION and SYS_STATUS
claim, and a fixed-wing's NAV_LAND (item and command)."""

from __future__ import annotations

import math

import pytest
from mavtest import HOME_ALT_M, PHYSICS_HZ, S, mavutil, of_type, start_of
from test_mav_mission import (
    HOME_ITEM,
    REL,
    WP,
    ack_result,
    download,
    protocol,
    reach,
    send_item,
    set_mode,
    upload,
)

from cosim.vehicles.fixed_wing.mav_modes import PlaneMode

ML = mavutil.mavlink
LAT0, LON0 = start_of(0)
A = (REL, WP, 0, 0, 0, 0, LAT0 + 0.02, LON0, 150.0)
B = (REL, WP, 0, 0, 0, 0, LAT0 + 0.02, LON0 + 0.03, 150.0)
C = (REL, WP, 0, 0, 0, 0, LAT0, LON0 + 0.03, 150.0)


def at(item: tuple) -> tuple[float, float]:
    return item[6], item[7]


def test_do_jump_repeats_then_goes_on(rig) -> None:
    r = rig(1)
    upload(r, [A, B, (REL, ML.MAV_CMD_DO_JUMP, 1, 2, 0, 0, 0, 0, 0), C])
    set_mode(r, PlaneMode.AUTO)
    seen = []
    for target in (A, B, A, B, A, B, C):
        _, reached = reach(r, *at(target))
        seen += reached
    assert seen == [1, 2, 1, 2, 1, 2, 4]  # jumped back twice, then on to item 4
    assert r.ep.vehicles[0].mission.complete


def test_a_jump_for_ever_and_a_loop_without_navigation(rig) -> None:
    r = rig(1)
    upload(r, [A, (REL, ML.MAV_CMD_DO_JUMP, 1, -1, 0, 0, 0, 0, 0), C])
    set_mode(r, PlaneMode.AUTO)
    seen = []
    for _ in range(5):
        seen += reach(r, *at(A))[1]
    assert seen == [1] * 5
    # a jump to itself: no navigation between, the mission stops instead of hanging
    upload(r, [(REL, ML.MAV_CMD_DO_JUMP, 1, -1, 0, 0, 0, 0, 0), A])
    cmds, replies = set_mode(r, PlaneMode.LOITER)
    cmds, replies = set_mode(r, PlaneMode.AUTO)
    assert ack_result(replies) == ML.MAV_RESULT_FAILED
    assert any("DO_JUMP loop" in t.text for t in of_type(replies, "STATUSTEXT"))


def circle_point(lat0: float, lon0: float, radius_m: float, deg: float) -> tuple[float, float]:
    n, e = radius_m * math.cos(math.radians(deg)), radius_m * math.sin(math.radians(deg))
    return lat0 + n / 111_319.49, lon0 + e / (111_319.49 * math.cos(math.radians(lat0)))


@pytest.mark.integration
def test_loiter_turns_ends_after_its_turns_round_the_centre(rig) -> None:
    r = rig(1)
    centre = (LAT0 + 0.01, LON0)
    upload(r, [(REL, ML.MAV_CMD_NAV_LOITER_TURNS, 2, 0, 400, 0, *centre, 150.0), C])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    c = cmds[0].command
    assert c.nav == "loiter" and c.loiter_radius_m == 400.0 and c.loiter_cw
    reached: list[int] = []
    steps = 0
    for k in range(0, 3 * 360, 30):  # clockwise round the centre
        _, got = reach(r, *circle_point(*centre, 400.0, k), ticks=12)
        reached += got
        steps += 1
        if got:
            break
    assert reached == [1]
    assert steps == 2 * 12 + 1  # two full turns from the first point on the circle


def test_loiter_time_counts_from_reaching_the_circle(rig) -> None:
    r = rig(1)
    centre = (LAT0 + 0.01, LON0)
    upload(r, [(REL, ML.MAV_CMD_NAV_LOITER_TIME, 10, 0, 300, 0, *centre, 150.0), C])
    set_mode(r, PlaneMode.AUTO)
    assert reach(r, *circle_point(*centre, 3000.0, 0), int(PHYSICS_HZ) * 20)[1] == []
    assert reach(r, *circle_point(*centre, 300.0, 0))[1] == []  # on the circle: 10 s
    assert reach(r, *circle_point(*centre, 300.0, 90), int(PHYSICS_HZ) * 9)[1] == []
    assert reach(r, *circle_point(*centre, 300.0, 180), int(PHYSICS_HZ) * 1)[1] == [1]


def test_loiter_to_alt_ends_at_its_altitude(rig) -> None:
    r = rig(1)
    centre = (LAT0 + 0.01, LON0)
    upload(r, [(ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_NAV_LOITER_TO_ALT, 0, 250, 0, 0, *centre,
                700.0), C])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    assert cmds[0].command.alt_m == 700.0 and cmds[0].command.loiter_radius_m == 250.0
    assert reach(r, *circle_point(*centre, 250.0, 0))[1] == []  # at 987 m: too high
    r.states[0, S["alt_msl_m"]] = 703.0
    assert reach(r, *circle_point(*centre, 250.0, 10))[1] == [1]


def test_conditions_hold_back_the_do_items_after_them(rig) -> None:
    r = rig(1)
    upload(r, [A, (REL, ML.MAV_CMD_CONDITION_DELAY, 3, 0, 0, 0, 0, 0, 0),
               (REL, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 28, -1, 0, 0, 0, 0),
               (REL, ML.MAV_CMD_CONDITION_DISTANCE, 500, 0, 0, 0, 0, 0, 0),
               (REL, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 32, -1, 0, 0, 0, 0), B])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    assert [vc.command.airspeed_mps for vc in cmds] == [25.0]  # the goto only
    far = circle_point(*at(A), 2000.0, 180)
    assert [vc.command.airspeed_mps for vc in reach(r, *far, int(PHYSICS_HZ) * 2)[0]] == []
    assert [vc.command.airspeed_mps for vc in reach(r, *far, int(PHYSICS_HZ))[0]] == [28.0]
    assert reach(r, *far, int(PHYSICS_HZ) * 5)[0] == []  # 2 km from A: not within 500 m
    near = circle_point(*at(A), 400.0, 180)
    assert [vc.command.airspeed_mps for vc in reach(r, *near)[0]] == [32.0]


def test_do_set_home_moves_home(rig) -> None:
    r = rig(1)
    upload(r, [(ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, LAT0 + 0.005,
                LON0 + 0.005, 450.0), A])
    _, replies = set_mode(r, PlaneMode.AUTO)
    home, = of_type(replies, "HOME_POSITION")
    assert (home.latitude, home.longitude, home.altitude) == (
        round((LAT0 + 0.005) * 1e7), round((LON0 + 0.005) * 1e7), 450_000)
    assert r.ep.vehicles[0].home == (pytest.approx(LAT0 + 0.005), pytest.approx(LON0 + 0.005),
                                     450.0)


def test_do_set_roi_points_the_gimbal_at_the_point(rig) -> None:
    """DO_SET_ROI_LOCATION: one gimbal command to look at the point (the
    cameras keep it in view from then on); ROI_NONE: one to stop tracking."""
    r = rig(1)
    roi = (LAT0 + 0.003, LON0 + 0.003)
    upload(r, [(ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_DO_SET_ROI_LOCATION, 0, 0, 0, 0, *roi,
                HOME_ALT_M + 2), A, B, (REL, ML.MAV_CMD_DO_SET_ROI_NONE, 0, 0, 0, 0, 0, 0, 0),
               C])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    [g] = [vc.command for vc in cmds if vc.command.points_gimbal]
    p = g.gimbal_look_at
    assert p is not None and (p.frame, p.alt_m, p.alt_agl) == ("geodetic", HOME_ALT_M + 2, False)
    assert (p.a, p.b) == pytest.approx(roi, abs=1e-7)
    assert g.gimbal_pitch_deg is None and not g.gimbal_hold and not g.flies
    assert not [c for c in r.step(4) if c.command.points_gimbal]  # tracked by the cameras
    cmds, reached = reach(r, *at(A))  # B starts: the DO items after it run (ROI_NONE)
    assert reached == [2]
    [g] = [vc.command for vc in cmds if vc.command.points_gimbal]
    assert g.gimbal_hold and g.gimbal_look_at is None


# -- fence and rally --------------------------------------------------------------
def upload_list(r, items: list[tuple], mtype: int) -> list[tuple[str, int]]:
    _, replies = r.request(lambda: r.gcs.mav.mission_count_send(1, 1, len(items), mtype))
    seen = list(replies)
    for seq, (frame, cmd, p1, p2, p3, p4, lat, lon, z) in enumerate(items):
        _, rep = r.request(lambda s=seq, f=frame, c=cmd, a=(p1, p2, p3, p4), la=lat, lo=lon,
                           zz=z: r.gcs.mav.mission_item_int_send(
                               1, 1, s, f, c, 0, 1, *a, round(la * 1e7), round(lo * 1e7), zz,
                               mtype))
        seen += rep
    return protocol(seen)


def test_fence_upload_download_and_a_breach_returns_home_with_an_event(rig) -> None:
    r = rig(1)
    lat, lon = r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]]
    d = 0.01
    poly = [(REL, ML.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 4, 0, 0, 0, la, lo, 0)
            for la, lo in ((lat - d, lon - d), (lat - d, lon + d), (lat + d, lon + d),
                           (lat + d, lon - d))]
    excl = [(REL, ML.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 200, 0, 0, 0, lat + 0.005, lon, 0)]
    assert upload_list(r, poly + excl, ML.MAV_MISSION_TYPE_FENCE)[-1] == (
        "MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    _, replies = r.request(lambda: r.gcs.mav.mission_request_list_send(
        1, 1, ML.MAV_MISSION_TYPE_FENCE))
    assert of_type(replies, "MISSION_COUNT")[0].count == 5
    _, replies = r.request(lambda: r.gcs.mav.mission_request_int_send(
        1, 1, 4, ML.MAV_MISSION_TYPE_FENCE))
    item, = of_type(replies, "MISSION_ITEM_INT")
    assert (item.command, item.param1, item.mission_type) == (
        ML.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 200, ML.MAV_MISSION_TYPE_FENCE)
    assert not r.step(4) and r.ep.vehicles[0].mode == PlaneMode.GUIDED  # inside: nothing
    cmds, _ = reach(r, lat + 0.005, lon + 0.0005)  # inside the exclusion circle
    assert r.ep.vehicles[0].mode == PlaneMode.RTL
    assert cmds[0].command.nav == "goto" and cmds[0].command.points[0].a == LAT0
    kind, fields = r.ep.drain_events()[0][1:]
    assert kind == "fence_breach" and "exclusion circle" in fields["why"]
    assert fields["action"] == "RTL"
    assert r.ep.counters()["fence_breaches"] == 1
    reach(r, lat + 0.02, lon)  # still outside (the polygon now): no second breach
    assert r.ep.counters()["fence_breaches"] == 1


def _fence_bits(r) -> tuple[bool, bool, bool]:
    """SYS_STATUS's geofence bits (present, enabled, healthy) of vehicle 1."""
    _, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, ML.MAVLINK_MSG_ID_SYS_STATUS, 0, 0, 0, 0, 0, 0))
    ss = of_type(replies, "SYS_STATUS")[-1]
    bit = ML.MAV_SYS_STATUS_GEOFENCE
    return (bool(ss.onboard_control_sensors_present & bit),
            bool(ss.onboard_control_sensors_enabled & bit),
            bool(ss.onboard_control_sensors_health & bit))


def test_sys_status_fence_bits_say_breach_only_when_breached(rig) -> None:
    """As ArduPilot reports them: healthy unless breached, fence or not, so
    that MAVProxy (which says 'fence breach' when the health bit drops) stays
    quiet until a breach."""
    r = rig(1)
    assert _fence_bits(r) == (False, False, True)  # no fence: nothing to breach
    lat, lon = r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]]
    circle = [(REL, ML.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 2000, 0, 0, 0, lat, lon, 0)]
    upload_list(r, circle, ML.MAV_MISSION_TYPE_FENCE)
    assert _fence_bits(r) == (True, True, True)  # inside it
    reach(r, lat + 0.05, lon)  # 5.5 km north: outside
    assert r.ep.vehicles[0].mission.breached
    assert _fence_bits(r) == (True, True, False)


def test_rtl_goes_to_the_nearest_rally_point(rig) -> None:
    r = rig(1)
    lat, lon = r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]]
    rally = [(REL, ML.MAV_CMD_NAV_RALLY_POINT, 0, 0, 0, 0, lat + 0.002, lon, 120.0),
             (REL, ML.MAV_CMD_NAV_RALLY_POINT, 0, 0, 0, 0, lat + 0.2, lon, 120.0)]
    assert upload_list(r, rally, ML.MAV_MISSION_TYPE_RALLY)[-1] == (
        "MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    cmds, replies = set_mode(r, PlaneMode.RTL)
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    p = cmds[0].command.points[0]
    assert (p.a, p.b) == (pytest.approx(lat + 0.002), pytest.approx(lon))
    assert cmds[0].command.alt_m == pytest.approx(HOME_ALT_M + 120.0)
    # a clear of every list empties the rally points too: RTL goes home again
    r.request(lambda: r.gcs.mav.mission_clear_all_send(1, 1, ML.MAV_MISSION_TYPE_ALL))
    set_mode(r, PlaneMode.LOITER)
    cmds, _ = set_mode(r, PlaneMode.RTL)
    assert cmds[0].command.points[0].a == LAT0


def test_fence_items_in_the_mission_list_and_bad_polygons_are_refused(rig) -> None:
    r = rig(1)
    _, _, msgs = upload(r, [(REL, ML.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 100, 0, 0, 0, LAT0,
                             LON0, 0)])
    assert ("MISSION_ACK", ML.MAV_MISSION_UNSUPPORTED) in protocol(msgs)
    bad = [(REL, ML.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 2, 0, 0, 0, LAT0, LON0, 0)] * 2
    seen = upload_list(r, bad, ML.MAV_MISSION_TYPE_FENCE)
    assert seen[:2] == [("MISSION_REQUEST_INT", 0), ("MISSION_ACK", ML.MAV_MISSION_INVALID_PARAM1)]
    assert not r.ep.vehicles[0].mission.fence


# -- what the vehicle claims ----------------------------------------------------------
def test_autopilot_version_and_sys_status_claim_what_exists(rig) -> None:
    r = rig(2, has_autopilot=False)
    r2 = rig(1)
    for rr, missions in ((r, False), (r2, True)):
        _, replies = rr.request(lambda rr=rr: rr.gcs.mav.command_long_send(
            1, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, ML.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
            0, 0, 0, 0, 0, 0))
        caps = of_type(replies, "AUTOPILOT_VERSION")[0].capabilities
        for flag in ("MAVLINK2", "COMMAND_INT", "PARAM_FLOAT", "PARAM_ENCODE_C_CAST"):
            assert caps & getattr(ML, f"MAV_PROTOCOL_CAPABILITY_{flag}"), flag
        for flag in ("MISSION_INT", "MISSION_FENCE", "MISSION_RALLY"):
            assert bool(caps & getattr(ML, f"MAV_PROTOCOL_CAPABILITY_{flag}")) == missions
        assert not caps & ML.MAV_PROTOCOL_CAPABILITY_FTP  # FTP is answered with NAKs only
        assert not caps & ML.MAV_PROTOCOL_CAPABILITY_TERRAIN
    _, replies = r2.request(lambda: r2.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, ML.MAVLINK_MSG_ID_SYS_STATUS, 0, 0, 0, 0, 0, 0))
    ss = of_type(replies, "SYS_STATUS")[0]
    present = ss.onboard_control_sensors_present
    assert present & ML.MAV_SYS_STATUS_SENSOR_GPS and present & ML.MAV_SYS_STATUS_AHRS
    for fake in ("SENSOR_3D_GYRO", "SENSOR_3D_MAG", "SENSOR_ABSOLUTE_PRESSURE", "GEOFENCE"):
        assert not present & getattr(ML, f"MAV_SYS_STATUS_{fake}"), fake
    d = 0.05
    lat, lon = LAT0, LON0
    poly = [(REL, ML.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 3, 0, 0, 0, la, lo, 0)
            for la, lo in ((lat - d, lon - d), (lat - d, lon + d), (lat + d, lon))]
    upload_list(r2, poly, ML.MAV_MISSION_TYPE_FENCE)
    assert r2.ep.vehicles[0].sensors_present() & ML.MAV_SYS_STATUS_GEOFENCE


def test_home_item_zero_is_ignored_on_upload(rig) -> None:
    r = rig(1)
    _, replies = r.request(lambda: r.gcs.mav.mission_count_send(1, 1, 2))
    send_item(r, 1, 0, HOME_ITEM)
    send_item(r, 1, 1, A)
    assert [m.command for m in download(r)] == [WP, WP]


def test_camera_items_become_camera_commands(rig) -> None:
    r = rig(1)
    M = ML.MAV_FRAME_MISSION
    upload(r, [A, (M, ML.MAV_CMD_IMAGE_START_CAPTURE, 0, 2.5, 4, 0, 0, 0, 0),
               (M, ML.MAV_CMD_DO_SET_CAM_TRIGG_DIST, 150, 0, 0, 0, 0, 0, 0),
               B, (M, ML.MAV_CMD_IMAGE_STOP_CAPTURE, 0, 0, 0, 0, 0, 0, 0),
               (M, ML.MAV_CMD_DO_DIGICAM_CONTROL, 0, 0, 0, 0, 1, 0, 0), C])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    cams = [vc.command.camera for vc in cmds if vc.command.camera is not None]
    assert [(c.interval_s, c.count, c.distance_m) for c in cams] == [(2.5, 4, None),
                                                                     (None, None, 150.0)]
    assert all(not vc.command.flies for vc in cmds[1:])
    cmds, _ = reach(r, *at(A))
    cams = [vc.command.camera for vc in cmds if vc.command.camera is not None]
    assert [(c.stop, c.shoot) for c in cams] == [(True, False), (False, True)]


def test_a_fixed_wing_lands_at_the_land_item(rig) -> None:
    """NAV_LAND in a plane's mission: the leg to its point is the approach
    (a goto with ``land``, at 1.1 x AIRSPEED_MIN); the item is reached once
    the aircraft is stopped on the ground, and it disarms as ArduPlane does."""
    r = rig(1)
    v = r.ep.vehicles[0]
    land_at = (LAT0 + 0.03, LON0)
    upload(r, [A, (REL, ML.MAV_CMD_NAV_LAND, 0, 0, 0, 0, *land_at, 0.0)])
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    cmds, reached = reach(r, *at(A))
    assert reached == [1]
    c = cmds[0].command
    assert c.land and c.nav == "goto"
    assert (c.points[0].a, c.points[0].b) == land_at
    approach = min(1.1 * v.params["AIRSPEED_MIN"], v.params["AIRSPEED_CRUISE"])
    assert c.airspeed_mps == pytest.approx(approach, abs=0.01)
    _, reached = reach(r, *land_at)  # over the point, still flying: not yet
    assert reached == [] and v.armed
    r.states[0, [S["alt_agl_m"], S["vd_mps"], S["vn_mps"], S["ve_mps"]]] = 0.1, 0.0, 0.0, 0.0
    _, reached = reach(r, *land_at)  # no weight on its skids yet: still flying
    assert reached == [] and v.armed and v.in_air()
    r.states[0, S["gear_force_lbs"]] = -88.0  # the ground holds it up
    _, reached = reach(r, *land_at)
    assert reached == [2] and not v.armed and v.mission.complete and not v.in_air()


def test_a_fixed_wing_lands_on_command_in_guided(rig) -> None:
    """NAV_LAND as a command: in GUIDED, at its position (none given:
    straight ahead); in another mode it is refused with a reason."""
    r = rig(1)
    set_mode(r, PlaneMode.LOITER)
    cmds, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0))
    assert ack_result(replies) == ML.MAV_RESULT_FAILED and not cmds
    assert any("GUIDED" in t.text for t in of_type(replies, "STATUSTEXT"))
    set_mode(r, PlaneMode.GUIDED)
    cmds, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0))
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    c = cmds[0].command
    assert c.land and c.nav is None  # straight ahead
    cmds, replies = r.request(lambda: r.gcs.mav.command_int_send(
        1, 1, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ML.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0,
        round((LAT0 + 0.01) * 1e7), round(LON0 * 1e7), 0.0))
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    c = cmds[0].command
    assert c.land and c.nav == "goto"
    assert (c.points[0].a, c.points[0].b) == (pytest.approx(LAT0 + 0.01), pytest.approx(LON0))
