"""The critical gap of one target: its conspicuity gap against a level (the
viewing distance, or the altitude) fitted as rising up to a threshold and
constant above it.

The critical-gap relation ``CG = tan(alpha) * d = tan(beta) * h``: beyond a
threshold the conspicuity measured as a distance stays constant. ``fit_gap``
makes the two-segment fit, judges whether the gap is constant above the
threshold (equal within a tolerance, shown by an equivalence test; data that
cannot show it are "inconclusive") and gives the critical gap with a t
interval over participants and the threshold with a bootstrap interval
(``GapFit``). ``fit_critical_gap`` is the plane of the screen (mm against
the viewing distance), ``fit_ground_gap`` the plane of the ground (m against
the altitude). Whether one level predicts the others is
``cosim.trials.critical_gap_check``.

Arrays in, a ``GapFit`` out: it reads no file, knows no CSV column and
draws nothing. numpy and the estimates of ``cosim.trials.estimates``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.trials.estimates import (
    EXACT_BOOT_MAX,
    cluster_ids,
    judge,
    mean_estimate,
    slope_estimate,
    t_interval,
)

#: participants needed to resample whole participants for the threshold's
#: interval (fewer: trials are resampled within levels). The critical gap's
#: own interval is a t interval over participants from two on: a percentile
#: bootstrap of a few people's means is too narrow (0.905 coverage with 10
#: people against 0.95 for the t interval; benchmarks/trials_error_rates.py)
MIN_BOOT_PARTICIPANTS = 10


@dataclass(frozen=True)
class GapFit:
    """The critical gap of one target against one variable (``fit_gap``).

    ``variable`` is what the levels are: the viewing distance ``d`` (the gap
    on the screen, in mm) or the altitude ``h`` (the gap on the ground, in
    m); ``unit`` is the unit of the levels, the gap and the threshold alike.

    ``status``:

    - "plateau": the gap rises up to ``threshold`` and is constant above it
      (constant: equal within ``tolerance``, see ``fit_gap``);
    - "plateau_from_start": constant over every level tested: the threshold
      is at or below the lowest level (``threshold`` is that level, with no
      interval);
    - "no_plateau": the gap still changes above the best breakpoint, by
      more than ``tolerance`` across it (or the bend cannot be told from
      the rise): no critical gap within the levels tested;
    - "inconclusive": the data cannot tell whether the gap is constant
      above the breakpoint (its change is neither shown nor ruled out):
      more trials or participants are needed;
    - "insufficient_data": fewer than ``min_plateau_levels + 1`` levels,
      fewer than ``2 * (min_plateau_levels + 1)`` trials, or every trial's
      gap the same.

    ``cg`` and ``threshold`` are given for the two plateau statuses only;
    ``detail`` says why. ``interval`` says how the CG interval was made:
    "t over participants" (2 or more people on the plateau: a t interval
    with one degree of freedom less than people, each person's trials
    counted as one unit, cluster-robust; over people who did as many trials
    each it is the t interval over their mean gaps) or "trial bootstrap"
    (one person, or none named: trials resampled within levels, the
    breakpoint chosen anew).
    """

    status: str
    detail: str
    n: int
    variable: str
    unit: str
    levels: list[float]
    #: the levels are the trials' values rounded to this
    round_to: float = 1.0
    participants: int = 0
    interval: str = ""
    #: replicates of the participant bootstrap without every level, left out
    boot_dropped: int = 0
    tolerance: float = 0.1
    cg: float | None = None
    cg_ci: tuple[float, float] | None = None
    threshold: float | None = None
    threshold_ci: tuple[float, float] | None = None
    #: the two-segment fit at the chosen breakpoint: plateau level and slope below it
    fit_level: float | None = None
    rising_slope: float | None = None
    rising_slope_ci: tuple[float, float] | None = None
    breakpoint: float | None = None
    #: residual check: slope of the gap against the level at and above the breakpoint
    #: (95 % interval), and the slope that would change the gap by ``tolerance``
    #: across the plateau
    plateau_slope: float | None = None
    plateau_slope_ci: tuple[float, float] | None = None
    negligible_slope: float | None = None
    plateau_n: int = 0
    plateau_levels: int = 0
    rmse: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def _candidates(levels: np.ndarray, steps: int, min_plateau_levels: int) -> np.ndarray:
    """Breakpoints tried: the lowest level (no rising part), then a fine
    grid from the second level up to the one that leaves
    ``min_plateau_levels`` levels on the plateau for the check (with one
    level below the breakpoint any breakpoint between the first two fits
    alike, so the second stands for them)."""
    last = levels.size - min_plateau_levels  # index of the highest breakpoint
    grid = [levels[:1]]
    for a, b in zip(levels[1:last], levels[2:last + 1]):
        grid.append(np.linspace(a, b, steps, endpoint=False))
    if last >= 1:
        grid.append(levels[last:last + 1])
    return np.unique(np.concatenate(grid))


def _hinge(levels: np.ndarray, counts: np.ndarray, sums: np.ndarray, cand: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``y = a + s * min(x - c, 0)``, ``s >= 0``, for every
    candidate ``c`` at once, from per-level counts and sums of y (the fit
    needs no more: every trial at a level has the same regressor).

    ``sums`` is (L,) or (B, L) (B bootstrap replicates), ``counts`` (L,) or,
    when whole participants are resampled, (B, L). Returns
    ``(sse_part, a, s, det)``, each (C,) or (B, C); ``sse_part`` is the
    squared error less the sum of y**2 (the same for every candidate).
    """
    x = np.minimum(levels[None, :] - cand[:, None], 0.0)  # (C, L)
    if counts.ndim == 2:
        n: Any = counts.sum(axis=-1, keepdims=True)
    else:
        n = float(counts.sum())
    sx = counts @ x.T
    sxx = counts @ (x * x).T
    sxy = sums @ x.T
    sy = sums.sum(axis=-1, keepdims=True) if sums.ndim == 2 else float(sums.sum())
    det = n * sxx - sx * sx
    good = det > 1e-9 * np.maximum(n * sxx, 1e-300)
    slope = np.where(good, (n * sxy - sx * sy) / np.where(good, det, 1.0), 0.0)
    slope = np.maximum(slope, 0.0)  # below the threshold the gap rises (or is flat)
    a = (sy - slope * sx) / np.maximum(n, 1e-300)
    part = -2 * a * sy - 2 * slope * sxy + n * a * a + 2 * a * slope * sx + slope * slope * sxx
    return part, a, slope, det


