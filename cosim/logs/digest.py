"""Digests of what a run did: its states and its simulation events, as
SHA-256 over a canonical encoding, so two runs (two backends, two worker
counts, two versions of the code) can be compared bit for bit.

- ``states``: every column of ``states.parquet`` in ``STATE_COLUMNS`` order,
  rows in tick order, vehicles in scenario order; numbers by their exact float64/int bytes,
  text columns by their decoded strings.
- ``events``: every event of ``events.jsonl`` with its fields, except those
  that describe how the run was made rather than what happened (the backend,
  wall-clock figures).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from cosim.logs.runfolder import read_states
from cosim.logs.writers import STATE_COLUMNS

#: event fields that say how a run was made, not what happened in it
_NOT_BEHAVIOUR = {"backend", "workers", "wall_s", "wall_time_s"}


def states_digest(run_dir: str | Path) -> tuple[str, int]:
    """(sha256 hex, rows) of a run's states."""
    table = read_states(run_dir)  # tick order; within a tick, the scenario's vehicle order
    h = hashlib.sha256()
    for name in STATE_COLUMNS:
        col = table[name]
        if pa.types.is_dictionary(col.type) or pa.types.is_string(col.type):
            h.update("\0".join(col.cast("string").to_pylist()).encode())
        else:
            h.update(np.ascontiguousarray(col.to_numpy()).tobytes())
        h.update(b"|")
    return h.hexdigest(), table.num_rows


def events_digest(run_dir: str | Path) -> tuple[str, int]:
    """(sha256 hex, count) of a run's events (see the module docstring)."""
    h = hashlib.sha256()
    n = 0
    for line in (Path(run_dir) / "events.jsonl").read_text().splitlines():
        ev: dict[str, Any] = json.loads(line)
        for key in _NOT_BEHAVIOUR:
            ev.pop(key, None)
        h.update(json.dumps(ev, sort_keys=True).encode() + b"\n")
        n += 1
    return h.hexdigest(), n


def run_digest(run_dir: str | Path) -> dict[str, Any]:
    """Both digests of a run and their sizes."""
    states, rows = states_digest(run_dir)
    events, count = events_digest(run_dir)
    return {"states": states, "rows": rows, "events": events, "event_count": count}
