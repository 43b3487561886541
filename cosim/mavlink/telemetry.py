"""The telemetry streams of an endpoint's vehicles, for all of them at once.

Each (message, vehicle) has a period in ticks and a next-due tick, the rule
of ``MavVehicle.due``: at an exchange a message is sent once if it is due,
and its next-due tick moves on by whole periods. The messages due at a tick
are built for every vehicle due at once, from the state rows where they come
from them (``vehicle.STATE_COLUMNS``), encoded in one batch per message
(``batch.BatchEncoder``) and sent together through the outbox. With signing
on, each packet is packed and signed alone (pymavlink signs).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from cosim.mavlink.batch import BatchEncoder
from cosim.mavlink.outbox import Outbox
from cosim.mavlink.vehicle import STATE_COLUMNS, STREAMABLE, MavVehicle, SimClock, StateFrame


class Telemetry:
    """The stream schedule of ``vehicles`` (their rows in ``frame``), sent
    through ``outbox``; follows every change of a vehicle's stream period
    (``MavVehicle.on_period_change``)."""

    def __init__(self, vehicles: Sequence[MavVehicle], clock: SimClock, frame: StateFrame,
                 outbox: Outbox, counts: Counter[str]) -> None:
        self.vehicles = vehicles
        self.clock = clock
        self.frame = frame
        self.outbox = outbox
        self.counts = counts
        n = len(vehicles)
        # period and next-due tick per (message, vehicle); -1 = off / not yet sent
        self._period = np.full((len(STREAMABLE), n), -1, dtype=np.int64)
        self._next_due = np.full((len(STREAMABLE), n), -1, dtype=np.int64)
        for j, v in enumerate(vehicles):
            v.on_period_change = self._period_changed
            for k, name in enumerate(STREAMABLE):
                p = v.period[name]
                self._period[k, j] = -1 if p is None else p
        self._encoders = {name: BatchEncoder(name) for name in STREAMABLE}
        self._first_due = -1  # the earliest next-due tick of any stream
        self._sysids = np.array([v.sysid for v in vehicles], dtype=np.int64)
        self._home_alt = np.array([v.home[2] for v in vehicles], dtype=float)
        self._zero_rates = np.zeros((n, 3))

    def _period_changed(self, v: MavVehicle, name: str) -> None:
        k, j = STREAMABLE.index(name), v.index
        p = v.period[name]
        self._period[k, j] = -1 if p is None else p
        nd = v.next_due[name]
        self._next_due[k, j] = -1 if nd is None else nd
        self._first_due = -1  # recomputed at the next exchange

    def send(self, tick: int) -> None:
        """Send every stream due at ``tick``, one message type for all due
        vehicles at once; the next-due ticks move on by whole periods."""
        if tick < self._first_due:  # nothing due before then (most exchanges)
            return
        on = self._period > 0
        nd = np.where(on & (self._next_due < 0), tick, self._next_due)
        due = on & (nd <= tick)
        p = np.where(on, self._period, 1)
        self._next_due = np.where(due, nd + p * ((tick - nd) // p + 1), nd)
        self._first_due = int(self._next_due[on].min()) if on.any() else 2 ** 62
        if not due.any():
            return
        out = self.outbox
        seq = out.seq
        blobs: list[bytes] = []
        lengths: list[np.ndarray] = []
        who: list[np.ndarray] = []
        for k in np.flatnonzero(due.any(axis=1)).tolist():
            name = STREAMABLE[k]
            idx = np.flatnonzero(due[k])
            vs = [self.vehicles[j] for j in idx.tolist()]
            if out.signing:  # each packet signed by pymavlink
                for v in vs:
                    out.send(v, name, v.fields(name, tick), tick)
                continue
            build = STATE_COLUMNS.get(name)
            if build is not None:
                rows = self.frame.rows
                assert rows is not None
                # only ATTITUDE reads the body rates: the others need not compute them
                pqr = (self.frame.latest_rates(len(self.vehicles)) if name == "ATTITUDE"
                       else self._zero_rates)
                cols = build(rows[idx], pqr[idx], self._home_alt[idx], self.clock, tick)
            else:
                dicts = [v.fields(name, tick) for v in vs]
                cols = {f: [d[f] for d in dicts] for f in dicts[0]}
            enc = self._encoders[name]
            rec = enc.payloads(len(idx), cols)
            blob, lens = enc.encode(rec, self._sysids[idx], seq[idx])
            seq[idx] = (seq[idx] + 1) % 256
            self.counts["packets_out"] += len(idx)
            blobs.append(blob)
            lengths.append(lens)
            who.append(idx)
            if out.subscribers:
                out.deliver(name, enc.field_names, vs, rec.tolist())
        if blobs:
            out.send_batch(b"".join(blobs), np.concatenate(lengths), np.concatenate(who),
                           self.clock.unix_us(tick))
