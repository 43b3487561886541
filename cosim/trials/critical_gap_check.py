"""Whether one measurement predicts the others: each level of a critical-gap
fit against the angle the gap of its other plateau levels predicts there
(``check_across_levels``), judged "holds", "fails" or "inconclusive"
(``VERDICTS``); the rows of critical_gap_check.csv.

A ``GapFit`` and the trials it was made from in, one row a level out: it
reads no file, knows no CSV column and draws nothing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.trials.critical_gap import GapFit
from cosim.trials.estimates import cluster_ids, difference_estimate, judge, mean_ci, t_interval

#: what a level's check says (critical_gap_check.csv ``verdict``)
VERDICTS = ("holds", "fails", "inconclusive", "untested", "below_threshold", "no_plateau")


def check_across_levels(fit: GapFit, x: np.ndarray, g: np.ndarray, *,
                        clusters: Sequence[str] | np.ndarray | None = None,
                        level: float = 0.95) -> list[dict[str, Any]]:
    """Whether one measurement predicts the others: per level of ``fit``'s
    variable, the gap (and its angle ``atan(gap / x)``) measured there
    against the one the critical gap predicts (``tan(angle) = CG / x``), CG
    taken from the *other* plateau levels only (leave one level out), and of
    those only the ones that are not themselves off: each level is first
    compared with all the others; the levels found off ("fails") are left
    out of the others' gap and every level compared again, until the levels
    left out no longer change (a level 25 % off no longer drags the others'
    gap and makes correct levels fail). ``compared_with`` lists the levels
    each was compared with.

    Every level gets a row: n, the measured mean gap with its t interval,
    the measured angle. On the plateau (``x >= threshold``) also the
    predicted angle, the difference (gap here - mean gap of the levels
    compared with, cluster-robust over ``clusters`` when given:
    ``difference_estimate``) and a ``verdict`` (``judge``):

    - "holds": the difference's 90 % interval lies within ``fit.tolerance``
      of the others' gap (an equivalence test at 5 %);
    - "fails": its interval at ``confidence`` (Bonferroni: 1 - (1 - level) / k
      for the k plateau levels) lies entirely outside the tolerance: the
      difference is shown to be larger than the tolerance (a level 7 % off
      with a 10 % tolerance does not fail);
    - "inconclusive": neither (too few trials to tell);
    - "untested": fewer than two trials here or at the other levels.

    Below the threshold the relation is not expected to hold
    ("below_threshold": the whole plateau's prediction, no verdict); no
    plateau: measured values only ("no_plateau"). ``holds`` is True / False
    for "holds" / "fails", else None."""
    x = np.asarray(x, dtype=float)
    g = np.asarray(g, dtype=float)
    who = cluster_ids(clusters, x.size)
    xr = np.round(x / fit.round_to) * fit.round_to
    on_plateau = (xr >= fit.threshold - 1e-9) if fit.threshold is not None else None
    k = len(np.unique(xr[on_plateau])) if on_plateau is not None else 0
    confidence = 1.0 - (1.0 - level) / max(k, 1)
    out = []
    judged: dict[float, dict[str, Any]] = {}  # the plateau's rows
    for v in np.unique(xr):
        here = xr == v
        m, lo, hi = mean_ci(g[here], level)
        row: dict[str, Any] = {
            "level": float(v), "n": int(here.sum()), "gap_mean": m, "gap_ci_lo": lo,
            "gap_ci_hi": hi, "angle_measured_deg": math.degrees(math.atan(m / v)),
            "angle_predicted_deg": None, "cg_predicting": None, "compared_with": None,
            "difference": None, "difference_ci_lo": None, "difference_ci_hi": None,
            "confidence": None, "verdict": "no_plateau", "holds": None}
        out.append(row)
        if fit.cg is None or on_plateau is None:
            continue
        if not on_plateau[here][0]:
            row.update(verdict="below_threshold", cg_predicting=fit.cg,
                       angle_predicted_deg=math.degrees(math.atan(fit.cg / v)))
            continue
        judged[float(v)] = row
    if on_plateau is None:
        return out
    plateau = on_plateau

    def compare(v: float, row: dict[str, Any], left_out: set[float]) -> None:
        here = xr == v
        others = plateau & ~here
        kept = others & ~np.isin(xr, list(left_out))
        if kept.sum() >= 2:  # (when every other level is off: all of them)
            others = kept
        row["verdict"] = "untested"
        if others.sum() < 2 or here.sum() < 2:
            return
        cg_o = float(g[others].mean())
        both = here | others
        est = difference_estimate(g[both], here[both], who[both] if who is not None else None)
        dlo, dhi = t_interval(est, confidence)
        verdict = {"equal": "holds", "differs": "fails", "unclear": "inconclusive"}[
            judge(est, fit.tolerance * abs(cg_o), level, confidence)]
        row.update(cg_predicting=cg_o, angle_predicted_deg=math.degrees(math.atan(cg_o / v)),
                   compared_with=" ".join(f"{u:g}" for u in np.unique(xr[others])),
                   difference=est[0] if est is not None else math.nan,
                   difference_ci_lo=dlo, difference_ci_hi=dhi, confidence=confidence,
                   verdict=verdict, holds={"holds": True, "fails": False}.get(verdict))

    left_out: set[float] = set()
    for _ in range(len(judged) + 1):  # (settles in two or three rounds)
        for v, row in judged.items():
            compare(v, row, left_out)
        off = {v for v, row in judged.items() if row["verdict"] == "fails"}
        if off == left_out:
            break
        left_out = off
    return out
