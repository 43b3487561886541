"""An example backend: every vehicle in the calling process (as ``inline``),
with the wall time of every exchange measured and summarised in the log when
the pool closes (median, 99th percentile, the slowest exchange and its tick).

A backend is a ``cosim.fdm_pool.base.Pool`` subclass. The base owns the
``states`` array (one row per vehicle, ``layout`` columns) and the
``setpoints`` array (one row per vehicle, ``channels`` columns, NaN = leave
alone) and the order of calls; a backend supplies three methods:

- ``_send(nsub)``: start ``nsub`` physics substeps with ``setpoints``;
- ``_wait(timeout_s)``: finish them, leaving the new rows in ``states``;
- ``_close()``: release what it holds.

It must give bit-identical states to ``inline`` for any worker count: run
cosim's conformance suite against it (``COSIM_CONFORMANCE_BACKENDS=traced
python -m pytest tests/fdm_pool/test_conformance.py``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np

from cosim.core.state import VehicleSpec
from cosim.fdm_pool.inline import InlinePool

log = logging.getLogger("cosim.traced")


class TracedPool(InlinePool):
    """Inline, with every exchange timed (an example backend)."""

    backend = "traced"

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float,
                 channels: Sequence[str] = (), workers: int | None = None) -> None:
        self.exchange_s: list[float] = []  # wall time of each exchange
        self._t0 = 0.0
        super().__init__(specs, dt_s, channels, workers)

    def _send(self, nsub: int) -> None:
        self._t0 = time.perf_counter()
        super()._send(nsub)

    def _wait(self, timeout_s: float | None) -> None:
        super()._wait(timeout_s)
        self.exchange_s.append(time.perf_counter() - self._t0)

    def _close(self) -> None:
        times = np.array(self.exchange_s)
        if times.size:
            worst = int(times.argmax())
            log.info("traced: %d exchanges of %d vehicles: median %.3f ms, p99 %.3f ms, "
                     "slowest %.3f ms (exchange %d)", times.size, self.n,
                     1e3 * float(np.median(times)), 1e3 * float(np.percentile(times, 99)),
                     1e3 * float(times[worst]), worst + 1)
        super()._close()
