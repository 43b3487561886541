"""MAVLink 2 signing state shared between the links of a run and between
runs using the same key: a signed packet accepted anywhere is a replay
everywhere else; a vehicle's own signed packet sent back makes nobody a peer."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from mavtest import PHYSICS_HZ, GroundStation, Rig, mavutil, of_type, state_rows
from test_mav_links import _vehicles
from test_mav_signing import ENV, KEY, PASSPHRASE, URL, _deliver, _now_us, _rtl

from cosim.mavlink import MavlinkConfig, MavlinkLinks
from cosim.mavlink import adapter as mav
from cosim.vehicles import get_class

ML = mavutil.mavlink
HERE = Path(__file__).resolve().parent


def _config(state_dir: Path, **kw: Any) -> MavlinkConfig:
    return MavlinkConfig(url=URL, signing_key_env=ENV, signing_link_id=7,
                         signing_state_dir=state_dir, **kw)


@pytest.fixture
def keyed(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV, PASSPHRASE)


#: another run using the key: an endpoint in its own process, exchanging until
#: its stdin closes, then printing its counters and the commands it produced
OTHER_RUN = """
import json, select, sys
from mavtest import PHYSICS_HZ, state_rows, vehicle_specs
from cosim.mavlink import MavlinkConfig, MavlinkEndpoint
cfg = MavlinkConfig(url="udpin:127.0.0.1:0", signing_key_env=sys.argv[1], signing_link_id=7,
                    signing_state_dir=sys.argv[2])
ep = MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ, cfg)
print(ep.local_address[1], flush=True)
states, tick, commands = state_rows(1), 0, 0
while not select.select([sys.stdin], [], [], 0.005)[0]:
    commands += len(ep.exchange(tick, states))
    tick += 4
