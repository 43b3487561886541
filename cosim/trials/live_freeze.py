"""SAGAT freeze probes in a live trial: the run paused at each probe's time,
the true state kept, the participant's page asked, the run resumed once
answered.

Owns two pieces. ``FreezeProbes``, a run participant: at the first exchange
at or after each probe's ``at_s`` it keeps the aircraft as that exchange
hands them (the state the cameras and the map were last drawn from) and
asks the run to pause (``Run.pause``: the loop waits before its next
exchange, so simulated time stops and nothing is skipped; the run's states
are those of a run never paused, and the pacer's clock stops with it, so a
freeze is neither lateness nor a burst of frames to catch up). ``Freezes``,
the live sessions' probes for the trial app: ``attach`` adds a
``FreezeProbes`` to a trial's run as the live console starts it,
``current`` says what the page should ask now, ``answered`` resumes the
run, and ``freeze_state`` is ``Instruments.freeze_state``: the true state at
a freeze (``sagat.FreezeState``): the aircraft kept at the freeze, and, for
a ``last_target`` question, each target's last sighting in the trial's
feeds from the run's ground truth (written as the cameras render: read once
the run is over, when ``Freezes`` scores the answers still unscored).

It does not serve HTTP (``instrument_routes``) or parse the study
(``instruments``).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.errors import CosimError
from cosim.trials.instruments import sagat_page, score_probe
from cosim.trials.sagat import (
    FreezeState,
    Probe,
    TargetAt,
    VehicleAt,
    last_sightings,
)

log = logging.getLogger(__name__)

_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m",
                                  "airspeed_mps")]
#: the blank map of a freeze spans at least this (m) and this much beyond what it holds
MIN_SPAN_M = 400.0
MARGIN = 0.25


@dataclass(frozen=True)
class Freeze:
    """One probe's freeze: the exchange it stopped at and the aircraft there."""

    probe: int
    tick: int
    time_s: float
    vehicles: tuple[VehicleAt, ...]


def freeze_tick(at_s: float, physics_hz: float, control_every: int) -> int:
    """The first exchange (tick) at or after ``at_s``."""
    return math.ceil(round(at_s * physics_hz, 6) / control_every) * control_every


class FreezeProbes:
    """The run participant that freezes a live trial at its probes' times
    (see the module docstring). ``run``: the ``cosim.sync.runner.Run``;
    ``on_over()`` is called from the run's thread once it is over."""

    name = "sagat_freezes"

    def __init__(self, probes: tuple[Probe, ...], run: Any,
                 on_over: Callable[[], None] | None = None) -> None:
        self.probes, self.run, self.on_over = probes, run, on_over
        self.freezes: dict[int, Freeze] = {}
        #: the probe the run is frozen at (None: running)
        self.frozen: int | None = None
        #: the run is over (its ground truth complete)
        self.over = False
        self._due: list[tuple[int, Probe]] = []
        self._lock = threading.Lock()

    def start(self, ctx: Any) -> None:
        self.ctx = ctx
        total = ctx.scenario.total_ticks
        self._due = [(t, p) for p in self.probes
                     if (t := freeze_tick(p.at_s, ctx.physics_hz, ctx.control_every)) < total]

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        if not self._due or tick < self._due[0][0]:
            return
        _, probe = self._due.pop(0)
        s = states[:, _COLS]
        n, e, _ = self.ctx.frame.geodetic_to_ned(s[:, 0], s[:, 1], s[:, 2])
        columns = list(self.ctx.columns)
        fuel = states[:, columns.index("fuel_kg")] if "fuel_kg" in columns else None
        vehicles = tuple(
            VehicleAt(vid, float(n[i]), float(e[i]), float(s[i, 2]), float(s[i, 3]),
                      float(s[i, 4]), None if fuel is None else float(fuel[i]))
            for i, vid in enumerate(self.ctx.ids) if np.isfinite(s[i]).all())
        with self._lock:
            self.freezes[probe.index] = Freeze(probe.index, tick, tick / self.ctx.physics_hz,
                                               vehicles)
            self.frozen = probe.index
        self.run.pause()
        self.ctx.events.emit("sagat_freeze", tick, vehicle=None, probe=probe.index)
        log.info("freeze for SAGAT probe %d at tick %d", probe.index, tick)

    def answered(self, probe: int) -> bool:
        """The probe's answers are in: the run goes on (True if it was frozen there)."""
        with self._lock:
            if self.frozen != probe:
                return False
            self.frozen = None
        self.run.resume()
        return True

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        return {"freezes": [{"probe": f.probe, "tick": f.tick, "time_s": f.time_s}
                            for f in self.freezes.values()]}

    def after_run(self, out_dir: Any) -> None:
        self.over = True
        if self.on_over is not None:
            self.on_over()


