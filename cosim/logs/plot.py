"""Plots of a run: where each vehicle went (north/east), and over time the
altitude of the aircraft and the ground speed of the ground vehicles (whose
altitude only follows the ground).

Reads the run folder as untrusted input (``cosim.logs.runfolder``): its
states, ``events.jsonl`` (goals, waypoints, stalls and impacts marked) and
``scenario.resolved.yaml`` (the vehicles' order and classes, the obstacles,
drawn grey on the map); writes a PNG. Every vehicle is drawn unless the
caller chooses (``vehicles``, ``max_vehicles``); the figure's title and the
returned ``Plotted`` say how many were. Each panel's tracks are one
``LineCollection``, so thousands of vehicles draw in seconds. matplotlib
runs headless (Agg).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import ConfigError
from cosim.logs.resolved import RESOLVED
from cosim.logs.runfolder import RunFolder, rows_by_vehicle
from cosim.logs.writers import replacing

#: events marked on the tracks: (marker, what the legend calls it); black,
#: the waypoints' hollow (they are many, and the track shows through)
_MARKED = {"goal_reached": ("*", "goal reached"), "waypoint_reached": ("o", "waypoint reached"),
           "stall": ("x", "stall"), "ground_impact": ("X", "ground impact")}
_HOLLOW = {"waypoint_reached"}
#: up to this many vehicles the legend names each one; more get one entry
LEGEND_VEHICLES = 12
_COLUMNS = ("tick", "time_s", "vehicle", "north_m", "east_m", "alt_msl_m", "vn_mps", "ve_mps")


@dataclass(frozen=True)
class Plotted:
    """What ``plot_run`` drew: ``drawn`` of the run's ``total`` vehicles."""

    path: Path
    drawn: int
    total: int
    how: str  # which ones, e.g. "all", "the first 50 (--max-vehicles 50)"

    def __str__(self) -> str:
        return f"{self.path} ({self.drawn} of {self.total} vehicles drawn: {self.how})"


def choose(ids: Sequence[str], patterns: Sequence[str] | None = None,
           max_vehicles: int | None = None) -> tuple[list[str], str]:
    """The vehicles to draw, in the run's order, and how they were chosen:
    those ``patterns`` name (ids or shell patterns such as ``fleet00*``; all
    when None), at most ``max_vehicles`` of them (the first)."""
    chosen = list(ids)
    how = "all"
    if patterns:
        unmatched = [p for p in patterns if not any(fnmatchcase(v, p) for v in ids)]
        if unmatched:
            shown = ", ".join(ids[:10]) + (f", ... ({len(ids)} in all)" if len(ids) > 10 else "")
            raise ConfigError(f"--vehicles: no vehicle of the run matches "
                              f"{', '.join(map(repr, unmatched))} (its vehicles: "
                              f"{shown or 'none'})")
        chosen = [v for v in ids if any(fnmatchcase(v, p) for p in patterns)]
        how = f"--vehicles {','.join(patterns)}"
    if max_vehicles is not None:
        if max_vehicles < 1:
            raise ConfigError(f"--max-vehicles must be >= 1, got {max_vehicles}")
        if len(chosen) > max_vehicles:
            chosen = chosen[:max_vehicles]
            first = f"the first {max_vehicles}: --max-vehicles {max_vehicles}"
            how = f"{how}, {first}" if patterns else f"{first}, in the scenario's order"
    return chosen, how


