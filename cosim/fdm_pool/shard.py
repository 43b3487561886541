"""A shard: the vehicles one process owns, stepped back to back.

Two model kinds (``cosim.vehicles``): JSBSim-backed vehicles, each running
all of its substeps before the next one starts (many FDMs in one process
are cache-bound, so this ordering is much faster than interleaving them);
and batched classes, all of a class's vehicles in the shard advanced by its
``BatchedModel`` (one vectorised call per substep). The shard writes its
states into a caller-owned ``(m, k)`` float64 view, which is a slice of
shared memory in worker processes and of an ordinary array in the inline
backend.

For JSBSim vehicles, unit scaling and the finiteness check run once per
shard in numpy. Frozen vehicles (ground impact, divergence) are no longer
stepped and their rows keep the state at which they froze. The per-substep
ground-contact check is skipped for a vehicle that cannot reach the ground
within the exchange (height of its CG above ground greater than ``(|vd| +
50 m/s) * exchange + 2 m + contact radius``, the contact radius being the
largest distance from the CG to any of the model's gear or structural
contact points, so that any attitude is covered), which leaves the results
unchanged and saves most of its cost.

Watched rows (``watch``: a camera's aircraft, gathered every ``every``
ticks inside an exchange) are stepped ``every`` substeps at a time with
their state row recorded after each run, which gives the same states as
stepping them in one go. A batched class's vehicles can be watched when its
model has ``step_watched`` (``cosim.vehicles.base.BatchedModel``): the shard
then steps that batch ``every`` substeps at a time, writing the watched rows
between, and only while some of its rows are watched; a model without it
integrates a whole exchange at once, so its vehicles cannot be watched.

A layout that ends with the ``cosim.vehicles.resume`` columns (a pool whose
vehicles may have to be rebuilt elsewhere: the ray backend's agents) also
gets, after every exchange, what such a rebuild needs beyond the state
array: each JSBSim vehicle's body rates, controls and autopilot integrators.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from cosim.core.state import (
    N_STATE,
    STATE_FIELDS,
    STATE_INDEX,
    STATUS_COL,
    VehicleSpec,
    VehicleStatus,
    plausible,
)
from cosim.errors import BuildError, ConfigError, CosimError, JSBSimError, VehicleError
from cosim.vehicles.base import BatchedModel
from cosim.vehicles.jsbsim_model import Vehicle
from cosim.vehicles.registry import get_class, state_layout
from cosim.vehicles.resume import FIELDS as RESUME_FIELDS
from cosim.vehicles.resume import Reader
from cosim.vehicles.resume import columns as resume_columns

#: ``BatchedModel.step_watched``: (nsub, every, rows of the batch, out)
WatchedStep = Callable[[int, int, np.ndarray, np.ndarray], None]
_SCALES = np.array([f.scale for f in STATE_FIELDS if f.prop is not None])
_AGL, _VD = STATE_INDEX["alt_agl_m"], STATE_INDEX["vd_mps"]
_MARGIN_MPS, _MARGIN_M = 50.0, 2.0


class Shard:
    def __init__(self) -> None:
        self.vehicles: list[Vehicle] = []  # the JSBSim-backed ones
        self.current: str | None = None  # id of the vehicle being built or stepped
        self.n_channels = 0
        self.dt_s = 0.0
        self._rows = np.zeros(0, dtype=np.intp)  # each JSBSim vehicle's row in the shard
        #: the batched classes: (class name, model, its rows in the shard)
        self.batches: list[tuple[str, BatchedModel, np.ndarray]] = []
        self.n_columns = N_STATE  # the state layout's width (``build``)
        self._extra: list[tuple[int, int]] = []  # (vehicle, first extra column) with extras
        self._active: list[int] = []  # JSBSim vehicles still stepped (indices)
        self._check: list[bool] = []  # per active vehicle: check ground every substep
        self._radius_m = np.zeros(0)  # per vehicle: contact radius (m)
        self._nsub = 1
        self.tick = 0  # physics ticks completed (the same in every shard of a pool)
        #: watched rows: (JSBSim vehicle index -> position in the watch), every
        self._watch_of: dict[int, int] = {}
        self._watch_rows = np.zeros(0, dtype=np.intp)
        self._watch_every = 0
        self._bad: list[tuple[int, int]] = []  # (watched position, first non-finite chunk)
        #: batch index -> (its model's ``step_watched``, its watched rows counted in
        #: the batch, their positions in the watch)
        self._watch_batch: dict[int, tuple[WatchedStep, np.ndarray, np.ndarray]] = {}
        self._extra_of: dict[int, int] = {}  # JSBSim vehicle index -> its first extra column
        #: the first of the ``cosim.vehicles.resume`` columns, when the layout has them
        self._resume_at: int | None = None
        self._readers: list[Reader] = []

    @classmethod
    def build(cls, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
              into: Shard | None = None, on_built: Callable[[int], None] | None = None,
              layout_names: Sequence[str] | None = None,
              watch: tuple[Sequence[int], int] | None = None) -> Shard:
        """Build and trim every vehicle. A JSBSim vehicle that cannot be loaded
        or trimmed does not stop the others: all such failures, with those of
        the batched classes (their ``BuildError``), are raised together as one
        ``BuildError`` in vehicle order; on any other failure ``current`` names
        the culprit. ``on_built(k)`` is called after each vehicle with the
        count so far. ``layout_names``: the run's state columns (the pool's
        ``state_layout``; by default these vehicles' own), for the columns
        classes add. ``watch``: (rows of ``specs``, every) gathered inside
        each exchange (``exchange``'s ``watched``)."""
        if layout_names is None:
            layout_names = [f.name for f in state_layout(specs)]
        shard = into if into is not None else cls()
        shard.n_channels = len(channels)
        shard.n_columns = len(layout_names)
        shard.dt_s = dt_s
        column = {name: j for j, name in enumerate(layout_names)}
        failures: list[tuple[str, str]] = []
        rows: list[int] = []
        batched: dict[str, list[int]] = {}
        for k, spec in enumerate(specs, 1):
            shard.current = spec.id
            vc = get_class(spec.vehicle_class)
            if vc.model_kind == "batched":
                batched.setdefault(vc.name, []).append(k - 1)
            else:
                try:
                    shard.vehicles.append(Vehicle(spec, dt_s, channels))
                    rows.append(k - 1)
                    if vc.state_columns:
                        shard._extra.append((len(shard.vehicles) - 1,
                                             column[vc.state_columns[0].name]))
                except JSBSimError as e:
                    failures.append((spec.id, str(e)))
            if on_built is not None and vc.model_kind != "batched":
                on_built(k)
        for name, brows in batched.items():
            shard.current = None
            try:
                model = get_class(name).make_batch([specs[r] for r in brows], dt_s, channels,
                                                   list(layout_names))
            except BuildError as e:  # reported with the others
                failures += e.failures
                continue
            shard.batches.append((name, model, np.asarray(brows, dtype=np.intp)))
            if on_built is not None:
                on_built(len(specs))
        shard.current = None
        if failures:
            order = {s.id: k for k, s in enumerate(specs)}
            raise BuildError(sorted(failures, key=lambda f: order.get(f[0], len(specs))),
                             len(specs))
        shard._rows = np.asarray(rows, dtype=np.intp)
        if watch is not None:
            shard._set_watch(specs, watch[0], watch[1])
        shard._radius_m = np.array([v.contact_radius_m for v in shard.vehicles])
        shard._resume_at = column.get(RESUME_FIELDS[0].name)
        if shard._resume_at is not None:  # gathered for a rebuild elsewhere
            shard._readers = [Reader(v.fdm) for v in shard.vehicles]
        shard._active = list(range(len(shard.vehicles)))
        shard._check = [True] * len(shard._active)
        return shard

    def _set_watch(self, specs: Sequence[VehicleSpec], rows: Sequence[int], every: int) -> None:
        index = {int(r): i for i, r in enumerate(self._rows.tolist())}
        in_batch = {int(r): (b, k) for b, (_, _, brows) in enumerate(self.batches)
                    for k, r in enumerate(brows.tolist())}
        watched: dict[int, tuple[list[int], list[int]]] = {}
        for j, r in enumerate(rows):
            if r in index:
                self._watch_of[index[r]] = j
                continue
            b, k = in_batch[r]
            if getattr(self.batches[b][1], "step_watched", None) is None:
                spec = specs[r]
                raise ConfigError(
                    f"vehicle {spec.id!r} (class {spec.vehicle_class}) is stepped with its "
                    f"class's other vehicles a whole exchange at a time: its states exist "
                    f"only at exchanges, so nothing (a camera) can be watched on it more "
                    f"often; use a rate that falls on exchanges")
            watched.setdefault(b, ([], []))
            watched[b][0].append(k)
            watched[b][1].append(j)
        self._watch_batch = {b: (self.batches[b][1].step_watched,  # type: ignore[attr-defined]
                                 np.asarray(ks, dtype=np.intp), np.asarray(js, dtype=np.intp))
                             for b, (ks, js) in watched.items()}
        self._watch_rows = np.asarray(rows, dtype=np.intp)
        self._watch_every = int(every)
        self._extra_of = dict(self._extra)

    def write_states(self, out: np.ndarray) -> None:
        """Read every active vehicle into ``out`` (SI units, status column)."""
        for _, model, rows in self.batches:
            block = out[rows]
            model.write_states(block)
            out[rows] = block
        active = self._active
        if not active:
            return
        vs = self.vehicles
        block = np.array([vs[i].raw_state() for i in active], dtype=np.float64).reshape(
            len(active), N_STATE - 1)
        block *= _SCALES
        finite = plausible(block)
        status = np.array([vs[i].status for i in active], dtype=np.float64)
        if not finite.all():
            for j in np.flatnonzero(~finite).tolist():
                vs[active[j]].status = VehicleStatus.DIVERGED
                status[j] = VehicleStatus.DIVERGED
        act = np.asarray(active)
        idx = self._rows[act]
        out[idx[finite], :STATUS_COL] = block[finite]  # diverged rows keep their last state
        out[idx, STATUS_COL] = status
        if self._extra:
            self._write_extra(out, set(act[finite].tolist()))
        if self._resume_at is not None and finite.any():
            ok = act[finite]
            at = self._resume_at
            reads = np.array([self._readers[i].read() for i in ok.tolist()], dtype=np.float64)
            out[self._rows[ok], at:at + len(RESUME_FIELDS)] = resume_columns(reads)
        if (status != VehicleStatus.ACTIVE).any():
            keep = status == VehicleStatus.ACTIVE
            act = act[keep]
            self._active = act.tolist()
            block = block[keep]
        reach = ((np.abs(block[:, _VD]) + _MARGIN_MPS) * (self._nsub * self.dt_s) + _MARGIN_M
                 + self._radius_m[act])
        self._check = (block[:, _AGL] <= reach).tolist()

    def _write_extra(self, out: np.ndarray, finite: set[int]) -> None:
        """The columns classes add, for the active vehicles whose states are finite."""
        for i, first in self._extra:
            if i in finite:
                values = self.vehicles[i].extra_state()
                out[self._rows[i], first:first + len(values)] = values

    def exchange(self, setpoints: np.ndarray | None, nsub: int, out: np.ndarray,
                 watched: np.ndarray | None = None) -> None:
        """Apply setpoints (NaN = leave as is), run ``nsub`` substeps per
        vehicle, write the new states into ``out``; ``watched`` (a shard
        built with a watch): ``(chunks, watched rows, columns)``, its first
        ``nsub // every`` chunks filled.

        Any failure (a JSBSim call returning False or raising, or anything
        else) becomes one ``VehicleError`` naming the vehicle and the tick the
        exchange started from; ``current`` keeps naming the vehicle.
        """
        tick = self.tick
        try:
            self._exchange(setpoints, nsub, out, watched)
        except JSBSimError as e:
            raise VehicleError(self.current, tick, str(e)) from e
        except CosimError:
            raise
        except Exception as e:
            raise VehicleError(self.current, tick, f"{type(e).__name__}: {e}") from e
        self.tick += nsub

    def _exchange(self, setpoints: np.ndarray | None, nsub: int, out: np.ndarray,
                  watched: np.ndarray | None) -> None:
        vs = self.vehicles
        if setpoints is not None and self.n_channels:
            mine = setpoints[self._rows]
            # the values written (not NaN), vehicle by vehicle in channel order:
            # one numpy pass, not a Python test of every channel of every row
            js, cs = np.nonzero(mine == mine)
            j = -1
            try:
                for j, c, v in zip(js.tolist(), cs.tolist(), mine[js, cs].tolist()):
                    vs[j].apply(c, v)
            except BaseException:
                self.current = vs[j].spec.id if j >= 0 else None
                raise
            for name, model, rows in self.batches:
                self.current = f"(the {name} vehicles)"
                model.apply(setpoints[rows])
            self.current = None
        if nsub > self._nsub:  # the margin was computed for a shorter exchange
            self._check = [True] * len(self._active)
        self._nsub = nsub
        watching = watched is not None and self._watch_every > 0
        if watching:
            assert watched is not None
            m = nsub // self._watch_every
            watched[:m] = out[self._watch_rows]  # frozen ones stay as they are
            self._bad.clear()
        i = -1
        try:
            if not watching:  # the hot path: nothing but the steps
                for i, check in zip(self._active, self._check):
                    vs[i].step(nsub, check)
            else:
                assert watched is not None
                for i, check in zip(self._active, self._check):
                    at = self._watch_of.get(i)
                    if at is None:
                        vs[i].step(nsub, check)
                    else:
                        self._step_watched(i, check, nsub, watched[:, at])
        except BaseException:
            self.current = vs[i].spec.id if i >= 0 else None
            raise
        for b, (name, model, _) in enumerate(self.batches):
            self.current = f"(the {name} vehicles)"
            part = self._watch_batch.get(b) if watching else None
            if part is None:  # the hot path: the whole exchange in one call
                model.step(nsub)
            else:
                assert watched is not None
                step_watched, ks, where = part
                block = watched[:m, where]  # a copy: the rows' last states in every chunk
                step_watched(nsub, self._watch_every, ks, block)
                watched[:m, where] = block
        self.current = None
        self.write_states(out)
        if watching:
            assert watched is not None
            watched[m - 1] = out[self._watch_rows]  # the last one is the exchange's
            for at, c in self._bad:
                watched[c:m, at] = out[self._watch_rows[at]]

    def _step_watched(self, i: int, check: bool, nsub: int, rows: np.ndarray) -> None:
        """Step vehicle ``i`` ``every`` substeps at a time, its row after each
        in ``rows``; once non-finite, it stops (``_bad``: the exchange's
        frozen row fills the rest)."""
        every = self._watch_every
        v = self.vehicles[i]
        first = self._extra_of.get(i)
        for c in range(nsub // every):
            if v.status == VehicleStatus.ACTIVE:
                v.step(every, check)
            row = np.asarray(v.raw_state(), dtype=np.float64) * _SCALES
            if not plausible(row[None, :])[0]:  # diverged: from here on its frozen row,
                self._bad.append((self._watch_of[i], c))  # known once write_states ran
                return
            rows[c, :STATUS_COL] = row
            rows[c, STATUS_COL] = v.status
            if first is not None:
                values = v.extra_state()
                rows[c, first:first + len(values)] = values
