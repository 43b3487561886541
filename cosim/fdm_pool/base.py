"""The pool contract shared by every backend.

A pool owns ``n`` vehicles, a ``(n, k)`` float64 ``states`` array (columns
``layout``: ``STATE_FIELDS``, then the columns their classes add) and a
``(n, c)`` float64 ``setpoints`` array whose columns are the channels named
in ``channels`` (JSBSim properties, or a batched class's inputs). The caller writes
setpoints (NaN means "leave unchanged"), then ``send(nsub)`` starts one
exchange of ``nsub`` physics substeps and ``wait(timeout_s)`` finishes it and
returns ``states``. ``step(nsub)`` does both. After each exchange the pool
resets ``setpoints`` to NaN. Pools are context managers; ``close()`` is
idempotent.

A pool built with a ``Watch`` also gathers a few rows' states inside each
exchange, every ``watch.every`` ticks (a camera's aircraft at its frame
rate, while everyone else is exchanged at the control rate): after
``wait``, ``watched[:watched_count]`` holds them, ``(chunk, watched row,
column)``, the last chunk equal to those rows of ``states``. The states
themselves are the same with or without a watch. A watched vehicle whose
state becomes non-finite inside an exchange is no longer stepped, and its
chunks from there on are its frozen row, the exchange's (an unwatched one
runs on to the end of the exchange first: a JSBSim failure in that rest
would be an error for it, not for the watched one).

A backend may have things to report that are not failures (a lost machine
replaced, and the run no longer bit-exact): it appends ``(kind, fields)``
to ``notices``, and the run turns each into an event.
"""

from __future__ import annotations

import enum
import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import numpy as np

from cosim.core.state import StateField, VehicleSpec
from cosim.errors import PoolStateError
from cosim.vehicles.registry import state_layout

log = logging.getLogger(__name__)


class BuildProgress:
    """Logs how many of ``total`` vehicles are built and trimmed, at most every
    ``every_s`` seconds (a build quicker than that says nothing)."""

    def __init__(self, total: int, every_s: float = 5.0) -> None:
        self.total = total
        self.every_s = every_s
        self.t0 = self.last = time.monotonic()

    def __call__(self, done: int) -> None:
        now = time.monotonic()
        if now - self.last >= self.every_s and done < self.total:
            self.last = now
            log.info("building: %d of %d vehicles built and trimmed (%.0f s)", done,
                     self.total, now - self.t0)


@dataclass(frozen=True)
class Watch:
    """Rows (of the pool) whose states are also gathered every ``every``
    ticks inside an exchange of at most ``max_nsub`` ticks (a multiple of
    ``every``)."""

    rows: tuple[int, ...]
    every: int
    max_nsub: int

    def check(self, n: int) -> None:
        if not self.rows:
            raise ValueError("a watch needs at least one row")
        if len(set(self.rows)) != len(self.rows) or list(self.rows) != sorted(self.rows):
            raise ValueError(f"watch rows must be increasing, got {list(self.rows)[:10]}")
        if self.rows[0] < 0 or self.rows[-1] >= n:
            raise ValueError(f"watch rows must be in 0..{n - 1}, got {list(self.rows)[:10]}")
        if self.every < 1 or self.max_nsub < self.every or self.max_nsub % self.every:
            raise ValueError(f"a watch every {self.every} ticks needs exchanges of a multiple "
                             f"of it, got at most {self.max_nsub}")

    @property
    def chunks(self) -> int:
        return self.max_nsub // self.every

    def part(self, rows: Sequence[int]) -> tuple[Watch | None, np.ndarray]:
        """This watch for a share holding the pool's ``rows`` (in that order,
        renumbered from 0), and the positions of its watched rows in
        ``self.rows``; (None, empty) if it holds none of them."""
        where = {int(r): k for k, r in enumerate(rows)}
        js = [j for j, r in enumerate(self.rows) if r in where]
        if not js:
            return None, np.zeros(0, dtype=np.intp)
        return (Watch(tuple(where[self.rows[j]] for j in js), self.every, self.max_nsub),
                np.asarray(js, dtype=np.intp))


