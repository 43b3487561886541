"""cosim: lockstep co-simulation of unmanned aircraft swarms.

One JSBSim flight-dynamics model per aircraft, held by a pool of worker
processes (``cosim.fdm_pool``) and advanced in lockstep by a synchronous
scheduler (``cosim.sync``), driven from validated YAML scenarios
(``cosim.scenario``) and logged to ``states.parquet``/``events.jsonl``
(``cosim.logs``).
"""

from cosim.errors import (
    ConfigError,
    CosimError,
    JSBSimError,
    ModelNotFound,
    PoolStateError,
    VehicleError,
    WorkerDied,
    WorkerError,
    WorkerTimeout,
)

__version__ = "0.1.0"


def __getattr__(name: str) -> object:
    """``cosim.run`` (``cosim.api.run``), imported on first use."""
    if name == "run":
        from cosim.api import run

        return run
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")


__all__ = [
    "ConfigError",
    "CosimError",
    "JSBSimError",
    "ModelNotFound",
    "PoolStateError",
    "VehicleError",
    "WorkerDied",
    "WorkerError",
    "WorkerTimeout",
    "__version__",
    "run",
]
