"""The reference backend: every vehicle in the calling process.

Every other backend is tested against this one.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from cosim.core.state import VehicleSpec
from cosim.fdm_pool.base import BuildProgress, Pool, Watch
from cosim.fdm_pool.shard import Shard


class InlinePool(Pool):
    """Every vehicle in the calling process: the reference."""

    backend = "inline"

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float,
                 channels: Sequence[str] = (), workers: int | None = None,
                 watch: Watch | None = None) -> None:
        if workers not in (None, 1):
            raise ValueError(f"the inline backend runs in one process; workers={workers}")
        super().__init__(specs, dt_s, channels, watch=watch)
        self._shard = Shard.build(self.specs, self.dt_s, self.channels,
                                  on_built=BuildProgress(self.n),
                                  layout_names=[f.name for f in self.layout],
                                  watch=(watch.rows, watch.every) if watch else None)
        self._shard.write_states(self.states)

    def _send(self, nsub: int) -> None:
        self._nsub = nsub

    def busy_s(self) -> list[float]:
        return [self._busy]

    _busy = 0.0

    def _wait(self, timeout_s: float | None) -> None:
        t0 = time.perf_counter()
        self._shard.exchange(self.setpoints, self._nsub, self.states,  # VehicleError on failure
                             self.watched if self.watch else None)
        self._busy = time.perf_counter() - t0

    def _close(self) -> None:
        self._shard.vehicles.clear()