commands += len(ep.exchange(tick, states))  # what was sent before the stop
ep.close()
print(json.dumps({"commands": commands, **ep.counters()}), flush=True)
"""


def test_a_packet_accepted_by_one_run_is_refused_by_another_running_at_the_same_time(
        keyed: None, rig: Any, tmp_path: Path) -> None:
    """Two processes share only the state folder: the other run started
    before the packet was accepted here, so only the file can tell it."""
    state = tmp_path / "signing"
    other = subprocess.Popen(
        [sys.executable, "-c", OTHER_RUN, ENV, str(state)], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(HERE), os.environ.get(
            "PYTHONPATH", "")])))
    try:
        assert other.stdout is not None
        port = int(other.stdout.readline())
        here = rig(1, config=_config(state), anchor_us=_now_us(), gcs_key=KEY)
        captured = _rtl(here.gcs)
        assert len(_deliver(here, lambda: here.gcs.send_raw(captured))) == 1
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(captured, ("127.0.0.1", port))  # replayed to the other run
            time.sleep(0.1)
            s.sendto(bytes(here.gcs.mav.command_long_encode(  # the station's next: obeyed
                1, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, 0, 0, 0, 0, 0, 0).pack(here.gcs.mav)),
                ("127.0.0.1", port))
        out, err = other.communicate("stop\n", timeout=20)
    finally:
        if other.poll() is None:
            other.kill()
            other.wait()
    c = json.loads(out.splitlines()[-1])
    assert (c["replay_dropped"], c["commands"]) == (1, 1), (c, err)


def _pump(links: MavlinkLinks, states: Any, tick: int, until: Any, wait_s: float = 3.0
          ) -> tuple[list[Any], int]:
    """Exchanges until ``until(links)``; the commands produced and the tick."""
    commands: list[Any] = []
    deadline = time.monotonic() + wait_s
    while not until(links) and time.monotonic() < deadline:
        tick += 4
        commands += links.exchange(tick, states)
        time.sleep(0.002)
    return commands, tick


def test_a_packet_accepted_on_one_link_is_refused_on_the_others(keyed: None,
                                                                tmp_path: Path) -> None:
    """245 vehicles, two links: system 3 of each is a different vehicle. An
    RTL captured on link 0 (its station's link id) replayed to link 1 is
    refused; link 1's own station, another link id, is obeyed."""
    n = 245
    links = MavlinkLinks(_vehicles(n), get_class, PHYSICS_HZ, _config(tmp_path / "signing"),
                         clock_anchor_unix_us=_now_us())
    (_, p0), (_, p1) = links.local_addresses
    gcs0 = GroundStation(f"udpout:127.0.0.1:{p0}", KEY)
    gcs1 = GroundStation(f"udpout:127.0.0.1:{p1}", KEY)
    states = state_rows(n)
    try:
        assert gcs0.mav.signing.link_id != gcs1.mav.signing.link_id

        def read_on(link: int, before: int) -> Any:
            return lambda ls: ls.endpoints[link].counters()["datagrams_in"] > before

        # NAV_RETURN_TO_LAUNCH for system 3: row 2 on link 0, row 242 on link 1
        captured = bytes(gcs0.mav.command_long_encode(
            3, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs0.mav))
        gcs0.send_raw(captured)
        cmds, tick = _pump(links, states, 0, read_on(0, 0))
        assert [c.row for c in cmds] == [2]
        gcs1.send_raw(captured)
        cmds, tick = _pump(links, states, tick, read_on(1, 0))
        assert cmds == []
        assert links.endpoints[1].counters()["replay_dropped"] == 1
        gcs1.send_raw(bytes(gcs1.mav.command_long_encode(
            3, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs1.mav)))
        cmds, tick = _pump(links, states, tick, read_on(1, 1))
        assert [c.row for c in cmds] == [242]
        assert links.counters()["replay_dropped"] == 1
    finally:
        gcs0.close()
        gcs1.close()
        links.close()


def _signed_rig(rig: Any, tmp_path: Path, n: int = 2) -> Rig:
    r: Rig = rig(n, config=_config(tmp_path / "signing"), anchor_us=_now_us(), gcs_key=KEY)
    return r


def test_a_vehicles_own_signed_packets_sent_back_make_no_peer(keyed: None, rig: Any,
                                                               tmp_path: Path) -> None:
    """A keyless sender reflecting the vehicles' signed heartbeats (each one
    fresh, so no replay of an accepted stream) gets no telemetry, and is not
    obeyed; neither is one signing as a vehicle (system 1, component 1) with
    the key, nor one replaying the station's accepted command."""
    r = _signed_rig(rig, tmp_path)
    r.step(int(PHYSICS_HZ) + 1)
    beats = [bytes(m.get_msgbuf()) for m in of_type(r.gcs.drain(wait_s=1.0), "HEARTBEAT")]
    assert len(beats) >= 2
    peers = list(r.ep.link.peers)
    reflector = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    reflector.bind(("127.0.0.1", 0))
    reflector.settimeout(0.3)
    try:
        for b in beats:
            _deliver(r, lambda b=b: reflector.sendto(b, r.ep.local_address))
        assert r.ep.link.peers == peers
        assert r.ep.counters()["echoes"] == len(beats)
        for link_id in (7, 3):  # a vehicle's own stream, and system 1 on another link id
            forger = mav.Packer(1, 1)
            forger.enable_signing(KEY, link_id)
            forger.advance_signing_time(mav.wall_signing_timestamp())
            pkt = forger.pack("COMMAND_LONG", target_system=2, target_component=1,
                              command=ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, confirmation=0,
                              param1=0, param2=0, param3=0, param4=0, param5=0, param6=0,
                              param7=0)
            assert _deliver(r, lambda p=pkt: reflector.sendto(p, r.ep.local_address)) == []
        assert r.ep.link.peers == peers
        assert r.ep.counters()["echoes"] == len(beats) + 2
        accepted = _rtl(r.gcs)  # the station's own, obeyed once; replayed from elsewhere
        assert len(_deliver(r, lambda: r.gcs.send_raw(accepted))) == 1
        assert _deliver(r, lambda: reflector.sendto(accepted, r.ep.local_address)) == []
        assert r.ep.link.peers == peers and r.ep.counters()["replay_dropped"] == 1
        r.step(int(PHYSICS_HZ) + 1)  # a second of telemetry: none for the reflector
        with pytest.raises(TimeoutError):
            reflector.recv(65535)
    finally:
        reflector.close()


def test_shared_state_merges_other_processes_and_holds_no_key(tmp_path: Path) -> None:
    """Two ``SharedSigning`` on one folder stand for two processes: what one
    accepts the other refuses; the vehicles' streams are known to both; the
    file holds no key and stays bounded."""
    from cosim.mavlink.signing import MAX_STREAMS, SharedSigning, SigningState

    station = mav.Packer(255, 190)
    station.enable_signing(KEY, 0)
    station.advance_signing_time(mav.wall_signing_timestamp())
    hb = {"type": 6, "autopilot": 8, "base_mode": 0, "custom_mode": 0, "system_status": 0}
    first, second = station.pack("HEARTBEAT", **hb), station.pack("HEARTBEAT", **hb)
    a, b = SharedSigning(KEY, tmp_path), SharedSigning(KEY, tmp_path)
    a.add_own([(7, 1, 1)])
    assert a.authenticate([first, first]) == [mav.SIG_OK, mav.SIG_REPLAY]
    assert b.authenticate([first, second]) == [mav.SIG_REPLAY, mav.SIG_OK]
    assert a.authenticate([second]) == [mav.SIG_REPLAY]
    vehicle = mav.Packer(1, 1)
    vehicle.enable_signing(KEY, 7)
    vehicle.advance_signing_time(mav.wall_signing_timestamp())
    assert b.authenticate([vehicle.pack("HEARTBEAT", **hb)]) == [mav.SIG_OWN]
    text = SigningState(KEY, tmp_path).path.read_text()
    assert KEY.hex() not in text and PASSPHRASE not in text
    many = {(0, i % 256, i // 256): 1000 + i for i in range(MAX_STREAMS + 50)}
    b.checker.merge(0, many)
    b.save_sent({(7, 1, 1): 5})
    doc = SigningState(KEY, tmp_path).read()
    assert len(doc.streams) == MAX_STREAMS and doc.vehicles.keys() == {(7, 1, 1)}
    assert doc.timestamp >= mav.wall_signing_timestamp() - 100_000
    SigningState(KEY, tmp_path).path.write_text("not json")
    assert SigningState(KEY, tmp_path).read() == (0, {}, {})  # reported, treated as empty


def test_a_state_folder_that_cannot_be_written_stops_the_run(keyed: None,
                                                             tmp_path: Path) -> None:
    from mavtest import vehicle_specs

    from cosim.mavlink import MavlinkEndpoint
    from cosim.mavlink.signing import SigningStateError

    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    with pytest.raises(SigningStateError, match=r"cannot write the signing state .*file/"
                                                r".*COSIM_CACHE_DIR"):
        MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ, _config(blocked))
