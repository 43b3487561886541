"""MAVSDK (the native binding, ``pip install mavsdk``: what most outside
scripts use) against `cosim run --mavlink` with one vehicle of each class:
it lists the three systems with their vehicle types, uploads to each a
6-item mission with a LOITER_TURNS and a DO_JUMP (a rover cannot circle: its
LOITER_TURNS is refused alone and skipped), starts them, follows their
progress to the end (the jump shows as the current item going back), reads
the flight mode, and changes a parameter of each (the set waits for the
vehicle's PARAM_VALUE)."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

mavsdk = pytest.importorskip(
    "mavsdk", minversion="4.0",
    reason="MAVSDK's Python binding is in the test extras: pip install -e .[test]")
mavutil = pytest.importorskip("pymavlink.mavutil")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem, MissionRaw  # noqa: E402
from mavsdk.plugins.param import Param  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

from tests.mavlink.mavtest import free_udp_port  # noqa: E402
from tests.mavlink.test_mav_run import _stop_sim  # noqa: E402

ML = mavutil.mavlink
SCENARIO = """\
schema_version: 1
name: mavsdk_three_classes
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 5}
duration_s: 1200
vehicles:
  - {id: plane, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300,
     heading_deg: 0, airspeed_kt: 80}}
  - {id: quad, model: F450, init: {north_m: 0, east_m: 50, alt_agl_m: 20}}
  - {id: car, class: ground, max_speed_mps: 6, init: {north_m: 0, east_m: 100,
     heading_deg: 0}}
"""
#: per system id: (leg length m, loiter radius m, altitude above home m, parameter, new value)
PLANS = {1: (600.0, 250.0, 300.0, "AIRSPEED_CRUISE", 22.0),
         2: (40.0, 12.0, 20.0, "WPNAV_SPEED", 400.0),
         3: (40.0, 12.0, 0.0, "WP_SPEED", 3.0)}
TYPES = {1: ML.MAV_TYPE_FIXED_WING, 2: ML.MAV_TYPE_QUADROTOR, 3: ML.MAV_TYPE_GROUND_ROVER}
REL = ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


pytestmark = pytest.mark.integration  # MAVSDK against a live run


def _at(lat: float, lon: float, north_m: float, east_m: float) -> tuple[int, int]:
    return (round((lat + north_m / 111_319.49) * 1e7),
            round((lon + east_m / (111_319.49 * math.cos(math.radians(lat)))) * 1e7))


def _plan(lat: float, lon: float, leg: float, radius: float, alt: float) -> list[MissionItem]:
    """Home, then: WP north, WP north-east, LOITER_TURNS 1 east, DO_JUMP to 1
    once, DO_CHANGE_SPEED, WP back at the start."""
    def nav(seq: int, command: int, north: float, east: float, p1: float = 0.0,
            p3: float = 0.0) -> MissionItem:
        x, y = _at(lat, lon, north, east)
        return MissionItem(seq, REL, command, int(seq == 0), 1, p1, 0.0, p3, 0.0, x, y, alt, 0)

    return [nav(0, ML.MAV_CMD_NAV_WAYPOINT, 0, 0),
            nav(1, ML.MAV_CMD_NAV_WAYPOINT, leg, 0),
            nav(2, ML.MAV_CMD_NAV_WAYPOINT, leg, leg),
            nav(3, ML.MAV_CMD_NAV_LOITER_TURNS, 0, leg, p1=1, p3=radius),
            MissionItem(4, ML.MAV_FRAME_MISSION, ML.MAV_CMD_DO_JUMP, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0),
            MissionItem(5, ML.MAV_FRAME_MISSION, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 1, 0,
                        25.0 if leg > 100 else 3.0, -1, 0, 0, 0, 0, 0),
            nav(6, ML.MAV_CMD_NAV_WAYPOINT, 0, 0)]


def _wait(what: str, ok: Any, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not ok():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


def test_mavsdk_lists_flies_missions_reads_modes_and_sets_parameters(tmp_path: Path) -> None:
    port = free_udp_port()
    scn = tmp_path / "three.yaml"
    scn.write_text(SCENARIO)
    out = tmp_path / "out"
    sim = subprocess.Popen(
        [sys.executable, "-m", "cosim", "-q", "run", str(scn), "--out", str(out),
         "--realtime", "20", "--no-progress", "--mavlink", f"udpout:127.0.0.1:{port}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        drone.add_any_connection(f"udpin://127.0.0.1:{port}")
        _wait("three systems", lambda: drone.system_count() == 3, 60)
        systems = {s.get_system_id(): s for s in drone.get_systems()}
        assert sorted(systems) == [1, 2, 3]
        assert all(s.has_autopilot() and s.is_connected() for s in systems.values())
        tel = {sid: Telemetry(s) for sid, s in systems.items()}
        for sid, t in tel.items():
            _wait(f"system {sid}'s position", lambda t=t: math.isfinite(
                t.position().latitude_deg), 30)
        assert tel[2].flight_mode() == FlightMode.HOLD  # ArduCopter LOITER
        assert tel[3].flight_mode() == FlightMode.HOLD  # ArduRover HOLD

        missions = {sid: MissionRaw(s) for sid, s in systems.items()}
        progress: dict[int, list[tuple[int, int]]] = {sid: [] for sid in systems}
        lock = threading.Lock()
        def seen(p: Any, sid: int) -> None:
            with lock:
                progress[sid].append((p.current, p.total))

        for sid, mr in missions.items():
            mr.subscribe_mission_progress(seen, sid)
            pos = tel[sid].position()
            leg, radius, alt, _, _ = PLANS[sid]
            mr.upload_mission(_plan(pos.latitude_deg, pos.longitude_deg, leg, radius, alt))
        for mr in missions.values():
            mr.start_mission()
        _wait("every mission to finish", lambda: all(
            mr.is_mission_finished() for mr in missions.values()), 120)
        for sid in systems:
            assert tel[sid].flight_mode() == FlightMode.MISSION, sid
            currents = [c for c, total in progress[sid] if total == 7]
            assert currents[-1] == 7, (sid, progress[sid])
            back = [a for a, b in zip(currents, currents[1:]) if b < a]
            assert back, f"system {sid}: the DO_JUMP never took it back: {currents}"
        for sid, s in systems.items():
            _, _, _, name, value = PLANS[sid]
            p = Param(s)
            p.set_param_float(name, value)
            assert p.get_param_float(name) == pytest.approx(value)
    finally:
        drone.destroy()
        err = _stop_sim(sim)
    assert sim.returncode == 130, err
    types = {}
    for sid, name in ((1, "plane"), (2, "quad"), (3, "car")):
        log = mavutil.mavlink_connection(str(out / f"{name}.tlog"), dialect="ardupilotmega")
        texts = []
        while (m := log.recv_match(type=["HEARTBEAT", "STATUSTEXT"])) is not None:
            if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == sid:
                types[sid] = m.type
            elif m.get_type() == "STATUSTEXT":
                texts.append(m.text)
        log.close()
        refused = any("LOITER_TURNS" in t for t in texts)
        assert refused == (sid == 3), (sid, texts)  # only the rover cannot circle
    assert types == TYPES
