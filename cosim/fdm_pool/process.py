"""The default backend: vehicles sharded over worker processes.

Layout: ``workers`` shards of contiguous vehicles. With two or more shards
the driver (calling) process steps shard 0 itself, so on a 2-core machine
two processes share the two cores rather than three fighting over them;
the other shards each live in a child process started with ``spawn`` that
builds and trims its own FDMs from picklable ``VehicleSpec`` values.

One exchange = one round trip through shared memory: the driver writes the
setpoints, bumps each child's command sequence number, steps its own
shard, then waits for every child's done number. Waiting spins with
``os.sched_yield`` for a short while, then polls with short sleeps, and
checks periodically that the peer is alive: a child killed by the OS
becomes ``WorkerDied`` within a fraction of a second; a child whose parent
died exits by itself. An exception inside a child comes back as
``WorkerError`` carrying the vehicle, the tick and the remote traceback.

Children are started by ``cosim.workers.start``: they never act on SIGINT
or SIGTERM (a signal sent to the whole process group, Ctrl-C in a terminal,
``timeout``, systemd, reaches the driver, which stops the run cleanly and
then stops its children; the signals are blocked from before a child's
start until it ignores them, so not even its start-up can be hit) and they
log like the driver.
"""

from __future__ import annotations

import atexit
import functools
import logging
import os
import threading
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from cosim.core import memory
from cosim.core import workers as worker_kit
from cosim.core.state import StateField, VehicleSpec
from cosim.errors import BuildError, WorkerDied, WorkerError, WorkerTimeout
from cosim.fdm_pool.base import BuildProgress, Pool, Watch
from cosim.fdm_pool.shard import Shard

log = logging.getLogger(__name__)

# control block: one 64-byte line of int64 per worker (_BUILT: vehicles built so far)
_SEQ, _DONE, _CMD, _NSUB, _STATUS, _BUILT = 0, 1, 2, 3, 4, 5
_CTRL_W = 8
_CMD_STEP, _CMD_STOP = 1, 2
_OK, _ERR = 0, 1
_SPINS = 3000  # sched_yield spins (about 1-2 ms) before falling back to sleeping
_LIVENESS_EVERY = 256


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def shard_bounds(n: int, workers: int) -> list[tuple[int, int]]:
    """Contiguous [start, stop) ranges, sizes differing by at most one."""
    base, extra = divmod(n, workers)
    out, start = [], 0
    for w in range(workers):
        stop = start + base + (1 if w < extra else 0)
        out.append((start, stop))
        start = stop
    return out


class _Shared:
    """Views of the shared arrays (rebuilt in each process from the raw arrays)."""

    def __init__(self, raw: dict[str, Any], n: int, c: int, w: int, width: int,
                 watch_shape: tuple[int, int] = (0, 0)) -> None:
        self.states = np.frombuffer(raw["states"], dtype=np.float64).reshape(n, width)
        chunks, rows = watch_shape
        self.watched = np.frombuffer(raw["watched"], dtype=np.float64)[
            : chunks * rows * width].reshape(chunks, rows, width)
        self.setpoints = np.frombuffer(raw["setpoints"], dtype=np.float64)[: n * c].reshape(n, c)
        self.ctrl = np.frombuffer(raw["ctrl"], dtype=np.int64).reshape(w, _CTRL_W)
        self.busy_s = np.frombuffer(raw["busy"], dtype=np.float64).reshape(w, _CTRL_W)


