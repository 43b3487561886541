"""The live sessions' figures: one a condition (``live_<condition>.png``),
detection probability on the left and detection latency on the right, each
level's estimate with its interval, the slope and its interval in the
panel's title for a numeric condition. ``live_tasking.png``: the operator's
commands from the map a minute against the first ``MAX_TASKING_PANELS``
conditions, a panel each, drawn the same way.

Table rows in (``live_analysis.live_tables``), a PNG out: it computes no
statistic and reads nothing. matplotlib (Agg), imported when drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.figures import _pyplot

#: the conditions the tasking figure draws, a panel each
MAX_TASKING_PANELS = 3
_LATENCIES = (("latency_any_s", "from first visible in any feed", "C0", "o"),
              ("latency_feed_s", "from first visible in the clicked feed", "C1", "s"))


def _slope_text(effects: Sequence[dict[str, Any]], measure: str, fmt: str) -> str:
    for e in effects:
        if e["measure"] == measure and np.isfinite(e["slope"]):
            return (f"slope {e['slope']:{fmt}} [{e['ci_lo']:{fmt}}, {e['ci_hi']:{fmt}}]")
    return ""


def plot_condition(path: Path, name: str, levels: Sequence[dict[str, Any]],
                   effects: Sequence[dict[str, Any]], level: float = 0.95) -> None:
    """Detection probability and latency against one condition's levels."""
    plt = _pyplot()
    keys, x_of, numeric = _levels_x(levels)
    span = (max(x_of.values()) - min(x_of.values())) if keys else 0.0
    nudge = 0.012 * span if numeric else 0.08
    pct = f"{100 * level:g}%"
    fig, (ax_d, ax_l) = plt.subplots(1, 2, figsize=(10, 4))

    def draw(ax: Any, measure: str, label: str, colour: str, marker: str, dx: float) -> None:
        rs = [r for r in levels if r["measure"] == measure and r["targets"]]
        if not rs:
            return
        x = np.array([x_of[r["level"]] + dx for r in rs])
        y = np.array([r["estimate"] for r in rs], dtype=float)
        lo = np.array([r["ci_lo"] for r in rs], dtype=float)
        hi = np.array([r["ci_hi"] for r in rs], dtype=float)
        err = np.nan_to_num(np.array([y - lo, hi - y]))
        ax.errorbar(x, y, yerr=err, fmt=marker + ("-" if numeric else ""), color=colour,
                    capsize=3, label=label)

    draw(ax_d, "detected", f"targets detected, {pct} interval", "C2", "o", 0.0)
    ax_d.set_ylim(-0.02, 1.02)
    ax_d.set_ylabel("detection probability")
    ax_d.set_title(_slope_text(effects, "detected", ".3f") and
                   f"detection: {_slope_text(effects, 'detected', '.3f')} per unit of {name}",
                   fontsize=9)
    for i, (measure, label, colour, marker) in enumerate(_LATENCIES):
        draw(ax_l, measure, label, colour, marker, (i - 0.5) * nudge)
    ax_l.set_ylabel(f"latency of first hit (s): mean, {pct} interval")
    ax_l.set_ylim(bottom=0)
    ax_l.set_title(_slope_text(effects, "latency_any_s", ".2f") and
                   f"latency (any feed): {_slope_text(effects, 'latency_any_s', '.2f')} "
                   f"s per unit of {name}", fontsize=9)
    for ax in (ax_d, ax_l):
        _x_axis(ax, name, keys, x_of, numeric)
    if not levels:
        ax_d.text(0.5, 0.5, "no targets", ha="center", va="center", transform=ax_d.transAxes)
    how = sorted({r["interval"] for r in levels if r["targets"]})
    fig.suptitle(f"Live sessions against {name}" + (f" (intervals: {', '.join(how)})"
                                                    if how else ""), fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _levels_x(levels: Sequence[dict[str, Any]]) -> tuple[list[Any], dict[Any, float], bool]:
    """(the levels in order, each one's x, whether they are numbers)."""
    keys = list(dict.fromkeys(r["level"] for r in levels))
    numeric = all(isinstance(k, float) for k in keys)
    return keys, {k: (float(k) if numeric else float(i)) for i, k in enumerate(keys)}, numeric


def _x_axis(ax: Any, name: str, keys: list[Any], x_of: dict[Any, float],
            numeric: bool) -> None:
    """A panel's x axis: the condition's levels, its legend and grid."""
    ax.set_xlabel(name)
    if not numeric:
        ax.set_xticks([x_of[k] for k in keys])
        ax.set_xticklabels([str(k) for k in keys], rotation=20, fontsize=8)
        ax.set_xlim(-0.6, len(keys) - 0.4)
    elif keys:
        ax.set_xticks([x_of[k] for k in keys])
        ax.set_xticklabels([f"{k:g}" for k in keys], fontsize=8)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)


def plot_tasking(path: Path, levels: Sequence[dict[str, Any]],
                 effects: Sequence[dict[str, Any]], level: float = 0.95) -> None:
    """The commands a minute (mean and interval at each level) against the
    first ``MAX_TASKING_PANELS`` conditions of ``levels`` (``live_analysis.
    tasking_tables``' rows), the slope in each panel's title."""
    plt = _pyplot()
    rows = [r for r in levels if r["measure"] == "commands_per_min"]
    names = list(dict.fromkeys(r["condition"] for r in rows))[:MAX_TASKING_PANELS] or ["-"]
    fig, axes = plt.subplots(1, len(names), figsize=(max(6.4, 4.2 * len(names) + 0.8), 4.0),
                             squeeze=False)
    pct = f"{100 * level:g}%"
    for ax, name in zip(axes[0], names):
        mine = [r for r in rows if r["condition"] == name and r["targets"]]
        keys, x_of, numeric = _levels_x(mine)
        if mine:
            y = np.array([r["estimate"] for r in mine], dtype=float)
            err = np.nan_to_num(np.array([y - np.array([r["ci_lo"] for r in mine], float),
                                          np.array([r["ci_hi"] for r in mine], float) - y]))
            ax.errorbar([x_of[r["level"]] for r in mine], y, yerr=err,
                        fmt="o" + ("-" if numeric else ""), color="C4", capsize=3,
                        label=f"mean, {pct} interval")
        else:
            ax.text(0.5, 0.5, "no trials", ha="center", va="center", transform=ax.transAxes)
        slope = _slope_text([e for e in effects if e["condition"] == name],
                            "commands_per_min", ".2f")
        ax.set_title(slope and f"{slope} commands a minute per unit of {name}", fontsize=9)
        ax.set_ylabel("commands from the map a minute")
        ax.set_ylim(bottom=0)
        _x_axis(ax, name, keys, x_of, numeric)
    how = sorted({r["interval"] for r in rows if r["targets"]})
    fig.suptitle("The operator's tasking: commands from the map a minute of each trial" +
                 (f"\n(intervals: {', '.join(how)})" if how else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