def blank_map_extent(freeze: Freeze, probe: Probe, start_ne_m: np.ndarray
                     ) -> list[float]:
    """``[north_min, north_max, east_min, east_max]`` (m) of the blank map a
    freeze asks on: the aircraft where they started and where they are, the
    questions' sectors and points, a margin around them."""
    pts = [list(p) for p in start_ne_m[:, :2]] + [[v.north_m, v.east_m]
                                                   for v in freeze.vehicles]
    for q in probe.questions:
        pts += [list(c) for c in q.sector] + ([list(q.point)] if q.point else [])
    a = np.asarray(pts, float)
    lo, hi = a.min(axis=0), a.max(axis=0)
    mid, span = (lo + hi) / 2, max(MIN_SPAN_M, float((hi - lo).max()) * (1 + 2 * MARGIN))
    return [round(float(mid[0] - span / 2), 1), round(float(mid[0] + span / 2), 1),
            round(float(mid[1] - span / 2), 1), round(float(mid[1] + span / 2), 1)]


class Freezes:
    """The freeze probes of an app's live sessions (at most one live trial
    per session at a time, as the live console runs them)."""

    def __init__(self, study: Any, store: Any) -> None:
        self.study, self.store = study, store
        #: session id -> (trial index, its run's FreezeProbes, its LiveRun)
        self.trials: dict[str, tuple[int, FreezeProbes, Any]] = {}

    def attach(self, session: dict[str, Any], trial_index: int, live_run: Any) -> None:
        """A live trial's run is about to start: its probes join it (the
        live console's ``on_start`` hook; before its thread starts)."""
        if not self.study.sagat:
            return
        sid = session["id"]
        probes = FreezeProbes(self.study.sagat, live_run.run,
                              on_over=lambda: self._over(sid, trial_index))
        live_run.run.extra_participants.append(probes)
        self.trials[sid] = (trial_index, probes, live_run)

    def current(self, sid: str) -> dict[str, Any] | None:
        """What the session's page asks now: the frozen probe's questions,
        the aircraft to choose from, the blank map's extent; None if not frozen."""
        entry = self.trials.get(sid)
        if entry is None:
            return None
        ti, probes, live_run = entry
        k = probes.frozen
        if k is None or not live_run.running:
            return None
        f = probes.freezes[k]
        return {**sagat_page(self.study, k), "trial_index": ti, "time_s": f.time_s,
                "aircraft": list(probes.ctx.ids),
                "extent_ne_m": blank_map_extent(f, self.study.sagat[k],
                                                probes.ctx.start_ned_m)}

    def asked(self, sid: str, trial_index: int, probe: int) -> bool:
        """Whether that trial of the session was frozen for that probe."""
        entry = self.trials.get(sid)
        return entry is not None and entry[0] == trial_index and probe in entry[1].freezes

    def answered(self, sid: str, trial_index: int, probe: int) -> None:
        """The probe is answered: the trial's run goes on."""
        entry = self.trials.get(sid)
        if entry is not None and entry[0] == trial_index and entry[1].answered(probe):
            log.info("session %s trial %d: probe %d answered; the run goes on", sid,
                     trial_index, probe)

    def freeze_state(self, session: dict[str, Any], trial_index: int, probe: Probe
                     ) -> FreezeState | None:
        """The true state at that freeze (``Instruments.freeze_state``); None
        if the trial was not frozen there, or the probe asks for the last
        target and the run is not over (scored when it is)."""
        entry = self.trials.get(session["id"])
        if entry is None or entry[0] != trial_index:
            return None
        _, probes, live_run = entry
        f = probes.freezes.get(probe.index)
        if f is None:
            return None
        targets: tuple[TargetAt, ...] = ()
        if any(q.kind == "last_target" for q in probe.questions):
            if not probes.over:
                return None
            targets = self._targets(live_run, f.time_s)
        return FreezeState(f.time_s, f.vehicles, targets)

    def _targets(self, live_run: Any, time_s: float) -> tuple[TargetAt, ...]:
        """The scenario's targets with their last sightings by ``time_s`` in
        the trial's feeds (its run's ground truth)."""
        from cosim.trials.live import _targets
        from cosim.trials.live_truth import read_run_truth

        feeds = [f.name for f in live_run.condition.feeds]
        seen = last_sightings(read_run_truth(live_run.out_dir, feeds), time_s,
                              self.study.scoring)
        return tuple(TargetAt(t["id"], t["north_m"], t["east_m"], seen.get(t["id"]))
                     for t in _targets(live_run.run.scn))

    def _over(self, sid: str, trial_index: int) -> None:
        """The trial's run is over (its thread): its probes' answers still
        unscored are scored now."""
        entry = self.trials.get(sid)
        if entry is None or entry[0] != trial_index:
            return
        session = {"id": sid}
        for row in self.store.instrument_answers(sid, "sagat"):
            if row["trial_index"] != trial_index or row.get("scores") is not None:
                continue
            probe = self.study.sagat[row["item"]]
            try:
                state = self.freeze_state(session, trial_index, probe)
                if state is not None:
                    self.store.score_instrument(row["id"],
                                                score_probe(probe, state, row["answer"]))
            except (CosimError, OSError) as e:  # ScoringError: no fuel in the state
                log.warning("session %s trial %d probe %d: not scored: %s", sid, trial_index,
                            row["item"], e)