def _trial_boot_sums(g: np.ndarray, level_of: np.ndarray, n_levels: int,
                     rng: np.random.Generator, n_boot: int) -> np.ndarray:
    """(n_boot, L) sums of g over trials drawn with replacement within each level."""
    out = np.empty((n_boot, n_levels))
    for j in range(n_levels):
        gj = g[level_of == j]
        if gj.size <= EXACT_BOOT_MAX:
            out[:, j] = gj[rng.integers(0, gj.size, size=(n_boot, gj.size))].sum(axis=1)
        else:
            out[:, j] = rng.normal(gj.sum(), math.sqrt(gj.size * float(gj.var())), n_boot)
    return out


def _people_boot_sums(g: np.ndarray, level_of: np.ndarray, n_levels: int, who: np.ndarray,
                      rng: np.random.Generator, n_boot: int
                      ) -> tuple[np.ndarray, np.ndarray, int]:
    """Whole participants drawn with replacement, all their trials with them:
    (sums (B, L), counts (B, L), replicates dropped). A replicate without a
    trial at some level (people who did not do every level) is drawn again,
    up to ten times over, and the ones still lacking a level are left out
    (counted), so the fit is always made on every level."""
    people = int(who.max()) + 1
    s = np.zeros((people, n_levels))
    c = np.zeros((people, n_levels))
    np.add.at(s, (who, level_of), g)
    np.add.at(c, (who, level_of), 1.0)
    p = np.full(people, 1.0 / people)
    sums, counts = [], []
    dropped = 0
    for _ in range(10):
        w = rng.multinomial(people, p, size=n_boot)
        bc = w @ c
        ok = (bc > 0).all(axis=1)
        dropped += int((~ok).sum())
        sums.append(w[ok] @ s)
        counts.append(bc[ok])
        if sum(len(x) for x in counts) >= n_boot:
            break
    return (np.concatenate(sums)[:n_boot], np.concatenate(counts)[:n_boot],
            dropped)


