"""sync: the lockstep tick loop and wall-clock pacing.

Owns simulation time (integer physics ticks), the order of work inside a
tick and when a run stops. It steps vehicles only through an ``fdm_pool``
pool and writes only through ``cosim.logs``.
"""

from cosim.sync.pacing import Pacer
from cosim.sync.runner import Run, RunResult, run_scenario

__all__ = ["Pacer", "Run", "RunResult", "run_scenario"]
