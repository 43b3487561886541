"""The mission protocol as ArduPlane speaks it: upload, download, clear,
flying it in AUTO (a ``waypoints`` command), MISSION_CURRENT and
MISSION_ITEM_REACHED, and MAVProxy's guided goto (MISSION_ITEM current=2)."""

from __future__ import annotations

from typing import Any

import pytest
from mavtest import HOME_ALT_M, PHYSICS_HZ, S, mavutil, of_type, start_of

from cosim.vehicles.fixed_wing.mav_modes import PlaneMode

ML = mavutil.mavlink
REL = ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
WP = ML.MAV_CMD_NAV_WAYPOINT
PROTOCOL = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT",
            "MISSION_ITEM_INT", "MISSION_ITEM")

#: (frame, command, param1..4, lat_deg, lon_deg, z) of a 4-waypoint mission (items 1..4)
LAT0, LON0 = start_of(0)
MISSION4 = [(REL, WP, 0, 0, 0, 0, LAT0 + 0.02, LON0, 150.0),
            (REL, WP, 0, 0, 0, 0, LAT0 + 0.02, LON0 + 0.03, 200.0),
            (ML.MAV_FRAME_GLOBAL_INT, WP, 0, 0, 0, 0, LAT0, LON0 + 0.03, 900.0),
            (ML.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, WP, 0, 0, 0, 0, LAT0 - 0.01, LON0, 300.0)]
HOME_ITEM = (ML.MAV_FRAME_GLOBAL_INT, WP, 0, 0, 0, 0, 0.0, 0.0, 0.0)  # what a GCS sends as 0


def protocol(msgs: list[Any]) -> list[tuple[str, int]]:
    """The mission-protocol messages as (type, seq / count / ack result)."""
    out = []
    for m in msgs:
        t = m.get_type()
        if t in PROTOCOL:
            out.append((t, m.type if t == "MISSION_ACK" else
                        m.count if t == "MISSION_COUNT" else m.seq))
    return out


def send_item(r, target: int, seq: int, item: tuple, use_int: bool = True,
              current: int = 0) -> tuple[list[Any], list[Any]]:
    frame, cmd, p1, p2, p3, p4, lat, lon, z = item
    if use_int:
        return r.request(lambda: r.gcs.mav.mission_item_int_send(
            target, 1, seq, frame, cmd, current, 1, p1, p2, p3, p4, round(lat * 1e7),
            round(lon * 1e7), z))
    return r.request(lambda: r.gcs.mav.mission_item_send(
        target, 1, seq, frame, cmd, current, 1, p1, p2, p3, p4, lat, lon, z))


def upload(r, items: list[tuple], target: int = 1, use_int: bool = True
           ) -> tuple[list[tuple[str, int]], list[Any], list[Any]]:
    """Upload items 1.. (home first): the vehicle's protocol replies, all
    commands and all replies."""
    cmds, replies = r.request(lambda: r.gcs.mav.mission_count_send(target, 1, len(items) + 1))
    seen = list(replies)
    for seq, item in enumerate([HOME_ITEM] + items):
        c, rep = send_item(r, target, seq, item, use_int)
        cmds += c
        seen += rep
    return protocol(seen), cmds, seen


def download(r, target: int = 1, use_int: bool = True) -> list[Any]:
    _, replies = r.request(lambda: r.gcs.mav.mission_request_list_send(target, 1))
    count, = of_type(replies, "MISSION_COUNT")
    items = []
    for seq in range(count.count):
        if use_int:
            _, rep = r.request(lambda s=seq: r.gcs.mav.mission_request_int_send(target, 1, s))
            item, = of_type(rep, "MISSION_ITEM_INT")
        else:
            _, rep = r.request(lambda s=seq: r.gcs.mav.mission_request_send(target, 1, s))
            item, = of_type(rep, "MISSION_ITEM")
        assert item.seq == seq
        items.append(item)
    _, rep = r.request(lambda: r.gcs.mav.mission_ack_send(target, 1, ML.MAV_MISSION_ACCEPTED))
    assert not protocol(rep)  # the client's ACK ends it: no answer
    return items


def set_mode(r, mode: int, target: int = 1) -> tuple[list[Any], list[Any]]:
    return r.request(lambda: r.gcs.mav.set_mode_send(
        target, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode))


def ack_result(replies: list[Any]) -> int:
    ack, = of_type(replies, "COMMAND_ACK")
    return int(ack.result)


