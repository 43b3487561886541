"""The ``ray`` backend's agent: one machine's share of the vehicles.

An agent is a Ray actor (the pool makes the class one, on the machine it
picks) that runs an ordinary ``process`` pool over its share, in shared
memory as on one machine, and steps it on the driver's call: one call per
exchange, its setpoints out and its states back (beside each state row the
columns ``cosim.vehicles.resume`` needs to rebuild it elsewhere). What an
agent raised, or why Ray says it is gone, is read back here for the driver.

It knows only its own share: which machine it runs on, the other agents,
and rebuilding after a fault are the pool's (``ray_cluster``); it never
imports Ray.
"""

from __future__ import annotations

import os
import socket
from typing import Any

import numpy as np

from cosim.core.state import StateField, VehicleSpec
from cosim.errors import CosimError
from cosim.fdm_pool.base import Watch
from cosim.fdm_pool.process import ProcessPool


class Agent:
    """One machine's share: a ``process`` pool in the agent's own process
    (a Ray actor), stepped on the driver's call."""

    def __init__(self) -> None:
        self.pool: ProcessPool | None = None

    def build(self, specs: list[VehicleSpec], dt_s: float, channels: tuple[str, ...],
              workers: int, layout: tuple[StateField, ...], tick: int,
              setpoints: np.ndarray | None,
              watch: Watch | None = None) -> tuple[np.ndarray, int, str]:
        """Build ``specs`` (trimmed, or as they were: ``VehicleSpec.resume``);
        ``setpoints`` (a rebuild): written before the first exchange. Returns
        the states, this process's pid and host."""
        self.pool = ProcessPool(specs, dt_s, channels, workers=workers, driver_steps=True,
                                layout=layout, watch=watch)
        self.pool.tick = tick
        if setpoints is not None:
            self.pool.setpoints[:] = setpoints
        return self.pool.states.copy(), os.getpid(), socket.gethostname()

    def step(self, setpoints: np.ndarray | None, nsub: int
             ) -> tuple[np.ndarray, list[float], np.ndarray | None]:
        """One exchange: the states, each worker's busy time, the watched rows."""
        assert self.pool is not None
        if setpoints is not None:
            keep = np.isnan(setpoints)  # NaN leaves a value written at a rebuild
            self.pool.setpoints[~keep] = setpoints[~keep]
        states = self.pool.step(nsub)
        watched = (self.pool.watched[:self.pool.watched_count].copy()
                   if self.pool.watch is not None else None)
        return states.copy(), self.pool.busy_s(), watched

    def worker_pids(self) -> list[int]:
        assert self.pool is not None
        return list(self.pool.pids.values())

    def stop(self) -> None:
        if self.pool is not None:
            self.pool.close()  # its worker processes stopped and reaped
            self.pool = None


def remote_cause(e: Any) -> BaseException:
    """The exception raised inside an agent (a ``CosimError`` as it was)."""
    cause = getattr(e, "cause", None)
    if isinstance(cause, CosimError):
        return cause
    return CosimError(f"the ray backend's agent failed: {e}")


def why_lost(e: Exception) -> str:
    """Ray's word on why an actor is gone, in one line."""
    text = str(e)
    for key in ("Worker exit detail:", "The actor is dead because"):
        if key in text:
            return text.split(key, 1)[1].strip().split(". ")[0]
    return text.strip().splitlines()[0] if text.strip() else type(e).__name__