class PoolState(enum.Enum):
    READY = "ready"
    WAITING = "waiting"  # send() called, wait() not yet
    FAILED = "failed"
    CLOSED = "closed"


class Pool(ABC):
    backend: str = "?"

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float,
                 channels: Sequence[str] = (),
                 layout: Sequence[StateField] | None = None,
                 watch: Watch | None = None) -> None:
        if not specs:
            raise ValueError("a pool needs at least one vehicle")
        self.specs = list(specs)
        self.ids = [s.id for s in specs]
        self.dt_s = float(dt_s)
        self.channels = tuple(channels)
        self.n = len(specs)
        self.tick = 0  # physics ticks completed
        self._state = PoolState.READY
        #: the state array's columns: ``STATE_FIELDS``, then those the classes add
        #: (``layout``: a whole run's, when this pool holds a part of its vehicles)
        self.layout = tuple(layout) if layout is not None else state_layout(self.specs)
        #: what the backend reports that is not a failure: ``(kind, fields)``
        self.notices: list[tuple[str, dict[str, Any]]] = []
        if watch is not None:
            watch.check(self.n)
        self.watch = watch
        #: the watched rows' states inside the last exchange (``Watch``)
        self.watched: np.ndarray = np.zeros(
            (watch.chunks if watch else 0, len(watch.rows) if watch else 0, len(self.layout)))
        self.watched_count = 0
        self.states: np.ndarray = np.zeros((self.n, len(self.layout)))
        self.setpoints: np.ndarray = np.full((self.n, len(self.channels)), np.nan)

    @property
    def workers(self) -> int:
        return 1

    @classmethod
    def default_workers(cls) -> int:
        """The workers this backend uses when none are asked for."""
        return 1

    @classmethod
    def available(cls) -> None:
        """Raise ``ConfigError`` saying what is missing if this backend cannot
        run here (a library not installed); checked before a run starts."""
        return None

    @property
    def pids(self) -> dict[int, int]:
        """Worker index -> pid of each worker process (none: every shard runs
        in the calling process)."""
        return {}

    def busy_s(self) -> list[float]:
        """Seconds each shard spent stepping in the last exchange (for benchmarks)."""
        return []

    def _require(self, *allowed: PoolState, action: str) -> None:
        if self._state not in allowed:
            raise PoolStateError(
                f"cannot {action}: {self.backend} pool is {self._state.value}"
                f" (allowed when {' or '.join(s.value for s in allowed)})")

    def send(self, nsub: int) -> None:
        """Start one exchange: apply setpoints and run ``nsub`` substeps."""
        self._require(PoolState.READY, action="send()")
        if nsub < 1:
            raise ValueError(f"nsub must be >= 1, got {nsub}")
        w = self.watch
        if w is not None and (nsub % w.every or nsub > w.max_nsub):
            raise ValueError(f"this pool watches rows every {w.every} ticks in exchanges of at "
                             f"most {w.max_nsub}: nsub {nsub} does not fit")
        self._state = PoolState.WAITING
        try:
            self._send(int(nsub))
        except BaseException:
            self._state = PoolState.FAILED
            raise

    def wait(self, timeout_s: float | None = None) -> np.ndarray:
        """Finish the exchange started by ``send`` and return ``states``."""
        self._require(PoolState.WAITING, action="wait()")
        try:
            self._wait(timeout_s)
        except BaseException:
            self._state = PoolState.FAILED
            raise
        self.tick += self._nsub
        self.watched_count = self._nsub // self.watch.every if self.watch else 0
        self.setpoints.fill(np.nan)
        self._state = PoolState.READY
        return self.states

    def step(self, nsub: int, timeout_s: float | None = None) -> np.ndarray:
        self.send(nsub)
        return self.wait(timeout_s)

    def close(self) -> None:
        if self._state is PoolState.CLOSED:
            return
        self._state = PoolState.CLOSED
        self._close()

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # backend hooks
    _nsub: int = 0

    @abstractmethod
    def _send(self, nsub: int) -> None: ...

    @abstractmethod
    def _wait(self, timeout_s: float | None) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...