def _worker_main(w: int, specs: list[VehicleSpec], start: int, stop: int, dt_s: float,
                 channels: tuple[str, ...], raw: dict[str, Any], n: int, n_workers: int,
                 err: Connection, layout_names: list[str], watch: Watch | None,
                 watch_shape: tuple[int, int]) -> None:
    # started by cosim.workers.start: shielded from the stop signals, logging
    # as the driver does
    sh = _Shared(raw, n, len(channels), n_workers, len(layout_names), watch_shape)
    ctrl = sh.ctrl[w]
    shard = Shard()
    try:
        t0 = time.perf_counter()

        def built(k: int) -> None:
            ctrl[_BUILT] = k

        part, js = (watch.part(range(start, stop)) if watch is not None
                    else (None, np.zeros(0, dtype=np.intp)))
        Shard.build(specs, dt_s, channels, into=shard, on_built=built,
                    layout_names=layout_names,
                    watch=(part.rows, part.every) if part is not None else None)
        mine = _Watched(part, js, len(layout_names))
        log.debug("worker %d (pid %d): %d vehicles built and trimmed in %.2f s", w,
                  os.getpid(), len(specs), time.perf_counter() - t0)
        shard.write_states(sh.states[start:stop])
        ctrl[_DONE] = 0  # ready
        last = 0
        sp = sh.setpoints[start:stop] if channels else None
        out = sh.states[start:stop]
        busy = sh.busy_s[w]
        while True:
            spins = 0
            while ctrl[_SEQ] == last:
                spins += 1
                if spins < _SPINS:
                    os.sched_yield()
                else:
                    time.sleep(0.0002)
                if spins % _LIVENESS_EVERY == 0 and worker_kit.parent_gone():
                    return  # the driver is gone: do not linger as an orphan
            last = int(ctrl[_SEQ])
            if ctrl[_CMD] == _CMD_STOP:
                ctrl[_DONE] = last
                return
            nsub = int(ctrl[_NSUB])
            t0 = time.perf_counter()
            shard.exchange(sp, nsub, out, mine.buf)
            mine.publish(sh.watched, nsub)
            busy[0] = time.perf_counter() - t0
            ctrl[_DONE] = last
    except BaseException as e:
        # status first: the driver then reads the pipe, so a traceback longer
        # than the pipe's buffer cannot block this send; vehicles that could not
        # be built travel as they are (the driver reports all of them together)
        ctrl[_STATUS] = _ERR
        try:
            err.send((shard.current, worker_kit.remote_traceback(),
                      e if isinstance(e, BuildError) else None))
        finally:
            ctrl[_DONE] = -2


class _Watched:
    """A shard's part of a watch: its own buffer, copied into the pool's
    shared one at its rows' positions after each exchange."""

    def __init__(self, part: Watch | None, positions: Sequence[int] | np.ndarray,
                 width: int) -> None:
        self.part = part
        self.js = np.asarray(positions, dtype=np.intp)
        self.buf = (np.zeros((part.chunks, len(part.rows), width)) if part is not None
                    else None)

    def publish(self, shared: np.ndarray, nsub: int) -> None:
        if self.part is not None:
            assert self.buf is not None
            m = nsub // self.part.every
            shared[:m, self.js] = self.buf[:m]