# -- upload / download / clear ------------------------------------------------
def test_upload_of_four_waypoints_follows_the_exact_request_sequence(rig) -> None:
    r = rig(2)
    seen, cmds, msgs = upload(r, MISSION4)
    assert seen == [("MISSION_REQUEST_INT", 0), ("MISSION_REQUEST_INT", 1),
                    ("MISSION_REQUEST_INT", 2), ("MISSION_REQUEST_INT", 3),
                    ("MISSION_REQUEST_INT", 4), ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)]
    assert not cmds  # uploading flies nothing
    assert all(m.get_srcSystem() == 1 and (m.target_system, m.target_component) == (255, 190)
               for m in msgs if m.get_type() in PROTOCOL)
    assert r.ep.counters()["mission_uploads"] == 1
    assert not r.ep.vehicles[1].mission.items  # vehicle 2 untouched


def test_download_returns_the_same_items_with_home_at_zero(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    items = download(r)
    assert len(items) == 5
    home = items[0]
    assert (home.command, home.frame) == (WP, ML.MAV_FRAME_GLOBAL)
    assert (home.x, home.y) == (round(LAT0 * 1e7), round(LON0 * 1e7))
    assert home.z == pytest.approx(HOME_ALT_M)
    for got, (frame, cmd, *_, lat, lon, z) in zip(items[1:], MISSION4):
        assert (got.frame, got.command) == (frame, cmd)
        assert (got.x, got.y) == (round(lat * 1e7), round(lon * 1e7))
        assert got.z == pytest.approx(z)
    # MISSION_REQUEST (float) answers with MISSION_ITEM in degrees
    floats = download(r, use_int=False)
    assert floats[2].x == pytest.approx(MISSION4[1][6], abs=1e-6)
    assert floats[2].y == pytest.approx(MISSION4[1][7], abs=1e-6)


def test_older_clients_upload_with_mission_item_floats(rig) -> None:
    r = rig(1)
    seen, _, _ = upload(r, MISSION4[:2], use_int=False)
    # the vehicle answers in kind once it sees MISSION_ITEM
    assert seen == [("MISSION_REQUEST_INT", 0), ("MISSION_REQUEST", 1), ("MISSION_REQUEST", 2),
                    ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)]
    items = download(r)
    # float32 degrees: a few decimetres of rounding (why MISSION_ITEM_INT exists)
    assert items[2].x == pytest.approx(MISSION4[1][6] * 1e7, abs=50)
    assert items[2].y == pytest.approx(MISSION4[1][7] * 1e7, abs=50)


