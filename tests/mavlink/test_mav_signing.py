"""MAVLink 2 signing: the key comes from a file or an environment variable;
with it on, telemetry is signed, only correctly signed packets are handled,
SETUP_SIGNING is ignored; with it off nothing changes."""

from __future__ import annotations

import hashlib
import re
import time
from pathlib import Path
from typing import Any

import pytest
from mavtest import PHYSICS_HZ, GroundStation, Rig, mavutil, of_type, vehicle_specs

from cosim.errors import ConfigError
from cosim.mavlink import MavlinkConfig, MavlinkEndpoint, load_signing_key
from cosim.mavlink import adapter as mav

ML = mavutil.mavlink
PASSPHRASE = "correct-horse-battery"
KEY = hashlib.sha256(PASSPHRASE.encode("ascii")).digest()  # MAVProxy's "signing key"
ENV = "COSIM_TEST_MAVLINK_KEY"
URL = "udpin:127.0.0.1:0"


def _now_us() -> int:
    return int(time.time()) * 1_000_000


@pytest.fixture
def signed(monkeypatch: pytest.MonkeyPatch, rig: Any, tmp_path: Path) -> Any:
    """A rig with signing on (key from ENV, link id 7, signing state in
    ``tmp_path/signing``) and a ground station holding the right key."""
    monkeypatch.setenv(ENV, PASSPHRASE)

    def make(n: int = 2, anchor_us: int | None = None) -> Rig:
        cfg = MavlinkConfig(url=URL, signing_key_env=ENV, signing_link_id=7,
                            signing_state_dir=tmp_path / "signing")
        return rig(n, config=cfg, anchor_us=_now_us() if anchor_us is None else anchor_us,
                   gcs_key=KEY)

    return make


def _loiter(gcs: GroundStation, target: int = 1, **kw: Any) -> None:
    gcs.mav.command_long_send(target, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, 0, 0, 0, 0, 0, 0,
                              **kw)


def _deliver(r: Rig, send: Any, wait_s: float = 2.0) -> list[Any]:
    """Send from anywhere, run exchanges until the datagram was read; the commands."""
    before = r.ep.counters()["datagrams_in"]
    send()
    commands: list[Any] = []
    deadline = time.monotonic() + wait_s
    while r.ep.counters()["datagrams_in"] == before and time.monotonic() < deadline:
        commands += r.step()
        time.sleep(0.001)
    return commands


def _signature(m: Any) -> tuple[int, int]:
    """(link id, timestamp) of a received signed message."""
    buf = bytes(m.get_msgbuf())
    assert buf[0] == ML.PROTOCOL_MARKER_V2 and buf[2] & ML.MAVLINK_IFLAG_SIGNED
    return buf[-13], int.from_bytes(buf[-12:-6], "little")


def test_a_ground_station_with_the_key_is_answered_and_sees_signed_telemetry(signed) -> None:
    r = signed(2)
    cmds, replies = r.request(lambda: _loiter(r.gcs))
    assert len(cmds) == 1
    acks = of_type(replies + r.gcs.drain(wait_s=0.3), "COMMAND_ACK", src=1)
    assert [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED]
    r.step(int(PHYSICS_HZ) + 1)
    msgs = r.gcs.drain(wait_s=1.0)
    beats = of_type(msgs, "HEARTBEAT")
    assert {b.get_srcSystem() for b in beats} == {1, 2}
    assert msgs and all(m.get_signed() for m in msgs)  # pymavlink verified them
    stamps = [_signature(m) for m in msgs if m.get_srcSystem() == 1]
    assert {link for link, _ in stamps} == {7}
    ts = [t for _, t in stamps]
    assert ts == sorted(ts) and len(set(ts)) == len(ts)  # strictly increasing
    # the timestamp follows the wall clock (10 us units since 2015), not the
    # simulation clock: one simulated hour later it has not jumped ahead
    r.step(int(3600 * PHYSICS_HZ))
    now = mav.wall_signing_timestamp()
    later = [_signature(m)[1] for m in r.gcs.drain(wait_s=1.0) if m.get_srcSystem() == 1]
    assert later and ts[-1] < later[0] <= now + 100_000
    c = r.ep.counters()
    assert c["unsigned_dropped"] == c["bad_signature_dropped"] == c["replay_dropped"] == 0


@pytest.mark.parametrize("key", [None, hashlib.sha256(b"wrong-passphrase").digest()],
                         ids=["no-key", "wrong-key"])
