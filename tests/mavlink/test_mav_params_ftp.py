"""The parameter protocol and the FTP NAK."""

from __future__ import annotations

import struct

import pytest
from mavtest import mavutil, of_type

from cosim.mavlink.params import ParamTable
from cosim.vehicles.fixed_wing.mav_params import ARDUPLANE_PARAMS as PARAM_DEFS

ML = mavutil.mavlink
NAMES = [p.name for p in PARAM_DEFS]


def test_param_request_list_sends_every_parameter_with_index_and_count(rig) -> None:
    r = rig(2)
    _, replies = r.request(lambda: r.gcs.mav.param_request_list_send(2, 1))
    values = of_type(replies, "PARAM_VALUE", 2)
    assert len(values) == len(NAMES) and not of_type(replies, "PARAM_VALUE", 1)
    assert [v.param_index for v in values] == list(range(len(NAMES)))
    assert {v.param_count for v in values} == {len(NAMES)}
    assert [v.param_id for v in values] == NAMES
    by_name = {v.param_id: v for v in values}
    assert "ARMING_CHECK" in by_name and by_name["ARMING_CHECK"].param_value == 1
    assert by_name["ARMING_CHECK"].param_type == ML.MAV_PARAM_TYPE_INT32
    assert by_name["SYSID_THISMAV"].param_value == 2
    assert by_name["ROLL_LIMIT_DEG"].param_type == ML.MAV_PARAM_TYPE_REAL32


def test_param_read_by_name_and_by_index(rig) -> None:
    r = rig(1)
    _, replies = r.request(lambda: r.gcs.mav.param_request_read_send(1, 1, b"TKOFF_ALT", -1))
    v, = of_type(replies, "PARAM_VALUE")
    assert (v.param_id, v.param_value, v.param_index) == ("TKOFF_ALT", 50,
                                                          NAMES.index("TKOFF_ALT"))
    _, replies = r.request(lambda: r.gcs.mav.param_request_read_send(1, 1, b"", 0))
    v, = of_type(replies, "PARAM_VALUE")
    assert (v.param_id, v.param_index) == (NAMES[0], 0)
    _, replies = r.request(lambda: r.gcs.mav.param_request_read_send(1, 1, b"NOPE", -1))
    assert not of_type(replies, "PARAM_VALUE")
    _, replies = r.request(lambda: r.gcs.mav.param_request_read_send(1, 1, b"", 999))
    assert not of_type(replies, "PARAM_VALUE")
    assert r.ep.counters()["param_unknown"] == 2


def test_param_set_changes_the_value_and_the_behaviour(rig) -> None:
    r = rig(1)
    cmds, replies = r.request(lambda: r.gcs.mav.param_set_send(
        1, 1, b"ROLL_LIMIT_DEG", 30.0, ML.MAV_PARAM_TYPE_REAL32))
    v, = of_type(replies, "PARAM_VALUE")
    assert (v.param_id, v.param_value) == ("ROLL_LIMIT_DEG", 30.0)
    assert cmds[0].command.bank_limit_deg == 30.0  # guidance's bank limit follows
    cmds, replies = r.request(lambda: r.gcs.mav.param_set_send(
        1, 1, b"STALL_PREVENTION", 0, ML.MAV_PARAM_TYPE_INT8))
    assert cmds[0].command.stall_protection is False
    # ALT_HOLD_RTL decides where RTL flies
    r.request(lambda: r.gcs.mav.param_set_send(1, 1, b"ALT_HOLD_RTL", 25000,
                                               ML.MAV_PARAM_TYPE_INT32))
    cmds, _ = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0))
    assert cmds[0].command.alt_m == pytest.approx(400.0 + 250.0)
    _, replies = r.request(lambda: r.gcs.mav.param_request_read_send(1, 1, b"ALT_HOLD_RTL",
                                                                     -1))
    assert of_type(replies, "PARAM_VALUE")[0].param_value == 25000


@pytest.mark.parametrize("name, value", [("ROLL_LIMIT_DEG", 89.0), ("STALL_PREVENTION", 7),
                                         ("SYSID_THISMAV", 9), ("ARMING_CHECK", float("nan"))])
def test_param_set_refused_replies_with_the_value_in_force(rig, name: str, value: float) -> None:
    r = rig(1)
    before = ParamTable(PARAM_DEFS, {}).values[NAMES.index(name)] if name != "SYSID_THISMAV" else 1
    cmds, replies = r.request(lambda: r.gcs.mav.param_set_send(
        1, 1, name.encode(), value, ML.MAV_PARAM_TYPE_REAL32))
    v, = of_type(replies, "PARAM_VALUE")
    assert (v.param_id, v.param_value) == (name, before) and not cmds
    assert of_type(replies, "STATUSTEXT")
    assert r.ep.counters()["param_rejected"] == 1


def test_param_overrides_are_validated() -> None:
    assert ParamTable(PARAM_DEFS, {"AIRSPEED_MIN": 28})["AIRSPEED_MIN"] == 28
    with pytest.raises(ValueError, match="unknown MAVLink parameter 'NOPE'"):
        ParamTable(PARAM_DEFS, {"NOPE": 1})
    with pytest.raises(ValueError, match="ROLL_LIMIT_DEG: 80 is outside 5..75"):
        ParamTable(PARAM_DEFS, {"ROLL_LIMIT_DEG": 80})


def _ftp_request(seq: int, opcode: int, session: int = 0) -> list[int]:
    head = struct.pack("<HBBBBBBI", seq, session, opcode, 0, 0, 0, 0, 0)
    return list(head) + [0] * (251 - len(head))


@pytest.mark.parametrize("opcode, error", [(4, 10), (3, 10), (5, 4), (2, 1)])
def test_ftp_is_answered_with_a_nak(rig, opcode: int, error: int) -> None:
    r = rig(2)
    _, replies = r.request(lambda: r.gcs.mav.file_transfer_protocol_send(
        0, 2, 1, _ftp_request(41, opcode, session=3)))
    nak, = of_type(replies, "FILE_TRANSFER_PROTOCOL")
    assert nak.get_srcSystem() == 2 and (nak.target_system, nak.target_component) == (255, 190)
    seq, session, op, size, req_op = struct.unpack_from("<HBBBB", bytes(nak.payload))
    assert (seq, session, op, size, req_op) == (42, 3, 129, 1, opcode)
    assert nak.payload[12] == error


def test_ftp_responses_are_never_answered(rig) -> None:
    r = rig(1)
    _, replies = r.request(lambda: r.gcs.mav.file_transfer_protocol_send(
        0, 1, 1, _ftp_request(7, 129)))
    assert not of_type(replies, "FILE_TRANSFER_PROTOCOL")
