"""Identity and telemetry, as a pymavlink ground station sees them."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from mavtest import (
    ANCHOR_US,
    HOME_ALT_M,
    PHYSICS_HZ,
    GroundStation,
    S,
    mavutil,
    of_type,
    state_rows,
    vehicle_specs,
)

from cosim.mavlink import DEFAULT_RATES_HZ, MavlinkConfig, MavlinkEndpoint
from cosim.mavlink.vehicle import MavVehicle, SimClock
from cosim.vehicles.fixed_wing.mav_modes import PlaneMode

ML = mavutil.mavlink


def test_n_heartbeats_with_distinct_system_ids(rig) -> None:
    r = rig(5)
    r.step(120)
    hbs = of_type(r.gcs.drain(wait_s=1.0), "HEARTBEAT")
    assert sorted(m.get_srcSystem() for m in hbs) == [1, 2, 3, 4, 5]
    for m in hbs:
        assert m.get_srcComponent() == 1
        assert m.type == ML.MAV_TYPE_FIXED_WING
        assert m.autopilot == ML.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert m.custom_mode == PlaneMode.GUIDED == 15
        assert m.base_mode == (ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                               | ML.MAV_MODE_FLAG_GUIDED_ENABLED
                               | ML.MAV_MODE_FLAG_STABILIZE_ENABLED
                               | ML.MAV_MODE_FLAG_SAFETY_ARMED)
        assert m.system_status == ML.MAV_STATE_ACTIVE
        assert m.get_header().mlen > 0 and m.get_msgbuf()[0] == 253  # MAVLink 2 framing
    # pymavlink's own mode mapping names it the way MAVProxy would
    assert mavutil.mode_string_v10(hbs[0]) == "GUIDED"


def test_default_udpout_reaches_a_listening_station_without_a_hello(tmp_path) -> None:
    """udpout: the ground station listens (as QGC does on 14550); nobody speaks first."""
    gcs = GroundStation("udpin:127.0.0.1:0")
    try:
        with MavlinkEndpoint(vehicle_specs(2), PHYSICS_HZ,
                             MavlinkConfig(url=f"udpout:127.0.0.1:{gcs.port}")) as ep:
            assert ep.local_address[0] == "127.0.0.1"  # bound to loopback
            ep.exchange(0, state_rows(2))
            hbs = of_type(gcs.drain(wait_s=1.0), "HEARTBEAT")
            assert sorted(m.get_srcSystem() for m in hbs) == [1, 2]
    finally:
        gcs.close()


def test_each_vehicle_has_its_own_sequence_numbers(rig) -> None:
    r = rig(2)
    msgs = []
    for _ in range(600):  # 20 s: ~320 packets per vehicle, so the 8-bit seq wraps
        r.step(4)
        msgs += r.gcs.drain()
    msgs += r.gcs.drain(wait_s=0.2)
    for sysid in (1, 2):
        seqs = [m.get_seq() for m in msgs if m.get_srcSystem() == sysid]
        assert len(seqs) >= 300
        steps = {(b - a) % 256 for a, b in zip(seqs, seqs[1:])}
        assert steps == {1}, f"system {sysid}: sequence gaps {steps}"


def test_telemetry_values_match_the_state_rows(rig) -> None:
    r = rig(3)
    tick = 12345  # 102.875 s
    r.step(tick)
    msgs = r.gcs.drain(wait_s=1.0)
    boot_ms = 102875
    for i in range(3):
        sysid, row = i + 1, r.states[i]
        gp, = of_type(msgs, "GLOBAL_POSITION_INT", sysid)
        assert gp.time_boot_ms == boot_ms
        assert gp.lat == round(row[S["lat_deg"]] * 1e7)
        assert gp.lon == round(row[S["lon_deg"]] * 1e7)
        assert gp.alt == round(row[S["alt_msl_m"]] * 1000)
        assert gp.relative_alt == round((row[S["alt_msl_m"]] - HOME_ALT_M) * 1000)
        assert (gp.vx, gp.vy, gp.vz) == (-3050, 2025, -150)
        assert gp.hdg == round(row[S["yaw_deg"]] * 100)

        att, = of_type(msgs, "ATTITUDE", sysid)
        assert att.time_boot_ms == boot_ms
        assert att.roll == pytest.approx(math.radians(row[S["roll_deg"]]), abs=1e-6)
        assert att.pitch == pytest.approx(math.radians(row[S["pitch_deg"]]), abs=1e-6)
        assert att.yaw == pytest.approx(math.radians(row[S["yaw_deg"]]) - 2 * math.pi, abs=1e-6)

        hud, = of_type(msgs, "VFR_HUD", sysid)
        assert hud.airspeed == pytest.approx(37.0)
        assert hud.groundspeed == pytest.approx(math.hypot(30.5, 20.25), abs=1e-5)
        assert hud.heading == int(row[S["yaw_deg"]])
        assert hud.throttle == 62
        assert hud.alt == pytest.approx(row[S["alt_msl_m"]], abs=1e-3)
        assert hud.climb == pytest.approx(1.5)

        gps, = of_type(msgs, "GPS_RAW_INT", sysid)
        assert gps.fix_type == ML.GPS_FIX_TYPE_3D_FIX
        assert gps.time_usec == 102_875_000
        assert (gps.lat, gps.lon, gps.alt) == (gp.lat, gp.lon, gp.alt)
        assert gps.vel == round(math.hypot(30.5, 20.25) * 100)
        assert gps.cog == round(math.degrees(math.atan2(20.25, -30.5)) % 360 * 100)

        st, = of_type(msgs, "SYSTEM_TIME", sysid)
        assert st.time_boot_ms == boot_ms
        assert st.time_unix_usec == ANCHOR_US + 102_875_000

        ss, = of_type(msgs, "SYS_STATUS", sysid)
        gps = ML.MAV_SYS_STATUS_SENSOR_GPS
        assert ss.onboard_control_sensors_present & gps
        assert ss.onboard_control_sensors_enabled & gps
        assert ss.onboard_control_sensors_health & gps
        assert not ss.onboard_control_sensors_present & ML.MAV_SYS_STATUS_GEOFENCE  # none yet
        assert ss.onboard_control_sensors_health & ML.MAV_SYS_STATUS_PREARM_CHECK


def test_attitude_rates_come_from_successive_sim_states(rig) -> None:
    r = rig(1)
    r.states[0, S["roll_deg"]] = 0.0
    r.states[0, S["pitch_deg"]] = 0.0
    r.step(24)
    r.gcs.drain(wait_s=0.5)
    r.states[0, S["yaw_deg"]] += 1.2  # 1.2 deg in 24 ticks = 0.2 s: 6 deg/s
    r.states[0, S["roll_deg"]] = 2.0  # 10 deg/s
    r.step(24)
    att, = of_type(r.gcs.drain(wait_s=1.0), "ATTITUDE")
    assert att.rollspeed == pytest.approx(math.radians(10.0), rel=1e-5)
    # body yaw rate r = psi' cos(phi) cos(theta)
    assert att.yawspeed == pytest.approx(math.radians(6.0) * math.cos(math.radians(2.0)),
                                         rel=1e-5)


def test_rates_over_a_simulated_minute_match_the_defaults(rig) -> None:
    r = rig(2)
    counts: Counter[tuple[str, int]] = Counter()
    gp_times: list[int] = []
    # the rig's first exchange was at tick 0 and sent a first round: count from tick 4
    for k in range(1, 60 * 30):  # control at 30 Hz: every 4 ticks, up to 60 s
        r.step(4)
        if k % 10 == 0:
            for m in r.gcs.drain():
                counts[m.get_type(), m.get_srcSystem()] += 1
                if m.get_type() == "GLOBAL_POSITION_INT" and m.get_srcSystem() == 1:
                    gp_times.append(m.time_boot_ms)
    for m in r.gcs.drain(wait_s=0.5):
        counts[m.get_type(), m.get_srcSystem()] += 1
    for name, hz in DEFAULT_RATES_HZ.items():
        for sysid in (1, 2):
            # ticks 4..7196 hold 60 s of sends minus the one at tick 0
            assert counts[name, sysid] == round(hz * 60) - 1, (name, sysid)
    assert set(np.diff(gp_times)) == {200}  # exactly 5 Hz of simulated time


@pytest.mark.parametrize("every", [1, 4, 7, 13])
def test_schedule_is_exact_for_any_exchange_interval(every: int) -> None:
    v = MavVehicle(vehicle_specs(1)[0], SimClock(PHYSICS_HZ, ANCHOR_US),
                   {"ATTITUDE": 10.0, "VFR_HUD": 0.0, "HOME_POSITION": 0.5})
    sent: Counter[str] = Counter()
    ticks = list(range(0, 7200, every))
    for t in ticks:
        sent.update(v.due(t))
    seconds = 7200 / PHYSICS_HZ
    assert sent["VFR_HUD"] == 0  # off
    assert sent["HOME_POSITION"] == seconds * 0.5
    for name, hz in (("HEARTBEAT", 1), ("GLOBAL_POSITION_INT", 5), ("ATTITUDE", 10)):
        period = round(PHYSICS_HZ / hz)
        # an exchange sends a message once if any due tick fell since the last one
        expected = sum(1 for prev, t in zip([-1] + ticks, ticks)
                       if any(prev < d <= t for d in range(0, 7200, period)))
        assert sent[name] == expected, name
        if every <= period:  # exchanges at least as often as the stream: exact rate
            assert sent[name] == seconds * hz, name


def test_stream_rates_are_configurable(rig) -> None:
    r = rig(1, config=MavlinkConfig(url="udpin:127.0.0.1:0",
                                    rates_hz={"ATTITUDE": 10.0, "VFR_HUD": 0.0}))
    counts: Counter[str] = Counter()
    for _ in range(300):  # 10 s
        r.step(4)
        counts.update(m.get_type() for m in r.gcs.drain())
    counts.update(m.get_type() for m in r.gcs.drain(wait_s=0.5))
    assert counts["ATTITUDE"] == 100
    assert counts["VFR_HUD"] == 0
    assert counts["HEARTBEAT"] == 10


def test_crashed_vehicle_reports_emergency_and_failed_prearm(rig) -> None:
    r = rig(2)
    r.states[1, S["status"]] = 1  # ground impact
    r.step(120)
    msgs = r.gcs.drain(wait_s=1.0)
    hb1, = of_type(msgs, "HEARTBEAT", 1)
    hb2, = of_type(msgs, "HEARTBEAT", 2)
    assert hb1.system_status == ML.MAV_STATE_ACTIVE
    assert hb2.system_status == ML.MAV_STATE_EMERGENCY
    ss2, = of_type(msgs, "SYS_STATUS", 2)
    assert not ss2.onboard_control_sensors_health & ML.MAV_SYS_STATUS_PREARM_CHECK