def plot_run(run_dir: str | Path, png: str | Path | None = None,
             vehicles: Sequence[str] | None = None, max_vehicles: int | None = None
             ) -> Plotted:
    """Write ``track.png`` (or ``png``) for the run in ``run_dir``: every
    vehicle, or those ``vehicles`` names (ids or patterns), at most
    ``max_vehicles`` (see ``choose``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    folder = RunFolder(run_dir)
    resolved = folder.resolved()
    t = folder.states(_COLUMNS)
    rows = rows_by_vehicle(t)
    listed = [v.id for v in resolved.vehicles if v.id in rows] if resolved else []
    known = set(listed)
    order = listed + [v for v in rows if v not in known]  # in the states, not the scenario
    if not order:
        raise ConfigError(f"{folder.path}: the run logged no states to plot")
    ids, how = choose(order, vehicles, max_vehicles)
    on_ground = {v.id for v in resolved.vehicles if v.on_ground} if resolved else set()
    col = {c: t[c].to_numpy(zero_copy_only=False) for c in _COLUMNS if c != "vehicle"}
    speed = np.hypot(col["vn_mps"], col["ve_mps"])
    air = [v for v in ids if v not in on_ground]
    ground = [v for v in ids if v in on_ground]

    fig = plt.figure(figsize=(14, 7.5))
    right = [p for p in (("air", air), ("ground", ground)) if p[1]]
    grid = fig.add_gridspec(len(right), 2, width_ratios=[1.15, 1])
    ax_map = fig.add_subplot(grid[:, 0])
    panels: dict[str, Any] = {k: fig.add_subplot(grid[i, 1]) for i, (k, _) in enumerate(right)}
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colour = {v: colours[i % len(colours)] for i, v in enumerate(ids)}

    def tracks(ax: Any, which: list[str], x: np.ndarray, y: np.ndarray) -> None:
        ax.add_collection(LineCollection(
            [np.column_stack((x[rows[v]], y[rows[v]])) for v in which],
            colors=[colour[v] for v in which], linewidths=1.1 if len(which) <= 200 else 0.6))
        ax.autoscale_view()

    tracks(ax_map, ids, col["east_m"], col["north_m"])
    first = np.array([rows[v][0] for v in ids])
    ax_map.scatter(col["east_m"][first], col["north_m"][first], marker="^",
                   c=[colour[v] for v in ids], s=30, zorder=3)
    if "air" in panels:
        tracks(panels["air"], air, col["time_s"], col["alt_msl_m"])
    if "ground" in panels:
        tracks(panels["ground"], ground, col["time_s"], speed)
    marked = _mark_events(folder, ids, rows, col["tick"], on_ground)
    for kind, points in marked.items():
        style: dict[str, Any] = {
            "marker": _MARKED[kind][0], "s": 45, "zorder": 4, "linewidths": 1.2,
            **({"facecolors": "none", "edgecolors": "k"} if kind in _HOLLOW else {"c": "k"})}
        k = np.array([r for r, _ in points])
        ax_map.scatter(col["east_m"][k], col["north_m"][k], **style)
        for panel, y in (("air", col["alt_msl_m"]), ("ground", speed)):
            kp = np.array([r for r, g in points if g == (panel == "ground")], dtype=int)
            if kp.size:
                panels[panel].scatter(col["time_s"][kp], y[kp], **style)
    obstacles = resolved.obstacles if resolved else ()
    for poly in obstacles:
        ax_map.fill([p[1] for p in poly], [p[0] for p in poly], color="0.6", alpha=0.7, lw=0)

    ax_map.set_xlabel("east of the origin (m)")
    ax_map.set_ylabel("north of the origin (m)")
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.grid(alpha=0.3)
    ax_map.set_title("ground tracks")
    if "air" in panels:
        ax = panels["air"]
        ax.set_ylabel("altitude (m above the WGS-84 ellipsoid)")
        ax.set_title(f"altitude of the aircraft ({len(air)})" if resolved else
                     f"altitude ({len(air)}; no {RESOLVED} to tell the ground vehicles)")
    if "ground" in panels:
        ax = panels["ground"]
        ax.set_ylabel("ground speed (m/s)")
        ax.set_title(f"speed of the ground vehicles ({len(ground)})")
    for ax in panels.values():
        ax.set_xlabel("simulation time (s)")
        ax.grid(alpha=0.3)

    handles: list[Any]
    if len(ids) <= LEGEND_VEHICLES:
        handles = [Line2D([], [], color=colour[v], lw=1.5, label=v) for v in ids]
    else:
        handles = [Line2D([], [], color="0.4", lw=1.0,
                          label=f"{len(ids)} vehicles, one line each (colours repeat)")]
    handles.append(Line2D([], [], ls="", marker="^", color="0.3", label="start"))
    handles += [Line2D([], [], ls="", marker=_MARKED[k][0], color="k", label=_MARKED[k][1],
                       markerfacecolor="none" if k in _HOLLOW else "k")
                for k in _MARKED if k in marked]
    if obstacles:
        handles.append(Patch(color="0.6", alpha=0.7, label="obstacle"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=9,
               frameon=False)
    rows_legend = -(-len(handles) // 7)
    name = resolved.name if resolved else folder.path.name
    fig.suptitle(f"{name}: {len(ids)} of {len(order)} vehicles drawn ({how})", fontsize=12)
    fig.tight_layout(rect=(0, 0.035 * rows_legend + 0.01, 1, 1))
    out = Path(png) if png else folder.path / "track.png"
    with replacing(out, "wb") as f:
        fig.savefig(f, dpi=110, format="png")
    plt.close(fig)
    return Plotted(out, len(ids), len(order), how)


def _mark_events(folder: RunFolder, ids: list[str], rows: dict[str, np.ndarray],
                 tick: np.ndarray, on_ground: set[str]) -> dict[str, list[tuple[int, bool]]]:
    """Per marked kind: (state row, on the ground) of each event of a drawn
    vehicle: its last state at or before the event's tick."""
    drawn = set(ids)
    out: dict[str, list[tuple[int, bool]]] = {}
    for e in folder.events():
        if e.kind not in _MARKED or e.vehicle is None or e.vehicle not in drawn:
            continue
        r = rows[e.vehicle]
        k = int(np.searchsorted(tick[r], e.tick, side="right")) - 1
        if k >= 0:
            out.setdefault(e.kind, []).append((int(r[k]), e.vehicle in on_ground))
    return out
