"""Plots of a run: ground track (north/east) and altitude over time, per vehicle.

Reads only the run's ``states.parquet``, ``events.jsonl`` and the obstacles of
``scenario.resolved.yaml`` (drawn grey on the track), as untrusted input
(``cosim.logs.runfolder``); writes a PNG. matplotlib runs headless (Agg).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.logs.runfolder import RunFolder
from cosim.logs.writers import replacing

_MARKED = {"goal_reached": "*", "waypoint_reached": "o", "stall": "x", "ground_impact": "X"}


def plot_run(run_dir: str | Path, png: str | Path | None = None, max_vehicles: int = 50) -> Path:
    """Write ``track.png`` (or ``png``) for the run in ``run_dir``; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = RunFolder(run_dir)
    run = folder.path
    t = folder.states(["tick", "time_s", "vehicle", "north_m", "east_m", "alt_msl_m"])
    vehicle = np.asarray(t["vehicle"].cast("string").to_pylist())
    north, east = t["north_m"].to_numpy(), t["east_m"].to_numpy()
    alt, time_s = t["alt_msl_m"].to_numpy(), t["time_s"].to_numpy()
    ids = list(dict.fromkeys(vehicle.tolist()))[:max_vehicles]
    fig, (ax_map, ax_alt) = plt.subplots(1, 2, figsize=(13, 5.5),
                                         gridspec_kw={"width_ratios": [1.1, 1]})
    for vid in ids:
        m = vehicle == vid
        (line,) = ax_map.plot(east[m], north[m], lw=1.2, label=vid)
        ax_map.plot(east[m][:1], north[m][:1], "^", color=line.get_color(), ms=6)
        ax_alt.plot(time_s[m], alt[m], lw=1.2, color=line.get_color(), label=vid)
    resolved = folder.resolved()
    for poly in resolved.obstacles if resolved else ():
        ax_map.fill([p[1] for p in poly], [p[0] for p in poly], color="0.6", alpha=0.7, lw=0)
    for e in folder.events():
        mark = _MARKED.get(e.kind)
        if mark is None or e.vehicle not in ids:
            continue
        m = (vehicle == e.vehicle) & (t["tick"].to_numpy() <= e.tick)
        if m.any():
            k = np.flatnonzero(m)[-1]
            ax_map.plot(east[k], north[k], mark, color="k", ms=8)
            ax_alt.plot(time_s[k], alt[k], mark, color="k", ms=8)
    ax_map.set_xlabel("east (m)")
    ax_map.set_ylabel("north (m)")
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.grid(alpha=0.3)
    ax_map.set_title(f"ground track ({run.name}); ^ start, * goal, o waypoint, x stall")
    ax_alt.set_xlabel("time (s)")
    ax_alt.set_ylabel("altitude (m, above the WGS-84 ellipsoid)")
    ax_alt.grid(alpha=0.3)
    ax_alt.set_title("altitude")
    if len(ids) <= 12:
        ax_alt.legend(fontsize=8, loc="best")
    fig.tight_layout()
    out = Path(png) if png else run / "track.png"
    with replacing(out, "wb") as f:
        fig.savefig(f, dpi=110, format="png")
    plt.close(fig)
    return out

