"""Estimates with their intervals, for the trials analysis.

Owns the statistics the analysis needs, and nothing of what they are about:
Student's t quantiles; means with t intervals, medians with bootstrap (or
order-statistic) intervals, proportions with Wilson intervals; and, with
trials grouped by participant, slopes, differences and means whose standard
errors are cluster-robust over participants (``slope_estimate``,
``difference_estimate``, ``mean_estimate``, each an ``Estimate``), their t
intervals (``t_interval``) and the equivalence judgement (``judge``).

It knows no CSV column, condition, file or figure. numpy, scipy.stats (the t
distribution) and the standard library.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from statistics import NormalDist

import numpy as np
from scipy import stats

#: (estimate, standard error, degrees of freedom)
Estimate = tuple[float, float, float]

#: groups with more values than this are not bootstrapped value by value
#: (memory n_boot x values): a median gets the order-statistic interval, a
#: distance level's resampled sum is drawn from its normal distribution (exact
#: mean and variance)
EXACT_BOOT_MAX = 2000


@functools.lru_cache(maxsize=4096)
def t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t with ``df`` (> 0, not necessarily whole: Welch's
    degrees of freedom) at ``p`` (Bonferroni levels included), from
    ``scipy.stats.t``. Cached: an analysis asks for the same few levels and
    degrees of freedom once per condition and level."""
    if not 0.0 < p < 1.0 or not df > 0:
        raise ValueError(f"t_quantile: need 0 < p < 1 and df > 0, got p={p!r}, df={df!r}")
    return float(stats.t.ppf(p, df))


def mean_ci(x: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """Mean and its t interval (NaN bounds for fewer than two values)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if x.size < 2:
        return m, math.nan, math.nan
    half = t_quantile(0.5 + level / 2, x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return m, m - half, m + half


def median_ci(x: np.ndarray, rng: np.random.Generator, n_boot: int = 1000,
              level: float = 0.95) -> tuple[float, float, float]:
    """Median and its percentile bootstrap interval (NaN bounds below two
    values). Above ``EXACT_BOOT_MAX`` values the distribution-free
    order-statistic interval (ranks n/2 -+ z sqrt(n)/2) replaces the bootstrap."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    med = float(np.median(x))
    if x.size < 2:
        return med, math.nan, math.nan
    if x.size > EXACT_BOOT_MAX:
        z = NormalDist().inv_cdf(0.5 + level / 2)
        xs = np.sort(x)
        half = z * math.sqrt(x.size) / 2
        j = max(int(math.floor(x.size / 2 - half)), 0)
        k = min(int(math.ceil(x.size / 2 + half)), x.size - 1)
        return med, float(xs[j]), float(xs[k])
    boots = np.median(x[rng.integers(0, x.size, size=(n_boot, x.size))], axis=1)
    lo, hi = np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])
    return med, float(lo), float(hi)


