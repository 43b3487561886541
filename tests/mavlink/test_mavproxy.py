"""MAVProxy (the PyPI ground station, run headless) against `cosim run --mavlink`:
it sees the vehicles, `mode GUIDED` is acknowledged, a `guided` goto flies the
vehicle there; with signing on it is ignored until it has `signing key`.

MAVProxy runs as users run it (``mavproxy.py --master=udpin:...``, its default
modules), driven through stdin like a terminal, with ``HOME`` and
``--state-basedir`` in ``tmp_path`` (no user init scripts or signing keys,
its logs land there); ``--out`` relays everything it receives to a pymavlink
listener so the test can follow the vehicles while MAVProxy commands them."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("MAVProxy", reason="MAVProxy is in the test extras: pip install -e .[test]")
mavutil = pytest.importorskip("pymavlink.mavutil")

from cosim.logs import read_states  # noqa: E402
from tests.mavlink.mavtest import GroundStation, free_udp_port  # noqa: E402
from tests.mavlink.test_mav_run import _dist_m, _start_sim, _stop_sim  # noqa: E402

LOITER, AUTO, GUIDED = 12, 10, 15  # ArduPlane custom modes
#: the mission file the README's MAVProxy walkthrough loads
SQUARE = Path(__file__).resolve().parents[2] / "examples" / "square.txt"


pytestmark = pytest.mark.integration  # MAVProxy against a live run


class MavProxy:
    """``mavproxy.py`` headless: commands written to its stdin, its console
    lines collected by a thread (``lines``)."""

    def __init__(self, tmp_path: Path, master: str, *extra: str) -> None:
        self.state = tmp_path / "mavproxy"
        home = tmp_path / "mavproxy-home"
        home.mkdir(parents=True, exist_ok=True)
        self.state.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ, HOME=str(home), PYTHONUNBUFFERED="1")
        env.pop("DISPLAY", None)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master={master}",
             f"--state-basedir={self.state}", *extra],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=env, cwd=self.state)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def send(self, command: str) -> int:
        """Type a command; returns the number of lines printed before it."""
        mark = len(self.lines)
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return mark

    def wait_for(self, pattern: str, timeout_s: float = 30.0, since: int = 0) -> re.Match[str]:
        """The first console line from ``since`` on matching ``pattern``."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        while True:
            for line in self.lines[since:]:
                m = rx.search(line)
                if m:
                    return m
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise AssertionError(f"MAVProxy printed no {pattern!r}:\n" + self.text())
            time.sleep(0.05)

    def text(self, since: int = 0) -> str:
        return "\n".join(self.lines[since:])

    def stop(self) -> None:
        """End of input quits MAVProxy; killed if it does not."""
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=15)
        self._reader.join(timeout=5)


@dataclass
class Session:
    """A running simulation, MAVProxy connected to it and a pymavlink
    listener for what MAVProxy relays (``--out``)."""

    sim: subprocess.Popen
    out: Path
    watch: GroundStation
    mp: MavProxy | None = None
    sim_stderr: str = ""

    def stop_sim(self) -> None:
        try:
            self.sim_stderr = _stop_sim(self.sim)
        except subprocess.TimeoutExpired:
            self.sim.kill()
            self.sim_stderr = self.sim.communicate(timeout=30)[1]
            raise

    def follow(self, sysid: int, until: Callable[[list[Any]], bool],
               timeout_s: float = 60.0) -> list[Any]:
        """Messages from ``sysid`` relayed by MAVProxy, until ``until(messages)``
        holds or the time is up."""
        seen: list[Any] = []
        deadline = time.monotonic() + timeout_s
        while not until(seen) and time.monotonic() < deadline:
            seen += [m for m in self.watch.drain(0.5) if m.get_srcSystem() == sysid]
        return seen


@contextmanager
def _session(tmp_path: Path, duration_s: int, realtime: str, *sim_args: str
             ) -> Iterator[Session]:
    """``cosim run`` sending to MAVProxy's ``udpin`` port; everything started
    is stopped (killed if need be) on the way out."""
    with ExitStack() as stack:
        watch = GroundStation("udpin:127.0.0.1:0")
        stack.callback(watch.close)
        port = free_udp_port()
        sim, out = _start_sim(tmp_path, duration_s, realtime, port, *sim_args)
        s = Session(sim, out, watch)
        stack.callback(s.stop_sim)
        s.mp = MavProxy(tmp_path, f"udpin:127.0.0.1:{port}",
                        f"--out=udpout:127.0.0.1:{watch.port}")
        stack.callback(s.mp.stop)
        yield s


def _modes(msgs: list[Any]) -> list[int]:
    return [m.custom_mode for m in msgs if m.get_type() == "HEARTBEAT"]


def _heartbeat_modes(tlog: Path, sysid: int) -> list[int]:
    """A vehicle's custom modes over the run (changes only), from its tlog."""
    conn = mavutil.mavlink_connection(str(tlog), dialect="ardupilotmega")
    modes: list[int] = []
    try:
        while (m := conn.recv_match(type="HEARTBEAT")) is not None:
            if m.get_srcSystem() == sysid and (not modes or modes[-1] != m.custom_mode):
                modes.append(m.custom_mode)
    finally:
        conn.close()
    return modes


