"""DO_SET_ROI_LOCATION and DO_SET_ROI_NONE as commands (COMMAND_LONG and
COMMAND_INT): one COMMAND_ACK each and the vocabulary's gimbal command, the
point's altitude read in the command's frame (what a ground station's
"look here" sends; a mission's ROI items: test_mav_mission_items)."""

from __future__ import annotations

import pytest
from mavtest import HOME_ALT_M, mavutil, of_type
from test_mav_commands import cint, long, one_ack

ML = mavutil.mavlink
ROI, NONE = ML.MAV_CMD_DO_SET_ROI_LOCATION, ML.MAV_CMD_DO_SET_ROI_NONE


def _gimbal(cmds, row: int = 0):
    assert len(cmds) == 1 and cmds[0].row == row
    c = cmds[0].command
    assert c.points_gimbal and not c.flies
    return c


@pytest.mark.parametrize("frame,z,alt_m,agl", [
    (ML.MAV_FRAME_GLOBAL_INT, 431.5, 431.5, False),  # above mean sea level
    (ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 12.0, HOME_ALT_M + 12.0, False),  # above home
    (ML.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, 3.0, 3.0, True),  # above the ground
])
def test_roi_location_looks_at_the_point(rig, frame: int, z: float, alt_m: float,
                                         agl: bool) -> None:
    r = rig(2)
    cmds, replies = cint(r, 2, ROI, frame, x=470_123_456, y=80_654_321, z=z)
    assert one_ack(replies, ROI, src=2) == ML.MAV_RESULT_ACCEPTED
    p = _gimbal(cmds, row=1).gimbal_look_at
    assert p is not None and (p.frame, p.alt_m, p.alt_agl) == ("geodetic", alt_m, agl)
    assert (p.a, p.b) == pytest.approx((47.0123456, 8.0654321), abs=1e-9)


def test_roi_location_by_command_long_is_in_degrees_above_home(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ROI, 0, 0, 0, 0, 47.01, 8.02, 5.0)
    assert one_ack(replies, ROI) == ML.MAV_RESULT_ACCEPTED
    p = _gimbal(cmds).gimbal_look_at
    assert p is not None and (p.alt_m, p.alt_agl) == (HOME_ALT_M + 5.0, False)
    assert (p.a, p.b) == pytest.approx((47.01, 8.02), abs=1e-5)  # float32 parameters


@pytest.mark.parametrize("send", [
    lambda r: long(r, 1, NONE),
    lambda r: cint(r, 1, NONE, ML.MAV_FRAME_GLOBAL_INT),
    lambda r: long(r, 1, ROI),  # no location (0, 0): as ArduPilot, the ROI is cleared
])
def test_roi_none_stops_tracking(rig, send) -> None:
    r = rig(1)
    cmds, replies = send(r)
    acks = of_type(replies, "COMMAND_ACK")
    assert [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED]
    c = _gimbal(cmds)
    assert c.gimbal_hold and c.gimbal_look_at is None and c.label() == "gimbal hold"


def test_a_roi_outside_the_world_is_denied_saying_why(rig) -> None:
    r = rig(1)
    cmds, replies = long(r, 1, ROI, 0, 0, 0, 0, 95.0, 8.0, 0.0)
    assert one_ack(replies, ROI) == ML.MAV_RESULT_DENIED and not cmds
    said = "".join(t.text for t in of_type(replies, "STATUSTEXT"))  # 50-character chunks
    assert "ROI: gimbal.look_at.lat_deg: must be -90..90, got 95.0" in said
