"""swarm.png: every commanded vehicle's track coloured by its group's phase,
with each group's centroid path (matplotlib, headless Agg)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cosim.swarm.config import SwarmSpec

_PHASE_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple",
                  "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def plot_swarm(path: str | Path, spec: SwarmSpec, group_index: Sequence[np.ndarray],
               ticks: Sequence[int], pos_ned_m: Sequence[np.ndarray],
               phases: Sequence[Sequence[int]], physics_hz: float, title: str = "") -> Path:
    """Write the plot; ``pos_ned_m[k]`` (n, 3) and ``phases[k]`` (per group) at ``ticks[k]``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    out = Path(path)
    pos = np.asarray(pos_ned_m, dtype=np.float64)  # (T, n, 3)
    ph = np.asarray(phases, dtype=np.int64).reshape(len(pos), -1)  # (T, groups)
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=90)
    legend: dict[str, Line2D] = {}
    # one colour per (group, phase), across groups
    offset = np.cumsum([0] + [len(g.phases) for g in spec.groups])
    for gi, (g, idx) in enumerate(zip(spec.groups, group_index)):
        if len(pos) < 2:
            break
        for k in idx.tolist():
            e, n = pos[:, k, 1] / 1000.0, pos[:, k, 0] / 1000.0
            seg = np.stack([np.stack([e[:-1], n[:-1]], 1), np.stack([e[1:], n[1:]], 1)], 1)
            colours = [_PHASE_COLOURS[(offset[gi] + p) % len(_PHASE_COLOURS)] if p >= 0
                       else "0.7" for p in ph[1:, gi]]
            ax.add_collection(LineCollection(list(seg), colors=colours, linewidths=0.8))
            ax.plot(e[0], n[0], "o", ms=2.5, color="0.3")
        c = pos[:, idx, :2].mean(axis=1) / 1000.0
        ax.plot(c[:, 1], c[:, 0], "--", color="k", lw=1.2)
        ax.plot(c[-1, 1], c[-1, 0], "x", color="k", ms=6)
        for p_i, phase in enumerate(g.phases):
            label = f"{g.name} {p_i}: {phase.behaviour}" if len(spec.groups) > 1 \
                else f"{p_i}: {phase.behaviour}"
            legend[label] = Line2D([], [], color=_PHASE_COLOURS[
                (offset[gi] + p_i) % len(_PHASE_COLOURS)])
    legend["after the last phase"] = Line2D([], [], color="0.7")
    legend["centroid"] = Line2D([], [], color="k", ls="--")
    ax.autoscale()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    t_end = ticks[-1] / physics_hz if len(ticks) else 0.0
    ax.set_title(f"{title} swarm tracks by phase ({t_end:.0f} s)".strip())
    ax.legend(legend.values(), legend.keys(), fontsize=7, loc="best")
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