def wilson_ci(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a proportion k/n ((NaN, NaN) for n = 0)."""
    if n <= 0:
        return math.nan, math.nan
    z = NormalDist().inv_cdf(0.5 + level / 2)
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z / den * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def cluster_ids(clusters: Sequence[str] | np.ndarray | None, n: int) -> np.ndarray | None:
    """Integer participant ids of ``n`` trials, or None when there are fewer
    than two participants (then trials are all there is to go on)."""
    if clusters is None:
        return None
    ids, who = np.unique(np.asarray(clusters, dtype=object), return_inverse=True)
    if ids.size < 2 or who.size != n:
        return None
    return who


def _within(v: np.ndarray, who: np.ndarray) -> np.ndarray:
    """``v`` less its participant's mean (participant fixed effects)."""
    g = int(who.max()) + 1
    means = np.bincount(who, weights=v, minlength=g) / np.maximum(
        np.bincount(who, minlength=g), 1)
    return v - means[who]


def slope_estimate(x: np.ndarray, y: np.ndarray, who: np.ndarray | None) -> Estimate | None:
    """(slope, standard error, degrees of freedom) of y on x, None when x
    does not vary.

    Without participants: OLS with the HC3 standard error (the spread of a
    gap grows with the level: an angle error of e is a distance error of
    about e*d), n - 2 degrees of freedom. With them: the slope *within*
    participants (each one's own mean taken out of x and y: people whose
    gaps differ, or who did different levels, do not make a slope), its
    cluster-robust standard error (CR1: each participant's summed scores,
    G/(G-1)) and G - 1 degrees of freedom for the G participants whose x
    varies. If no participant's x varies (each did one level), the pooled
    slope with the same cluster-robust error. None also below 3 points."""
    if x.size < 3 or np.ptp(x) == 0:
        return None
    if who is not None:
        xd, yd = _within(x, who), _within(y, who)
        inside = float(xd @ xd)
        if inside > 1e-12 * max(float(((x - x.mean()) ** 2).sum()), 1e-300):
            b = float(xd @ yd) / inside
            res = yd - b * xd
            varies = np.bincount(who, weights=np.abs(xd)) > 0
            g = int(varies.sum())
            if g < 2:
                return None
            scores = np.bincount(who, weights=xd * res)
            return b, math.sqrt(g / (g - 1) * float(scores @ scores)) / inside, float(g - 1)
    xc = x - x.mean()
    sxx = float(xc @ xc)
    if sxx == 0.0:
        return None
    b = float(xc @ (y - y.mean())) / sxx
    res = y - y.mean() - b * xc
    if who is not None:
        g = int(who.max()) + 1
        scores = np.bincount(who, weights=xc * res, minlength=g)
        return b, math.sqrt(g / (g - 1) * float(scores @ scores)) / sxx, float(g - 1)
    lev = 1.0 / x.size + xc * xc / sxx
    return b, math.sqrt(float(np.sum((xc * res / (1.0 - lev)) ** 2))) / sxx, float(x.size - 2)


def difference_estimate(y: np.ndarray, here: np.ndarray,
                        who: np.ndarray | None) -> Estimate | None:
    """(difference of y between ``here`` and the rest, standard error, degrees
    of freedom): Welch's (mean here - mean of the rest) without participants;
    with them, the difference within participants (``slope_estimate`` on the
    indicator: each person's own level taken out). None when either side has
    fewer than two trials or no participant was on both sides."""
    a, b = y[here], y[~here]
    if a.size < 2 or b.size < 2:
        return None
    if who is not None:
        return slope_estimate(here.astype(float), y, who)
    va, vb = float(a.var(ddof=1)) / a.size, float(b.var(ddof=1)) / b.size
    se = math.sqrt(va + vb)
    df = (va + vb) ** 2 / (va * va / (a.size - 1) + vb * vb / (b.size - 1)) if se else 1.0
    return float(a.mean() - b.mean()), se, df


def mean_estimate(y: np.ndarray, who: np.ndarray | None) -> Estimate | None:
    """(mean of y, standard error, degrees of freedom), None below two values.
    Without participants: the trials' standard error, n - 1 degrees of
    freedom. With them: cluster-robust (CR1: each participant's summed
    deviations, G/(G-1)) with G - 1 degrees of freedom for the G participants:
    when every participant has as many trials, exactly the t interval over
    the participants' means, and centred on the trials' mean when they do
    not. None also below two participants."""
    if y.size < 2:
        return None
    m = float(y.mean())
    if who is None:
        return m, float(y.std(ddof=1)) / math.sqrt(y.size), float(y.size - 1)
    _, person = np.unique(who, return_inverse=True)
    g = int(person.max()) + 1
    if g < 2:
        return None
    scores = np.bincount(person, weights=y - m)
    return m, math.sqrt(g / (g - 1) * float(scores @ scores)) / y.size, float(g - 1)


def t_interval(est: Estimate | None, level: float) -> tuple[float, float]:
    """The t interval at ``level`` of an (estimate, standard error, degrees of
    freedom); NaN bounds for no estimate."""
    if est is None:
        return math.nan, math.nan
    b, se, df = est
    half = t_quantile(0.5 + level / 2, df) * se if se > 0 else 0.0
    return b - half, b + half


def judge(est: Estimate | None, margin: float, level: float,
           test_level: float) -> str:
    """Whether an estimated change is shown negligible or shown larger than
    negligible: "equal" when its ``2 * level - 1`` interval lies within
    +-``margin`` (an equivalence test at ``1 - level``), "differs" when its
    ``test_level`` interval lies entirely outside +-``margin`` (a change shown
    to exceed the margin, not merely shown to be there: a change of 7 % is
    not "differs" for a 10 % margin however many trials show it), "unclear"
    else, and when there is no estimate (too few points, or too few
    participants on both sides of it)."""
    if est is None:
        return "unclear"
    elo, ehi = t_interval(est, 2 * level - 1)
    if -margin <= elo and ehi <= margin:
        return "equal"
    lo, hi = t_interval(est, test_level)
    return "differs" if lo > margin or hi < -margin else "unclear"