def fit_gap(x: np.ndarray, g: np.ndarray, *, rng: np.random.Generator,
            variable: str, unit: str, gap: str, round_to: float,
            clusters: Sequence[str] | np.ndarray | None = None, steps: int = 10,
            n_boot: int = 1000, min_plateau_levels: int = 3, tolerance: float = 0.1,
            level: float = 0.95) -> GapFit:
    """Estimate a target's critical gap and the threshold above which it holds.

    ``x``: each trial's level of the variable (the viewing distance, or the
    altitude), grouped to the nearest ``round_to``; ``g``: its conspicuity
    gap there (on the screen, mm; on the ground, m). ``gap`` names it in
    messages. ``clusters``: each trial's participant.

    Method: ``g`` against ``x`` is fitted by a continuous two-segment
    ("hinge") model ``g = CG + s * min(x - x0, 0)`` with ``s >= 0``: rising
    linearly below ``x0``, constant above. For each candidate ``x0``
    (``_candidates``: the levels and ``steps`` subdivisions between them)
    the model is linear in (CG, s) and solved by least squares; ``x0`` is
    the candidate of least squared error. At least ``min_plateau_levels``
    levels must lie at or above ``x0`` (so a threshold within the last two
    levels tested cannot be found).

    Then, in order:

    1. rising part: if ``x0`` is above the lowest level but the 95 %
       interval of the rise's slope (given ``x0``, as if it were known; within
       participants when they are named: ``slope_estimate``) includes 0, the rise
       is not resolved and the constant model (``x0`` = the lowest level) is
       used;
    2. is the gap constant above ``x0``? The OLS slope of ``g`` against
       ``x`` over the trials at and above ``x0`` (standard error
       cluster-robust over participants, else HC3; ``slope_estimate``) is compared
       with the negligible slope ``delta``, the one that changes the gap by
       ``tolerance`` of its level across the plateau: constant when its
       90 % interval lies within +-delta (an equivalence test at 5 %);
       changing ("no_plateau") when its 95 % interval lies entirely outside
       +-delta (a change shown to exceed the tolerance); otherwise
       "inconclusive" (``judge``). With a rising part the
       95 % interval must also lie below ``s`` (the bend is real, not a
       lack of data above ``x0``), else "no_plateau";
    3. CG is the mean of ``g`` over the plateau, with a t interval over
       the participants there (``mean_estimate``: each participant counted once,
       ``GapFit.interval``); the threshold's interval is a percentile
       bootstrap (participants, or trials within levels), the breakpoint
       chosen anew each time.
    """
    x = np.asarray(x, dtype=float)
    g = np.asarray(g, dtype=float)
    xr = np.round(x / round_to) * round_to
    levels, level_of = np.unique(xr, return_inverse=True)
    n = int(g.size)
    people = np.asarray(clusters, dtype=object) if clusters is not None else None
    who = cluster_ids(people, n)
    base: dict[str, Any] = {"n": n, "variable": variable, "unit": unit,
                            "levels": [float(v) for v in levels], "round_to": round_to,
                            "participants": int(np.unique(people).size) if people is not None
                            else 0, "tolerance": tolerance}
    if min_plateau_levels < 2:
        raise ValueError(f"min_plateau_levels must be >= 2, got {min_plateau_levels}")
    need = min_plateau_levels + 1
    if levels.size < need or n < 2 * need:
        return GapFit(status="insufficient_data",
                      detail=f"{n} trials at {levels.size} levels of the {variable}: need at "
                             f"least {2 * need} trials at {need} levels", **base)
    if np.ptp(g) == 0.0:
        return GapFit(status="insufficient_data",
                      detail=f"every one of the {n} trials has the same gap, {float(g[0]):g} "
                             f"{unit}: nothing to fit (a data error? a gap of 0 is a target "
                             f"lost at the fixation point itself)", **base)
    cand = _candidates(levels, steps, min_plateau_levels)
    counts = np.bincount(level_of, minlength=levels.size).astype(float)
    sums = np.bincount(level_of, weights=g, minlength=levels.size)
    part, a, s, det = _hinge(levels, counts, sums, cand)
    sse = np.maximum(part + float(g @ g), 0.0)
    best = int(np.argmin(sse))
    x0 = float(cand[best])
    s_ci: tuple[float, float] | None = None
    if x0 > levels[0] and det[best] > 0:
        # the rise's slope given x0: the slope of g on min(x - x0, 0), within
        # participants when they are known (slope_estimate)
        slo, shi = t_interval(slope_estimate(np.minimum(xr - x0, 0.0), g, who), level)
        if math.isfinite(slo):
            s_ci = (slo, shi)
    rising_resolved = s_ci is not None and s_ci[0] > 0
    if not rising_resolved:
        best = 0  # the first candidate is the lowest level: no rising part
        x0 = float(cand[0])
    fit_level = float(a[best])
    rmse = math.sqrt(float(sse[best]) / n)
    above = xr >= x0 - 1e-9
    span = f"{levels[0]:g}-{levels[-1]:g} {unit}"
    delta = tolerance * abs(fit_level) / max(float(levels[-1]) - x0, 1e-300)
    est = slope_estimate(xr[above], g[above], who[above] if who is not None else None)
    pb = est[0] if est is not None else math.nan
    plo, phi = t_interval(est, level)
    elo, ehi = t_interval(est, 2 * level - 1)  # 90 %: the equivalence test
    common: dict[str, Any] = dict(
        base, breakpoint=x0, fit_level=fit_level,
        rising_slope=float(s[best]) if rising_resolved else 0.0,
        rising_slope_ci=s_ci if rising_resolved else None,
        plateau_slope=pb, plateau_slope_ci=(plo, phi), negligible_slope=delta,
        plateau_n=int(above.sum()), plateau_levels=int(np.unique(xr[above]).size), rmse=rmse)
    slope_text = (f"slope {pb:.3g} {unit}/{unit}, {level:.0%} CI [{plo:.3g}, {phi:.3g}]; "
                  f"within +-{delta:.3g} counts as constant ({tolerance:.0%} of the gap "
                  f"across the plateau)")
    verdict = judge(est, delta, level, level)
    if rising_resolved and phi >= float(s[best]):
        return GapFit(
            status="no_plateau",
            detail=(f"above the best breakpoint {x0:g} {unit} the slope of {gap} "
                    f"({pb:.4g} {unit}/{unit}, {level:.0%} CI [{plo:.4g}, {phi:.4g}]) cannot be "
                    f"told from the slope below it ({float(s[best]):.4g}): no plateau "
                    f"established within {span} (too few trials above it?)"),
            **common)
    if verdict == "differs":
        return GapFit(status="no_plateau",
                      detail=(f"{gap} still changes above the best breakpoint {x0:g} {unit}, "
                              f"by more than {tolerance:.0%} across it ({slope_text}): no "
                              f"critical gap within {span}"), **common)
    if verdict == "unclear":
        return GapFit(status="inconclusive",
                      detail=(f"cannot tell whether {gap} is constant above {x0:g} {unit} "
                              f"({slope_text}; its {2 * level - 1:.0%} CI [{elo:.3g}, "
                              f"{ehi:.3g}] is not within that): more trials or participants "
                              f"needed; the mean above it is {float(g[above].mean()):.4g} "
                              f"{unit}"), **common)

    cg = float(g[above].mean())
    q = [(1 - level) / 2, (1 + level) / 2]
    dropped = 0
    # the CG's interval: a t interval over the participants on the plateau
    people_est = mean_estimate(g[above], who[above]) if who is not None else None
    x0s = np.empty(0)
    if rising_resolved or people_est is None:  # the bootstrap: the threshold, or the CG
        if who is not None and int(who.max()) + 1 >= MIN_BOOT_PARTICIPANTS:
            boot, bcounts, dropped = _people_boot_sums(g, level_of, levels.size, who, rng,
                                                       n_boot)
            interval = "participant bootstrap"
        else:
            boot, bcounts = _trial_boot_sums(g, level_of, levels.size, rng, n_boot), counts
            interval = "trial bootstrap"
        if boot.shape[0] and rising_resolved:
            bpart, _, _, _ = _hinge(levels, bcounts, boot, cand)
            x0s = cand[np.argmin(bpart, axis=1)]
        else:
            x0s = np.full(boot.shape[0], cand[0])
        on = levels[None, :] >= x0s[:, None] - 1e-9  # (B, L): levels on the plateau
        with np.errstate(invalid="ignore", divide="ignore"):
            cgs = (boot * on).sum(axis=1) / (on * bcounts).sum(axis=1)
        cgs = cgs[np.isfinite(cgs)]
        cg_lo, cg_hi = ((float(v) for v in np.quantile(cgs, q)) if cgs.size
                        else (math.nan, math.nan))
    if people_est is not None:
        cg_lo, cg_hi = t_interval(people_est, level)
        interval = "t over participants"
    if rising_resolved and x0s.size:
        x0_lo, x0_hi = (float(v) for v in np.quantile(x0s, q))
        x0_ci: tuple[float, float] | None = (x0_lo, x0_hi)
    else:
        x0_ci = None
    if rising_resolved:
        status = "plateau"
        detail = f"{gap} rises up to {x0:g} {unit} and is constant above it ({slope_text})"
    else:
        status = "plateau_from_start"
        detail = (f"{gap} is constant over every level tested ({span}; {slope_text}): the "
                  f"threshold is at or below {levels[0]:g} {unit}")
    return GapFit(status=status, detail=detail, interval=interval, boot_dropped=dropped,
                  cg=cg, cg_ci=(cg_lo, cg_hi), threshold=x0, threshold_ci=x0_ci, **common)


