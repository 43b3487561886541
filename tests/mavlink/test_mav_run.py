"""`cosim run --mavlink`: a pymavlink ground station against a running
simulation (loopback, ephemeral port)."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

mavutil = pytest.importorskip("pymavlink.mavutil")

from tests.mavlink.mavtest import GroundStation  # noqa: E402

ML = mavutil.mavlink
SCENARIO = """
schema_version: 1
name: mav3
origin: {lat_deg: 37.0, lon_deg: -116.0, ground_alt_m: 1000}
duration_s: 600
vehicles:
  - {id: uav, count: 3, model: uav700, formation: {type: line, spacing_m: 1000},
     init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}}
"""


pytestmark = pytest.mark.integration  # live runs with ground stations


def _dist_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    dn = math.radians(lat2 - lat1) * 6371000.0
    de = math.radians(lon2 - lon1) * 6371000.0 * math.cos(math.radians(lat1))
    return math.hypot(dn, de)


def _start_sim(tmp_path: Path, duration_s: int, realtime: str, gcs_port: int,
               *extra: str, scenario: str = SCENARIO) -> tuple[subprocess.Popen, Path]:
    """``cosim run`` of the 3-vehicle scenario (or ``scenario``) with MAVLink
    sent to ``gcs_port``."""
    scn = tmp_path / "mav3.yaml"
    scn.write_text(scenario.replace("duration_s: 600", f"duration_s: {duration_s}"))
    out = tmp_path / "out"
    sim = subprocess.Popen(
        [sys.executable, "-m", "cosim", "-q", "run", str(scn), "--out", str(out),
         "--realtime", realtime, "--no-progress", "--mavlink",
         f"udpout:127.0.0.1:{gcs_port}", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return sim, out


def _stop_sim(sim: subprocess.Popen) -> str:
    """Ctrl-C, wait; returns stderr."""
    sim.send_signal(signal.SIGINT)
    return sim.communicate(timeout=30)[1]


def test_ground_station_repositions_one_vehicle_and_flies_a_mission_on_another(
        tmp_path: Path) -> None:
    gcs = GroundStation("udpin:127.0.0.1:0")
    sim, out = _start_sim(tmp_path, 600, "10", gcs.port)
    try:
        seen: dict[int, object] = {}
        start: dict[int, tuple[float, float]] = {}
        deadline = time.monotonic() + 60
        while (len(seen) < 3 or len(start) < 3) and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                src = m.get_srcSystem()
                if m.get_type() == "HEARTBEAT":
                    seen[src] = m
                elif m.get_type() == "GLOBAL_POSITION_INT" and src not in start:
                    start[src] = (m.lat * 1e-7, m.lon * 1e-7)
        assert sorted(seen) == [1, 2, 3], f"heartbeats from {sorted(seen)}"
        for hb in seen.values():
            assert hb.type == ML.MAV_TYPE_FIXED_WING
            assert hb.autopilot == ML.MAV_AUTOPILOT_ARDUPILOTMEGA

        gcs.hello()
        gcs.conn.mav.set_mode_send(3, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 15)  # GUIDED
        lat0, lon0 = start[3]
        target = (lat0 + 2000.0 / 111_000.0, lon0)  # about 2 km north
        gcs.conn.mav.command_int_send(
            3, 1, ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_DO_REPOSITION, 0, 0, -1,
            ML.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, 0, round(target[0] * 1e7),
            round(target[1] * 1e7), 1300.0)
        acks, closest = [], 1e9
        deadline = time.monotonic() + 60
        while closest > 700 and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                if m.get_type() == "COMMAND_ACK" and m.get_srcSystem() == 3:
                    acks.append(m)
                if m.get_type() == "GLOBAL_POSITION_INT" and m.get_srcSystem() == 3:
                    closest = min(closest, _dist_m(m.lat * 1e-7, m.lon * 1e-7, *target))
        assert [a.command for a in acks if a.command == ML.MAV_CMD_DO_REPOSITION] == [
            ML.MAV_CMD_DO_REPOSITION]
        assert all(a.result == ML.MAV_RESULT_ACCEPTED for a in acks)
        assert closest <= 700, f"vehicle 3 got no closer than {closest:.0f} m"

        # a 4-waypoint square uploaded to vehicle 2 and flown in AUTO
        lat2, lon2 = start[2]
        dlat, dlon = 1500.0 / 111_000.0, 1500.0 / (111_000.0 * math.cos(math.radians(lat2)))
        square = [(lat2 + dlat, lon2), (lat2 + dlat, lon2 + dlon), (lat2, lon2 + dlon),
                  (lat2, lon2)]
        items = [(lat2, lon2)] + square  # item 0: home (ignored by the vehicle)
        gcs.conn.mav.mission_count_send(2, 1, len(items), ML.MAV_MISSION_TYPE_MISSION)
        ack = None
        deadline = time.monotonic() + 20
        while ack is None and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                if m.get_srcSystem() != 2:
                    continue
                if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                    lat, lon = items[m.seq]
                    gcs.conn.mav.mission_item_int_send(
                        2, 1, m.seq, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                        ML.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, round(lat * 1e7),
                        round(lon * 1e7), 300.0, ML.MAV_MISSION_TYPE_MISSION)
                elif m.get_type() == "MISSION_ACK":
                    ack = m
        assert ack is not None and ack.type == ML.MAV_MISSION_ACCEPTED
        gcs.conn.mav.set_mode_send(2, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 10)  # AUTO
        reached: list[int] = []
        auto_seen = False
        deadline = time.monotonic() + 60
        while len(reached) < 3 and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                if m.get_srcSystem() != 2:
                    continue
                if m.get_type() == "HEARTBEAT" and m.custom_mode == 10:
                    auto_seen = True
                if m.get_type() == "MISSION_ITEM_REACHED" and m.seq not in reached:
                    reached.append(m.seq)
        assert auto_seen, "vehicle 2 never reported AUTO in its heartbeat"
        assert reached[:3] == [1, 2, 3], reached
    finally:
        err = _stop_sim(sim)
        gcs.close()
    assert sim.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mavlink"]["counters"]["packets_out"] > 0
    events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    cmds = [e for e in events if e["event"] == "mavlink_command"]
    assert [c["vehicle"] for c in cmds][:1] == ["uav2"]
    assert any("DO_REPOSITION" in c["origin"] for c in cmds)
    assert any(c["vehicle"] == "uav1" and c["origin"] == "mission" and "goto" in c["command"]
               for c in cmds)
    tlogs = sorted(p.name for p in out.glob("*.tlog"))
    assert tlogs == ["uav0.tlog", "uav1.tlog", "uav2.tlog"]
    assert mavutil.mavlink_connection(str(out / "uav2.tlog")).recv_match(type="HEARTBEAT")


@pytest.mark.parametrize("vehicle_class", ["fixed_wing", "fixed_wing_rigid"])
def test_a_lone_plane_of_each_tier_obeys_a_reposition_and_a_speed_change(
        tmp_path: Path, vehicle_class: str) -> None:
    """One uav700 of the JSBSim tier or the rigid-body tier: an ArduPlane
    heartbeat, its start in GLOBAL_POSITION_INT, and a guided reposition 3 km
    east and 100 m up with a faster airspeed that shows in its flight within
    a few simulated seconds (the times are the messages' time_boot_ms)."""
    scenario = SCENARIO.replace("count: 3, model: uav700, formation: {type: line, "
                                "spacing_m: 1000},",
                                f"class: {vehicle_class}, model: uav700,")
    gcs = GroundStation("udpin:127.0.0.1:0")
    sim, out = _start_sim(tmp_path, 600, "10", gcs.port, scenario=scenario)
    try:
        hb = pos0 = None
        deadline = time.monotonic() + 60  # numba's first compilation on a cold cache
        while (hb is None or pos0 is None) and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                if m.get_type() == "HEARTBEAT":
                    hb = m
                elif m.get_type() == "GLOBAL_POSITION_INT" and pos0 is None:
                    pos0 = m
        assert hb is not None and pos0 is not None, "no heartbeat or position"
        assert (hb.get_srcSystem(), hb.type, hb.autopilot) == (
            1, ML.MAV_TYPE_FIXED_WING, ML.MAV_AUTOPILOT_ARDUPILOTMEGA)
        assert _dist_m(pos0.lat * 1e-7, pos0.lon * 1e-7, 37.0, -116.0) < 100.0
        assert abs(pos0.relative_alt / 1000.0 - 300.0) < 2.0 and pos0.hdg in (0, 35999)
        gcs.hello()
        target = (37.0, -116.0 + 3000.0 / (111_000.0 * math.cos(math.radians(37.0))))
        gcs.conn.mav.command_int_send(
            1, 1, ML.MAV_FRAME_GLOBAL_INT, ML.MAV_CMD_DO_REPOSITION, 0, 0, -1,
            ML.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, 0, round(target[0] * 1e7),
            round(target[1] * 1e7), 1400.0)
        gcs.conn.mav.command_long_send(1, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 65.0, -1,
                                       0, 0, 0, 0)
        acks: dict[int, int] = {}
        track: list[tuple[float, float, float]] = []  # (time_boot_s, heading_deg, alt_m)
        speeds: list[tuple[float, float]] = []  # (time_boot_s, airspeed_mps)
        t_ms = pos0.time_boot_ms
        deadline = time.monotonic() + 30
        while (not track or track[-1][0] - track[0][0] < 10.0) \
                and time.monotonic() < deadline:
            for m in gcs.drain(0.5):
                kind = m.get_type()
                if kind == "COMMAND_ACK":
                    acks[m.command] = m.result
                elif kind == "GLOBAL_POSITION_INT":
                    t_ms = m.time_boot_ms
                    if len(acks) == 2:  # from the first position after both answers
                        track.append((t_ms / 1000.0, m.hdg / 100.0, m.alt / 1000.0))
                elif kind == "VFR_HUD" and len(acks) == 2:
                    speeds.append((t_ms / 1000.0, m.airspeed))
        assert acks == {ML.MAV_CMD_DO_REPOSITION: ML.MAV_RESULT_ACCEPTED,
                        ML.MAV_CMD_DO_CHANGE_SPEED: ML.MAV_RESULT_ACCEPTED}, acks
        assert track and track[-1][0] - track[0][0] >= 10.0, "positions stopped coming"
        (t0, hdg0, alt0), later = track[0], [p for p in track if p[0] <= track[0][0] + 10.0]
        hdg_deg = max(p[1] if p[1] < 180.0 else p[1] - 360.0 for p in later)
        assert hdg_deg - (hdg0 if hdg0 < 180.0 else hdg0 - 360.0) > 45.0, later
        assert max(p[2] for p in later) - alt0 > 30.0, later
        fast = [v for t, v in speeds if t <= t0 + 10.0]
        assert fast and max(fast) - fast[0] > 5.0, speeds
    finally:
        err = _stop_sim(sim)
        gcs.close()
    assert sim.returncode == 130, err
    events = [json.loads(x)["event"] for x in (out / "events.jsonl").read_text().splitlines()]
    assert "ground_impact" not in events and "divergence" not in events


def test_signed_run_answers_only_a_ground_station_with_the_key(tmp_path: Path,
                                                               monkeypatch) -> None:
    import hashlib

    keyfile = tmp_path / "key"
    keyfile.write_text("correct-horse\n")
    good = GroundStation("udpin:127.0.0.1:0")
    good.conn.setup_signing(hashlib.sha256(b"correct-horse").digest(), sign_outgoing=True)
    sim, out = _start_sim(tmp_path, 120, "5", good.port,
                          "--mavlink-signing-key-file", str(keyfile))
    bad = GroundStation("udpout:127.0.0.1:1")  # re-aimed below, once the port is known
    try:
        addr = None
        deadline = time.monotonic() + 60
        while addr is None and time.monotonic() < deadline:
            for m in good.drain(0.5):
                if m.get_type() == "HEARTBEAT":
                    assert m.get_signed()  # telemetry is signed
                    addr = next(iter(good.conn.clients), None)  # the simulation's socket
        assert addr is not None, "no signed heartbeat"
        bad.close()
        bad = GroundStation(f"udpout:{addr[0]}:{addr[1]}")  # no key
        bad.conn.mav.command_long_send(1, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0,
                                       0, 0)
        good.conn.mav.command_long_send(1, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0,
                                        0, 0)
        good_acks, bad_msgs = [], []
        deadline = time.monotonic() + 10
        while not good_acks and time.monotonic() < deadline:
            good_acks += [m for m in good.drain(0.5) if m.get_type() == "COMMAND_ACK"]
        bad_msgs = bad.drain(1.0)
        assert good_acks and good_acks[0].result == ML.MAV_RESULT_ACCEPTED
        assert not [m for m in bad_msgs if m.get_type() == "COMMAND_ACK"]
    finally:
        err = _stop_sim(sim)
        good.close()
        bad.close()
    assert sim.returncode == 130, err
    counters = json.loads((out / "summary.json").read_text())["mavlink"]["counters"]
    assert counters["unsigned_dropped"] >= 1


def test_signing_key_problems_are_usage_errors(tmp_path: Path, capsys) -> None:
    from cosim.cli import main

    scn = tmp_path / "mav3.yaml"
    scn.write_text(SCENARIO)
    args = ["run", str(scn), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(args + ["--mavlink-signing-key-file", str(tmp_path / "nokey")]) == 2
    assert "needs MAVLink" in capsys.readouterr().err
    assert main(args + ["--mavlink", "--mavlink-signing-key-file",
                        str(tmp_path / "nokey")]) == 2
    assert "nokey" in capsys.readouterr().err
    assert main(args + ["--mavlink", "--mavlink-signing-key-env", "COSIM_TEST_NO_SUCH_VAR"]) == 2
    assert "COSIM_TEST_NO_SUCH_VAR" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_fuzzing_a_live_run_leaves_the_vehicles_flying_and_answering(tmp_path: Path) -> None:
    """Random bytes, random well-formed messages and handled messages with
    extreme fields for a fixed time, then the vehicles still fly and answer, no
    handler failed and no vehicle was lost; everything bad is counted, nothing
    stops."""
    import random
    import socket

    from test_mav_fuzz import random_message

    from cosim.mavlink.adapter import Packer

    rng = random.Random(20261121)
    gcs = GroundStation("udpin:127.0.0.1:0")
    sim, out = _start_sim(tmp_path, 300, "2", gcs.port)
    fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        addr = None
        deadline = time.monotonic() + 60
        while addr is None and time.monotonic() < deadline:
            if [m for m in gcs.drain(0.5) if m.get_type() == "HEARTBEAT"]:
                addr = next(iter(gcs.conn.clients), None)
        assert addr is not None
        sender = mavutil.mavlink.MAVLink(None, srcSystem=254, srcComponent=1)
        kinds = [c for c in mavutil.mavlink.mavlink_map.values()
                 if c.name not in ("SETUP_SIGNING",)]
        sent_random = sent_messages = 0
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            if rng.random() < 0.5:  # garbage, truncated, corrupted
                data = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300)))
                if rng.random() < 0.3:
                    data = b"\xfd" + data  # looks like a MAVLink 2 start
                sent_random += 1
            elif rng.random() < 0.5:  # a handled type with extreme fields (test_mav_fuzz)
                m = random_message(rng)
                try:
                    data = Packer(m.src_system, m.src_component).pack(m.name, **dict(m.fields))
                except ValueError:
                    continue
                sent_messages += 1
            else:  # a well-formed message of a random type with random fields
                cls = rng.choice(kinds)
                args = []
                for ftype in cls.fieldtypes:
                    if ftype == "char":
                        args.append(b"x")
                    elif ftype in ("float", "double"):
                        args.append(rng.uniform(-1e6, 1e6))
                    else:
                        bits = {"uint8_t": 8, "int8_t": 7, "uint16_t": 16, "int16_t": 15,
                                "uint32_t": 32, "int32_t": 31, "uint64_t": 63,
                                "int64_t": 63}.get(ftype.split("[")[0], 8)
                        args.append(rng.getrandbits(bits))
                try:
                    msg = cls(*args)
                    data = msg.pack(sender)
                except Exception:
                    continue
                sent_messages += 1
            fuzz.sendto(data, addr)
        assert sent_random > 100 and sent_messages > 100
        # still answering and flying. Like any ground station, repeat an
        # unacknowledged command (datagrams sent while the fuzz still fills the
        # simulation's receive buffer may be dropped by the kernel, as on any
        # lossy link, counted in kernel_dropped; or the answer may come after
        # the backlog, later than a second: a repeat says neither)
        acks, positions = [], []
        deadline = time.monotonic() + 20
        next_try = 0.0
        def answered() -> bool:  # ours: the fuzzer's own requests may be DENIED to 255
            return any(a.result == ML.MAV_RESULT_ACCEPTED for a in acks)

        while (not answered() or len(positions) < 10) and time.monotonic() < deadline:
            if not answered() and time.monotonic() >= next_try:
                gcs.hello()
                gcs.conn.mav.command_long_send(2, 1, ML.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0,
                                               0, 0, 0, 0)
                next_try = time.monotonic() + 1.0
            for m in gcs.drain(0.2):
                if (m.get_type() == "COMMAND_ACK" and m.get_srcSystem() == 2
                        and m.command == ML.MAV_CMD_REQUEST_MESSAGE and m.target_system == 255):
                    acks.append(m)  # ours (the fuzzer's own commands get answers too)
                if m.get_type() == "GLOBAL_POSITION_INT" and m.get_srcSystem() == 1:
                    positions.append((m.lat, m.lon))
        assert len(set(positions)) > 1  # vehicle 1 still moves
    finally:
        fuzz.close()
        err = _stop_sim(sim)
        gcs.close()
    assert sim.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "interrupted"
    c = summary["mavlink"]["counters"]
    assert c["garbage"] + c["bad_crc"] + c["truncated"] + c["malformed"] > 0, c
    assert c["handler_errors"] == 0, c
    events = [json.loads(x)["event"] for x in (out / "events.jsonl").read_text().splitlines()]
    assert "ground_impact" not in events and "divergence" not in events  # no vehicle lost
    # ours among them (the fuzzer's random messages may come from system 255 too, and
    # its own REQUEST_MESSAGEs of odd ids are answered to 255 as DENIED)
    assert any(a.result == ML.MAV_RESULT_ACCEPTED for a in acks), (
        [a.result for a in acks], c)


def test_a_signed_run_keeps_the_vehicles_its_scenario_puts_on_mavlink(tmp_path: Path) -> None:
    """The signing options alone (no --mavlink) keep the scenario's own link,
    its mavlink.vehicles included: only those are on MAVLink."""
    from cosim.cli import main

    keyfile = tmp_path / "key"
    keyfile.write_text("correct-horse\n")
    keyfile.chmod(0o600)
    scn = tmp_path / "mav3.yaml"
    scn.write_text(SCENARIO.replace("duration_s: 600", "duration_s: 1")
                   + "mavlink: {url: 'udpin:127.0.0.1:0', vehicles: [uav1]}\n")
    out = tmp_path / "o"
    assert main(["run", str(scn), "--out", str(out), "--no-progress",
                 "--mavlink-signing-key-file", str(keyfile)]) == 0
    assert sorted(p.name for p in out.glob("*.tlog")) == ["uav1.tlog"]
    assert json.loads((out / "summary.json").read_text())["mavlink"]["counters"]["links"] == 1
