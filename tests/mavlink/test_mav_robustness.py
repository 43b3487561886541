"""Bad input is counted and ignored; the endpoint's contract (URLs, binding,
peers, lifecycle, validation) holds."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest
from mavtest import (
    PHYSICS_HZ,
    GroundStation,
    free_udp_port,
    mavutil,
    of_type,
    state_rows,
    vehicle_specs,
)

from cosim.core.state import VehicleSpec
from cosim.errors import ConfigError
from cosim.mavlink import (
    EndpointClosed,
    LinkError,
    LinkUrl,
    MavlinkConfig,
    MavlinkEndpoint,
    mav_specs,
)
from cosim.mavlink.adapter import Decoder, Packer
from cosim.vehicles import get_class

ML = mavutil.mavlink


def _command(target: int = 1) -> bytes:
    return Packer(255, 190).pack("COMMAND_LONG", target_system=target, target_component=1,
                                 command=ML.MAV_CMD_NAV_LOITER_UNLIM, confirmation=0,
                                 param1=0, param2=0, param3=0, param4=0, param5=0, param6=0,
                                 param7=0)


def test_garbage_bad_crc_and_truncated_datagrams_are_counted_and_ignored(rig) -> None:
    r = rig(2)
    good = _command()
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0x5A
    unknown_id = bytearray(Packer(255, 190).pack("HEARTBEAT", type=6, autopilot=8, base_mode=0,
                                                 custom_mode=0, system_status=0))
    unknown_id[7:10] = (54321).to_bytes(3, "little")  # a message id no dialect defines
    datagrams = [b"hello, vehicles", bytes(range(256)), good[:9], good[:-1], bytes(bad_crc),
                 bytes(unknown_id), b"\xfd", b"\xfe\xff" * 40]
    before = r.ep.counters()
    for d in datagrams:
        r.gcs.send_raw(d)
    cmds, replies = r.request(lambda: r.gcs.send_raw(b"junk" + good + b"\x00\x01"))
    for _ in range(10):  # make sure every datagram was read
        cmds += r.step()
    after = r.ep.counters()
    grew = {k: after[k] - before[k] for k in after if after[k] != before[k]}
    assert grew["garbage"] >= 3 and grew["bad_crc"] >= 1 and grew["truncated"] >= 3
    assert grew["unknown_message"] == 1
    assert after["handler_errors"] == 0 and after["decoder_errors"] == 0
    # the one good command inside the last datagram still got its single ACK
    assert len(cmds) == 1
    acks = of_type(replies + r.gcs.drain(wait_s=0.3), "COMMAND_ACK")
    assert [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED]


def test_decoder_never_raises_and_resyncs_after_random_bytes() -> None:
    d = Decoder()
    rng = np.random.default_rng(1)
    valid = _command()
    for _ in range(3000):
        data = rng.integers(0, 256, size=int(rng.integers(0, 300)), dtype=np.uint8).tobytes()
        d.decode(data)  # anything at all: never raises
        # noise without start-of-packet markers, then a real packet: always recovered
        noise = data.replace(b"\xfd", b"").replace(b"\xfe", b"")
        assert [m.name for m in d.decode(noise + valid)] == ["COMMAND_LONG"]
    assert d.counts["datagrams"] == 6000 and d.counts["decoder_errors"] == 0
    assert d.counts["garbage"] > 2000


def test_a_command_flood_is_bounded_per_exchange(rig) -> None:
    r = rig(1, config=MavlinkConfig(url="udpin:127.0.0.1:0", max_datagrams_per_exchange=50))
    for _ in range(120):
        r.gcs.send_raw(_command())
    first = len(r.step())
    assert first == 50 and r.ep.counters()["poll_capped"] >= 1
    rest = sum(len(r.step()) for _ in range(10))
    assert first + rest == 120  # nothing lost on loopback, just spread over exchanges


def test_our_own_packets_looped_back_are_dropped(rig) -> None:
    r = rig(2)
    echo = Packer(2).pack("COMMAND_LONG", target_system=1, target_component=1,
                          command=ML.MAV_CMD_NAV_LOITER_UNLIM, confirmation=0, param1=0,
                          param2=0, param3=0, param4=0, param5=0, param6=0, param7=0)
    cmds, replies = r.request(lambda: r.gcs.send_raw(echo))
    assert not cmds and not of_type(replies, "COMMAND_ACK")
    assert r.ep.counters()["echoes"] == 1


def test_peers_are_remembered_and_capped(rig) -> None:
    r = rig(1, config=MavlinkConfig(url="udpin:127.0.0.1:0", max_peers=2))
    port = r.ep.local_address[1]
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(3)]
    try:
        for s in socks:
            s.sendto(b"not mavlink", ("127.0.0.1", port))  # garbage does not make a peer
        r.step()
        assert len(r.ep.link.peers) == 1
        for s in socks:
            s.sendto(_command(), ("127.0.0.1", port))
        for _ in range(5):
            r.step()
        c = r.ep.counters()
        assert len(r.ep.link.peers) == 2 and c["peers_displaced"] >= 1
    finally:
        for s in socks:
            s.close()


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _heartbeat(sysid: int) -> bytes:
    return Packer(sysid, 190).pack("HEARTBEAT", type=6, autopilot=8, base_mode=0,
                                   custom_mode=0, system_status=0)


def _flood(port: int, n: int) -> None:
    """``n`` throwaway senders, one valid packet each, from their own sockets."""
    for i in range(n):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(_heartbeat(100 + i % 100), ("127.0.0.1", port))


def _settle(r) -> None:
    """Run exchanges until the endpoint has read everything waiting."""
    for _ in range(20):
        before = r.ep.counters()["datagrams_in"]
        r.step()
        time.sleep(0.005)
        if r.ep.counters()["datagrams_in"] == before:
            return


@pytest.mark.parametrize("station_first", [True, False], ids=["station-first", "flood-first"])
def test_a_hundred_throwaway_senders_never_cut_off_a_real_station(rig,
                                                                  station_first: bool) -> None:
    """A station heartbeating at 1 Hz keeps (or gets) its telemetry and its
    acknowledgements beside 100 one-packet senders, whether it was there
    before them or arrives after they filled the table."""
    r = rig(2, config=MavlinkConfig(url="udpin:127.0.0.1:0"))
    clock = FakeClock()
    r.ep.link.table.clock = clock
    port = r.ep.local_address[1]
    if station_first:
        station = r.gcs
        station.hello()  # its second packet (the rig sent the first): live
        _settle(r)
    _flood(port, 100)
    _settle(r)
    if not station_first:
        assert len(r.ep.link.peers) == 16  # full of throwaways
        station = GroundStation(f"udpout:127.0.0.1:{port}")
    try:
        for _ in range(3):  # a few seconds of heartbeats, a flood between each
            clock.t += 1.0
            station.hello()
            addr = ("127.0.0.1", station.port)  # bound by its first send
            _settle(r)
            _flood(port, 100)
            _settle(r)
        assert addr in r.ep.link.peers
        station.drain(wait_s=0.1)
        r.step(int(PHYSICS_HZ) + 1)  # telemetry due: the station gets it
        beats = of_type(station.drain(wait_s=1.0), "HEARTBEAT")
        assert {b.get_srcSystem() for b in beats} == {1, 2}
        before = r.ep.counters()["datagrams_in"]
        station.send_raw(_command(2))
        cmds = []
        while r.ep.counters()["datagrams_in"] == before:
            cmds += r.step()
        acks = of_type(station.drain(wait_s=1.0), "COMMAND_ACK")
        assert len(cmds) == 1 and [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED]
        c = r.ep.counters()
        assert len(r.ep.link.peers) == 16 and c["peers_displaced"] + c["peers_refused"] >= 300
    finally:
        if station is not r.gcs:
            station.close()


def test_a_full_table_of_live_stations_refuses_a_newcomer_but_answers_it(rig) -> None:
    r = rig(1, config=MavlinkConfig(url="udpin:127.0.0.1:0", max_peers=1))
    r.ep.link.table.clock = FakeClock()
    r.gcs.hello()  # the rig's station: two packets, live
    _settle(r)
    other = GroundStation(f"udpout:127.0.0.1:{r.ep.local_address[1]}")
    try:
        for _ in range(3):
            other.hello()
        _settle(r)
        assert r.ep.link.peers == [("127.0.0.1", r.gcs.port)]
        assert r.ep.counters()["peers_refused"] >= 3
        before = r.ep.counters()["datagrams_in"]
        other.send_raw(_command())
        while r.ep.counters()["datagrams_in"] == before:
            r.step()
        acks = of_type(other.drain(wait_s=1.0), "COMMAND_ACK")  # its answer, not telemetry
        assert [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED]
        r.step(int(PHYSICS_HZ) + 1)
        assert of_type(other.drain(wait_s=0.3), "HEARTBEAT") == []
    finally:
        other.close()


def test_quiet_peers_expire_but_the_udpout_target_stays(tmp_path: Path) -> None:
    ep = MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ,
                         MavlinkConfig(url=f"udpout:127.0.0.1:{free_udp_port()}"))
    try:
        clock = FakeClock()
        ep.link.table.clock = clock
        target = list(ep.link.peers)
        gcs = GroundStation(f"udpout:127.0.0.1:{ep.local_address[1]}")
        try:
            gcs.hello()
            states = state_rows(1)
            for _ in range(50):
                ep.exchange(0, states)
                if len(ep.link.peers) == 2:
                    break
                time.sleep(0.01)
            assert len(ep.link.peers) == 2
            clock.t += 10.5  # quiet for longer than PEER_TIMEOUT_S
            ep.exchange(0, states)
            assert ep.link.peers == target and ep.counters()["peers_expired"] == 1
        finally:
            gcs.close()
    finally:
        ep.close()


@pytest.mark.parametrize("url, parsed", [
    ("udpout:127.0.0.1:14550", ("udpout", "127.0.0.1", 14550)),
    ("udpin:0.0.0.0:14551", ("udpin", "0.0.0.0", 14551)),
    ("udp:localhost:14552", ("udpin", "localhost", 14552)),
])
def test_url_forms(url: str, parsed: tuple[str, str, int]) -> None:
    u = LinkUrl.parse(url)
    assert (u.mode, u.host, u.port) == parsed


@pytest.mark.parametrize("url", ["tcp:127.0.0.1:5760", "udpout:127.0.0.1", "udpin::14550",
                                 "udpout:127.0.0.1:port", "udpout:127.0.0.1:0", "udpin:h:70000"])
def test_bad_urls_are_config_errors(url: str) -> None:
    with pytest.raises(ConfigError, match="expected udpout:HOST:PORT"):
        LinkUrl.parse(url)


def test_udpin_binds_to_loopback_and_a_busy_port_is_a_clear_error() -> None:
    with MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ,
                         MavlinkConfig(url="udpin:127.0.0.1:0")) as ep:
        host, port = ep.local_address
        assert host == "127.0.0.1" and port > 0 and not ep.link.peers
        with pytest.raises(LinkError, match=f"cannot bind 127.0.0.1:{port}.*pick another port"):
            MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ,
                            MavlinkConfig(url=f"udpin:127.0.0.1:{port}"))


def test_lifecycle_and_argument_errors(tmp_path) -> None:
    ep = MavlinkEndpoint(vehicle_specs(2), PHYSICS_HZ, MavlinkConfig(url="udpin:127.0.0.1:0"),
                         tlog_dir=tmp_path)
    states = state_rows(2)
    ep.exchange(8, states)
    ep.exchange(8, states)  # the same tick again is fine
    with pytest.raises(ValueError, match="tick 4 is before the previous exchange's tick 8"):
        ep.exchange(4, states)
    with pytest.raises(ValueError, match=r"states must be \(n >= 2, "):
        ep.exchange(12, states[:1])
    ep.close()
    ep.close()  # twice is fine
    with pytest.raises(EndpointClosed, match="after close"):
        ep.exchange(12, states)


def test_bad_configuration_is_reported_all_at_once() -> None:
    specs = vehicle_specs(2)
    dup = [specs[0], specs[0]]
    with pytest.raises(ConfigError) as e:
        MavlinkEndpoint(dup, PHYSICS_HZ, MavlinkConfig(
            url="udpin:127.0.0.1:0", rates_hz={"ATTITUDE": -1, "MISSION_ITEM": 1}))
    text = str(e.value)
    assert "duplicate vehicle system id(s): [1]" in text
    assert "ATTITUDE: rate must be a number >= 0" in text
    assert "'MISSION_ITEM' is not a message cosim streams" in text
    with pytest.raises(ConfigError, match="at most 240"):
        MavlinkEndpoint(vehicle_specs(241), PHYSICS_HZ)


def test_mav_specs_from_scenario_vehicles() -> None:
    v = VehicleSpec(id="a b", model="c172p", aircraft_dir="", model_source="jsbsim",
                    lat_deg=47.1, lon_deg=8.2, alt_msl_m=900, heading_deg=0,
                    airspeed_mps=51.4, terrain_alt_m=420,
                    profile={"airspeed_min_kt": 55, "airspeed_max_kt": 140})
    s, = mav_specs([v], get_class, first_sysid=7, first_row=3)
    assert (s.sysid, s.row, s.name) == (7, 3, "a b")
    assert (s.start_lat_deg, s.start_lon_deg, s.start_alt_msl_m, s.home_alt_msl_m) == (
        47.1, 8.2, 900, 420)
    assert s.params == {"AIRSPEED_MIN": 29, "AIRSPEED_MAX": 72, "AIRSPEED_CRUISE": 51.4}