class ProcessPool(Pool):
    """Vehicles sharded over worker processes (shared memory, one round trip per exchange)."""

    backend = "process"

    @classmethod
    def default_workers(cls) -> int:
        return default_workers()

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str] = (),
                 workers: int | None = None, driver_steps: bool | None = None,
                 start_timeout_s: float | None = None,
                 layout: Sequence[StateField] | None = None,
                 watch: Watch | None = None) -> None:
        super().__init__(specs, dt_s, channels, layout, watch)
        w = default_workers() if workers is None else int(workers)
        if w < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        w = min(w, self.n)
        self._n_workers = w
        self._driver_steps = (w >= 2) if driver_steps is None else bool(driver_steps)
        self.bounds = shard_bounds(self.n, w)
        c = len(self.channels)
        ctx = worker_kit.context()
        self._raw = {
            "states": ctx.RawArray("d", self.n * len(self.layout)),
            "setpoints": ctx.RawArray("d", max(1, self.n * c)),
            "ctrl": ctx.RawArray("q", w * _CTRL_W),
            "busy": ctx.RawArray("d", w * _CTRL_W),
            "watched": ctx.RawArray("d", max(1, self.watched.size)),
        }
        watch_shape = self.watched.shape[:2]
        self._sh = _Shared(self._raw, self.n, c, w, len(self.layout), watch_shape)
        self.watched = self._sh.watched
        layout_names = [f.name for f in self.layout]
        self.states = self._sh.states
        self.setpoints = self._sh.setpoints
        self.setpoints.fill(np.nan)
        self._sh.ctrl[:, _DONE] = -1
        self._seq = 0
        self._procs: dict[int, Any] = {}
        self._errs: dict[int, Connection] = {}
        self._own: Shard | None = None
        self._own_watched = _Watched(None, [], len(self.layout))
        first_child = 1 if self._driver_steps else 0
        # children ignore SIGTERM, so multiprocessing's own exit handler (terminate,
        # then join every daemonic child) would wait forever for a pool left open
        # or half closed: close it first (atexit runs the last registered first;
        # multiprocessing registered its handler when the shared arrays were made)
        atexit.register(self.close)
        #: the workers' allocator and pages (``cosim.core.memory``)
        self.allocator = memory.allocator()
        child_env = self.allocator.child_env(os.environ)
        try:
            for i in range(first_child, w):
                a, b = self.bounds[i]
                r, s = ctx.Pipe(duplex=False)
                self._errs[i] = r
                # recorded as it starts: a Ctrl-C handled right after is then
                # a pool whose close stops it
                worker_kit.start(
                    _worker_main, (i, self.specs[a:b], a, b, self.dt_s, self.channels,
                                   self._raw, self.n, w, s, layout_names, watch,
                                   watch_shape),
                    name=f"cosim-worker-{i}", env=child_env,
                    on_start=functools.partial(self._procs.__setitem__, i))
                s.close()
            self._build(start_timeout_s if start_timeout_s is not None
                        else 60.0 + 0.05 * self.n)
        except BaseException:
            self._close()
            raise
        log.debug("process pool: %d vehicles, %d workers (driver steps: %s), bounds %s",
                  self.n, w, self._driver_steps, self.bounds)

    @property
    def workers(self) -> int:
        return self._n_workers

    @property
    def pids(self) -> dict[int, int]:
        """Worker index -> pid of its child process (the driver's shard has none)."""
        return {i: p.pid for i, p in self._procs.items()}

    _own_busy = 0.0

    def busy_s(self) -> list[float]:
        own = [self._own_busy] if self._own is not None else []
        return own + [float(self._sh.busy_s[i, 0]) for i in self._procs]

    def _vehicles_of(self, i: int) -> list[str]:
        a, b = self.bounds[i]
        return self.ids[a:b]

    def _send(self, nsub: int) -> None:
        self._nsub = nsub
        self._seq += 1
        ctrl = self._sh.ctrl
        for i in self._procs:
            ctrl[i, _NSUB] = nsub
            ctrl[i, _CMD] = _CMD_STEP
            ctrl[i, _SEQ] = self._seq  # written last: publishes the command

    def _wait(self, timeout_s: float | None) -> None:
        if self._own is not None:
            a, b = self.bounds[0]
            t0 = time.perf_counter()
            self._own.exchange(self.setpoints[a:b] if self.channels else None,  # VehicleError
                               self._nsub, self.states[a:b], self._own_watched.buf)
            self._own_watched.publish(self.watched, self._nsub)
            self._own_busy = time.perf_counter() - t0
        self._await(self._seq, timeout_s, what=f"finish tick {self.tick + self._nsub}")

    def _await(self, seq: int, timeout_s: float | None, what: str) -> None:
        ctrl = self._sh.ctrl
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        for i, proc in self._procs.items():
            spins = 0
            while ctrl[i, _DONE] != seq:
                if ctrl[i, _STATUS] == _ERR:
                    self._raise_remote(i)
                spins += 1
                if spins < _SPINS:
                    os.sched_yield()
                else:
                    time.sleep(0.0001)
                if spins % _LIVENESS_EVERY == 0:
                    if proc.exitcode is not None and ctrl[i, _DONE] != seq:
                        if ctrl[i, _STATUS] == _ERR:
                            self._raise_remote(i)
                        raise WorkerDied(i, proc.pid, proc.exitcode, self._vehicles_of(i),
                                         self.tick)
                    if deadline is not None and time.monotonic() > deadline:
                        assert timeout_s is not None
                        raise WorkerTimeout(i, proc.pid, self._vehicles_of(i), self.tick,
                                            timeout_s, what)

    def _build(self, timeout_s: float) -> None:
        """Build the driver's own shard (if it steps one) while the children
        build theirs, then wait for every child; vehicles that could not be
        built, in any shard, are raised together as one ``BuildError``."""
        progress = BuildProgress(self.n)
        ctrl = self._sh.ctrl
        children = list(self._procs)
        failures: list[tuple[str, str]] = []
        own = 0
        pages: threading.Thread | None = None

        def built(k: int) -> None:
            nonlocal own
            own = k
            progress(own + int(ctrl[children, _BUILT].sum()))

        if self._driver_steps:
            a, b = self.bounds[0]
            part, js = (self.watch.part(range(a, b)) if self.watch is not None
                        else (None, np.zeros(0, dtype=np.intp)))
            self._own_watched = _Watched(part, js, len(self.layout))
            try:
                self._own = Shard.build(self.specs[a:b], self.dt_s, self.channels,
                                        on_built=built,
                                        layout_names=[f.name for f in self.layout],
                                        watch=(part.rows, part.every) if part else None)
                self._own.write_states(self.states[a:b])
            except BuildError as e:
                failures += e.failures
            else:
                if (self.allocator.huge_pages
                        and not memory.driver_has_huge_pages(self.allocator)):
                    # beside the wait for the children (the kernel's work, not Python's)
                    pages = threading.Thread(target=self._own_pages, name="cosim-pages",
                                             daemon=True)
                    pages.start()
        deadline = time.monotonic() + timeout_s
        for i, proc in self._procs.items():
            while ctrl[i, _DONE] != 0:
                if ctrl[i, _STATUS] == _ERR:
                    remote = self._remote(i)
                    if not isinstance(remote, BuildError):
                        raise remote
                    failures += remote.failures
                    break
                if proc.exitcode is not None and ctrl[i, _STATUS] != _ERR:
                    raise WorkerDied(i, proc.pid, proc.exitcode, self._vehicles_of(i), 0)
                if time.monotonic() > deadline:
                    raise WorkerTimeout(i, proc.pid, self._vehicles_of(i), 0, timeout_s,
                                        "build and trim its vehicles")
                progress(own + int(ctrl[children, _BUILT].sum()))
                time.sleep(0.005)
        if pages is not None:
            pages.join()
        if failures:
            order = {v: k for k, v in enumerate(self.ids)}
            raise BuildError(sorted(failures, key=lambda f: order.get(f[0], 0)), self.n)

    @staticmethod
    def _own_pages() -> None:
        """Huge pages for the driver's own flight models, when it started
        without its allocator's setting (``cosim.run()`` from a script)."""
        t0 = time.perf_counter()
        done = memory.advise_heap()
        log.debug("driver: %.0f MiB of heap gathered into huge pages in %.2f s",
                  done / 2**20, time.perf_counter() - t0)

    def _remote(self, i: int) -> BaseException:
        """What child ``i`` reported: the vehicles it could not build
        (``BuildError``), or any other failure as a ``WorkerError``."""
        conn = self._errs[i]
        if conn.poll(5.0):
            vehicle, tb, built = conn.recv()
        else:
            vehicle, tb, built = None, "(the worker reported an error but sent no traceback)", None
        return built if built is not None else WorkerError(i, vehicle, self.tick, tb)

    def _raise_remote(self, i: int) -> None:
        raise self._remote(i)

    def _close(self) -> None:
        ctrl = self._sh.ctrl
        self._seq += 1
        for i in self._procs:
            ctrl[i, _CMD] = _CMD_STOP
            ctrl[i, _SEQ] = self._seq
        for i, p in self._procs.items():
            if ctrl[i, _DONE] == -1:  # still building: it would not see the stop yet
                p.kill()
        worker_kit.stop(list(self._procs.values()), 2.0)  # stuck ones are killed
        for c in self._errs.values():
            c.close()
        self._procs.clear()
        self._errs.clear()
        self._own = None
        atexit.unregister(self.close)  # last: a close cut short is finished at exit
