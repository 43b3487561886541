"""Per-vehicle .tlog files, read back by pymavlink."""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import pytest
from mavtest import ANCHOR_US, PHYSICS_HZ, mavutil

from cosim.mavlink.outbox import TLOG_FLUSH_S

ML = mavutil.mavlink


def _read(path: Path) -> list:
    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while True:
        m = log.recv_msg()
        if m is None:
            break
        out.append(m)
    log.close()
    return out


def test_tlogs_hold_both_directions_with_sim_time_stamps(rig, tmp_path: Path) -> None:
    r = rig(2)
    for _ in range(30):  # 1 s
        r.step(4)
    r.request(lambda: r.gcs.mav.command_long_send(2, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0,
                                                  0, 0, 0, 0, 0, 0, 0))
    ack_tick = r.tick
    for _ in range(30):
        r.step(4)
    # written to disk at least every TLOG_FLUSH_S: readable while the run goes on
    time.sleep(TLOG_FLUSH_S)
    r.step(0)
    paths = sorted((tmp_path / "tlogs").glob("*.tlog"))
    assert [p.name for p in paths] == ["uav1.tlog", "uav2.tlog"]
    live = _read(paths[1])
    r.ep.close()
    msgs = _read(paths[1])
    assert len(msgs) == len(live) > 0
    assert not [m for m in msgs if m.get_type() == "BAD_DATA"]
    kinds = Counter(m.get_type() for m in msgs)
    for kind in ("HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD", "SYS_STATUS",
                 "GPS_RAW_INT", "SYSTEM_TIME", "COMMAND_LONG", "COMMAND_ACK"):
        assert kinds[kind] >= 1, kind
    assert kinds["GLOBAL_POSITION_INT"] == 5 * 2 + 1  # 2 s of 5 Hz, plus the one at tick 0
    # ours come from system 2; the ground station's from 255 (its hello and the command)
    assert {m.get_srcSystem() for m in msgs} == {2, 255}
    cmd, = [m for m in msgs if m.get_type() == "COMMAND_LONG"]
    ack, = [m for m in msgs if m.get_type() == "COMMAND_ACK"]
    expected_s = (ANCHOR_US + ack_tick * 1_000_000 / PHYSICS_HZ) / 1e6
    assert cmd._timestamp == pytest.approx(expected_s, abs=1e-6)
    assert ack._timestamp == pytest.approx(expected_s, abs=1e-6)
    # every telemetry record is stamped with the sim time it describes
    for m in msgs:
        if m.get_type() == "GLOBAL_POSITION_INT":
            assert m._timestamp == pytest.approx(ANCHOR_US / 1e6 + m.time_boot_ms / 1000,
                                                 abs=1e-6)
    stamps = [m._timestamp for m in msgs]
    assert stamps == sorted(stamps)
    assert not [m for m in _read(paths[0]) if m.get_type() == "COMMAND_LONG"]  # not for it
