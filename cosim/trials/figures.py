"""The trials analysis' figures: critical_gap.png (a panel a critical-gap fit,
at most ``MAX_PANELS``, those with a critical gap first: ``shown_first``) and
recognition.png (accuracy against each factor).

Fits and table rows in, PNG files out: it computes no statistic but a level's
mean interval for its error bar, and reads nothing. matplotlib (Agg),
imported when a figure is drawn.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.conditions import MAX_LEVELS
from cosim.trials.critical_gap_fits import GapData
from cosim.trials.estimates import mean_ci

#: panels of critical_gap.png (the fits with a critical gap first); every fit
#: is in critical_gap.csv
MAX_PANELS = 12

#: the order in which figures and print-outs show fits: a critical gap first
_SHOWN_FIRST = ("plateau", "plateau_from_start", "no_plateau", "inconclusive",
                "insufficient_data")


def shown_first(statuses: Sequence[str]) -> list[int]:
    """Indices of fits (by their ``GapFit.status``) in the order figures and
    print-outs show them: those with a critical gap first, then those
    without one, then those without enough data; the fits' own order within
    each."""
    rank = {st: i for i, st in enumerate(_SHOWN_FIRST)}
    return sorted(range(len(statuses)), key=lambda i: rank.get(statuses[i], len(rank)))


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_critical_gap(path: Path, all_fits: list[GapData]) -> int:
    """One panel a fit: the trials' gaps, level means with 95 % intervals and
    the two-segment fit (dotted when it was rejected). At most ``MAX_PANELS``
    panels, the fits with a critical gap first (``shown_first``); a line at
    the foot says how many were left out. Returns the panels drawn."""
    plt = _pyplot()
    fits = [all_fits[i] for i in shown_first([gf.fit.status for gf in all_fits])[:MAX_PANELS]]
    n = max(len(fits), 1)
    cols = min(n, 2 if n <= 4 else 3)
    rows = math.ceil(n / cols)
    left_out = len(all_fits) - len(fits)
    foot = 0.35 if left_out else 0.0  # inches for the line saying what was left out
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 3.8 * rows + foot),
                             squeeze=False)
    flat = list(axes.ravel())
    if not fits:
        flat[0].text(0.5, 0.5, "no conspicuity responses with a varied viewing distance "
                     "or altitude", ha="center", va="center", fontsize=8)
    for ax in flat[len(fits) if fits else 1:]:
        ax.set_axis_off()
    for ax, gf in zip(flat, fits):
        f, u = gf.fit, gf.fit.unit
        symbol, angle = ("d", "alpha") if u == "mm" else ("h", "beta")
        g = gf.g
        ax.plot(gf.x, g, ".", color="0.6", ms=3, label="trials")
        xr = np.round(gf.x / f.round_to) * f.round_to
        lv = np.unique(xr)
        stats = [mean_ci(g[xr == v]) for v in lv]
        mu = np.array([st[0] for st in stats])
        err = np.array([[st[0] - st[1], st[2] - st[0]] for st in stats]).T
        ax.errorbar(lv, mu, yerr=np.nan_to_num(err), fmt="o", color="C0", capsize=3,
                    label="mean, 95% CI")
        if f.breakpoint is not None and f.fit_level is not None:
            xs = np.linspace(lv[0], lv[-1], 200)
            ys = f.fit_level + (f.rising_slope or 0.0) * np.minimum(xs - f.breakpoint, 0)
            ax.plot(xs, ys, "-" if f.cg is not None else ":",
                    color="C3" if f.cg is not None else "C1",
                    label="two-segment fit" if f.cg is not None
                    else "best two-segment fit (rejected)")
        if f.cg is not None and f.threshold is not None:
            ax.axhline(f.cg, color="C3", ls=":", lw=1, label=f"CG = {f.cg:.3g} {u}")
            ax.axvline(f.threshold, color="C3", ls="--", lw=1,
                       label=f"{symbol}0 = {f.threshold:.0f} {u}")
        ax.set_title(f"{gf.label}: {f.status}", fontsize=10)
        ax.set_xlabel(f"{f.variable} ({u})")
        ax.set_ylabel(f"tan({angle}) * {symbol} ({u})")
        ax.legend(fontsize=7, loc="lower right")
    height = 3.8 * rows + foot
    if left_out:
        fig.text(0.5, 0.12 / height, f"{len(fits)} of {len(all_fits)} fits shown, those with "
                 f"a critical gap first; {left_out} more in critical_gap.csv", ha="center",
                 va="bottom", fontsize=9, color="C3")
    fig.tight_layout(rect=(0.0, foot / height, 1.0, 1.0))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return len(fits)


def plot_recognition(path: Path, rows: list[dict[str, Any]]) -> None:
    """A panel a factor: accuracy with its Wilson interval at each level."""
    plt = _pyplot()
    by: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by.setdefault(row["factor"], []).append(row)
    titles = {"alt_agl_m": "altitude AGL (m)", "speed_kt": "speed (kt)", "target": "target",
              "angular_size_bin_deg": "target angular size (deg)",
              "eccentricity_bin_deg": "eccentricity (deg)"}
    n = max(len(by), 1)
    cols = min(n, 3)
    nrows = math.ceil(n / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.3 * cols, 3.4 * nrows), squeeze=False)
    flat = list(axes.ravel())
    if not by:
        flat[0].text(0.5, 0.5, "no 'recognise' responses", ha="center", va="center")
    for ax, (factor, rs) in zip(flat, by.items()):
        label = titles.get(factor, factor)
        if len(rs) > MAX_LEVELS:  # (targets: the others are cut into MAX_LEVELS bins)
            keep = sorted(sorted(range(len(rs)), key=lambda i: -rs[i]["n"])[:MAX_LEVELS])
            label += (f" ({MAX_LEVELS} of {len(rs)} with the most trials; all in "
                      "recognition.csv)")
            rs = [rs[i] for i in keep]
        acc = np.array([r["accuracy"] for r in rs], dtype=float)
        err = np.array([[r["accuracy"] - r["ci_lo"], r["ci_hi"] - r["accuracy"]] for r in rs],
                       dtype=float).T
        if factor in ("alt_agl_m", "speed_kt"):  # at the middle of a bin
            x = np.array([(r["bin_lo"] + r["bin_hi"]) / 2 for r in rs], dtype=float)
            ax.errorbar(x, acc, yerr=err, fmt="o-", capsize=3)
        else:
            x = np.arange(len(rs), dtype=float)
            ax.errorbar(x, acc, yerr=err, fmt="o", capsize=3)
            ax.set_xticks(x)
            ax.set_xticklabels([r["level"] for r in rs], rotation=20, fontsize=7)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(label, fontsize=10 if len(label) < 40 else 7)
        ax.set_ylabel("accuracy (95% Wilson)")
    for ax in flat[len(by) if by else 1:]:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
