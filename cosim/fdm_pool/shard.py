"""A shard: the vehicles one process owns, stepped back to back.

Each vehicle runs all of its substeps before the next vehicle starts (many
FDMs in one process are cache-bound, so this ordering is much faster than
interleaving them). The shard writes its states into a caller-owned
``(m, k)`` float64 view, which is a slice of shared memory in worker
processes and of an ordinary array in the inline backend.

Unit scaling and the finiteness check run once per shard in numpy. Frozen
vehicles (ground impact, divergence) are no longer stepped and their rows
keep the state at which they froze. The per-substep ground-contact check is
skipped for a vehicle that cannot reach the ground within the exchange
(height of its CG above ground greater than ``(|vd| + 50 m/s) * exchange +
2 m + contact radius``, the contact radius being the largest distance from
the CG to any of the model's gear or structural contact points, so that any
attitude is covered), which leaves the results unchanged and saves most of
its cost.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from cosim.errors import BuildError, CosimError, JSBSimError, VehicleError
from cosim.fdm_pool.spec import (
    N_STATE,
    STATE_FIELDS,
    STATE_INDEX,
    STATUS_COL,
    VehicleSpec,
    VehicleStatus,
)
from cosim.fdm_pool.vehicle import Vehicle

_SCALES = np.array([f.scale for f in STATE_FIELDS if f.prop is not None])
_AGL, _VD = STATE_INDEX["alt_agl_m"], STATE_INDEX["vd_mps"]
_MARGIN_MPS, _MARGIN_M = 50.0, 2.0


class Shard:
    def __init__(self) -> None:
        self.vehicles: list[Vehicle] = []
        self.current: str | None = None  # id of the vehicle being built or stepped
        self.n_channels = 0
        self.dt_s = 0.0
        self._active: list[int] = []  # indices still stepped
        self._check: list[bool] = []  # per active vehicle: check ground every substep
        self._radius_m = np.zeros(0)  # per vehicle: contact radius (m)
        self._nsub = 1
        self.tick = 0  # physics ticks completed (the same in every shard of a pool)

    @classmethod
    def build(cls, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
              into: Shard | None = None, on_built: Callable[[int], None] | None = None
              ) -> Shard:
        """Build and trim every vehicle. A vehicle JSBSim cannot load or trim
        does not stop the others: all such failures are raised together as one
        ``BuildError``; on any other failure ``current`` names the culprit.
        ``on_built(k)`` is called after each vehicle with the count so far."""
        shard = into if into is not None else cls()
        shard.n_channels = len(channels)
        shard.dt_s = dt_s
        failures: list[tuple[str, str]] = []
        for k, spec in enumerate(specs, 1):
            shard.current = spec.id
            try:
                shard.vehicles.append(Vehicle(spec, dt_s, channels))
            except JSBSimError as e:
                failures.append((spec.id, str(e)))
            if on_built is not None:
                on_built(k)
        shard.current = None
        if failures:
            raise BuildError(failures, len(specs))
        shard._radius_m = np.array([v.contact_radius_m for v in shard.vehicles])
        shard._active = list(range(len(shard.vehicles)))
        shard._check = [True] * len(shard._active)
        return shard

    def write_states(self, out: np.ndarray) -> None:
        """Read every active vehicle into ``out`` (SI units, status column)."""
        active = self._active
        if not active:
            return
        vs = self.vehicles
        block = np.array([vs[i].raw_state() for i in active], dtype=np.float64).reshape(
            len(active), N_STATE - 1)
        block *= _SCALES
        finite = np.isfinite(block).all(axis=1)
        status = np.array([vs[i].status for i in active], dtype=np.float64)
        if not finite.all():
            for j in np.flatnonzero(~finite).tolist():
                vs[active[j]].status = VehicleStatus.DIVERGED
                status[j] = VehicleStatus.DIVERGED
        idx = np.asarray(active)
        out[idx[finite], :STATUS_COL] = block[finite]  # diverged rows keep their last state
        out[idx, STATUS_COL] = status
        if (status != VehicleStatus.ACTIVE).any():
            keep = status == VehicleStatus.ACTIVE
            idx = idx[keep]
            self._active = idx.tolist()
            block = block[keep]
        reach = ((np.abs(block[:, _VD]) + _MARGIN_MPS) * (self._nsub * self.dt_s) + _MARGIN_M
                 + self._radius_m[idx])
        self._check = (block[:, _AGL] <= reach).tolist()

    def exchange(self, setpoints: np.ndarray | None, nsub: int, out: np.ndarray) -> None:
        """Apply setpoints (NaN = leave as is), run ``nsub`` substeps per
        vehicle, write the new states into ``out``.

        Any failure (a JSBSim call returning False or raising, or anything
        else) becomes one ``VehicleError`` naming the vehicle and the tick the
        exchange started from; ``current`` keeps naming the vehicle.
        """
        tick = self.tick
        try:
            self._exchange(setpoints, nsub, out)
        except JSBSimError as e:
            raise VehicleError(self.current, tick, str(e)) from e
        except CosimError:
            raise
        except Exception as e:
            raise VehicleError(self.current, tick, f"{type(e).__name__}: {e}") from e
        self.tick += nsub

    def _exchange(self, setpoints: np.ndarray | None, nsub: int, out: np.ndarray) -> None:
        vs = self.vehicles
        if setpoints is not None and self.n_channels:
            written = np.flatnonzero(~np.isnan(setpoints).all(axis=1))
            for j in written.tolist():
                self.current = vs[j].spec.id
                vs[j].apply(setpoints[j].tolist())
            self.current = None
        if nsub > self._nsub:  # the margin was computed for a shorter exchange
            self._check = [True] * len(self._active)
        self._nsub = nsub
        i = -1
        try:
            for i, check in zip(self._active, self._check):
                vs[i].step(nsub, check)
        except BaseException:
            self.current = vs[i].spec.id if i >= 0 else None
            raise
        self.write_states(out)