def test_clear_all_empties_the_mission(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    _, replies = r.request(lambda: r.gcs.mav.mission_clear_all_send(1, 1))
    assert protocol(replies) == [("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)]
    assert len(download(r)) == 1  # home only


@pytest.mark.parametrize("item, result", [
    ((ML.MAV_FRAME_LOCAL_NED, WP, 0, 0, 0, 0, 0.0, 0.0, 100.0),
     ML.MAV_MISSION_UNSUPPORTED_FRAME),
    ((REL, WP, 0, 0, 0, 0, 95.0, LON0, 100.0), ML.MAV_MISSION_INVALID_PARAM5_X),
    ((REL, ML.MAV_CMD_DO_JUMP, 9, 1, 0, 0, 0.0, 0.0, 0.0), ML.MAV_MISSION_INVALID_PARAM1),
    ((REL, ML.MAV_CMD_NAV_LOITER_TURNS, 0, 0, 200, 0, LAT0, LON0, 100.0),
     ML.MAV_MISSION_INVALID_PARAM1)])
def test_malformed_items_end_the_upload_and_keep_the_old_mission(
        rig, item: tuple, result: int) -> None:
    r = rig(1)
    upload(r, MISSION4)
    seen, _, msgs = upload(r, [MISSION4[0], item])
    assert seen == [("MISSION_REQUEST_INT", 0), ("MISSION_REQUEST_INT", 1),
                    ("MISSION_REQUEST_INT", 2), ("MISSION_ACK", result)]
    texts = [t.text for t in of_type(msgs, "STATUSTEXT")]
    assert any("Mission item 2" in t for t in texts), texts
    assert len(download(r)) == 5  # the mission on board is unchanged


def test_items_the_vehicle_cannot_fly_are_refused_alone_and_skipped(rig) -> None:
    r = rig(1)
    items = [MISSION4[0], (REL, ML.MAV_CMD_NAV_SPLINE_WAYPOINT, 0, 0, 0, 0, LAT0, LON0, 90.0),
             (REL, ML.MAV_CMD_DO_SET_SERVO, 5, 1500, 0, 0, 0, 0, 0.0), MISSION4[1]]
    seen, _, msgs = upload(r, items)
    assert seen[-1] == ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    texts = " ".join(t.text for t in of_type(msgs, "STATUSTEXT"))
    assert "Mission item 2" in texts and "Mission item 3" in texts
    assert texts.count("MAV_MISSION_UNSUPPORTED") == 2
    got = download(r)
    assert [m.command for m in got[1:]] == [WP, ML.MAV_CMD_NAV_SPLINE_WAYPOINT,
                                            ML.MAV_CMD_DO_SET_SERVO, WP]
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    assert cmds[0].command.nav == "goto"
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = MISSION4[0][6], MISSION4[0][7]
    cmds = r.step(4)
    assert [m.seq for m in of_type(r.gcs.drain(wait_s=1.0), "MISSION_ITEM_REACHED")] == [1]
    c = cmds[0].command  # items 2 and 3 skipped: on to item 4
    assert (c.points[0].a, c.points[0].b) == (MISSION4[1][6], MISSION4[1][7])
    assert r.ep.vehicles[0].mission.current == 4
    assert r.ep.counters()["mission_items_refused"] == 2


def test_out_of_sequence_item_is_answered_with_invalid_sequence(rig) -> None:
    r = rig(1)
    r.request(lambda: r.gcs.mav.mission_count_send(1, 1, 3))
    _, rep = send_item(r, 1, 2, MISSION4[0])
    assert protocol(rep) == [("MISSION_ACK", ML.MAV_MISSION_INVALID_SEQUENCE)]
    _, rep = send_item(r, 1, 0, HOME_ITEM)  # the upload is still open
    assert protocol(rep) == [("MISSION_REQUEST_INT", 1)]


def test_upload_requests_are_retried_then_time_out_in_simulation_time(rig) -> None:
    r = rig(1)
    _, rep = r.request(lambda: r.gcs.mav.mission_count_send(1, 1, 2))
    assert protocol(rep) == [("MISSION_REQUEST_INT", 0)]
    r.step(int(PHYSICS_HZ) - 1)
    assert not protocol(r.gcs.drain(wait_s=0.2))
    r.step(1)  # one simulated second later: asked again
    assert protocol(r.gcs.drain(wait_s=1.0)) == [("MISSION_REQUEST_INT", 0)]
    seen: list[Any] = []
    for _ in range(8):
        r.step(int(PHYSICS_HZ))
        seen += r.gcs.drain(wait_s=0.3)
    assert protocol(seen)[-1] == ("MISSION_ACK", ML.MAV_MISSION_OPERATION_CANCELLED)
    assert r.ep.counters()["mission_upload_timeouts"] == 1
    assert r.ep.vehicles[0].mission.upload is None


# -- flying it -------------------------------------------------------------
def test_auto_is_refused_without_a_mission(rig) -> None:
    r = rig(1)
    cmds, replies = set_mode(r, PlaneMode.AUTO)
    assert ack_result(replies) == ML.MAV_RESULT_FAILED and not cmds
    text, = of_type(replies, "STATUSTEXT")
    assert "no mission" in text.text
    assert r.ep.vehicles[0].mode == PlaneMode.GUIDED


def test_auto_flies_the_first_navigation_item_as_a_goto(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    cmds, replies = set_mode(r, PlaneMode.AUTO)
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    cur = of_type(replies, "MISSION_CURRENT")
    assert cur and cur[-1].seq == 1 and cur[-1].total == 4
    c, = [vc.command for vc in cmds]
    assert c.nav == "goto" and len(c.points) == 1
    p = c.points[0]
    assert (p.frame, p.a, p.b) == ("geodetic", pytest.approx(LAT0 + 0.02), pytest.approx(LON0))
    assert c.alt_m == pytest.approx(HOME_ALT_M + 150.0) and not c.alt_agl
    assert c.airspeed_mps == 25.0  # AIRSPEED_CRUISE until a DO_CHANGE_SPEED
    hb = None
    r.step(120)
    for m in r.gcs.drain(wait_s=1.0):
        if m.get_type() == "HEARTBEAT":
            hb = m
        if m.get_type() == "MISSION_CURRENT":  # the 1 Hz stream
            assert (m.seq, m.mission_mode, m.mission_state) == (1, 1, 3)
    assert hb is not None and hb.custom_mode == PlaneMode.AUTO


def reach(r, lat: float, lon: float, ticks: int = 4) -> tuple[list[Any], list[int]]:
    """Put vehicle 1 at (lat, lon), run an exchange: (commands, items reached)."""
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = lat, lon
    cmds = r.step(ticks)
    return cmds, [m.seq for m in of_type(r.gcs.drain(wait_s=0.5), "MISSION_ITEM_REACHED")]


def test_each_item_reached_flies_the_next_in_its_altitude_frame(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    set_mode(r, PlaneMode.AUTO)
    want = [(HOME_ALT_M + 200.0, False), (900.0, False), (300.0, True)]
    for k in range(3):
        cmds, reached = reach(r, MISSION4[k][6], MISSION4[k][7])
        assert reached == [k + 1]
        c = cmds[0].command
        assert (c.points[0].a, c.points[0].b) == (MISSION4[k + 1][6], MISSION4[k + 1][7])
        assert (c.alt_m, c.alt_agl) == (pytest.approx(want[k][0]), want[k][1])
    _, reached = reach(r, MISSION4[3][6], MISSION4[3][7])
    assert reached == [4]
    assert r.ep.vehicles[0].mission.state(True)["mission_state"] == 5  # complete
    # leaving AUTO keeps the current item; AUTO resumes from it
    set_mode(r, PlaneMode.LOITER)
    assert r.ep.vehicles[0].mission.current == 4


def test_a_passed_leg_counts_as_reached(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    r.states[0, S["lat_deg"]], r.states[0, S["lon_deg"]] = LAT0, LON0
    set_mode(r, PlaneMode.AUTO)
    # 1 km east of the waypoint but past its latitude: the leg is passed
    _, reached = reach(r, LAT0 + 0.021, LON0 + 0.013)
    assert reached == [1]


def test_set_current_restarts_from_that_item(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    set_mode(r, PlaneMode.AUTO)
    cmds, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_DO_SET_MISSION_CURRENT, 0, 3, 0, 0, 0, 0, 0, 0))
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    assert of_type(replies, "MISSION_CURRENT")[-1].seq == 3
    assert cmds[0].command.points[0].a == MISSION4[2][6]
    cmds, replies = r.request(lambda: r.gcs.mav.mission_set_current_send(1, 1, 2))
    assert of_type(replies, "MISSION_CURRENT")[-1].seq == 2
    assert cmds[0].command.points[0].a == MISSION4[1][6]


def test_mission_start_enters_auto_from_its_first_item(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    cmds, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_MISSION_START, 0, 2, 0, 0, 0, 0, 0, 0))
    assert ack_result(replies) == ML.MAV_RESULT_ACCEPTED
    assert r.ep.vehicles[0].mode == PlaneMode.AUTO
    assert cmds[0].command.points[0].a == MISSION4[1][6]
    _, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_MISSION_START, 0, 9, 0, 0, 0, 0, 0, 0))
    assert ack_result(replies) == ML.MAV_RESULT_DENIED


def test_speed_takeoff_loiter_and_rtl_items(rig) -> None:
    r = rig(1)
    items = [(REL, ML.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0.0, 0.0, 100.0),  # airborne: done
             (REL, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 30, -1, 0, 0.0, 0.0, 0.0),
             MISSION4[0],
             (REL, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, -300, 0, LAT0, LON0 + 0.01, 120.0),
             MISSION4[1]]  # after an unlimited loiter: never reached
    assert upload(r, items)[0][-1] == ("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)
    cmds, _ = set_mode(r, PlaneMode.AUTO)
    take, speed, c = (vc.command for vc in cmds)
    assert take.nav == "loiter" and take.alt_m == pytest.approx(HOME_ALT_M + 100.0)
    assert speed.airspeed_mps == 30.0 and speed.nav is None
    # above its altitude already: the take-off is done in the same exchange
    assert (c.points[0].a, c.airspeed_mps) == (MISSION4[0][6], 30.0)
    cmds, reached = reach(r, MISSION4[0][6], MISSION4[0][7])
    assert reached == [3]
    c = cmds[0].command
    assert c.nav == "loiter" and c.loiter_radius_m == 300.0 and not c.loiter_cw
    assert (c.points[0].a, c.points[0].b) == (LAT0, LON0 + 0.01)
    for _ in range(5):
        assert reach(r, LAT0, LON0 + 0.01, 600)[1] == []  # never ends
    # RTL: home at ALT_HOLD_RTL, circled; reached there, the mission goes on (ArduPlane)
    _, cmds, _ = upload(r, [(REL, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0),
                            MISSION4[1]])
    c = cmds[0].command  # already in AUTO: the new mission is flown at once
    assert (c.nav, c.points[0].a, c.points[0].b) == ("goto", LAT0, LON0)
    assert c.alt_m == pytest.approx(HOME_ALT_M + 100.0)
    cmds, reached = reach(r, LAT0, LON0)
    assert reached == [1] and cmds[0].command.points[0].a == MISSION4[1][6]
    _, reached = reach(r, MISSION4[1][6], MISSION4[1][7])
    assert reached == [2] and r.ep.vehicles[0].mission.complete


def test_new_mission_in_auto_is_flown_from_its_first_item(rig) -> None:
    r = rig(1)
    upload(r, MISSION4)
    set_mode(r, PlaneMode.AUTO)
    _, cmds, _ = upload(r, [MISSION4[3]])
    assert len(cmds) == 1 and cmds[0].command.points[0].a == MISSION4[3][6]


# -- guided goto ------------------------------------------------------------
def test_guided_goto_by_mission_item_int_current_2(rig) -> None:
    r = rig(2)
    target = (REL, WP, 0, 0, 0, 0, LAT0 + 0.03, LON0 - 0.01, 250.0)
    cmds, replies = send_item(r, 2, 0, target, current=2)
    assert protocol(replies) == [("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)]
    assert len(cmds) == 1 and cmds[0].row == 1
    c = cmds[0].command
    assert c.nav == "goto"
    assert (c.points[0].a, c.points[0].b) == (pytest.approx(LAT0 + 0.03),
                                              pytest.approx(LON0 - 0.01))
    assert c.alt_m == pytest.approx(HOME_ALT_M + 250.0)
    assert not r.ep.vehicles[1].mission.items  # not a mission upload
    # the float form works too; outside GUIDED it is refused
    cmds, replies = send_item(r, 2, 0, target, use_int=False, current=2)
    assert cmds and protocol(replies) == [("MISSION_ACK", ML.MAV_MISSION_ACCEPTED)]
    set_mode(r, PlaneMode.LOITER, target=2)
    cmds, replies = send_item(r, 2, 0, target, current=2)
    assert not cmds and protocol(replies) == [("MISSION_ACK", ML.MAV_MISSION_ERROR)]




# -- a mission put on board from inside cosim ----------------------------------
def _items(points: list[tuple[float, float]], alt_m: float = 120.0) -> list[Any]:
    from cosim.mavlink.mission import MissionItem

    return [MissionItem(k + 1, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ML.MAV_CMD_NAV_WAYPOINT,
                        x=round(la * 1e7), y=round(lo * 1e7), z=alt_m)
            for k, (la, lo) in enumerate(points)]


def test_a_loaded_mission_is_downloaded_by_a_ground_station_and_flown_in_auto(rig) -> None:
    r = rig(2)
    pts = [(LAT0 + 0.01, LON0), (LAT0 + 0.01, LON0 + 0.01), (LAT0, LON0 + 0.01)]
    r.ep.load_mission(1, _items(pts), fly=True)  # the second vehicle (system id 2)
    cmds = r.step()
    c, = cmds
    assert c.row == 1 and c.command.nav == "goto"  # its first item, flown at once
    got = download(r, target=2)
    assert [(i.seq, i.x, i.y) for i in got[1:]] == [
        (k + 1, round(la * 1e7), round(lo * 1e7)) for k, (la, lo) in enumerate(pts)]
    assert len(download(r, target=1)) == 1  # the other vehicle's: home only
    r.step(120)
    hb = [m for m in r.gcs.drain(wait_s=1.0) if m.get_type() == "HEARTBEAT"
          and m.get_srcSystem() == 2]
    assert hb and hb[-1].custom_mode == PlaneMode.AUTO


def test_a_malformed_loaded_mission_is_the_callers_error(rig) -> None:
    from cosim.mavlink.mission import MissionItem

    r = rig(1)
    r.ep.load_mission(0, [MissionItem(1, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                      ML.MAV_CMD_NAV_WAYPOINT, x=2_000_000_000, y=0)])
    with pytest.raises(ValueError, match="mission item 1"):
        r.step()
    with pytest.raises(KeyError, match="no vehicle at state row 5"):
        r.ep.load_mission(5, [])