def test_a_ground_station_without_the_right_key_gets_nothing(signed, key: bytes | None) -> None:
    r = signed(2)
    intruder = GroundStation(f"udpout:127.0.0.1:{r.ep.local_address[1]}", key)
    try:
        peers = list(r.ep.link.peers)
        cmds = _deliver(r, lambda: (intruder.hello(), _loiter(intruder)))
        cmds += r.step()
        assert cmds == []
        c = r.ep.counters()
        counter = "unsigned_dropped" if key is None else "bad_signature_dropped"
        assert c[counter] >= 1
        assert c["commands_out"] == 0 and c["mavlink1_dropped"] == 0
        assert r.ep.link.peers == peers  # not a peer: it gets no telemetry
        r.step(int(PHYSICS_HZ) + 1)
        assert intruder.drain(wait_s=0.3) == []
        assert of_type(r.gcs.drain(wait_s=0.3), "COMMAND_ACK") == []
    finally:
        intruder.close()


def test_mavlink1_packets_are_dropped_when_signing_is_on(signed) -> None:
    r = signed(1)
    cmds = _deliver(r, lambda: _loiter(r.gcs, force_mavlink1=True))
    assert cmds == []
    c = r.ep.counters()
    assert c["mavlink1_dropped"] == 1 and c["unsigned_dropped"] == 1


def test_a_replayed_signed_packet_is_dropped(signed) -> None:
    r = signed(1)
    pkt = r.gcs.mav.command_long_encode(1, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, 0, 0, 0, 0, 0,
                                        0).pack(r.gcs.mav)
    assert len(_deliver(r, lambda: r.gcs.send_raw(pkt))) == 1
    assert _deliver(r, lambda: r.gcs.send_raw(pkt)) == []
    assert r.ep.counters()["replay_dropped"] == 1


def test_setup_signing_from_the_network_is_ignored(signed) -> None:
    r = signed(1)
    other = hashlib.sha256(b"attacker").digest()
    _deliver(r, lambda: r.gcs.mav.setup_signing_send(1, 1, list(other), 0))
    assert r.ep.counters()["setup_signing_ignored"] == 1
    # the key did not change: the old key still commands, telemetry still verifies
    cmds, replies = r.request(lambda: _loiter(r.gcs))
    assert len(cmds) == 1
    acks = of_type(replies + r.gcs.drain(wait_s=0.3), "COMMAND_ACK", src=1)
    assert [a.result for a in acks] == [ML.MAV_RESULT_ACCEPTED] and acks[0].get_signed()


def test_the_key_is_read_from_a_file(tmp_path: Path, rig) -> None:
    f = tmp_path / "mavlink.key"
    f.write_text(PASSPHRASE + "\n", encoding="ascii")
    cfg = MavlinkConfig(url=URL, signing_key_file=f)
    assert cfg.signing and load_signing_key(cfg) == KEY
    assert load_signing_key(MavlinkConfig(url=URL, signing_key_file=str(f))) == KEY
    r = rig(1, config=cfg, anchor_us=_now_us(), gcs_key=KEY)
    cmds, _ = r.request(lambda: _loiter(r.gcs))
    assert len(cmds) == 1


@pytest.mark.parametrize("mode, warned", [(0o600, False), (0o400, False), (0o640, True),
                                           (0o644, True), (0o602, True)])
def test_a_key_file_other_users_can_read_or_change_is_warned_about(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, mode: int, warned: bool) -> None:
    f = tmp_path / "mavlink.key"
    f.write_text(PASSPHRASE + "\n", encoding="ascii")
    f.chmod(mode)
    with caplog.at_level("WARNING", logger="cosim.mavlink"):
        assert load_signing_key(MavlinkConfig(url=URL, signing_key_file=f)) == KEY
    said = [r.getMessage() for r in caplog.records if "key file" in r.getMessage()]
    if not warned:
        assert said == []
        return
    assert len(said) == 1
    assert re.search(rf"key file {re.escape(str(f))} has mode {mode:04o}: other users of this "
                     rf"machine can read or change the passphrase .*chmod 600 "
                     rf"{re.escape(str(f))}$", said[0]), said[0]


def test_the_key_is_read_from_an_environment_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV, f"  {PASSPHRASE}\n")
    cfg = MavlinkConfig(signing_key_env=ENV)
    assert cfg.signing and load_signing_key(cfg) == KEY
    assert mav.signing_key(PASSPHRASE) == KEY
    assert load_signing_key(MavlinkConfig()) is None and not MavlinkConfig().signing