def test_mavproxy_sees_the_vehicles_sets_guided_and_flies_a_goto(tmp_path: Path) -> None:
    """The README's walkthrough: modes, a guided goto, the mission file it
    loads flown in AUTO; no 'fence breach' (no fence is uploaded), and no
    altitude read-outs once `set altreadout 0` (the README's advice)."""
    with _session(tmp_path, 600, "10") as s:
        assert s.mp is not None
        mp = s.mp
        for sysid in (1, 2, 3):
            mp.wait_for(rf"Detected vehicle {sysid}:1 on link 0", 60)
        quiet = mp.send("set altreadout 0")
        mark = mp.send("vehicle 3")
        mp.wait_for(r"Set vehicle 3", since=mark)
        # vehicles start in GUIDED: go LOITER first so that GUIDED is a change
        for mode, number in (("LOITER", LOITER), ("GUIDED", GUIDED)):
            mark = mp.send(f"mode {mode}")
            mp.wait_for(r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", since=mark)
            seen = s.follow(3, lambda msgs, n=number: n in _modes(msgs))
            assert number in _modes(seen), f"vehicle 3 heartbeats {_modes(seen)} after {mode}"
        seen = s.follow(3, lambda msgs: any(m.get_type() == "GLOBAL_POSITION_INT" for m in msgs))
        last = [m for m in seen if m.get_type() == "GLOBAL_POSITION_INT"][-1]
        target = (last.lat * 1e-7 - 2000.0 / 111_000.0, last.lon * 1e-7)  # about 2 km south
        # 400 m above home: a climb of 100 m, which MAVProxy would read out
        mark = mp.send(f"guided {target[0]:.7f} {target[1]:.7f} 400")
        mp.wait_for(r"Got COMMAND_ACK: DO_REPOSITION: ACCEPTED", since=mark)

        def dist(msgs: list[Any]) -> float:
            return min((_dist_m(m.lat * 1e-7, m.lon * 1e-7, *target) for m in msgs
                        if m.get_type() == "GLOBAL_POSITION_INT"), default=1e9)

        seen = s.follow(3, lambda msgs: dist(msgs) <= 500, timeout_s=90)
        assert dist(seen) <= 500, f"vehicle 3 got no closer than {dist(seen):.0f} m"

        mark = mp.send("vehicle 2")
        mp.wait_for(r"Set vehicle 2", since=mark)
        mark = mp.send(f"wp load {SQUARE}")
        mp.wait_for(r"Loaded 6 waypoints from", since=mark)
        mp.wait_for(r"Sent all 6 waypoints", since=mark)
        mark = mp.send("mode AUTO")
        mp.wait_for(r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", since=mark)

        def flying_item_1(msgs: list[Any]) -> bool:
            return AUTO in _modes(msgs) and any(
                m.get_type() == "MISSION_CURRENT" and m.seq == 1 for m in msgs)

        seen = s.follow(2, flying_item_1)
        assert flying_item_1(seen), f"vehicle 2 heartbeats {_modes(seen)} after AUTO"
        assert "fence breach" not in mp.text()
        assert not [x for x in mp.lines[quiet + 1:] if re.search(r"(^|> )height \d+$", x)]
    assert s.sim.returncode == 130, s.sim_stderr
    out = s.out
    assert _heartbeat_modes(out / "uav2.tlog", 3)[-2:] == [LOITER, GUIDED]
    events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    assert any(e["event"] == "mavlink_command" and e["vehicle"] == "uav2"
               and "DO_REPOSITION" in e["origin"] for e in events)
    t = read_states(out)  # the simulation's own record of the flight
    rows = [i for i, v in enumerate(t["vehicle"].to_pylist()) if v == "uav2"]
    lats, lons = t["lat_deg"].to_pylist(), t["lon_deg"].to_pylist()
    assert min(_dist_m(lats[i], lons[i], *target) for i in rows) <= 500
    assert (mp.state / "mav.tlog").stat().st_size > 0  # MAVProxy's log went to tmp_path


def test_signed_run_ignores_mavproxy_until_it_has_the_key(tmp_path: Path) -> None:
    keyfile = tmp_path / "key"
    keyfile.write_text("correct-horse\n")
    keyfile.chmod(0o600)
    with _session(tmp_path, 300, "5", "--mavlink-signing-key-file", str(keyfile)) as s:
        assert s.mp is not None
        mp = s.mp
        mp.wait_for(r"Detected vehicle 2:1 on link 0", 60)  # signed telemetry reads fine
        mark = mp.send("vehicle 2")
        mp.wait_for(r"Set vehicle 2", since=mark)
        s.watch.drain()
        mark = mp.send("mode LOITER")  # unsigned: dropped
        seen = s.follow(2, lambda msgs: len(_modes(msgs)) >= 8)  # 8 s of simulation
        assert _modes(seen) and set(_modes(seen)) == {GUIDED}, _modes(seen)
        assert "COMMAND_ACK" not in mp.text(mark)

        mark = mp.send("signing key correct-horse")
        mp.wait_for(r"Setup signing key", since=mark)
        mark = mp.send("mode LOITER")
        mp.wait_for(r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", since=mark)
        seen = s.follow(2, lambda msgs: LOITER in _modes(msgs))
        assert LOITER in _modes(seen), _modes(seen)
    assert s.sim.returncode == 130, s.sim_stderr
    counters = json.loads((s.out / "summary.json").read_text())["mavlink"]["counters"]
    assert counters["unsigned_dropped"] > 0
    assert counters["bad_signature_dropped"] == 0
    assert _heartbeat_modes(s.out / "uav1.tlog", 2) == [GUIDED, LOITER]
