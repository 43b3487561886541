"""Experiment 2, recognition: accuracy against each condition, and a
logistic model of recognition on altitude and speed.

Owns the rows of recognition.csv (``RECOGNITION_FIELDS``: accuracy with 95 %
Wilson intervals per altitude, speed, target, and quantile bins of the
target's angular size and eccentricity; ``analyse_recognition``), the
logistic regression (``logistic_regression``: the target as a factor, left
out beyond ``MAX_LEVELS`` targets) and the summary by factor
(``by_factor``).

Responses in, rows out: it reads no file, writes none and draws nothing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from statistics import NormalDist
from typing import Any

import numpy as np

from cosim.trials.conditions import MAX_LEVELS
from cosim.trials.estimates import wilson_ci
from cosim.trials.responses import Responses

RECOGNITION_FIELDS = ("factor", "level", "bin_lo", "bin_hi", "n", "recognised", "accuracy",
                      "ci_lo", "ci_hi", "reaction_time_mean_ms")


def logistic_regression(x: np.ndarray, y: np.ndarray, names: Sequence[str], *,
                        level: float = 0.95, max_iter: int = 50) -> dict[str, Any]:
    """Maximum-likelihood logistic regression by Newton/IRLS (an intercept is
    added), with Wald intervals. Returns ``{"converged": False, ...}`` when
    the fit does not converge or the data are separated."""
    x = np.column_stack([np.ones(len(y)), np.asarray(x, dtype=float).reshape(len(y), -1)])
    y = np.asarray(y, dtype=float)
    beta = np.zeros(x.shape[1])
    converged = False
    cov = None
    for _ in range(max_iter):
        p = 1.0 / (1.0 + np.exp(-np.clip(x @ beta, -30, 30)))
        w = p * (1 - p)
        info = x.T @ (x * w[:, None])
        try:
            step = np.linalg.solve(info, x.T @ (y - p))
        except np.linalg.LinAlgError:
            break
        beta = beta + step
        if np.max(np.abs(step)) < 1e-8:
            converged = True
            break
    if converged:
        p = 1.0 / (1.0 + np.exp(-np.clip(x @ beta, -30, 30)))
        info = x.T @ (x * (p * (1 - p))[:, None])
        try:
            cov = np.linalg.inv(info)
        except np.linalg.LinAlgError:
            converged = False
    if not converged or cov is None or np.max(np.abs(beta)) > 25 or not np.all(np.diag(cov) > 0):
        return {"converged": False, "n": int(len(y)),
                "detail": "no maximum-likelihood fit (separated or degenerate data)"}
    z = NormalDist().inv_cdf(0.5 + level / 2)
    se = np.sqrt(np.diag(cov))
    coef = {}
    for i, nm in enumerate(["intercept", *names]):
        coef[nm] = {"estimate": float(beta[i]), "se": float(se[i]),
                    "ci": [float(beta[i] - z * se[i]), float(beta[i] + z * se[i])]}
    return {"converged": True, "n": int(len(y)), "coefficients": coef}


def _quantile_bins(v: np.ndarray, n_bins: int) -> np.ndarray:
    edges = np.unique(np.quantile(v, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 2:
        edges = np.array([v.min(), v.max()])
    return edges


def analyse_recognition(rec: Responses, levels: dict[str, np.ndarray],
                        bins: dict[str, list[dict[str, Any]]], n_bins: int
                        ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Accuracy tables per factor, and the logistic regression on altitude and
    speed. ``levels``: each trial's altitude and speed level, ``bins`` those
    of the conditions cut into bins (``condition_levels``): a row a level,
    or a bin."""
    y = rec.recognised
    rt = rec.num["reaction_time_ms"]
    rows: list[dict[str, Any]] = []

    def add(factor: str, label: str, m: np.ndarray, lo: float | None = None,
            hi: float | None = None) -> None:
        n = int(m.size)  # m: the trials' indices
        k = int(y[m].sum())
        c_lo, c_hi = wilson_ci(k, n)
        rts = rt[m][~np.isnan(rt[m])]
        rows.append(dict(zip(RECOGNITION_FIELDS, (
            factor, label, lo, hi, n, k, k / n if n else None, c_lo, c_hi,
            float(rts.mean()) if rts.size else None))))

    for factor, col in (("alt_agl_m", "condition_alt_agl_m"), ("speed_kt", "condition_speed_kt")):
        v = levels[col]
        have = np.flatnonzero(np.isfinite(v))
        values, which = np.unique(v[have], return_inverse=True)
        ranges = {b["level"]: (b["lo"], b["hi"]) for b in bins.get(col, [])}
        for j, lv in enumerate(values):
            lo, hi = ranges.get(float(lv), (float(lv), float(lv)))
            add(factor, f"{lv:g}" if lo == hi else f"{lo:g}-{hi:g}", have[which == j], lo, hi)
    tarr = np.asarray(rec.text["condition_target"], dtype=object)
    by_target: dict[str, list[int]] = {}
    for i, t in enumerate(rec.text["condition_target"]):
        by_target.setdefault(t, []).append(i)
    for t in sorted(by_target):
        add("target", t, np.asarray(by_target[t], dtype=np.int64))
    for factor, col in (("angular_size_bin_deg", "target_angular_size_deg"),
                        ("eccentricity_bin_deg", "eccentricity_deg")):
        v = rec.num[col]
        ok = ~np.isnan(v)
        if not ok.any():
            continue
        edges = _quantile_bins(v[ok], n_bins)
        for i in range(edges.size - 1):
            lo, hi = float(edges[i]), float(edges[i + 1])
            last = i == edges.size - 2
            m = ok & (v >= lo) & ((v <= hi) if last else (v < hi))
            add(factor, f"[{lo:.3g}, {hi:.3g}{']' if last else ')'}", np.flatnonzero(m), lo, hi)

    # logistic regression: altitude (per 100 m), speed (per 100 kt), target as a factor
    alt = rec.num["condition_alt_agl_m"]
    spd = rec.num["condition_speed_kt"]
    cols: list[np.ndarray] = []
    names: list[str] = []
    use = np.ones(len(rec), dtype=bool)
    for nm, v, scale in (("alt_per_100m", alt, 100.0), ("speed_per_100kt", spd, 100.0)):
        present = ~np.isnan(v)
        if np.unique(v[present]).size >= 2:
            use &= present
            cols.append(v / scale)
            names.append(nm)
    targets = sorted(by_target)
    # a factor of more than MAX_LEVELS targets would make the model's matrix
    # (targets x targets) the whole cost: the model is made without it
    as_factor = targets[1:] if len(targets) <= MAX_LEVELS else []
    for t in as_factor:
        cols.append((tarr == t).astype(float))
        names.append(f"target[{t}]")
    if not names or use.sum() < len(names) + 2:
        logistic: dict[str, Any] = {"converged": False, "n": int(use.sum()),
                                    "detail": "no factor varies (or too few responses)"}
    else:
        x = np.column_stack([c[use] for c in cols])
        logistic = logistic_regression(x, y[use], names)
        if as_factor:
            logistic["reference_target"] = targets[0]
    if len(targets) > MAX_LEVELS:
        logistic["targets_left_out"] = (f"{len(targets)} targets, more than {MAX_LEVELS}: "
                                        "the model is made without the target as a factor")
    return rows, logistic


def by_factor(rows: Iterable[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The accuracy rows by factor, for the summary."""
    by: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by.setdefault(row["factor"], []).append(
            {k: row[k] for k in ("level", "n", "accuracy", "ci_lo", "ci_hi")})
    return by


def recognition_summary(rec: Responses, rows: list[dict[str, Any]],
                        logistic: dict[str, Any]) -> dict[str, Any]:
    """The "recognise" part of the analysis' summary: responses, accuracy
    with its Wilson interval, the accuracy rows by factor and the model."""
    n_rec = len(rec)
    k_rec = int(np.nansum(rec.recognised))
    return {
        "responses": n_rec, "recognised": k_rec,
        "accuracy": k_rec / n_rec if n_rec else None,
        "accuracy_ci": list(wilson_ci(k_rec, n_rec)) if n_rec else None,
        "by": by_factor(rows),
        "logistic": logistic,
    }
