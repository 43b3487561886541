"""MAVLink test helpers: synthetic state rows, endpoints on ephemeral
loopback ports and a pymavlink ground station (no JSBSim needed)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")  # before mavutil picks its dialect
mavutil = pytest.importorskip("pymavlink.mavutil")

from cosim.core.state import N_STATE, STATE_INDEX  # noqa: E402
from cosim.mavlink import MavlinkConfig, MavlinkEndpoint, MavVehicleSpec  # noqa: E402

S = STATE_INDEX
PHYSICS_HZ = 120.0
ANCHOR_US = 1_600_000_000_000_000  # 2020-09-13T12:26:40Z: a fixed past instant
HOME_ALT_M = 400.0
START_ALT_M = 1000.0


def start_of(i: int) -> tuple[float, float]:
    return 47.0 + 0.01 * i, 8.0 + 0.02 * i


def state_rows(n: int) -> np.ndarray:
    """n flying vehicles with distinct, non-round values in every column used."""
    s = np.zeros((n, N_STATE))
    for i in range(n):
        lat, lon = start_of(i)
        s[i, S["lat_deg"]] = lat + 0.00123
        s[i, S["lon_deg"]] = lon - 0.00456
        s[i, S["alt_msl_m"]] = 987.654 + 10 * i
        s[i, S["alt_agl_m"]] = s[i, S["alt_msl_m"]] - HOME_ALT_M
        s[i, S["roll_deg"]] = 12.5 - i
        s[i, S["pitch_deg"]] = 3.25
        s[i, S["yaw_deg"]] = 200.0 + 7 * i  # > 180: checks the -pi..pi wrap
        s[i, S["vn_mps"]] = -30.5
        s[i, S["ve_mps"]] = 20.25
        s[i, S["vd_mps"]] = -1.5
        s[i, S["airspeed_mps"]] = 37.0
        s[i, S["throttle"]] = 0.62
        s[i, S["ap_engaged"]] = 1.0
        s[i, S["bank_limit_deg"]] = 45.0
        s[i, S["status"]] = 0.0
    return s


def vehicle_specs(n: int, has_autopilot: bool = True, **kw: Any) -> list[MavVehicleSpec]:
    """n fixed-wing vehicles (ArduPlane; ``has_autopilot=False``: a plain JSBSim
    model's personality, no autopilot; ``personality=``: another one)."""
    from cosim.vehicles.fixed_wing import DEFAULT_MIN_ALT_AGL_M, FIXED_WING
    from cosim.vehicles.plain import PLAIN

    cls = FIXED_WING if has_autopilot else PLAIN
    kw.setdefault("min_alt_agl_m", DEFAULT_MIN_ALT_AGL_M)
    kw.setdefault("personality", cls.mavlink)
    kw.setdefault("safety", cls.safety_problems)
    return [MavVehicleSpec(row=i, sysid=i + 1, name=f"uav{i + 1}", start_lat_deg=start_of(i)[0],
                           start_lon_deg=start_of(i)[1], start_alt_msl_m=START_ALT_M,
                           home_alt_msl_m=HOME_ALT_M,
                           **kw) for i in range(n)]


class GroundStation:
    """A pymavlink client (system 255, component 190) talking to an endpoint."""

    def __init__(self, url: str, key: bytes | None = None) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190,
                                               dialect="ardupilotmega")
        self.mav = self.conn.mav
        if key is not None:  # as MAVProxy's "signing key" does
            self.conn.setup_signing(key, sign_outgoing=True)

    @property
    def port(self) -> int:
        return int(self.conn.port.getsockname()[1])

    def hello(self) -> None:
        self.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def send_raw(self, data: bytes) -> None:
        self.conn.write(data)

    def drain(self, wait_s: float = 0.0) -> list[Any]:
        """Every message waiting (after waiting up to ``wait_s`` for the first)."""
        out: list[Any] = []
        deadline = time.monotonic() + wait_s
        while True:
            m = self.conn.recv_msg()
            if m is not None:
                if m.get_type() != "BAD_DATA":
                    out.append(m)
                continue
            if out or time.monotonic() >= deadline:
                return out
            time.sleep(0.001)

    def close(self) -> None:
        self.conn.close()


class Rig:
    """An endpoint (udpin on an ephemeral loopback port), its state rows and a
    ground station that has said hello; ``step()`` runs one exchange."""

    def __init__(self, tmp_path: Path, n: int, config: MavlinkConfig | None = None,
                 anchor_us: int = ANCHOR_US, gcs_key: bytes | None = None,
                 **spec_kw: Any) -> None:
        self.n = n
        self.states = state_rows(n)
        self.tick = 0
        self.ep = MavlinkEndpoint(vehicle_specs(n, **spec_kw), PHYSICS_HZ,
                                  config or MavlinkConfig(url="udpin:127.0.0.1:0"),
                                  tlog_dir=tmp_path / "tlogs", clock_anchor_unix_us=anchor_us)
        self.gcs = GroundStation(f"udpout:127.0.0.1:{self.ep.local_address[1]}", gcs_key)
        self.gcs.hello()
        self.step()
        self.gcs.drain(wait_s=1.0)
        assert self.ep.link.peers, "the endpoint did not learn the ground station's address"

    def step(self, ticks: int = 0) -> list[Any]:
        """Advance ``ticks`` and run one exchange; the commands it returned."""
        self.tick += ticks
        return list(self.ep.exchange(self.tick, self.states))

    def request(self, send: Callable[[], None], wait_s: float = 2.0) -> tuple[list[Any],
                                                                                  list[Any]]:
        """Send something, run exchanges (same tick) until it has been read;
        returns (commands, replies)."""
        before = self.ep.counters()["datagrams_in"]
        send()
        commands: list[Any] = []
        deadline = time.monotonic() + wait_s
        while True:
            commands += self.step()
            if self.ep.counters()["datagrams_in"] > before or time.monotonic() > deadline:
                break
            time.sleep(0.001)
        return commands, self.gcs.drain(wait_s=0.2)

    def close(self) -> None:
        self.gcs.close()
        self.ep.close()


def free_udp_port() -> int:
    """A loopback UDP port nobody holds right now (bind, read, release: another
    process could take it before the caller binds it; fine on a test machine)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def of_type(msgs: list[Any], kind: str, src: int | None = None) -> list[Any]:
    return [m for m in msgs if m.get_type() == kind and (src is None or m.get_srcSystem() == src)]
