"""Joining a Ray cluster that is not there: ``cosim run --backend ray`` ends
within a bound with an error naming the address, and Ctrl-C or SIGTERM end
it at once while it tries (Ray itself would retry for many minutes in native
code, deaf to signals). No cluster is started: the addresses are loopback
ones where nothing listens, or where a socket listens and never answers;
and without an address, a private local Ray runs the scenario and is gone
afterwards."""

from __future__ import annotations

import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration,  # cosim run starting or joining Ray
              pytest.mark.xdist_group("ray"),  # beside the cluster's tests, not at once
              pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                                 reason="the ray backend needs Ray (pip install -e '.[test]')")]

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "quickstart.yaml"
HOST = "127.0.0.2"  # loopback, as the test clusters use
Starter = Callable[..., "subprocess.Popen[str]"]
#: python, cosim and Ray imported, the scenario read: a few seconds on the test machine
START_S = 20.0


@pytest.fixture
def run(tmp_path: Path) -> Iterator[Starter]:
    """``run(*args)``: ``cosim run`` of a small scenario on the ray backend, in
    a process of its own (killed at the end if it still runs)."""
    procs: list[subprocess.Popen[str]] = []
    # a local Ray's files in a folder of the test's (short: Ray's socket paths
    # must fit in 107 bytes), not in /tmp/ray
    ray_tmp = tempfile.mkdtemp(prefix="cr", dir="/tmp")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["RAY_TMPDIR"] = ray_tmp

    def start(*args: str) -> subprocess.Popen[str]:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", str(tmp_path / "run"),
             "--no-progress", "--backend", "ray", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
        return procs[-1]

    start.ray_tmp = ray_tmp  # type: ignore[attr-defined]
    yield start
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.communicate()
    shutil.rmtree(ray_tmp, ignore_errors=True)


@pytest.fixture
def silent() -> Iterator[socket.socket]:
    """A loopback port that accepts connections and never says a word."""
    with socket.socket() as srv:
        srv.bind((HOST, 0))
        srv.listen(8)
        srv.settimeout(START_S + 30.0)
        yield srv


def _finish(p: subprocess.Popen[str], timeout_s: float) -> str:
    """Its stderr once it has ended; killed (and the test failed) if it has
    not within ``timeout_s``."""
    try:
        return p.communicate(timeout=timeout_s)[1]
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        pytest.fail(f"cosim run still ran after {timeout_s:g} s (killed)")


def _accept(srv: socket.socket, n: int) -> list[socket.socket]:
    """The first ``n`` connections (cosim's check that something listens, then Ray's)."""
    return [srv.accept()[0] for _ in range(n)]


def test_nothing_listening_is_said_at_once_naming_the_address(run: Starter) -> None:
    with socket.socket() as held:  # bound, not listening: connections are refused
        held.bind((HOST, 0))
        address = f"{HOST}:{held.getsockname()[1]}"
        t0 = time.monotonic()
        p = run("--address", address)
        err = _finish(p, START_S + 30.0)
    assert time.monotonic() - t0 < START_S, "it should not wait for Ray's retries"
    assert p.returncode == 1, err
    assert f"cannot join the Ray cluster at {address}: nothing listens there (connection " \
           f"refused)" in err and "ray start --head" in err, err
    assert "Traceback" not in err


def test_no_answer_ends_the_run_after_the_connect_timeout(run: Starter,
                                                          silent: socket.socket) -> None:
    address = f"{HOST}:{silent.getsockname()[1]}"
    p = run("--address", address, "--connect-timeout-s", "2")
    held = _accept(silent, 2)
    t0 = time.monotonic()
    err = _finish(p, 30.0)
    assert time.monotonic() - t0 < 10.0
    assert p.returncode == 1, err
    assert f"cannot join the Ray cluster at {address}: something listens there but did not " \
           f"take this process into a Ray cluster within 2 s (--connect-timeout-s)" in err, err
    assert "RAY_AUTH_TOKEN" in err and "Traceback" not in err
    for c in held:
        c.close()


@pytest.mark.parametrize("sig, reason", [(signal.SIGINT, "interrupted"),
                                         (signal.SIGTERM, "terminated")])
def test_a_signal_while_joining_ends_the_run_at_once(run: Starter, silent: socket.socket,
                                                     sig: signal.Signals, reason: str) -> None:
    p = run("--address", f"{HOST}:{silent.getsockname()[1]}")
    held = _accept(silent, 2)  # Ray is connecting: the default timeout is 30 s away
    time.sleep(0.5)
    t0 = time.monotonic()
    p.send_signal(sig)
    err = _finish(p, 30.0)
    assert time.monotonic() - t0 < 5.0
    assert p.returncode == 130, err
    assert f"stopped while building the vehicles ({reason})" in err, err
    for c in held:
        c.close()


def test_an_address_that_is_not_host_port_is_a_usage_error(run: Starter) -> None:
    p = run("--address", "headnode")
    err = _finish(p, START_S + 30.0)
    assert p.returncode == 2, err
    assert "the Ray cluster's address 'headnode' is not HOST:PORT" in err, err


def test_the_connect_timeout_is_refused_by_a_backend_that_joins_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from cosim.cli import main

    rc = main(["run", str(SCENARIO), "--out", str(tmp_path / "run"), "--backend", "inline",
               "--connect-timeout-s", "5"])
    assert rc == 2
    assert "--connect-timeout-s: the inline backend does not take it; backends that do: " \
           "ray" in capsys.readouterr().err


def _ray_processes(ray_tmp: str) -> set[int]:
    """Running (not zombie) Ray core processes of the Ray whose files are in
    ``ray_tmp`` (other tests' clusters may run beside this one)."""
    out = set()
    for d in Path("/proc").iterdir():
        try:
            args = (d / "cmdline").read_bytes()
            state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError, ValueError):
            continue
        if (state != "Z" and args.split(b"\0")[0].endswith((b"gcs_server", b"raylet"))
                and ray_tmp.encode() in args):
            out.add(int(d.name))
    return out


def test_without_an_address_a_private_local_ray_runs_it_and_is_gone_after(
        run: Starter) -> None:
    # its processes die with the thread that started them: that thread must
    # live as long as the run (a joining thread that ended killed them)
    p = run("--duration-s", "1")
    seen = set()  # its Ray's processes, seen while it runs (the filter finds them)
    while p.poll() is None and not seen:
        seen = _ray_processes(run.ray_tmp)  # type: ignore[attr-defined]
        time.sleep(0.1)
    err = _finish(p, 120.0)
    assert p.returncode == 0, err
    assert "joined a local Ray" in err
    assert seen, "no Ray process of the run's own was seen while it ran"
    deadline = time.monotonic() + 15.0
    while (left := _ray_processes(run.ray_tmp)  # type: ignore[attr-defined]
           ) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, f"Ray processes left running: {sorted(left)}"
