"""fdm_pool: owns the vehicle models and steps them.

Backends behind one contract (``Pool``), found by name in a registry
(``backends``: the built-in ``inline``, every vehicle in the calling
process, the reference; ``process``, the default, shards in worker
processes, states and setpoints in shared memory, one round trip per
exchange; and any registered by another package). Results do not depend on
the backend or the number of workers.
This package never reads scenarios, schedules commands or writes logs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from cosim.core.state import N_STATE, STATE_FIELDS, STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.fdm_pool.backends import Backend, backend_names, backends, get_backend
from cosim.fdm_pool.base import Pool, PoolState
from cosim.fdm_pool.inline import InlinePool
from cosim.fdm_pool.process import ProcessPool, default_workers


def make_pool(specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str] = (),
              backend: str = "process", workers: int | None = None, **options: Any) -> Pool:
    """Build and trim every vehicle on the backend called ``backend``
    (``cosim.fdm_pool.backends``: built-in or registered by a package);
    ``options``: that backend's own (``Backend.options``)."""
    return get_backend(backend).make(specs, dt_s, channels, workers=workers, **options)


__all__ = ["Backend", "InlinePool", "N_STATE", "Pool", "PoolState", "ProcessPool",
           "STATE_FIELDS", "STATE_INDEX", "VehicleSpec", "VehicleStatus", "default_workers",
           "backend_names", "backends", "get_backend", "make_pool"]
