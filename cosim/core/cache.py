"""Where cosim keeps what it can make again (one rule, for every part):
``$COSIM_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/cosim``, else
``~/.cache/cosim``. Its folders: ``wrapped/`` (aircraft with the cosim
autopilot attached), ``ground/`` (procedural ground tiles; ``COSIM_GROUND_CACHE
=off`` keeps none), ``signing/`` (MAVLink signing timestamps: replay
protection, not a cache to delete while runs use the key), ``fused/`` (the
rigid-body tier's generated numba loops). Deleting the rest
only costs the time to make it again."""

from __future__ import annotations

import os
from pathlib import Path

#: the environment variable that moves every cache folder
CACHE_ENV = "COSIM_CACHE_DIR"


def cache_folder(*parts: str) -> Path:
    """The cache folder (see the module docstring), joined with ``parts``."""
    env = os.environ.get(CACHE_ENV)
    if env:
        root = Path(env)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        root = (Path(xdg) if xdg else Path.home() / ".cache") / "cosim"
    return root.joinpath(*parts)
