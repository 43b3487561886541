"""Analysis of conspicuity trial responses (DESIGN.md 3.5): ``analyse(csv, out_dir)``.

Reads the responses CSV the trial server exports (one row per response,
columns ``COLUMNS``), drops practice rows and writes into ``out_dir``:

- ``conspicuity.csv``: experiment 1 ("disappear" and "track" protocols) per condition
  (target, viewing distance, altitude and speed where given): n, mean and
  median conspicuity angle alpha (deg) and conspicuity distance (mm on the
  screen), means with a 95 % t interval, medians with a 95 % percentile
  bootstrap interval.
- ``critical_gap.csv``, ``critical_gap_predictions.csv``, ``critical_gap.png``:
  per target the critical gap ``CG = tan(alpha) * d`` (mm) and the threshold
  viewing distance ``d0`` above which it is constant, with the check that it
  is, and the angle ``beta = atan(CG / h)`` it predicts at each altitude
  present in the data (see ``fit_critical_gap`` for the method).
- ``recognition.csv``, ``recognition.png``: experiment 2 ("recognise"
  protocol) accuracy against altitude, speed, target, target angular size
  bins and eccentricity bins, with 95 % Wilson intervals, and a logistic
  regression of recognition on altitude and speed (target as a factor).
- ``analysis.json``: the summary ``analyse`` returns.

The CSV is untrusted: it is read up to ``MAX_BYTES`` and ``MAX_ROWS`` (larger
files are refused), every row is checked and all problems are reported at
once as ``ConfigError`` lines ``file:line: column: message``.

Owns only the reading and statistics of response files; it never talks to
the trial server, renders or runs a scenario. numpy, matplotlib (Agg) and the
standard library only (no scipy: the t and normal quantiles are computed
here).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np

from cosim.errors import ConfigError

log = logging.getLogger(__name__)

#: the columns the trial server exports, in its order
COLUMNS: tuple[str, ...] = (
    "session", "participant", "trial_index", "practice", "protocol", "clip", "run",
    "condition_speed_kt", "condition_alt_agl_m", "condition_target", "frame",
    "video_time_s", "reaction_time_ms", "key", "target_in_view", "eccentricity_deg",
    "onscreen_distance_mm", "target_angular_size_deg", "viewing_distance_mm",
    "screen_width_mm", "screen_height_mm", "screen_width_px", "screen_height_px",
    "recognised",
)
PROTOCOLS = ("disappear", "recognise", "track")
#: the protocols whose responses are conspicuity angles (the target's eccentricity
#: from where the eyes are: the fixation mark, or the tracked dot)
CONSPICUITY = ("disappear", "track")
#: input limits: larger files are refused, not truncated
MAX_BYTES = 50 * 1024 * 1024
MAX_ROWS = 1_000_000
#: problems kept for the error message (the rest are counted)
MAX_PROBLEMS = 200
#: eccentricity_deg and atan(onscreen_distance_mm / viewing_distance_mm) further apart
#: than this are counted (and logged) as inconsistent
ECCENTRICITY_TOLERANCE_DEG = 0.5
#: groups with more values than this are not bootstrapped value by value
#: (memory n_boot x values): a median gets the order-statistic interval, a
#: distance level's resampled sum is drawn from its normal distribution (exact
#: mean and variance)
_EXACT_BOOT_MAX = 2000

# numeric columns: name -> (required, lower bound, lower bound inclusive, upper bound)
# (the upper bound is inclusive but for eccentricity_deg: tan(90 deg) is no distance)
_NUMERIC: dict[str, tuple[bool, float, bool, float]] = {
    "trial_index": (True, 0.0, True, math.inf),
    "condition_speed_kt": (False, 0.0, True, math.inf),
    "condition_alt_agl_m": (False, 0.0, False, math.inf),
    "frame": (False, 0.0, True, math.inf),
    "video_time_s": (False, 0.0, True, math.inf),
    "reaction_time_ms": (False, 0.0, True, math.inf),
    "eccentricity_deg": (False, 0.0, True, 90.0),
    "onscreen_distance_mm": (False, 0.0, True, math.inf),
    "target_angular_size_deg": (False, 0.0, False, 180.0),
    "viewing_distance_mm": (True, 0.0, False, math.inf),
    "screen_width_mm": (True, 0.0, False, math.inf),
    "screen_height_mm": (True, 0.0, False, math.inf),
    "screen_width_px": (True, 0.0, False, math.inf),
    "screen_height_px": (True, 0.0, False, math.inf),
}
_INTEGER = {"trial_index", "frame", "screen_width_px", "screen_height_px"}
_FLAGS = ("practice", "target_in_view")


# ---------------------------------------------------------------- reading


@dataclass
class Responses:
    """Validated responses as numpy columns (one entry per row, file order).

    Numeric columns are float64 with NaN where the CSV cell was empty; text
    columns are lists of str. ``line`` holds each row's first line in the file.
    """

    path: str
    line: np.ndarray
    text: dict[str, list[str]]
    num: dict[str, np.ndarray]
    practice: np.ndarray  # bool
    target_in_view: np.ndarray  # bool
    recognised: np.ndarray  # float: NaN (empty), 0 or 1
    extra_columns: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.line.size)

    def subset(self, mask: np.ndarray) -> Responses:
        idx = np.flatnonzero(mask)
        return Responses(
            path=self.path, line=self.line[idx],
            text={k: [v[i] for i in idx] for k, v in self.text.items()},
            num={k: v[idx] for k, v in self.num.items()},
            practice=self.practice[idx], target_in_view=self.target_in_view[idx],
            recognised=self.recognised[idx], extra_columns=self.extra_columns)


class _Problems:
    def __init__(self, path: str) -> None:
        self.path = path
        self.kept: list[str] = []
        self.more = 0

    def add(self, line: int, message: str) -> None:
        if len(self.kept) < MAX_PROBLEMS:
            self.kept.append(f"{self.path}:{line}: {message}")
        else:
            self.more += 1

    def raise_if_any(self) -> None:
        if self.kept:
            raise ConfigError(self.kept, self.more)


def read_responses(csv_path: str | Path, *, max_bytes: int = MAX_BYTES,
                   max_rows: int = MAX_ROWS) -> Responses:
    """Read and check a responses CSV; raise ``ConfigError`` listing every bad row.

    The header must hold every column of ``COLUMNS`` (in any order; extra
    columns are ignored with a warning). Files over ``max_bytes`` or with
    more than ``max_rows`` data rows are refused. Each cell is checked:
    numbers finite and in range, flags 0/1, ``protocol`` one of
    ``PROTOCOLS``, ``recognised`` empty/0/1 (0/1 on "recognise" rows),
    ``eccentricity_deg`` and ``onscreen_distance_mm`` present on
    "disappear" rows with the target in view.
    """
    name = str(csv_path)
    try:
        with open(csv_path, "rb") as f:
            raw = f.read(max_bytes + 1)
    except OSError as e:
        raise ConfigError(f"{name}: cannot read: {e.strerror or e}") from e
    if len(raw) > max_bytes:
        raise ConfigError(f"{name}: larger than the limit of {max_bytes} bytes; refused "
                          "(split the file or analyse fewer sessions)")
    try:
        content = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise ConfigError(f"{name}:{line}: not UTF-8 text ({e.reason} at byte {e.start})") from e

    problems = _Problems(name)
    reader = csv.reader(io.StringIO(content, newline=""))
    try:
        header = next(reader, None)
    except csv.Error as e:
        raise ConfigError(f"{name}:1: unreadable header: {e}") from e
    if header is None or not any(h.strip() for h in header):
        raise ConfigError(f"{name}:1: empty file: expected a header with the columns "
                          f"{', '.join(COLUMNS)}")
    header = [h.strip() for h in header]
    missing = [c for c in COLUMNS if c not in header]
    dupes = sorted({h for h in header if header.count(h) > 1})
    if missing or dupes:
        msgs = []
        if missing:
            msgs.append(f"missing column{'s' if len(missing) > 1 else ''}: {', '.join(missing)}")
        if dupes:
            msgs.append(f"duplicate column{'s' if len(dupes) > 1 else ''}: {', '.join(dupes)}")
        raise ConfigError(f"{name}:1: {'; '.join(msgs)}")
    extra = [h for h in header if h not in COLUMNS]
    if extra:
        log.warning("%s: ignoring unknown columns: %s", name, ", ".join(extra))
    col = {c: header.index(c) for c in COLUMNS}

    text: dict[str, list[str]] = {c: [] for c in ("session", "participant", "protocol", "clip",
                                                  "run", "condition_target", "key")}
    num: dict[str, list[float]] = {c: [] for c in _NUMERIC}
    flags: dict[str, list[bool]] = {c: [] for c in _FLAGS}
    recognised: list[float] = []
    lines: list[int] = []
    rows = 0
    prev_line = 1
    while True:
        start = prev_line + 1
        try:
            row = next(reader, None)
        except csv.Error as e:
            raise ConfigError(problems.kept + [f"{name}:{start}: unreadable CSV: {e}"],
                              problems.more) from e
        prev_line = reader.line_num
        if row is None:
            break
        if not row or (len(row) == 1 and not row[0].strip()):
            continue  # blank line
        rows += 1
        if rows > max_rows:
            raise ConfigError(f"{name}:{start}: more than {max_rows} data rows; refused "
                              "(split the file or analyse fewer sessions)")
        if len(row) != len(header):
            problems.add(start, f"expected {len(header)} fields, got {len(row)}")
            continue
        cells = {c: row[i].strip() for c, i in col.items()}
        ok = True
        values: dict[str, float] = {}
        for c, (required, lo, lo_incl, hi) in _NUMERIC.items():
            v = _number(cells[c], c, required, lo, lo_incl, hi, c in _INTEGER)
            if isinstance(v, str):
                problems.add(start, f"{c}: {v}")
                ok = False
            else:
                values[c] = v
        fl: dict[str, bool] = {}
        for c in _FLAGS:
            if c == "target_in_view" and cells[c] == "":  # no key press: no frame shown
                fl[c] = False
                continue
            if cells[c] not in ("0", "1"):
                problems.add(start, f"{c}: expected 0 or 1, got {cells[c]!r}")
                ok = False
            else:
                fl[c] = cells[c] == "1"
        protocol = cells["protocol"]
        if protocol not in PROTOCOLS:
            problems.add(start, f"protocol: expected one of {', '.join(map(repr, PROTOCOLS))}, "
                                f"got {protocol!r}")
            ok = False
        rec = cells["recognised"]
        if rec not in ("", "0", "1"):
            problems.add(start, f"recognised: expected empty, 0 or 1, got {rec!r}")
            ok = False
        elif protocol == "recognise" and rec == "":
            problems.add(start, "recognised: required (0 or 1) on a 'recognise' response")
            ok = False
        if not cells["condition_target"]:
            problems.add(start, "condition_target: required, got an empty cell")
            ok = False
        if ok and protocol in CONSPICUITY and fl["target_in_view"]:
            for c in ("eccentricity_deg", "onscreen_distance_mm"):
                if math.isnan(values[c]):
                    problems.add(start, f"{c}: required on a 'disappear' response with "
                                        "the target in view, got an empty cell")
                    ok = False
        if not ok:
            continue
        lines.append(start)
        for c in text:
            text[c].append(cells[c])
        for c in _NUMERIC:
            num[c].append(values[c])
        for c in _FLAGS:
            flags[c].append(fl[c])
        recognised.append(math.nan if rec == "" else float(rec))
    problems.raise_if_any()
    return Responses(
        path=name, line=np.asarray(lines, dtype=np.int64), text=text,
        num={c: np.asarray(v, dtype=float) for c, v in num.items()},
        practice=np.asarray(flags["practice"], dtype=bool),
        target_in_view=np.asarray(flags["target_in_view"], dtype=bool),
        recognised=np.asarray(recognised, dtype=float), extra_columns=extra)


def _number(cell: str, column: str, required: bool, lo: float, lo_incl: bool, hi: float,
            integer: bool) -> float | str:
    """The cell as a float (NaN when empty and optional) or a problem message."""
    if cell == "":
        return "required, got an empty cell" if required else math.nan
    try:
        v = float(cell)
    except ValueError:
        return f"expected a number, got {cell[:40]!r}"
    if not math.isfinite(v):
        return f"expected a finite number, got {cell[:40]!r}"
    if integer and v != int(v):
        return f"expected a whole number, got {cell!r}"
    hi_incl = column != "eccentricity_deg"
    if v < lo or (v == lo and not lo_incl) or v > hi or (v == hi and not hi_incl):
        left = "[" if lo_incl else "("
        right = "]" if hi_incl else ")"
        return f"expected a value in {left}{lo:g}, {hi:g}{right}, got {cell!r}"
    return v


# ---------------------------------------------------------------- statistics


def t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t with ``df`` degrees of freedom.

    Exact for df 1 and 2; otherwise the Cornish-Fisher expansion of
    Abramowitz & Stegun 26.7.5 around the normal quantile (relative error
    below 1e-3 at p = 0.975 for df >= 3).
    """
    if not 0.0 < p < 1.0 or not df > 0:
        raise ValueError(f"t_quantile: need 0 < p < 1 and df > 0, got p={p!r}, df={df!r}")
    if df == 1:
        return math.tan(math.pi * (p - 0.5))
    if df == 2:
        return (2 * p - 1) / math.sqrt(2 * p * (1 - p))
    z = NormalDist().inv_cdf(p)
    g1 = (z ** 3 + z) / 4
    g2 = (5 * z ** 5 + 16 * z ** 3 + 3 * z) / 96
    g3 = (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / 384
    g4 = (79 * z ** 9 + 776 * z ** 7 + 1482 * z ** 5 - 1920 * z ** 3 - 945 * z) / 92160
    return z + g1 / df + g2 / df ** 2 + g3 / df ** 3 + g4 / df ** 4


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
    values). Above ``_EXACT_BOOT_MAX`` values the distribution-free
    order-statistic interval (ranks n/2 -+ z sqrt(n)/2) replaces the bootstrap."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    med = float(np.median(x))
    if x.size < 2:
        return med, math.nan, math.nan
    if x.size > _EXACT_BOOT_MAX:
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


