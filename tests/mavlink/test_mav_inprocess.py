"""In-process clients (subscribe/inject, no socket) and lockstep with an
outside controller: the same messages, the same tick, whichever way."""

from __future__ import annotations

import dataclasses
import math
import socket
import struct
import time
from pathlib import Path
from typing import Any

import pytest
from mavtest import ANCHOR_US, PHYSICS_HZ, S, mavutil, state_rows, vehicle_specs

from cosim.mavlink import LockstepTimeout, MavlinkConfig, MavlinkEndpoint
from cosim.mavlink import adapter as mav

CTRL = 245  # the controller's system id


def _endpoint(tmp_path: Path, n: int, **cfg: Any) -> MavlinkEndpoint:
    return MavlinkEndpoint(vehicle_specs(n), PHYSICS_HZ, MavlinkConfig(**cfg),
                           tlog_dir=tmp_path, clock_anchor_unix_us=ANCHOR_US)


def _reposition(sysid: int, lat_deg: float, lon_deg: float, alt_m: float) -> mav.Message:
    return mav.make_message(
        "COMMAND_INT", src_system=CTRL, src_component=190, target_system=sysid,
        target_component=1, frame=mav.MAV_FRAME_GLOBAL_INT, command=mav.MAV_CMD_DO_REPOSITION,
        param1=-1, param2=mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, x=int(lat_deg * 1e7),
        y=int(lon_deg * 1e7), z=alt_m)


def test_in_process_client_sees_wire_values_and_commands_without_a_socket(
        tmp_path: Path) -> None:
    ep = _endpoint(tmp_path, 2, url=None)
    got: list[mav.Message] = []
    ep.subscribe(got.append)
    states = state_rows(2)
    assert ep.exchange(0, states) == []
    att = [m for m in got if m.name == "ATTITUDE" and m.src_system == 2]
    assert len(att) == 1
    roll = att[0].fields["roll"]
    # exactly what a receiver decodes: the float32 nearest the radians
    rad = math.radians(states[1, S["roll_deg"]])
    assert roll == struct.unpack("<f", struct.pack("<f", rad))[0] and roll != rad
    assert {m.name for m in got} >= {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE"}
    got.clear()
    ep.inject(_reposition(2, 47.02, 8.03, 1100.0))
    cmds = ep.exchange(4, states)
    assert [c.row for c in cmds] == [1]
    assert cmds[0].origin.endswith("in-process")
    acks = [m for m in got if m.name == "COMMAND_ACK"]
    assert [(a.src_system, a.fields["result"]) for a in acks] == [(2, mav.MAV_RESULT_ACCEPTED)]
    assert ep.counters()["injected"] == 1 and ep.link.peers == []
    ep.close()
    # the tlog holds what the vehicle received from the in-process client too,
    # as the packet it would have been on the network, and its answer
    log = mavutil.mavlink_connection(str(tmp_path / "uav2.tlog"), dialect="ardupilotmega")
    seen = []
    while (m := log.recv_msg()) is not None:
        seen.append((m.get_type(), m.get_srcSystem()))
    log.close()
    assert ("COMMAND_INT", CTRL) in seen and ("COMMAND_ACK", 2) in seen
    assert seen.index(("COMMAND_INT", CTRL)) < seen.index(("COMMAND_ACK", 2))


class _Controller:
    """A bare outside controller on a UDP socket (system 245)."""

    def __init__(self, sim_port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.addr = ("127.0.0.1", sim_port)
        self.mav = mavutil.mavlink.MAVLink(None, srcSystem=CTRL, srcComponent=190)

    def send(self, msg: Any) -> None:
        self.sock.sendto(msg.pack(self.mav), self.addr)

    def until_timesync(self) -> tuple[list[Any], int]:
        """Messages up to the simulation's TIMESYNC request; its ts1."""
        parser = mavutil.mavlink.MAVLink(None)
        seen: list[Any] = []
        while True:
            data = self.sock.recv(65535)
            for m in parser.parse_buffer(data) or []:
                if m.get_type() == "TIMESYNC" and m.tc1 == 0:
                    return seen, int(m.ts1)
                seen.append(m)


def test_lockstep_controller_commands_land_on_the_next_exchange(tmp_path: Path) -> None:
    ep = _endpoint(tmp_path, 2, url="udpin:127.0.0.1:0", lockstep_sysid=CTRL,
                   lockstep_timeout_s=5.0)
    ctl = _Controller(ep.local_address[1])
    try:
        states = state_rows(2)
        ctl.send(mavutil.mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        assert ep.exchange(0, states) == []  # waited for the hello
        seen, ts1 = ctl.until_timesync()
        assert ts1 == 0 and any(m.get_type() == "GLOBAL_POSITION_INT" for m in seen)
        # the command, then the answer: both handled at the next exchange
        ML = mavutil.mavlink
        ctl.send(ML.MAVLink_command_int_message(
            2, 1, ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_DO_REPOSITION, 0, 0, -1,
            ML.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, 0, int(47.02e7), int(8.03e7), 1100.0))
        ctl.send(mavutil.mavlink.MAVLink_timesync_message(123, ts1))
        cmds = ep.exchange(4, states)
        assert [c.row for c in cmds] == [1]
        _, ts1 = ctl.until_timesync()
        assert ts1 == int(4 * 1e9 / PHYSICS_HZ) // 1000 * 1000
        # no answer: a named error, not a hang
        t0 = time.monotonic()
        ep.config = dataclasses.replace(ep.config, lockstep_timeout_s=0.3)
        with pytest.raises(LockstepTimeout, match="TIMESYNC answer for tick 4"):
            ep.exchange(8, states)
        assert time.monotonic() - t0 < 5
    finally:
        ctl.sock.close()
        ep.close()



def test_a_new_bank_limit_is_announced_as_param_value(tmp_path: Path) -> None:
    ep = _endpoint(tmp_path, 2, url=None)
    got: list[mav.Message] = []
    ep.subscribe(got.append)
    states = state_rows(2)
    ep.exchange(0, states)
    assert not [m for m in got if m.name == "PARAM_VALUE"]  # 45 deg: the default
    states[1, S["bank_limit_deg"]] = 60.0  # the schedule set bank_limit_deg on vehicle 2
    got.clear()
    ep.exchange(4, states)
    pv = [m for m in got if m.name == "PARAM_VALUE"]
    assert [(m.src_system, m.fields["param_id"], m.fields["param_value"]) for m in pv] == [
        (2, "ROLL_LIMIT_DEG", 60.0)]
    got.clear()
    ep.exchange(8, states)  # announced once
    assert not [m for m in got if m.name == "PARAM_VALUE"]
    ep.close()


def test_a_controller_that_never_says_hello_is_a_named_timeout(tmp_path: Path) -> None:
    ep = _endpoint(tmp_path, 1, url="udpin:127.0.0.1:0", lockstep_sysid=CTRL,
                   lockstep_timeout_s=0.2)
    try:
        with pytest.raises(LockstepTimeout, match=r"no message from the controller "
                                                  r"\(system 245\) within 0.2 s at tick 0"):
            ep.exchange(0, state_rows(1))
    finally:
        ep.close()
