"""A shard: the vehicles one process owns, stepped back to back.

Each vehicle runs all of its substeps before the next vehicle starts (many
FDMs in one process are cache-bound, so this ordering is much faster than
interleaving them). The shard writes its states into a caller-owned
``(m, k)`` float64 view, which is a slice of shared memory in worker
processes and of an ordinary array in the inline backend.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cosim.fdm_pool.spec import VehicleSpec
from cosim.fdm_pool.vehicle import Vehicle


class Shard:
    def __init__(self) -> None:
        self.vehicles: list[Vehicle] = []
        self.current: str | None = None  # id of the vehicle being built or stepped
        self.n_channels = 0

    @classmethod
    def build(cls, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
              into: Shard | None = None) -> Shard:
        """Build and trim every vehicle; on failure ``current`` names the culprit."""
        shard = into if into is not None else cls()
        shard.n_channels = len(channels)
        for spec in specs:
            shard.current = spec.id
            shard.vehicles.append(Vehicle(spec, dt_s, channels))
        shard.current = None
        return shard

    def write_states(self, out: np.ndarray) -> None:
        out[:] = [v.read_state() for v in self.vehicles]

    def exchange(self, setpoints: np.ndarray | None, nsub: int, out: np.ndarray) -> None:
        """Apply setpoints (NaN = leave as is), run ``nsub`` substeps per
        vehicle, write the new states into ``out``."""
        if setpoints is not None and self.n_channels:
            written = np.flatnonzero(~np.isnan(setpoints).all(axis=1))
            for j in written.tolist():
                self.current = self.vehicles[j].spec.id
                self.vehicles[j].apply(setpoints[j].tolist())
        for v in self.vehicles:
            self.current = v.spec.id
            v.step(nsub)
        self.current = None
        self.write_states(out)