def slope_ci(x: np.ndarray, y: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """OLS slope of y on x and its t interval (NaN without at least 3 points
    and 2 distinct x). The standard error is the heteroscedasticity-consistent
    HC3 one: the spread of tan(alpha)*d grows with d (an angle error of e
    is a distance error of about e*d)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size < 3 or np.ptp(x) == 0:
        return math.nan, math.nan, math.nan
    xc = x - x.mean()
    sxx = float(xc @ xc)
    b = float(xc @ (y - y.mean())) / sxx
    res = y - y.mean() - b * xc
    lev = 1.0 / x.size + xc * xc / sxx
    se = math.sqrt(float(np.sum((xc * res / (1.0 - lev)) ** 2))) / sxx
    half = t_quantile(0.5 + level / 2, x.size - 2) * se
    return b, b - half, b + half


# ---------------------------------------------------------------- critical gap


@dataclass(frozen=True)
class CriticalGapFit:
    """The critical gap of one target (``fit_critical_gap``).

    ``status``: "plateau" (tan(alpha)*d rises up to ``d0_mm`` and is
    constant above it), "plateau_from_start" (constant over every distance
    tested: the threshold is at or below the shortest, ``d0_mm``),
    "no_plateau" (still changing above the best breakpoint: no critical
    gap established within the distances tested; ``cg_mm`` and ``d0_mm``
    are None; ``detail`` says why) or
    "insufficient_data" (fewer than ``min_plateau_levels + 1`` viewing
    distances, or fewer than two trials a distance on average).
    """

    status: str
    detail: str
    n: int
    distances_mm: list[float]
    cg_mm: float | None = None
    cg_ci_mm: tuple[float, float] | None = None
    d0_mm: float | None = None
    d0_ci_mm: tuple[float, float] | None = None
    #: the two-segment fit at the chosen breakpoint: plateau level and slope below it
    fit_level_mm: float | None = None
    rising_slope: float | None = None
    rising_slope_ci: tuple[float, float] | None = None
    breakpoint_mm: float | None = None
    #: residual check: slope of tan(alpha)*d against d at and above the breakpoint (mm/mm)
    plateau_slope: float | None = None
    plateau_slope_ci: tuple[float, float] | None = None
    plateau_n: int = 0
    plateau_levels: int = 0
    rmse_mm: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def _candidates(levels: np.ndarray, steps: int, min_plateau_levels: int) -> np.ndarray:
    """Breakpoints tried: the shortest distance (no rising part), then a fine
    grid from the second distance up to the one that leaves
    ``min_plateau_levels`` distances on the plateau for the check (with one
    distance below the breakpoint any breakpoint between the first two fits
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
    """Least-squares ``y = a + s * min(d - c, 0)``, ``s >= 0``, for every
    candidate ``c`` at once, from per-level counts and sums of y (the fit
    needs no more: every trial at a level has the same regressor).

    ``sums`` is (L,) or (B, L) (B bootstrap replicates). Returns
    ``(sse_part, a, s, det)``, each (C,) or (B, C); ``sse_part`` is the
    squared error less the sum of y**2 (the same for every candidate).
    """
    x = np.minimum(levels[None, :] - cand[:, None], 0.0)  # (C, L)
    n = float(counts.sum())
    sx = x @ counts
    sxx = (x * x) @ counts
    sxy = sums @ x.T
    sy = sums.sum(axis=-1, keepdims=True) if sums.ndim == 2 else float(sums.sum())
    det = n * sxx - sx * sx
    good = det > 1e-9 * np.maximum(n * sxx, 1e-300)
    slope = np.where(good, (n * sxy - sx * sy) / np.where(good, det, 1.0), 0.0)
    slope = np.maximum(slope, 0.0)  # below the threshold tan(alpha)*d rises (or is flat)
    a = (sy - slope * sx) / n
    part = -2 * a * sy - 2 * slope * sxy + n * a * a + 2 * a * slope * sx + slope * slope * sxx
    return part, a, slope, det


def _boot_level_sums(g_by_level: list[np.ndarray], rng: np.random.Generator,
                     n_boot: int) -> np.ndarray:
    """(n_boot, L) sums of y over trials resampled with replacement within each level."""
    out = np.empty((n_boot, len(g_by_level)))
    for j, g in enumerate(g_by_level):
        if g.size <= _EXACT_BOOT_MAX:
            out[:, j] = g[rng.integers(0, g.size, size=(n_boot, g.size))].sum(axis=1)
        else:
            out[:, j] = rng.normal(g.sum(), math.sqrt(g.size * float(g.var())), n_boot)
    return out


def fit_critical_gap(d_mm: np.ndarray, alpha_deg: np.ndarray, *, rng: np.random.Generator,
                     distance_round_mm: float = 10.0, steps: int = 10, n_boot: int = 1000,
                     min_plateau_levels: int = 3, level: float = 0.95) -> CriticalGapFit:
    """Estimate the critical gap and threshold distance of one target.

    Method: ``g = tan(alpha) * d`` (the conspicuity distance in mm implied by
    the angle) against the viewing distance ``d`` (rounded to
    ``distance_round_mm`` to form the distance levels) is fitted by a
    continuous two-segment ("hinge") model ``g = CG + s * min(d - d0, 0)``
    with ``s >= 0``: rising linearly below ``d0``, constant above. For each
    candidate ``d0`` (``_candidates``: the distance levels and ``steps``
    subdivisions between them) the model is linear in (CG, s) and solved by
    least squares; ``d0`` is the candidate of least squared error. At least
    ``min_plateau_levels`` distances must lie at or above ``d0`` (with two,
    a plateau is wrongly found in 1-2 % of data sets that rise everywhere;
    so a threshold within the last two distances tested cannot be found).

    Then, in order:

    1. rising part: if ``d0`` is above the shortest distance but the 95 %
       t interval of ``s`` (given ``d0``) includes 0, the rise is not
       resolved and the constant model (``d0`` = shortest distance) is used;
    2. residual check: the OLS slope of ``g`` against ``d`` over the trials
       at and above ``d0`` (``min_plateau_levels`` distances) must have a 95 %
       t interval (HC3 standard error) that contains 0 and, when there is a
       rising part, lies below its slope ``s`` (the bend is real, not a lack
       of data above ``d0``); otherwise no plateau is established within the
       distances tested ("no_plateau", no CG reported);
    3. CG is the mean of ``g`` over the plateau; the intervals of CG and
       ``d0`` are percentile bootstrap intervals (trials resampled within
       each distance level, the breakpoint chosen anew each time).

    Trials are treated as independent (participants are not modelled).
    """
    d_mm = np.asarray(d_mm, dtype=float)
    g = np.tan(np.radians(np.asarray(alpha_deg, dtype=float))) * d_mm
    dr = np.round(d_mm / distance_round_mm) * distance_round_mm
    levels = np.unique(dr)
    n = int(g.size)
    base: dict[str, Any] = {"n": n, "distances_mm": [float(v) for v in levels]}
    if min_plateau_levels < 2:
        raise ValueError(f"min_plateau_levels must be >= 2, got {min_plateau_levels}")
    need = min_plateau_levels + 1
    if levels.size < need or n < 2 * need:
        return CriticalGapFit(status="insufficient_data",
                              detail=f"{n} trials at {levels.size} viewing distances: need at "
                                     f"least {2 * need} trials at {need} distances", **base)
    cand = _candidates(levels, steps, min_plateau_levels)
    g_by_level = [g[dr == v] for v in levels]
    counts = np.array([x.size for x in g_by_level], dtype=float)
    part, a, s, det = _hinge(levels, counts, np.array([x.sum() for x in g_by_level]), cand)
    sse = np.maximum(part + float(g @ g), 0.0)
    best = int(np.argmin(sse))
    d0 = float(cand[best])
    zq = t_quantile(0.5 + level / 2, max(n - 2, 1))
    s_ci: tuple[float, float] | None = None
    if d0 > levels[0] and det[best] > 0:
        sigma2 = float(sse[best]) / (n - 2)
        half = zq * math.sqrt(sigma2 * n / float(det[best]))
        s_ci = (float(s[best]) - half, float(s[best]) + half)
    rising_resolved = s_ci is not None and s_ci[0] > 0
    if not rising_resolved:
        best = 0  # the first candidate is the shortest distance: no rising part
        d0 = float(cand[0])
    fit_level = float(a[best])
    rmse = math.sqrt(float(sse[best]) / n)
    above = dr >= d0 - 1e-9
    pb, plo, phi = slope_ci(dr[above], g[above], level)
    common: dict[str, Any] = dict(
        base, breakpoint_mm=d0, fit_level_mm=fit_level,
        rising_slope=float(s[best]) if rising_resolved else 0.0,
        rising_slope_ci=s_ci if rising_resolved else None,
        plateau_slope=pb, plateau_slope_ci=(plo, phi), plateau_n=int(above.sum()),
        plateau_levels=int(np.unique(dr[above]).size), rmse_mm=rmse)
    if not plo <= 0.0 <= phi:
        return CriticalGapFit(
            status="no_plateau",
            detail=(f"tan(alpha)*d still changes above the best breakpoint {d0:g} mm: slope "
                    f"{pb:.4g} mm/mm, {level:.0%} CI [{plo:.4g}, {phi:.4g}] excludes 0; no "
                    f"critical gap within {levels[0]:g}-{levels[-1]:g} mm"),
            **common)
    if rising_resolved and phi >= float(s[best]):
        return CriticalGapFit(
            status="no_plateau",
            detail=(f"above the best breakpoint {d0:g} mm the slope of tan(alpha)*d "
                    f"({pb:.4g} mm/mm, {level:.0%} CI [{plo:.4g}, {phi:.4g}]) cannot be told "
                    f"from the slope below it ({float(s[best]):.4g}): no plateau established "
                    f"within {levels[0]:g}-{levels[-1]:g} mm (too few trials above it?)"),
            **common)

    # bootstrap: resample within distance levels, choose the breakpoint anew
    boot = _boot_level_sums(g_by_level, rng, n_boot)  # (B, L)
    if rising_resolved:
        bpart, _, _, _ = _hinge(levels, counts, boot, cand)
        d0s = cand[np.argmin(bpart, axis=1)]
    else:
        d0s = np.full(n_boot, cand[0])
    on = levels[None, :] >= d0s[:, None] - 1e-9  # (B, L): levels on the plateau
    cgs = (boot * on).sum(axis=1) / (on * counts).sum(axis=1)
    q = [(1 - level) / 2, (1 + level) / 2]
    cg_lo, cg_hi = (float(v) for v in np.quantile(cgs, q))
    d0_lo, d0_hi = (float(v) for v in np.quantile(d0s, q))
    cg = float(g[above].mean())
    if rising_resolved:
        status = "plateau"
        detail = (f"tan(alpha)*d rises up to d0 = {d0:g} mm and is constant above it "
                  f"(slope {pb:.3g} mm/mm, {level:.0%} CI [{plo:.3g}, {phi:.3g}] contains 0)")
    else:
        status = "plateau_from_start"
        detail = (f"tan(alpha)*d is constant over every distance tested ({levels[0]:g}-"
                  f"{levels[-1]:g} mm): the threshold is at or below {levels[0]:g} mm")
    return CriticalGapFit(status=status, detail=detail, cg_mm=cg, cg_ci_mm=(cg_lo, cg_hi),
                          d0_mm=d0, d0_ci_mm=(d0_lo, d0_hi), **common)


def predict_beta_deg(cg_mm: float, alt_agl_m: float) -> float:
    """The angle under which the critical gap is seen from altitude h:
    ``tan(beta) = CG / h`` (CG and h in one unit; the relation of
    ``cosim.conspicuity.angles.angle_for_gap_deg``)."""
    return math.degrees(math.atan(cg_mm / (alt_agl_m * 1000.0)))


# ---------------------------------------------------------------- recognition


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


# ---------------------------------------------------------------- the whole analysis


CONSPICUITY_FIELDS = (
    "target", "viewing_distance_mm", "alt_agl_m", "speed_kt", "n",
    "alpha_mean_deg", "alpha_mean_ci_lo_deg", "alpha_mean_ci_hi_deg",
    "alpha_median_deg", "alpha_median_ci_lo_deg", "alpha_median_ci_hi_deg",
    "distance_mean_mm", "distance_mean_ci_lo_mm", "distance_mean_ci_hi_mm",
    "distance_median_mm", "distance_median_ci_lo_mm", "distance_median_ci_hi_mm",
    "gap_mean_mm",
)
CRITICAL_GAP_FIELDS = (
    "target", "status", "n", "distances_mm", "cg_mm", "cg_ci_lo_mm", "cg_ci_hi_mm",
    "d0_mm", "d0_ci_lo_mm", "d0_ci_hi_mm", "breakpoint_mm", "rising_slope",
    "plateau_slope", "plateau_slope_ci_lo", "plateau_slope_ci_hi", "plateau_n",
    "plateau_levels", "rmse_mm", "detail",
)
PREDICTION_FIELDS = ("target", "alt_agl_m", "cg_mm", "tan_beta", "beta_deg",
                     "beta_ci_lo_deg", "beta_ci_hi_deg")
RECOGNITION_FIELDS = ("factor", "level", "bin_lo", "bin_hi", "n", "recognised", "accuracy",
                      "ci_lo", "ci_hi", "reaction_time_mean_ms")


def analyse(csv_path: str | Path, out_dir: str | Path, *, seed: int = 0,
            n_boot: int = 1000, distance_round_mm: float = 10.0, n_bins: int = 4,
            min_plateau_levels: int = 3, plots: bool = True, max_bytes: int = MAX_BYTES,
            max_rows: int = MAX_ROWS) -> dict[str, Any]:
    """Analyse a responses CSV into ``out_dir`` and return the summary.

    ``csv_path``: the trial server's export (``COLUMNS``); refused with a
    ``ConfigError`` naming file:line of every bad row, or when larger than
    ``max_bytes`` / ``max_rows``. Practice rows are excluded from everything.

    Writes ``conspicuity.csv``, ``critical_gap.csv``,
    ``critical_gap_predictions.csv``, ``recognition.csv``, ``analysis.json``
    and (with ``plots``) ``critical_gap.png`` and ``recognition.png``;
    every file is written even when its protocol has no rows (header only,
    a "no data" figure).

    ``seed`` fixes the bootstraps (``n_boot`` resamples); viewing distances
    are grouped to the nearest ``distance_round_mm``; angular size and
    eccentricity are cut into ``n_bins`` quantile bins.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    allr = read_responses(csv_path, max_bytes=max_bytes, max_rows=max_rows)
    r = allr.subset(~allr.practice)
    protocol = np.asarray(r.text["protocol"], dtype=object)
    dis = r.subset(np.isin(protocol, CONSPICUITY))
    rec = r.subset(protocol == "recognise")

    # ---- experiment 1: conspicuity per condition
    in_view = dis.target_in_view
    used = dis.subset(in_view)
    alpha = used.num["eccentricity_deg"]
    dist = used.num["onscreen_distance_mm"]
    vd = used.num["viewing_distance_mm"]
    implied = np.degrees(np.arctan(dist / vd))
    bad_ecc = np.abs(implied - alpha) > ECCENTRICITY_TOLERANCE_DEG
    if bad_ecc.any():
        log.warning("%s: %d 'disappear' rows whose eccentricity_deg differs from "
                    "atan(onscreen_distance_mm / viewing_distance_mm) by more than %g deg "
                    "(first at line %d)", allr.path, int(bad_ecc.sum()),
                    ECCENTRICITY_TOLERANCE_DEG, int(used.line[np.argmax(bad_ecc)]))
    vd_r = np.round(vd / distance_round_mm) * distance_round_mm
    targets = used.text["condition_target"]
    alt = used.num["condition_alt_agl_m"]
    spd = used.num["condition_speed_kt"]
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i in range(len(used)):
        key = (targets[i], float(vd_r[i]), _key(alt[i]), _key(spd[i]))
        groups.setdefault(key, []).append(i)
    cons_rows: list[dict[str, Any]] = []
    for key in sorted(groups, key=_sort_key):
        m = np.asarray(groups[key], dtype=np.int64)
        a_m, a_lo, a_hi = mean_ci(alpha[m])
        a_md, a_mlo, a_mhi = median_ci(alpha[m], rng, n_boot)
        s_m, s_lo, s_hi = mean_ci(dist[m])
        s_md, s_mlo, s_mhi = median_ci(dist[m], rng, n_boot)
        gap = float(np.mean(np.tan(np.radians(alpha[m])) * vd[m]))
        cons_rows.append(dict(zip(CONSPICUITY_FIELDS, (
            key[0], key[1], key[2], key[3], int(m.size), a_m, a_lo, a_hi, a_md, a_mlo,
            a_mhi, s_m, s_lo, s_hi, s_md, s_mlo, s_mhi, gap))))
    _write_csv(out / "conspicuity.csv", CONSPICUITY_FIELDS, cons_rows)

    # ---- critical gap per target, predictions at every altitude present
    altitudes = sorted({float(v) for v in r.num["condition_alt_agl_m"] if not math.isnan(v)})
    fits: dict[str, CriticalGapFit] = {}
    tarr = np.asarray(targets, dtype=object)
    for t in sorted(set(targets)):
        m = tarr == t
        fits[t] = fit_critical_gap(vd[m], alpha[m], rng=rng, n_boot=n_boot,
                                   distance_round_mm=distance_round_mm,
                                   min_plateau_levels=min_plateau_levels)
    cg_rows = []
    pred_rows = []
    for t, f in fits.items():
        cg_rows.append({
            "target": t, "status": f.status, "n": f.n,
            "distances_mm": " ".join(f"{v:g}" for v in f.distances_mm),
            "cg_mm": f.cg_mm, "cg_ci_lo_mm": f.cg_ci_mm[0] if f.cg_ci_mm else None,
            "cg_ci_hi_mm": f.cg_ci_mm[1] if f.cg_ci_mm else None, "d0_mm": f.d0_mm,
            "d0_ci_lo_mm": f.d0_ci_mm[0] if f.d0_ci_mm else None,
            "d0_ci_hi_mm": f.d0_ci_mm[1] if f.d0_ci_mm else None,
            "breakpoint_mm": f.breakpoint_mm, "rising_slope": f.rising_slope,
            "plateau_slope": f.plateau_slope,
            "plateau_slope_ci_lo": f.plateau_slope_ci[0] if f.plateau_slope_ci else None,
            "plateau_slope_ci_hi": f.plateau_slope_ci[1] if f.plateau_slope_ci else None,
            "plateau_n": f.plateau_n, "plateau_levels": f.plateau_levels,
            "rmse_mm": f.rmse_mm, "detail": f.detail})
        if f.cg_mm is None:
            continue
        for h in altitudes:
            lo, hi = f.cg_ci_mm if f.cg_ci_mm else (math.nan, math.nan)
            pred_rows.append({
                "target": t, "alt_agl_m": h, "cg_mm": f.cg_mm,
                "tan_beta": f.cg_mm / (h * 1000.0), "beta_deg": predict_beta_deg(f.cg_mm, h),
                "beta_ci_lo_deg": predict_beta_deg(max(lo, 0.0), h),
                "beta_ci_hi_deg": predict_beta_deg(max(hi, 0.0), h)})
    _write_csv(out / "critical_gap.csv", CRITICAL_GAP_FIELDS, cg_rows)
    _write_csv(out / "critical_gap_predictions.csv", PREDICTION_FIELDS, pred_rows)

    # ---- experiment 2: recognition
    rec_rows, logistic = _recognition(rec, n_bins)
    _write_csv(out / "recognition.csv", RECOGNITION_FIELDS, rec_rows)

    files = ["conspicuity.csv", "critical_gap.csv", "critical_gap_predictions.csv",
             "recognition.csv", "analysis.json"]
    if plots:
        _plot_critical_gap(out / "critical_gap.png", used, fits, distance_round_mm)
        _plot_recognition(out / "recognition.png", rec_rows)
        files += ["critical_gap.png", "recognition.png"]

    n_rec = len(rec)
    k_rec = int(np.nansum(rec.recognised))
    summary: dict[str, Any] = {
        "input": allr.path,
        "rows": len(allr),
        "practice_rows_excluded": int(allr.practice.sum()),
        "ignored_columns": allr.extra_columns,
        "disappear": {
            "responses": len(dis), "used": len(used),
            "excluded_target_not_in_view": int((~in_view).sum()),
            "eccentricity_inconsistent_rows": int(bad_ecc.sum()),
            "conditions": len(cons_rows),
        },
        "critical_gap": {t: f.as_dict() for t, f in fits.items()},
        "predictions": pred_rows,
        "recognise": {
            "responses": n_rec, "recognised": k_rec,
            "accuracy": k_rec / n_rec if n_rec else None,
            "accuracy_ci": list(wilson_ci(k_rec, n_rec)) if n_rec else None,
            "by": _by_factor(rec_rows),
            "logistic": logistic,
        },
        "settings": {"seed": seed, "n_boot": n_boot, "distance_round_mm": distance_round_mm,
                     "n_bins": n_bins, "min_plateau_levels": min_plateau_levels},
        "out_dir": str(out),
        "files": files,
    }
    summary = _json_clean(summary)
    (out / "analysis.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return summary


def _recognition(rec: Responses, n_bins: int) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Accuracy tables per factor, and the logistic regression on altitude and speed."""
    y = rec.recognised
    rt = rec.num["reaction_time_ms"]
    rows: list[dict[str, Any]] = []

    def add(factor: str, label: str, m: np.ndarray, lo: float | None = None,
            hi: float | None = None) -> None:
        n = int(m.sum())
        k = int(y[m].sum())
        c_lo, c_hi = wilson_ci(k, n)
        rts = rt[m][~np.isnan(rt[m])]
        rows.append(dict(zip(RECOGNITION_FIELDS, (
            factor, label, lo, hi, n, k, k / n if n else None, c_lo, c_hi,
            float(rts.mean()) if rts.size else None))))

    for factor, col in (("alt_agl_m", "condition_alt_agl_m"), ("speed_kt", "condition_speed_kt")):
        v = rec.num[col]
        for lv in sorted({float(x) for x in v if not math.isnan(x)}):
            add(factor, f"{lv:g}", v == lv, lv, lv)
    tarr = np.asarray(rec.text["condition_target"], dtype=object)
    for t in sorted(set(rec.text["condition_target"])):
        add("target", t, tarr == t)
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
            add(factor, f"[{lo:.3g}, {hi:.3g}{']' if last else ')'}", m, lo, hi)

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
    targets = sorted(set(rec.text["condition_target"]))
    for t in targets[1:]:
        cols.append((tarr == t).astype(float))
        names.append(f"target[{t}]")
    if not names or use.sum() < len(names) + 2:
        logistic: dict[str, Any] = {"converged": False, "n": int(use.sum()),
                                    "detail": "no factor varies (or too few responses)"}
    else:
        x = np.column_stack([c[use] for c in cols])
        logistic = logistic_regression(x, y[use], names)
        if targets[1:]:
            logistic["reference_target"] = targets[0]
    return rows, logistic


def _by_factor(rows: Iterable[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    by: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by.setdefault(row["factor"], []).append(
            {k: row[k] for k in ("level", "n", "accuracy", "ci_lo", "ci_hi")})
    return by


def _key(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


def _sort_key(key: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple((0, "") if v is None else (1, v) for v in key)


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def _write_csv(path: Path, fields: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(fields)
        for row in rows:
            w.writerow([_fmt(row.get(k)) for k in fields])


def _json_clean(v: Any) -> Any:
    """NaN/inf -> None, numpy scalars -> Python, tuples -> lists."""
    if isinstance(v, dict):
        return {str(k): _json_clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_clean(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# ---------------------------------------------------------------- figures


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_critical_gap(path: Path, used: Responses, fits: dict[str, CriticalGapFit],
                       distance_round_mm: float) -> None:
    plt = _pyplot()
    n = max(len(fits), 1)
    fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 3.8), squeeze=False)
    if not fits:
        axes[0, 0].text(0.5, 0.5, "no 'disappear' responses", ha="center", va="center")
        axes[0, 0].set_axis_off()
    tarr = np.asarray(used.text["condition_target"], dtype=object)
    for ax, (t, f) in zip(axes[0], fits.items()):
        m = tarr == t
        d = used.num["viewing_distance_mm"][m]
        g = np.tan(np.radians(used.num["eccentricity_deg"][m])) * d
        ax.plot(d, g, ".", color="0.6", ms=3, label="trials")
        dr = np.round(d / distance_round_mm) * distance_round_mm
        lv = np.unique(dr)
        stats = [mean_ci(g[dr == v]) for v in lv]
        mu = np.array([s[0] for s in stats])
        err = np.array([[s[0] - s[1], s[2] - s[0]] for s in stats]).T
        ax.errorbar(lv, mu, yerr=np.nan_to_num(err), fmt="o", color="C0", capsize=3,
                    label="mean, 95% CI")
        if f.breakpoint_mm is not None and f.fit_level_mm is not None:
            xs = np.linspace(lv[0], lv[-1], 200)
            ys = f.fit_level_mm + (f.rising_slope or 0.0) * np.minimum(xs - f.breakpoint_mm, 0)
            ax.plot(xs, ys, "-" if f.cg_mm is not None else ":",
                    color="C3" if f.cg_mm is not None else "C1",
                    label="two-segment fit" if f.cg_mm is not None
                    else "best two-segment fit (rejected)")
        if f.cg_mm is not None and f.d0_mm is not None:
            ax.axhline(f.cg_mm, color="C3", ls=":", lw=1, label=f"CG = {f.cg_mm:.3g} mm")
            ax.axvline(f.d0_mm, color="C3", ls="--", lw=1, label=f"d0 = {f.d0_mm:.0f} mm")
        ax.set_title(f"{t}: {f.status}", fontsize=10)
        ax.set_xlabel("viewing distance d (mm)")
        ax.set_ylabel("tan(alpha) * d (mm)")
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_recognition(path: Path, rows: list[dict[str, Any]]) -> None:
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
        acc = np.array([r["accuracy"] for r in rs], dtype=float)
        err = np.array([[r["accuracy"] - r["ci_lo"], r["ci_hi"] - r["accuracy"]] for r in rs],
                       dtype=float).T
        if factor in ("alt_agl_m", "speed_kt"):
            x = np.array([r["bin_lo"] for r in rs], dtype=float)
            ax.errorbar(x, acc, yerr=err, fmt="o-", capsize=3)
        else:
            x = np.arange(len(rs), dtype=float)
            ax.errorbar(x, acc, yerr=err, fmt="o", capsize=3)
            ax.set_xticks(x)
            ax.set_xticklabels([r["level"] for r in rs], rotation=20, fontsize=7)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(titles.get(factor, factor))
        ax.set_ylabel("accuracy (95% Wilson)")
    for ax in flat[len(by) if by else 1:]:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
