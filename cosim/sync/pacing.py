"""Wall-clock pacing: a thin layer over the tick loop.

``Pacer(factor)`` holds simulation time to ``factor`` x wall time. It never
drifts silently: every paced tick records how late it finished relative to
its deadline, and ``stats()`` reports p50/p99/max lateness and the number
of overruns. A run too slow for real time runs as fast as it can and
catches up when it can (the deadline is absolute, not per tick).
``hold()`` and ``release()`` stop its clock while a run is paused: the
pause is neither lateness nor time to catch up.
"""

from __future__ import annotations

import time

import numpy as np


class Pacer:
    def __init__(self, factor: float) -> None:
        if not factor > 0:
            raise ValueError(f"real-time factor must be > 0, got {factor}")
        self.factor = float(factor)
        self._t0: float | None = None
        self._late: list[float] = []
        self._held: float | None = None

    def start(self) -> None:
        self._t0 = time.monotonic()

    def hold(self) -> None:
        """Stop the clock (a paused run): deadlines move on by the time held."""
        if self._held is None:
            self._held = time.monotonic()

    def release(self) -> None:
        """Start the clock again after ``hold``."""
        if self._held is not None and self._t0 is not None:
            self._t0 += time.monotonic() - self._held
        self._held = None

    def pace(self, sim_time_s: float) -> float:
        """Call after finishing the tick that ends at ``sim_time_s``: records its
        lateness, then sleeps until its deadline if early. Returns lateness (s)."""
        if self._t0 is None:
            self.start()
        assert self._t0 is not None
        deadline = self._t0 + sim_time_s / self.factor
        late = time.monotonic() - deadline
        self._late.append(late)
        if late < 0:
            time.sleep(-late)
        return late

    def stats(self) -> dict[str, float | int]:
        if not self._late:
            return {"factor": self.factor, "ticks": 0}
        a = np.maximum(np.asarray(self._late), 0.0) * 1e3
        return {
            "factor": self.factor,
            "ticks": int(a.size),
            "lateness_ms_p50": float(np.percentile(a, 50)),
            "lateness_ms_p99": float(np.percentile(a, 99)),
            "lateness_ms_max": float(a.max()),
            "overruns": int(np.count_nonzero(a > 0)),
        }
