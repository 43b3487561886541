"""Each trial's level of a condition (viewing distance, altitude, speed), for
the trials analysis.

Owns how a condition's values become levels: rounded to a step, and, when a
condition takes more than ``MAX_LEVELS`` distinct values among the trials
analysed together (a measured value exported in place of the swept one),
cut into ``MAX_LEVELS`` bins of about equal trial counts
(``condition_levels``), so that the levels of a fit, the fits per held
condition and the rows of the tables stay few; and the key a level has in
tables (``level_key``: None where a trial has none).

Arrays in, arrays out: it reads no file, fits nothing and draws nothing.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: a condition (viewing distance, altitude, speed) with more distinct values
#: than this among the rows analysed together is cut into this many bins of
#: about equal trial counts (``condition_levels``): the levels of a fit, the
#: fits per held condition and the rows of the tables stay few
MAX_LEVELS = 20


def condition_levels(v: np.ndarray, round_to: float | None = None,
                     max_levels: int = MAX_LEVELS) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Each trial's level of a condition: its value rounded to ``round_to``
    (none when None), NaN where it has none. More than ``max_levels``
    distinct levels (a measured value exported in place of the swept one)
    are cut into ``max_levels`` bins of about equal trial counts, never
    splitting one value, and each trial's level is its bin's mean (rounded
    likewise, so it lies within the bin). Returns (levels, bins): the bins
    as ``{"lo", "hi", "level", "n" (trials), "values" (distinct values)}``,
    empty when the values were few."""
    v = np.asarray(v, dtype=float)
    out = v.copy()
    ok = np.isfinite(v)
    vr = np.round(v[ok] / round_to) * round_to if round_to else v[ok]
    out[ok] = vr
    values, inverse, counts = np.unique(vr, return_inverse=True, return_counts=True)
    if values.size <= max_levels:
        return out, []
    # the bin of each distinct value: by the share of trials below it
    first = (np.cumsum(counts) - counts) * max_levels // vr.size
    _, value_bin = np.unique(first, return_inverse=True)
    trial_bin = value_bin[inverse]
    n = np.bincount(trial_bin)
    mean = np.bincount(trial_bin, weights=vr) / n
    level = np.round(mean / round_to) * round_to if round_to else mean
    out[ok] = level[trial_bin]
    lo = np.full(n.size, np.inf)
    hi = np.full(n.size, -np.inf)
    np.minimum.at(lo, value_bin, values)
    np.maximum.at(hi, value_bin, values)
    held = np.bincount(value_bin)
    return out, [{"lo": float(a), "hi": float(b), "level": float(c), "n": int(k),
                  "values": int(u)} for a, b, c, k, u in zip(lo, hi, level, n, held)]


def level_key(v: float) -> float | None:
    """A level as a table's key: None where the trial has none (NaN)."""
    return None if math.isnan(v) else float(v)
