"""The scaling figure: the real-time factor, the fraction of the
no-communication ceiling and of the hot-step limit against the number of
aircraft (``cosim bench --plot``, ``benchmarks/scaling_plot.py``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: the right panel's two fractions: line style, and what each means
STYLES = {"fraction_of_ceiling": "o-", "fraction_of_hot_limit": "s--"}
MEANING = {"fraction_of_ceiling": "pool / no-communication ceiling",
           "fraction_of_hot_limit": "pool / hot-step limit (cores x one hot model's rate)"}


def plot_scaling(series: dict[str, list[dict[str, Any]]], path: str | Path,
                 title: str = "") -> None:
    """Real-time factor (left) and the fractions of the no-communication
    ceiling (solid) and of the hot-step limit (dashed, where measured) on
    the right, against the number of aircraft, one colour per series, log
    axes, the 1x line drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cosim.logs.figures import plain_log_axis

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    top = 1.0
    sizes: list[float] = []
    rtfs: list[float] = [1.0]
    for label, rows in series.items():
        n = [r["vehicles"] for r in rows]
        sizes += n
        rtfs += [r["pool_rtf"] for r in rows]
        line, = ax1.plot(n, [r["pool_rtf"] for r in rows], "o-", label=label)
        for key, style in STYLES.items():
            eff = [(r["vehicles"], r[key]) for r in rows if key in r]
            if eff:
                ax2.plot(*zip(*eff), style, color=line.get_color())
                top = max(top, *(e for _, e in eff))
    ax1.axhline(1.0, color="k", lw=1, ls="--", label="real time")
    ax1.set(xscale="log", yscale="log", xlabel="aircraft",
            ylabel="real-time factor (simulated s / wall s)", title="speed")
    plain_log_axis(ax1.xaxis, sizes)
    plain_log_axis(ax1.yaxis, rtfs, own_values=False)
    ax2.axhline(1.0, color="k", lw=1, ls=":")
    for key, style in STYLES.items():  # the colours are the left panel's
        ax2.plot([], [], style, color="grey", label=MEANING[key])
    # above 1 the pool beat its ceiling (a noisy measurement): shown, not clipped
    ax2.set(xscale="log", xlabel="aircraft", ylabel="pool / limit",
            title="efficiency", ylim=(0, max(1.2, top * 1.1)))
    plain_log_axis(ax2.xaxis, sizes)
    # under the panels, clear of the lines
    ax1.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    ax2.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    ax1.grid(True, which="both", alpha=0.3)
    ax2.grid(True, which="both", alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
