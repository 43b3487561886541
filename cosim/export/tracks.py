"""A run's tracks as the exporters write them: each vehicle's samples at
``rate_hz`` (the first logged row of each vehicle in each 1/rate_hz
interval), read from the run folder as untrusted input
(``cosim.logs.runfolder``): samples without a known position or attitude
(NaN) are left out; a value out of range is an error naming its row."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from cosim.errors import ConfigError
from cosim.logs import RunFolder
from cosim.logs.resolved import RESOLVED
from cosim.logs.runfolder import rows_by_vehicle

MAX_RATE_HZ = 1000.0


_COLUMNS = ("time_s", "vehicle", "lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "pitch_deg",
            "yaw_deg")


@dataclass(frozen=True)
class Vehicle:
    """What an export says of one vehicle: its id, model and replay type."""

    id: str
    model: str
    kind: str  # Tacview's object type (the class's ``display_type``)


@dataclass
class Tracks:
    """The sampled states of a run: per vehicle, arrays over its samples."""

    vehicles: list[Vehicle]
    time_s: dict[str, np.ndarray]
    lat: dict[str, np.ndarray]
    lon: dict[str, np.ndarray]
    alt: dict[str, np.ndarray]
    roll: dict[str, np.ndarray]
    pitch: dict[str, np.ndarray]
    yaw: dict[str, np.ndarray]
    origin: tuple[float, float]
    title: str


def load_tracks(run: Path, rate_hz: float = 10.0) -> Tracks:
    """A finished (or recovered) run's tracks sampled at ``rate_hz``; the
    folder is read as untrusted input (``cosim.logs.runfolder``)."""
    folder = RunFolder(run)
    if not folder.has("states.parquet"):
        raise ConfigError(f"{run}: not a cosim run folder (no states.parquet)")
    if not folder.has(RESOLVED):
        raise ConfigError(f"{run}: no {RESOLVED} (run `cosim recover {run}` first if the run "
                          f"was killed)")
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= MAX_RATE_HZ):
        raise ConfigError(f"--rate-hz must be > 0 and at most {MAX_RATE_HZ:g}, got {rate_hz:g}")
    resolved = folder.resolved()
    assert resolved is not None
    table = folder.states(_COLUMNS)
    cols = {c: table[c].to_numpy(zero_copy_only=False).astype(float) for c in _COLUMNS
            if c != "vehicle"}
    rows = rows_by_vehicle(table)
    slot = np.floor(cols["time_s"] * rate_hz + 1e-9)
    known = np.ones(table.num_rows, dtype=bool)  # NaN: not known, left out
    for c in _COLUMNS[2:]:
        known &= np.isfinite(cols[c])
    out: dict[str, dict[str, np.ndarray]] = {k: {} for k in _COLUMNS[2:]}
    times: dict[str, np.ndarray] = {}
    for v in resolved.vehicles:
        r = rows.get(v.id)
        if r is None:
            continue
        s = slot[r]
        keep = r[np.concatenate(([True], s[1:] != s[:-1]))]
        ok = keep[known[keep]]
        if not len(ok):
            continue
        times[v.id] = cols["time_s"][ok]
        for k in _COLUMNS[2:]:
            out[k][v.id] = cols[k][ok]
    if not times:
        raise ConfigError(f"{run}: the run logged no states to export")
    return Tracks([Vehicle(v.id, v.model, v.kind) for v in resolved.vehicles if v.id in times],
                  times, out["lat_deg"], out["lon_deg"], out["alt_msl_m"], out["roll_deg"],
                  out["pitch_deg"], out["yaw_deg"],
                  (resolved.origin_lat_deg, resolved.origin_lon_deg), resolved.name)


def iso(epoch: datetime, t: float) -> str:
    """ISO 8601 UTC with milliseconds."""
    return (epoch + timedelta(seconds=t)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def frames(tr: Tracks) -> Iterator[tuple[float, list[tuple[int, str, int]]]]:
    """(time, [(vehicle index, id, sample index)]) in time order."""
    events = sorted((float(t), k, v.id, j) for k, v in enumerate(tr.vehicles)
                    for j, t in enumerate(tr.time_s[v.id]))
    i = 0
    while i < len(events):
        t = events[i][0]
        group = []
        while i < len(events) and events[i][0] == t:
            group.append(events[i][1:])
            i += 1
        yield t, group