def _config_error(cfg: MavlinkConfig) -> str:
    with pytest.raises(ConfigError) as e:
        load_signing_key(cfg)
    with pytest.raises(ConfigError):  # the endpoint refuses it too, before opening a socket
        MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ, cfg)
    return str(e.value)


def test_bad_key_sources_are_config_errors(tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    missing = tmp_path / "nope.key"
    assert str(missing) in _config_error(MavlinkConfig(url=URL, signing_key_file=missing))
    empty = tmp_path / "empty.key"
    empty.write_text("\n \n")
    msg = _config_error(MavlinkConfig(url=URL, signing_key_file=empty))
    assert str(empty) in msg and "empty" in msg
    two = tmp_path / "two.key"
    two.write_text("two words\n")
    assert "whitespace" in _config_error(MavlinkConfig(url=URL, signing_key_file=two))
    latin = tmp_path / "latin.key"
    latin.write_bytes("clé".encode("latin-1"))
    assert "ASCII" in _config_error(MavlinkConfig(url=URL, signing_key_file=latin))
    assert str(tmp_path) in _config_error(MavlinkConfig(url=URL, signing_key_file=tmp_path))
    monkeypatch.delenv(ENV, raising=False)
    msg = _config_error(MavlinkConfig(url=URL, signing_key_env=ENV))
    assert ENV in msg and "not set" in msg
    monkeypatch.setenv(ENV, "")
    msg = _config_error(MavlinkConfig(url=URL, signing_key_env=ENV))
    assert ENV in msg and "empty" in msg
    monkeypatch.setenv(ENV, "naïve")
    assert "ASCII" in _config_error(MavlinkConfig(url=URL, signing_key_env=ENV))
    monkeypatch.setenv(ENV, PASSPHRASE)
    assert "not both" in _config_error(MavlinkConfig(url=URL, signing_key_env=ENV,
                                                     signing_key_file=empty))
    assert "link id" in _config_error(MavlinkConfig(url=URL, signing_key_env=ENV,
                                                    signing_link_id=256))
    assert "empty" in _config_error(MavlinkConfig(url=URL, signing_key_env=""))


def test_signing_off_sends_unsigned_packets(rig) -> None:
    r = rig(1)
    assert r.ep.signature_checker is None and not r.ep.vehicles[0].packer.signing
    r.step(int(PHYSICS_HZ) + 1)
    msgs = r.gcs.drain(wait_s=1.0)
    assert msgs and not any(bytes(m.get_msgbuf())[2] & ML.MAVLINK_IFLAG_SIGNED for m in msgs)
    c = r.ep.counters()
    assert c["unsigned_dropped"] == c["setup_signing_ignored"] == 0


def test_signature_checker_verdicts() -> None:
    p = mav.Packer(255, 190)
    p.enable_signing(KEY, 3)
    now = mav.wall_signing_timestamp()
    p.advance_signing_time(now)
    hb = {"type": 6, "autopilot": 8, "base_mode": 0, "custom_mode": 0, "system_status": 0}
    first, second = p.pack("HEARTBEAT", **hb), p.pack("HEARTBEAT", **hb)
    p.advance_signing_time(5)  # never goes back
    assert p.signing_timestamp == now + 2
    chk = mav.SignatureChecker(KEY)
    assert chk.check(second) == mav.SIG_OK
    assert chk.check(first) == mav.SIG_REPLAY
    tampered = bytearray(p.pack("HEARTBEAT", **hb))
    tampered[-1] ^= 1
    assert chk.check(bytes(tampered)) == mav.SIG_BAD
    assert chk.check(mav.Packer(255, 190).pack("HEARTBEAT", **hb)) == mav.SIG_UNSIGNED
    assert chk.check(b"\xfe\x00") == mav.SIG_MAVLINK1
    assert mav.signing_timestamp(mav.SIGNING_EPOCH_UNIX_US + 1234) == 123
    old = mav.Packer(254, 190)  # a new stream a minute and a bit behind: stale
    old.enable_signing(KEY, 3)
    old.advance_signing_time(now - mav.NEW_STREAM_WINDOW - 10_000)
    assert chk.check(old.pack("HEARTBEAT", **hb)) == mav.SIG_STALE
    # restored from an earlier run: that stream's old packets are replays at once
    again = mav.SignatureChecker(KEY, chk.timestamp, chk.last_timestamp)
    assert again.check(second) == mav.SIG_REPLAY


# --- replay protection across runs ------------------------------------------------------

def _rtl(gcs: GroundStation) -> bytes:
    """A signed RTL command from ``gcs``, as bytes on the wire."""
    return bytes(gcs.mav.command_long_encode(1, 1, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0,
                                             0, 0, 0, 0).pack(gcs.mav))


def test_a_signed_command_captured_in_one_run_is_refused_in_every_later_run(
        signed, tmp_path: Path) -> None:
    from pymavlink import mavutil as mu

    first = signed(1)
    captured = _rtl(first.gcs)
    assert len(_deliver(first, lambda: first.gcs.send_raw(captured))) == 1  # flown in run 1
    first.close()
    tlog = tmp_path / "tlogs" / "uav1.tlog"
    log = mu.mavlink_connection(str(tlog), dialect="ardupilotmega")
    from_tlog = None
    while (m := log.recv_match(type="COMMAND_LONG")) is not None:
        if m.get_srcSystem() == 255:
            from_tlog = bytes(m.get_msgbuf())
    assert from_tlog == captured
    for _ in range(2):  # run 2 and run 3: each starts from the saved state
        later = signed(1)
        for packet in (captured, from_tlog):
            assert _deliver(later, lambda p=packet, lt=later: lt.gcs.send_raw(p)) == []
        c = later.ep.counters()
        assert c["replay_dropped"] == 2 and c["commands_out"] == 0
        # the real station, signing afresh, still commands
        assert len(_deliver(later, lambda lt=later: lt.gcs.send_raw(_rtl(lt.gcs)))) == 1
        later.close()


@pytest.mark.parametrize("age_s", [86_400.0, None], ids=["a-day-old", "2015"])
def test_a_new_stream_stamped_long_ago_is_refused(signed, age_s: float | None) -> None:
    r = signed(1)
    old = mav.Packer(200, 190)
    old.enable_signing(KEY, 3)
    stamp = 1 if age_s is None else mav.wall_signing_timestamp() - int(age_s * 100_000)
    old.advance_signing_time(stamp)
    pkt = old.pack("COMMAND_LONG", target_system=1, target_component=1,
                   command=ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, confirmation=0, param1=0, param2=0,
                   param3=0, param4=0, param5=0, param6=0, param7=0)
    assert _deliver(r, lambda: r.gcs.send_raw(pkt)) == []
    assert r.ep.counters()["stale_stream_dropped"] == 1
    fresh = mav.Packer(201, 190)  # a new stream of now: accepted
    fresh.enable_signing(KEY, 3)
    fresh.advance_signing_time(mav.wall_signing_timestamp())
    pkt = fresh.pack("COMMAND_LONG", target_system=1, target_component=1,
                     command=ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, confirmation=0, param1=0,
                     param2=0, param3=0, param4=0, param5=0, param6=0, param7=0)
    assert len(_deliver(r, lambda: r.gcs.send_raw(pkt))) == 1


@pytest.mark.parametrize("loopback, signing", [(False, False), (False, True), (True, False)])
def test_a_non_loopback_link_without_signing_is_warned_about(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture, tmp_path: Path,
        loopback: bool, signing: bool) -> None:
    """Tests bind loopback only: the link is told it is not, to check the rule."""
    from cosim.mavlink.link import UdpLink

    monkeypatch.setattr(UdpLink, "loopback", property(lambda self: loopback))
    monkeypatch.setenv(ENV, PASSPHRASE)
    cfg = MavlinkConfig(url=URL, signing_key_env=ENV if signing else None,
                        signing_state_dir=tmp_path)
    with caplog.at_level("WARNING", logger="cosim.mavlink"):
        MavlinkEndpoint(vehicle_specs(1), PHYSICS_HZ, cfg).close()
    warned = [r for r in caplog.records if "WITHOUT signing" in r.getMessage()]
    assert bool(warned) == (not loopback and not signing)
    if warned:
        assert "anyone who can send to it can command every vehicle" in warned[0].getMessage()


def test_an_unsigned_station_on_a_signed_udpin_link_gets_nothing(signed) -> None:
    """With signing on, telemetry goes only to stations that sent a correctly
    signed packet (the README says so): an unsigned one on a udpin link hears
    nothing and its commands are dropped and counted."""
    r = signed(2)
    plain = GroundStation(f"udpout:127.0.0.1:{r.ep.local_address[1]}")
    try:
        for _ in range(3):
            cmds = _deliver(r, lambda: (plain.hello(), _loiter(plain)))
            assert cmds == []
        r.step(int(PHYSICS_HZ) + 1)
        assert plain.drain(wait_s=0.5) == []
        assert r.ep.counters()["unsigned_dropped"] >= 6
        assert of_type(r.gcs.drain(wait_s=0.5), "HEARTBEAT")  # the signed one does hear
    finally:
        plain.close()
