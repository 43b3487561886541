"""The instruments' figures: ``tlx.png`` (each participant's raw TLX block by
block, then the mean raw and weighted TLX at each level of each condition)
and ``sagat.png`` (accuracy of each kind of question over all answers and at
each condition's levels).

Table rows in (``instrument_analysis``), a PNG out: it computes no
statistic and reads nothing. matplotlib (Agg), imported when drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.figures import _pyplot

#: the most conditions drawn, a panel each (the tables hold them all)
MAX_PANELS = 3
#: the most participants drawn one line each in the TLX's first panel
MAX_LINES = 24


def _conditions(levels: Sequence[dict[str, Any]], also: int = 0) -> list[str]:
    """The conditions drawn: the first ``MAX_PANELS`` (and ``also`` panels more)."""
    return list(dict.fromkeys(r["condition"] for r in levels))[:MAX_PANELS + also]


def _axis(ax: Any, keys: list[Any], name: str) -> dict[Any, float]:
    """x positions of a condition's levels (numbers at their value) and its ticks."""
    numeric = all(isinstance(k, float) for k in keys)
    x_of = {k: float(k) if numeric else float(i) for i, k in enumerate(keys)}
    ax.set_xticks(list(x_of.values()))
    ax.set_xticklabels([f"{k:g}" if numeric else str(k) for k in keys], fontsize=8,
                       rotation=0 if numeric else 20)
    if not numeric:
        ax.set_xlim(-0.6, len(keys) - 0.4)
    else:
        ax.margins(x=0.12)
    ax.set_xlabel(name)
    ax.grid(alpha=0.3)
    return x_of


def _errorbars(ax: Any, x: Sequence[float], rs: Sequence[dict[str, Any]], key: str,
               **kw: Any) -> None:
    y = np.array([r[key] for r in rs], dtype=float)
    lo = np.array([r["ci_lo"] for r in rs], dtype=float)
    hi = np.array([r["ci_hi"] for r in rs], dtype=float)
    ax.errorbar(x, y, yerr=np.nan_to_num(np.clip([y - lo, hi - y], 0, None)), capsize=3,
                **kw)


def plot_tlx(path: Path, blocks: Sequence[dict[str, Any]], levels: Sequence[dict[str, Any]],
             level: float = 0.95) -> None:
    """Raw TLX per participant and block, and TLX against each condition."""
    plt = _pyplot()
    conds = _conditions(levels)
    fig, axes = plt.subplots(1, 1 + len(conds), figsize=(4.2 * (1 + len(conds)), 4),
                             squeeze=False)
    ax0 = axes[0][0]
    people = sorted({str(r["participant"]) for r in blocks})
    for p in people[:MAX_LINES]:
        rs = sorted((r for r in blocks if str(r["participant"]) == p), key=lambda r: r["block"])
        ax0.plot([r["block"] for r in rs], [r["raw_tlx"] for r in rs], "o-", alpha=0.7,
                 label=p if len(people) <= 8 else None)
    ax0.set_title("raw TLX, each participant" + (f" (first {MAX_LINES} of {len(people)})"
                                                 if len(people) > MAX_LINES else ""),
                  fontsize=9)
    ax0.set_xlabel("block")
    ax0.set_ylabel("TLX (0-100)")
    if blocks:
        ax0.set_xticks(sorted({int(r["block"]) for r in blocks}))
    if 0 < len(people) <= 8:
        ax0.legend(fontsize=7, title="participant", title_fontsize=7)
    if not blocks:
        ax0.text(0.5, 0.5, "no TLX answers", ha="center", va="center",
                 transform=ax0.transAxes)
    ax0.grid(alpha=0.3)
    pct = f"{100 * level:g}%"
    for ax, name in zip(axes[0][1:], conds):
        rs = [r for r in levels if r["condition"] == name]
        x_of = _axis(ax, list(dict.fromkeys(r["level"] for r in rs)), name)
        span = max(x_of.values()) - min(x_of.values()) if len(x_of) > 1 else 1.0
        for dx, (m, label, c) in zip((-0.015, 0.015), (("raw_tlx", "raw", "C0"),
                                                       ("weighted_tlx", "weighted", "C1"))):
            mr = [r for r in rs if r["measure"] == m and r["blocks"]]
            if mr:
                _errorbars(ax, [x_of[r["level"]] + dx * span for r in mr], mr, "estimate",
                           fmt="o", color=c, label=f"{label} TLX, mean, {pct} interval")
        ax.legend(fontsize=7)
        ax.set_title(f"TLX against {name}", fontsize=9)
    for ax in axes[0]:
        ax.set_ylim(0, 100)
    how = sorted({r["interval"] for r in levels if r["blocks"]})
    fig.suptitle("NASA-TLX" + (f" (intervals: {', '.join(how)})" if how else ""), fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sagat(path: Path, levels: Sequence[dict[str, Any]], level: float = 0.95) -> None:
    """SAGAT accuracy per kind of question: over all answers, and against
    each condition."""
    plt = _pyplot()
    conds = _conditions(levels, also=1)  # all answers, then the conditions
    fig, axes = plt.subplots(1, max(len(conds), 1), figsize=(4.5 * max(len(conds), 1), 4),
                             squeeze=False)
    kinds = sorted({r["kind"] for r in levels})
    pct = f"{100 * level:g}%"
    for ax, name in zip(axes[0], conds):
        rs = [r for r in levels if r["condition"] == name]
        keys = list(dict.fromkeys(r["level"] for r in rs))
        if name == "(all)":
            x_of = {k: float(i) for i, k in enumerate(kinds)}
            kr = [next(r for r in rs if r["kind"] == k) for k in kinds]
            for i, r in enumerate(kr):  # each kind in its colour of the other panels
                _errorbars(ax, [x_of[r["kind"]]], [r], "accuracy", fmt="o", color=f"C{i}")
            ax.set_xticks(list(x_of.values()))
            ax.set_xticklabels([f"{k}\n({r['questions']} answers)" for k, r in zip(kinds, kr)],
                               fontsize=8)
            ax.set_xlim(-0.6, len(kinds) - 0.4)
            ax.set_xlabel("question kind")
            ax.set_title("all answers", fontsize=9)
            ax.grid(alpha=0.3)
        else:
            x_of = _axis(ax, keys, name)
            span = max(x_of.values()) - min(x_of.values()) if len(x_of) > 1 else 1.0
            for i, kind in enumerate(kinds):
                kr = [r for r in rs if r["kind"] == kind and r["questions"]]
                if kr:
                    dx = (i - (len(kinds) - 1) / 2) * 0.03 * span
                    _errorbars(ax, [x_of[r["level"]] + dx for r in kr], kr, "accuracy",
                               fmt="o", color=f"C{i}", label=kind)
            ax.set_title(f"accuracy against {name}", fontsize=9)
            ax.legend(fontsize=7, title="question kind", title_fontsize=7)
        ax.set_ylim(-0.02, 1.02)
    axes[0][0].set_ylabel(f"share answered correctly, {pct} interval")
    if not levels:
        axes[0][0].text(0.5, 0.5, "no scored SAGAT answers", ha="center", va="center",
                        transform=axes[0][0].transAxes)
    how = sorted({r["interval"] for r in levels if r["questions"]})
    fig.suptitle("SAGAT" + (f" (intervals: {', '.join(how)})" if how else ""), fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
