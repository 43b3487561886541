"""The worker toolkit the process pools share (``cosim.workers``): shielded
children outlive a Ctrl-C until their driver stops them, children log as
their driver does and know when it is gone, tracebacks travel bounded, and
``stop`` ends what does not stop by itself."""

from __future__ import annotations

import logging
import os
import signal
import time
from multiprocessing.connection import Connection

from cosim.core import workers as worker_kit
from cosim.errors import how_it_ended


def _report(conn: Connection) -> None:
    """Send what the child sees of its setup, then wait to be told to end."""
    conn.send({"cosim_level": logging.getLogger("cosim").getEffectiveLevel(),
               "parent_gone": worker_kit.parent_gone(),
               "sigint": signal.getsignal(signal.SIGINT) == signal.SIG_IGN})
    conn.recv()


def _fail(conn: Connection, size: int) -> None:
    try:
        raise ValueError("x" * size + " the end")
    except ValueError:
        conn.send(worker_kit.remote_traceback())


def _exit(code: int) -> None:
    os._exit(code)


def _sleep() -> None:
    time.sleep(60)


def test_a_shielded_child_logs_like_its_driver_and_ignores_ctrl_c() -> None:
    ctx = worker_kit.context()
    mine, theirs = ctx.Pipe()
    cosim_log = logging.getLogger("cosim")
    before = cosim_log.level
    cosim_log.setLevel(logging.DEBUG)
    try:
        p = worker_kit.start(_report, (theirs,), name="test-report")
    finally:
        cosim_log.setLevel(before)
    try:
        assert mine.poll(60), "the child did not report"
        seen = mine.recv()
        assert seen == {"cosim_level": logging.DEBUG, "parent_gone": False, "sigint": True}
        os.kill(p.pid, signal.SIGINT)  # as Ctrl-C would, to the whole group
        os.kill(p.pid, signal.SIGTERM)
        time.sleep(0.3)
        assert p.is_alive() and worker_kit.ended([p]) == []
        mine.send("end")
        assert worker_kit.ended([p], timeout_s=30) == [0]
        assert p.exitcode == 0
    finally:
        worker_kit.stop([p], 1.0)


def test_an_unshielded_child_keeps_the_default_signals() -> None:
    ctx = worker_kit.context()
    mine, theirs = ctx.Pipe()
    # a process started in the background (nohup, `cmd &`) inherits SIGINT
    # ignored, and so would any child: give the child a driver that takes it
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        p = worker_kit.start(_report, (theirs,), name="test-report", shielded=False,
                             inherit_logging=False)
    finally:
        signal.signal(signal.SIGINT, before)
    try:
        assert mine.poll(60)
        assert mine.recv()["sigint"] is False
        worker_kit.stop([p], 10.0, terminate=True)
        assert how_it_ended(p.exitcode) == "killed by SIGTERM"
    finally:
        worker_kit.stop([p], 1.0)


def test_stop_kills_what_does_not_stop_and_ended_names_who_ended() -> None:
    procs = [worker_kit.start(_sleep, (), name="test-sleep"),
             worker_kit.start(_exit, (3,), name="test-exit")]
    try:
        assert worker_kit.ended(procs, timeout_s=30) == [1]
        assert how_it_ended(procs[1].exitcode) == "exited with code 3"
        t0 = time.monotonic()
        worker_kit.stop(procs, 0.5)  # the shielded sleeper ignores SIGTERM: killed
        assert time.monotonic() - t0 < 10
        assert how_it_ended(procs[0].exitcode) == "killed by SIGKILL"
    finally:
        worker_kit.stop(procs, 1.0)


def test_a_remote_traceback_is_bounded_and_keeps_the_error() -> None:
    ctx = worker_kit.context()
    for size, cut in ((100, False), (10 * worker_kit.MAX_TRACEBACK_CHARS, True)):
        mine, theirs = ctx.Pipe()
        p = worker_kit.start(_fail, (theirs, size), name="test-fail")
        try:
            assert mine.poll(60)
            tb = mine.recv()
        finally:
            worker_kit.stop([p], 10.0)
        assert tb.rstrip().endswith("the end")
        assert tb.startswith("Traceback (most recent call last)")
        assert "ValueError: xxx" in tb and ("(traceback cut" in tb) == cut
        assert len(tb) <= worker_kit.MAX_TRACEBACK_CHARS + 100


def _maps(conn: Connection) -> None:
    with open("/proc/self/maps") as f:
        conn.send((f.read(), os.environ.get("LD_PRELOAD")))


def test_the_allocator_is_chosen_and_preloaded_into_the_child_only(monkeypatch) -> None:
    """COSIM_ALLOCATOR: 'system' preloads nothing, 'auto' takes the first
    library present; the child maps the library it was given while the
    driver's LD_PRELOAD stays as it was."""
    import pytest

    from cosim.core import memory

    monkeypatch.setenv("COSIM_ALLOCATOR", "system")
    assert memory.allocator().preload is None
    monkeypatch.setenv("COSIM_ALLOCATOR", "auto")
    alloc = memory.allocator()
    present = [p for p in memory.ALLOCATORS if os.path.isfile(p)]
    assert alloc.preload == (present[0] if present else None)
    if alloc.preload is None:
        pytest.skip("no jemalloc or mimalloc here (apt-get install libjemalloc2)")
    before = os.environ.get("LD_PRELOAD")
    a, b = worker_kit.context().Pipe(duplex=False)
    p = worker_kit.start(_maps, (b,), "cosim-test-maps", env=alloc.child_env(os.environ))
    maps, env = a.recv()
    p.join(10)
    assert os.path.basename(alloc.preload) in maps and env is not None and alloc.preload in env
    assert os.environ.get("LD_PRELOAD") == before


def _sleep_a_while() -> None:
    time.sleep(30)


def test_a_child_is_recorded_before_a_stop_signal_that_arrived_while_it_started() -> None:
    """A SIGTERM that arrives while a child starts is handled as ``start``
    unblocks it; a handler that raises (the CLI's Ctrl-C during a build) then
    leaves ``start`` without a return value, and the child would be unknown
    to its pool, alive at exit, ignoring the interpreter's SIGTERM: the
    interpreter hung joining it. ``on_start`` records it first."""
    import pytest

    class Stop(Exception):
        pass

    def handler(signum: int, frame: object) -> None:
        raise Stop

    recorded: list = []

    def record(p) -> None:
        recorded.append(p)
        os.kill(os.getpid(), signal.SIGTERM)  # pending: blocked until start unblocks it

    old = signal.signal(signal.SIGTERM, handler)
    try:
        with pytest.raises(Stop):
            worker_kit.start(_sleep_a_while, (), "cosim-test-race", on_start=record)
    finally:
        signal.signal(signal.SIGTERM, old)
    assert len(recorded) == 1 and recorded[0].is_alive()
    worker_kit.stop(recorded, 1.0)  # it ignores SIGTERM: stopped by the kill after the grace
    assert not recorded[0].is_alive()
