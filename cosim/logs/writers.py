"""State, event and summary writers (see the package docstring)."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from cosim.fdm_pool.spec import STATE_INDEX
from cosim.geo import LocalFrame

#: the columns of states.parquet, in order
STATE_COLUMNS: tuple[str, ...] = (
    "tick", "time_s", "vehicle", "lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m",
    "north_m", "east_m", "down_m", "roll_deg", "pitch_deg", "yaw_deg",
    "vn_mps", "ve_mps", "vd_mps", "airspeed_mps", "alpha_deg", "throttle",
    "bank_limit_deg", "ap_engaged", "stalled", "stall_protection_active", "command", "status",
)
_FROM_STATE = ("lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m", "roll_deg", "pitch_deg",
               "yaw_deg", "vn_mps", "ve_mps", "vd_mps", "airspeed_mps", "alpha_deg", "throttle",
               "bank_limit_deg", "ap_engaged", "stalled", "stall_protection_active")
_FLAGS = ("ap_engaged", "stalled", "stall_protection_active", "status")


def _schema() -> pa.Schema:
    fields = []
    for c in STATE_COLUMNS:
        if c == "tick":
            fields.append(pa.field(c, pa.int64()))
        elif c in ("vehicle", "command"):
            fields.append(pa.field(c, pa.dictionary(pa.int32(), pa.string())))
        elif c in _FLAGS:
            fields.append(pa.field(c, pa.int8()))
        else:
            fields.append(pa.field(c, pa.float64()))
    return pa.schema(fields)


class StateLog:
    """Buffers logged rows and writes them as complete parquet parts.

    A part is written when ``flush_rows`` rows are buffered or ``flush_s``
    seconds of wall time have passed since the last part, and on ``close``.
    """

    def __init__(self, folder: Path, ids: list[str], frame: LocalFrame, physics_hz: float,
                 flush_rows: int = 200_000, flush_s: float = 5.0) -> None:
        self.dir = Path(folder)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.ids = pa.array(ids, pa.string())
        self.n = len(ids)
        self.frame = frame
        self.physics_hz = physics_hz
        self.flush_rows = flush_rows
        self.flush_s = flush_s
        self.schema = _schema()
        self._ticks: list[int] = []
        self._rows: list[np.ndarray] = []
        self._labels: list[str] = []
        self._parts = 0
        self._last_flush = time.monotonic()
        self.rows_written = 0
        self._cols = [STATE_INDEX[c] for c in _FROM_STATE]
        self._closed = False

    def append(self, tick: int, states: np.ndarray, commands: list[str] | None = None) -> None:
        """Buffer one logged tick (copies ``states``); ``commands``: each
        vehicle's active command, for the ``command`` column."""
        self._ticks.append(tick)
        self._rows.append(states[:, self._cols + [STATE_INDEX["status"]]].copy())
        self._labels.extend(commands if commands is not None else [""] * self.n)
        buffered = len(self._rows) * self.n
        if buffered >= self.flush_rows or time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        if not self._rows:
            return
        block = np.concatenate(self._rows)  # (ticks*n, k)
        ticks = np.repeat(np.asarray(self._ticks, dtype=np.int64), self.n)
        vehicle = pa.DictionaryArray.from_arrays(
            pa.array(np.tile(np.arange(self.n, dtype=np.int32), len(self._ticks))), self.ids)
        cols: dict[str, Any] = {"tick": ticks, "time_s": ticks / self.physics_hz,
                                "vehicle": vehicle}
        for j, name in enumerate(_FROM_STATE):
            cols[name] = block[:, j]
        north, east, down = self.frame.geodetic_to_ned(cols["lat_deg"], cols["lon_deg"],
                                                        cols["alt_msl_m"])
        cols["north_m"], cols["east_m"], cols["down_m"] = north, east, down
        for c in _FLAGS[:-1]:
            cols[c] = cols[c].astype(np.int8)
        cols["status"] = block[:, -1].astype(np.int8)
        cols["command"] = pa.array(self._labels, pa.string()).dictionary_encode()
        table = pa.table([cols[c] for c in STATE_COLUMNS], schema=self.schema)
        final = self.dir / f"part-{self._parts:06d}.parquet"
        tmp = final.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, final)
        self._parts += 1
        self.rows_written += table.num_rows
        self._ticks, self._rows, self._labels = [], [], []
        self._last_flush = time.monotonic()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.flush()


def read_states(folder: str | Path) -> pa.Table:
    """Read a run's ``states.parquet`` (a file or a parts folder) as one table."""
    p = Path(folder)
    if p.is_dir() and (p / "states.parquet").exists():
        p = p / "states.parquet"
    if p.is_dir():
        parts = sorted(p.glob("part-*.parquet"))
        if not parts:
            return _schema().empty_table()
        return pa.concat_tables([pq.read_table(x) for x in parts])
    return pq.read_table(p)


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (np.floating, np.integer)):
        return _jsonable(v.item())
    return v


class EventLog:
    """``events.jsonl``: one object per line, written and flushed as it happens."""

    def __init__(self, path: Path, physics_hz: float) -> None:
        self.path = Path(path)
        self.physics_hz = physics_hz
        self._f = open(self.path, "a", buffering=1)  # noqa: SIM115 - closed in close()
        self.counts: dict[str, int] = {}

    def emit(self, kind: str, tick: int, vehicle: str | None = None, **fields: Any) -> None:
        rec = {"event": kind, "tick": tick, "time_s": tick / self.physics_hz,
               "vehicle": vehicle}
        rec.update({k: _jsonable(v) for k, v in fields.items()})
        self._f.write(json.dumps(rec) + "\n")
        self._f.flush()
        self.counts[kind] = self.counts.get(kind, 0) + 1

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()


def write_json_atomic(path: Path, data: Any) -> None:
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=_jsonable) + "\n")
    os.replace(tmp, path)
