"""Safety and per-phase metrics of a swarm run.

``SwarmMonitor.update(tick, pos_ned_m)`` takes the commanded vehicles'
positions (local NED metres) at every exchange: the in-process participant
gives the ground truth (the state array), ``cosim swarm --connect`` the
telemetry it received (it has nothing else). It keeps

- the minimum separation, 3-D and horizontal, with the closest pair and
  when, at every exchange (``swarm_separation.csv``) and over the run
  (the summary); a ``swarm_separation`` event when the 3-D closest pair drops below
  ``separation_warn_m`` (and one when it is clear again);
- per phase (from the controller's ``swarm_phase`` events): minimum
  separation inside the group, distance travelled per vehicle, spread
  (largest and mean distance to the group centroid) at the end;
- a track sample at every controller step, for the plot.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.swarm.config import SwarmSpec


class SwarmMonitor:
    def __init__(self, spec: SwarmSpec, ids: Sequence[str], group_index: Sequence[np.ndarray],
                 physics_hz: float) -> None:
        self.spec = spec
        self.ids = list(ids)
        self.group_index = [np.sort(np.asarray(g)) for g in group_index]
        self.hz = float(physics_hz)
        n = len(self.ids)
        self.prev: np.ndarray | None = None
        self.travelled_m = np.zeros(n)
        self.min3 = (float("inf"), -1, -1, 0)  # distance, i, j, tick
        self.minh = (float("inf"), -1, -1, 0)
        self.below = False
        self.warnings = 0
        #: per group: the open phase's accumulators, and the closed phases
        self.open: list[dict[str, Any] | None] = [None] * len(self.group_index)
        self.closed: list[list[dict[str, Any]]] = [[] for _ in self.group_index]
        self.track_ticks: list[int] = []
        self.track_pos: list[np.ndarray] = []
        self.track_phase: list[list[int]] = []  # per sample, per group: phase (-1: none)
        self.events: list[tuple[str, int, dict[str, Any]]] = []
        self._mask: np.ndarray | None = None
        #: every exchange: tick, closest 3-D distance, its pair (indices), closest horizontal
        self.separation_log: list[tuple[int, float, int, int, float]] = []

    def _upper(self, n: int) -> np.ndarray:
        """0 above the diagonal, inf on and below it (each pair once, no self-pairs)."""
        if self._mask is None or len(self._mask) != n:
            self._mask = np.where(np.triu(np.ones((n, n), dtype=bool), k=1), 0.0, np.inf)
        return self._mask

    def update(self, tick: int, pos_ned_m: np.ndarray) -> None:
        pos = np.asarray(pos_ned_m, dtype=np.float64)
        if np.isnan(pos).any():
            return
        if self.prev is not None:
            step = np.linalg.norm(pos - self.prev, axis=1)
            self.travelled_m += step
            for o, gi in zip(self.open, self.group_index):
                if o is not None:
                    o["travelled"] += step[gi]
        self.prev = pos
        if len(pos) < 2:
            return
        # one (n, n) pass per axis gives both distances (broadcasting by column is
        # several times faster than gathering the pairs' rows)
        n = len(pos)
        x, y, z = (np.ascontiguousarray(pos[:, c]) for c in range(3))
        dx = x[:, None] - x[None, :]
        h2 = dx * dx
        dx = y[:, None] - y[None, :]
        h2 += dx * dx
        h2 += self._upper(n)
        dx = z[:, None] - z[None, :]
        d2 = dx * dx
        d2 += h2
        i, j = divmod(int(np.argmin(d2)), n)
        d3 = float(np.sqrt(d2[i, j]))
        if d3 < self.min3[0]:
            self.min3 = (d3, i, j, tick)
        hi, hj = divmod(int(np.argmin(h2)), n)
        dh = float(np.sqrt(h2[hi, hj]))
        self.separation_log.append((tick, d3, i, j, dh))
        if dh < self.minh[0]:
            self.minh = (dh, hi, hj, tick)
        warn = self.spec.separation_warn_m
        if d3 < warn and not self.below:
            self.below = True
            self.warnings += 1
            self.events.append(("swarm_separation", tick, {
                "state": "below", "distance_m": d3, "threshold_m": warn,
                "pair": [self.ids[i], self.ids[j]]}))
        elif d3 >= warn and self.below:
            self.below = False
            self.events.append(("swarm_separation", tick, {
                "state": "clear", "distance_m": d3, "threshold_m": warn}))
        for o, gi in zip(self.open, self.group_index):
            if o is None or len(gi) < 2:
                continue
            # rows in ascending order: the group's block keeps the upper-triangle mask
            if len(gi) == n:  # the whole swarm: the run's closest pairs
                g3, pa, pb, gh = d3, i, j, dh
            else:
                g2 = d2[np.ix_(gi, gi)]
                a, b = divmod(int(np.argmin(g2)), len(gi))
                g3, pa, pb = float(np.sqrt(g2[a, b])), int(gi[a]), int(gi[b])
                gh = float(np.sqrt(h2[np.ix_(gi, gi)].min()))
            if g3 < o["min3"][0]:
                o["min3"] = (g3, pa, pb, tick)
            o["minh"] = min(o["minh"], gh)
        if tick % self.spec.every_ticks == 0:
            self.track_ticks.append(tick)
            self.track_pos.append(pos.copy())
            self.track_phase.append([-1 if o is None else int(o["phase"]) for o in self.open])

    def phase_event(self, tick: int, fields: dict[str, Any]) -> None:
        """Take one of the controller's ``swarm_phase`` events."""
        names = [g.name for g in self.spec.groups]
        gi = names.index(fields["group"])
        if fields["state"] == "start":
            self.open[gi] = {"phase": fields["phase"], "behaviour": fields["behaviour"],
                             "start_tick": tick, "travelled": np.zeros(len(self.group_index[gi])),
                             "min3": (float("inf"), -1, -1, tick), "minh": float("inf")}
            return
        o = self.open[gi]
        self.open[gi] = None
        if o is None:
            return
        idx = self.group_index[gi]
        rec: dict[str, Any] = {
            "phase": o["phase"], "behaviour": o["behaviour"], "reason": fields.get("reason"),
            "start_s": o["start_tick"] / self.hz, "end_s": tick / self.hz,
            "time_s": (tick - o["start_tick"]) / self.hz,
            "min_separation_3d_m": _finite(o["min3"][0]),
            "min_separation_horizontal_m": _finite(o["minh"]),
            "closest_pair": ([self.ids[o["min3"][1]], self.ids[o["min3"][2]]]
                             if o["min3"][1] >= 0 else None),
            "distance_travelled_m": {self.ids[k]: round(float(v), 1)
                                     for k, v in zip(idx.tolist(), o["travelled"])},
        }
        if self.prev is not None:
            p = self.prev[idx, :2]
            d = np.hypot(*(p - p.mean(axis=0)).T)
            rec["final_spread_max_m"] = float(d.max())
            rec["final_spread_mean_m"] = float(d.mean())
        self.closed[gi].append(rec)

    def summary(self) -> dict[str, Any]:
        def pair(m: tuple[float, int, int, int]) -> dict[str, Any] | None:
            if m[1] < 0:
                return None
            return {"distance_m": m[0], "pair": [self.ids[m[1]], self.ids[m[2]]],
                    "t_s": m[3] / self.hz}

        return {
            "min_separation_3d": pair(self.min3),
            "min_separation_horizontal": pair(self.minh),
            "separation_warn_m": self.spec.separation_warn_m,
            "separation_warnings": self.warnings,
            "distance_travelled_m": {k: round(float(v), 1)
                                     for k, v in zip(self.ids, self.travelled_m)},
            "phases": {g.name: self.closed[gi] for gi, g in enumerate(self.spec.groups)},
        }

    def write_separation_csv(self, path: Path) -> None:
        """The closest pair at every exchange: ``swarm_separation.csv``."""
        with open(path, "w") as f:
            f.write("tick,t_s,min_separation_3d_m,vehicle_a,vehicle_b,"
                    "min_separation_horizontal_m\n")
            for tick, d3, i, j, dh in self.separation_log:
                f.write(f"{tick},{tick / self.hz:.4f},{d3:.3f},{self.ids[i]},{self.ids[j]},"
                        f"{dh:.3f}\n")

    def drain_events(self) -> list[tuple[str, int, dict[str, Any]]]:
        ev, self.events = self.events, []
        return ev


def _finite(x: float) -> float | None:
    return x if np.isfinite(x) else None
