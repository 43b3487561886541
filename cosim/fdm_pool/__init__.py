"""fdm_pool: owns the vehicle models and steps them.

Backends behind one contract (``Pool``): ``inline`` (every vehicle in the
calling process: the reference) and ``process`` (default: shards in worker
processes, states and setpoints in shared memory, one round trip per
exchange). Results do not depend on the backend or the number of workers.
This package never reads scenarios, schedules commands or writes logs.
"""

from __future__ import annotations

from collections.abc import Sequence

from cosim.fdm_pool.base import Pool, PoolState
from cosim.fdm_pool.inline import InlinePool
from cosim.fdm_pool.process import ProcessPool, default_workers
from cosim.fdm_pool.spec import (
    N_STATE,
    STATE_FIELDS,
    STATE_INDEX,
    VehicleSpec,
    VehicleStatus,
)

BACKENDS = ("inline", "process")


def make_pool(specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str] = (),
              backend: str = "process", workers: int | None = None) -> Pool:
    """Build and trim every vehicle on the chosen backend."""
    if backend == "inline":
        return InlinePool(specs, dt_s, channels)
    if backend == "process":
        return ProcessPool(specs, dt_s, channels, workers=workers)
    raise ValueError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")


__all__ = ["BACKENDS", "InlinePool", "N_STATE", "Pool", "PoolState", "ProcessPool",
           "STATE_FIELDS", "STATE_INDEX", "VehicleSpec", "VehicleStatus", "default_workers",
           "make_pool"]