def fit_critical_gap(d_mm: np.ndarray, alpha_deg: np.ndarray, *, rng: np.random.Generator,
                     distance_round_mm: float = 10.0, **kw: Any) -> GapFit:
    """The critical gap on the screen, ``CG = tan(alpha) * d`` (mm), and the
    threshold viewing distance ``d0`` (mm) above which it is constant
    (``fit_gap``; ``kw`` as there). With the eyes on the perpendicular
    through the screen centre and the fixation mark there, ``tan(alpha) * d``
    is the on-screen distance; ``analyse`` fits that distance itself (for a
    tracked arrow off the centre the two differ)."""
    d = np.asarray(d_mm, dtype=float)
    return fit_gap(d, np.tan(np.radians(np.asarray(alpha_deg, dtype=float))) * d, rng=rng,
                   variable="viewing distance d", unit="mm", gap="tan(alpha)*d",
                   round_to=distance_round_mm, **kw)


def fit_ground_gap(h_m: np.ndarray, beta_deg: np.ndarray, *, rng: np.random.Generator,
                   depth_m: np.ndarray | None = None, altitude_round_m: float = 1.0,
                   **kw: Any) -> GapFit:
    """The critical gap on the ground, ``CG = tan(beta) * h`` (m), and the
    threshold altitude ``h0`` (m) above which it is constant: ``beta`` is
    the conspicuity angle at the camera (``camera_gap_deg``), ``h`` its
    height above the ground (the levels) and ``depth_m``, when known, the
    camera's depth to the target's centre (``target_depth_m``), used in
    place of ``h`` for the gap (a target's centre is above the ground: at
    30 m a truck's is 6 % nearer the camera). ``fit_gap``; ``kw`` as there."""
    h = np.asarray(h_m, dtype=float)
    depth = h if depth_m is None else np.where(np.isfinite(depth_m), depth_m, h)
    return fit_gap(h, np.tan(np.radians(np.asarray(beta_deg, dtype=float))) * depth, rng=rng,
                   variable="altitude h", unit="m", gap="tan(beta)*h",
                   round_to=altitude_round_m, **kw)

