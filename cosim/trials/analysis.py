"""Analysis of conspicuity trial responses (DESIGN.md 3.5): ``analyse(csv, out_dir)``.

Reads the responses CSV the trial server exports (one row per response,
columns ``COLUMNS``), drops practice rows and writes into ``out_dir``:

- ``conspicuity.csv``: experiment 1 ("disappear" and "track" protocols) per condition
  (target, viewing distance, altitude and speed where given): n, participants,
  mean and median conspicuity angle alpha (deg) and conspicuity distance (mm
  on the screen), means with a 95 % t interval, medians with a 95 %
  percentile bootstrap interval; and, where the clips' field of view is
  known, the mean angle beta seen from the camera and the gap on the ground
  ``tan(beta) * h`` (m).
- ``critical_gap.csv``, ``critical_gap_check.csv``, ``critical_gap.png``: the
  critical-gap relation ``CG = tan(alpha) * d = tan(beta) * h`` (DESIGN 3.5)
  in its two planes, per protocol and target. On the screen: the
  on-screen distance (``tan(alpha) * d``, mm) against the viewing distance,
  per altitude when several; its critical gap and the threshold viewing
  distance ``d0``. On the ground: ``tan(beta) * h`` (m) against the altitude,
  per viewing distance when several, ``beta`` being the conspicuity angle
  seen from the camera (``camera_gap_deg``) and ``h`` the camera's depth to
  the target (``target_depth_m``; the altitude where unknown): for a nadir
  camera the distance on the ground between the point looked at and the
  target; its critical gap and the threshold altitude ``h0``. "Constant"
  means equal within a tolerance (10 % of the gap), shown by an equivalence
  test; data that cannot show it are "inconclusive" (``fit_gap``). Each
  plateau is checked level by level: the gap of the other levels predicts
  the angle there (``tan(beta) = CG / h``; levels that fail themselves left
  out of the others), and the difference is judged "holds", "fails" (shown
  to exceed the tolerance) or "inconclusive" (``check_across_levels``).
  Participants' trials are not taken as independent: slopes and
  differences are compared within participants, the CG interval is a t
  interval over participants. The
  two planes are not mixed: the screen's mm and the ground's metres are
  related only through a clip's camera and the display, which differ
  between studies.
- ``recognition.csv``, ``recognition.png``: experiment 2 ("recognise"
  protocol) accuracy against altitude, speed, target, target angular size
  bins and eccentricity bins, with 95 % Wilson intervals, and a logistic
  regression of recognition on altitude and speed (target as a factor).
- ``analysis.json``: the summary ``analyse`` returns.

The CSV is untrusted: it must be a regular file (a FIFO or a device is never
opened for reading), it is read up to ``MAX_BYTES`` and ``MAX_ROWS`` (larger
files are refused), every row is checked and all problems are reported at
once as ``ConfigError`` lines ``file:line: column: message``. The work is
bounded whatever the file holds: a condition with more than ``MAX_LEVELS``
distinct values (a measured altitude exported in place of the swept one) is
cut into ``MAX_LEVELS`` bins (``bin_conditions``), at most ``MAX_FITS``
critical-gap fits are made (more is refused) and ``critical_gap.png`` shows at
most ``MAX_PANELS`` of them. Every CSV written is safe to open in a
spreadsheet (``cosim.trials.spreadsheet``).

Owns only the reading and statistics of response files; it never talks to
the trial server, renders or runs a scenario. numpy, scipy.stats (the t
distribution), matplotlib (Agg) and the standard library.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import ConfigError
from cosim.trials.conditions import MAX_LEVELS, condition_levels, level_key
from cosim.trials.critical_gap import GapFit, fit_gap
from cosim.trials.critical_gap_check import check_across_levels
from cosim.trials.estimates import mean_ci, median_ci, wilson_ci
from cosim.trials.recognition import RECOGNITION_FIELDS, analyse_recognition, by_factor
from cosim.trials.responses import CONSPICUITY, MAX_BYTES, MAX_ROWS, Responses, read_responses
from cosim.trials.spreadsheet import SafeWriter

log = logging.getLogger(__name__)

#: eccentricity_deg and atan(onscreen_distance_mm / viewing_distance_mm) further apart
#: than this are counted (and logged) as inconsistent
ECCENTRICITY_TOLERANCE_DEG = 0.5
#: critical-gap fits one analysis makes at most (protocols x targets x held
#: conditions x the two planes); responses asking for more are refused
MAX_FITS = 200
#: panels of critical_gap.png (the fits with a critical gap first); every fit
#: is in critical_gap.csv
MAX_PANELS = 12


# ---------------------------------------------------------------- recognition


# ---------------------------------------------------------------- the whole analysis


CONSPICUITY_FIELDS = (
    "protocol", "target", "viewing_distance_mm", "alt_agl_m", "speed_kt", "n",
    "alpha_mean_deg", "alpha_mean_ci_lo_deg", "alpha_mean_ci_hi_deg",
    "alpha_median_deg", "alpha_median_ci_lo_deg", "alpha_median_ci_hi_deg",
    "distance_mean_mm", "distance_mean_ci_lo_mm", "distance_mean_ci_hi_mm",
    "distance_median_mm", "distance_median_ci_lo_mm", "distance_median_ci_hi_mm",
    "gap_mean_mm", "participants", "beta_n", "beta_mean_deg", "beta_mean_ci_lo_deg",
    "beta_mean_ci_hi_deg", "ground_gap_mean_m",
)
CRITICAL_GAP_FIELDS = (
    "fit", "target", "protocol", "variable", "unit", "held", "status", "n", "participants",
    "levels", "cg", "cg_ci_lo", "cg_ci_hi", "cg_interval", "threshold", "threshold_ci_lo",
    "threshold_ci_hi", "breakpoint", "rising_slope", "plateau_slope", "plateau_slope_ci_lo",
    "plateau_slope_ci_hi", "negligible_slope", "plateau_n", "plateau_levels", "rmse",
    "levels_holds", "levels_fails", "levels_inconclusive", "levels_untested", "detail",
)
CHECK_FIELDS = (
    "fit", "target", "variable", "unit", "level", "n", "verdict", "holds", "gap_mean",
    "gap_ci_lo", "gap_ci_hi", "angle_measured_deg", "angle_predicted_deg", "cg_predicting",
    "compared_with", "difference", "difference_ci_lo", "difference_ci_hi", "confidence",
)


@dataclass(frozen=True)
class _GapData:
    """One critical-gap fit and the trials it was made from."""

    label: str
    target: str
    protocol: str
    held: str  # what is the same for every trial of the fit ("" when nothing else varies)
    x: np.ndarray
    g: np.ndarray
    people: np.ndarray
    fit: GapFit


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


def _gap_fits(used: Responses, levels: dict[str, np.ndarray], rng: np.random.Generator, *,
              n_boot: int, distance_round_mm: float, altitude_round_m: float,
              min_plateau_levels: int, tolerance: float) -> list[_GapData]:
    """The critical-gap fits the conspicuity responses allow.

    On the screen: the on-screen distance (``tan(alpha) * d`` with the eyes
    in front of the fixation mark) against the viewing distance, one fit per
    protocol, target and altitude with at least two viewing distances. On the
    ground: ``tan(beta) * h`` against the altitude (``beta`` =
    ``camera_gap_deg``; ``h``: the camera's depth to the target,
    ``target_depth_m``, where known, else the altitude), one fit per
    protocol, target and viewing distance with at least two altitudes. A
    label names the target, the held altitude / viewing distance when the
    data have more than one, and the protocol when they have both.
    ``levels``: each trial's level of the viewing distance and the altitude
    (``condition_levels``: rounded, and binned when there are many). More
    than ``MAX_FITS`` fits are refused (``ConfigError``)."""
    t_all = np.asarray(used.text["condition_target"], dtype=object)
    proto = np.asarray(used.text["protocol"], dtype=object)
    vd = levels["viewing_distance_mm"]
    alt = levels["condition_alt_agl_m"]
    ground = np.tan(np.radians(used.num["camera_gap_deg"])) * used.num["target_depth_m"]
    people = np.asarray(used.text["participant"], dtype=object)
    several = len(set(proto)) > 1
    jobs: list[tuple[str, str, str, np.ndarray, np.ndarray, np.ndarray, str, str]] = []
    specs = (  # (which, levels, held, gap, unit of held, name of held)
        ("screen", vd, alt, used.num["onscreen_distance_mm"], "m", "alt_agl_m"),
        ("ground", alt, vd, ground, "mm", "viewing_distance_mm"))
    for which, x, held, gap, held_unit, held_name in specs:
        groups: dict[tuple[str, str], dict[float | None, list[int]]] = {}
        for i in np.flatnonzero(np.isfinite(x) & np.isfinite(gap)):
            groups.setdefault((proto[i], t_all[i]), {}).setdefault(
                level_key(held[i]), []).append(int(i))
        for protocol, target in sorted(groups):
            by_held = groups[(protocol, target)]
            # the held values in order, the trials that do not say last
            for h in sorted(by_held, key=lambda v: (v is None, v or 0.0)):
                m = np.asarray(by_held[h], dtype=np.int64)
                if np.unique(x[m]).size < 2:
                    continue  # the variable does not vary: nothing to fit
                label = target if len(by_held) <= 1 or h is None else \
                    f"{target}, {h:g} {held_unit}"
                if several:
                    label = f"{label}, {protocol}"
                if which == "ground":
                    label = f"{label} (ground)"
                jobs.append((which, label, target, x[m], gap[m], people[m], protocol,
                             "" if h is None else f"{held_name}={h:g}"))
    if len(jobs) > MAX_FITS:
        raise ConfigError(
            f"{used.path}: the conspicuity responses ask for {len(jobs)} critical-gap fits "
            f"(one per protocol, target and held altitude or viewing distance, in each "
            f"plane), more than the {MAX_FITS} one analysis makes: analyse fewer targets "
            f"at a time")
    out: list[_GapData] = []
    for which, label, target, x_m, gap_m, people_m, protocol, held_text in jobs:
        variable, unit, name, step = (
            ("viewing distance d", "mm", "tan(alpha)*d", distance_round_mm)
            if which == "screen" else ("altitude h", "m", "tan(beta)*h", altitude_round_m))
        fit = fit_gap(x_m, gap_m, rng=rng, clusters=people_m, n_boot=n_boot,
                      min_plateau_levels=min_plateau_levels, round_to=step,
                      variable=variable, unit=unit, gap=name, tolerance=tolerance)
        out.append(_GapData(label, target, protocol, held_text, x_m, gap_m, people_m, fit))
    return out


def _gap_row(gf: _GapData, checks: list[dict[str, Any]]) -> dict[str, Any]:
    f = gf.fit
    verdicts = [c["verdict"] for c in checks]
    return {
        "fit": gf.label, "target": gf.target, "protocol": gf.protocol,
        "variable": f.variable, "unit": f.unit,
        "held": gf.held, "status": f.status, "n": f.n, "participants": f.participants,
        "levels": " ".join(f"{v:g}" for v in f.levels), "cg": f.cg,
        "cg_ci_lo": f.cg_ci[0] if f.cg_ci else None,
        "cg_ci_hi": f.cg_ci[1] if f.cg_ci else None, "cg_interval": f.interval,
        "threshold": f.threshold,
        "threshold_ci_lo": f.threshold_ci[0] if f.threshold_ci else None,
        "threshold_ci_hi": f.threshold_ci[1] if f.threshold_ci else None,
        "breakpoint": f.breakpoint, "rising_slope": f.rising_slope,
        "plateau_slope": f.plateau_slope,
        "plateau_slope_ci_lo": f.plateau_slope_ci[0] if f.plateau_slope_ci else None,
        "plateau_slope_ci_hi": f.plateau_slope_ci[1] if f.plateau_slope_ci else None,
        "negligible_slope": f.negligible_slope,
        "plateau_n": f.plateau_n, "plateau_levels": f.plateau_levels, "rmse": f.rmse,
        **{f"levels_{v}": verdicts.count(v) for v in ("holds", "fails", "inconclusive",
                                                        "untested")},
        "detail": f.detail}


def analyse(csv_path: str | Path, out_dir: str | Path, *, seed: int = 0,
            n_boot: int = 1000, distance_round_mm: float = 10.0, n_bins: int = 4,
            altitude_round_m: float = 1.0, min_plateau_levels: int = 3,
            tolerance: float = 0.1, plots: bool = True,
            exclude_reshown: bool = False, max_bytes: int = MAX_BYTES,
            max_rows: int = MAX_ROWS) -> dict[str, Any]:
    """Analyse a responses CSV into ``out_dir`` and return the summary.

    ``csv_path``: the trial server's export (``COLUMNS``); refused with a
    ``ConfigError`` naming file:line of every bad row, or when larger than
    ``max_bytes`` / ``max_rows``. Practice rows are excluded from everything;
    with ``exclude_reshown`` also trials shown a second time after a reload
    (they are counted either way).

    Writes ``conspicuity.csv``, ``critical_gap.csv``, ``critical_gap_check.csv``,
    ``recognition.csv``, ``analysis.json`` and (with ``plots``)
    ``critical_gap.png`` and ``recognition.png``; every file is written even
    when its protocol has no rows (header only, a "no data" figure).

    ``seed`` fixes the bootstraps (``n_boot`` resamples); viewing distances
    are grouped to the nearest ``distance_round_mm``, altitudes to the
    nearest ``altitude_round_m``; angular size and eccentricity are cut
    into ``n_bins`` quantile bins. ``tolerance``: the share of the gap within
    which it counts as constant (``fit_gap``).
    """
    if not 0.0 < tolerance <= 1.0:
        raise ConfigError(f"tolerance must be in (0, 1] (a share of the gap), got {tolerance!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    allr = read_responses(csv_path, max_bytes=max_bytes, max_rows=max_rows)
    # the camera's depth to the target, where the export does not say: the altitude
    depth = allr.num["target_depth_m"]
    allr.num["target_depth_m"] = np.where(np.isfinite(depth), depth,
                                          allr.num["condition_alt_agl_m"])
    r = allr.subset(~allr.practice & ~(allr.reshown & exclude_reshown))
    protocol = np.asarray(r.text["protocol"], dtype=object)
    dis = r.subset(np.isin(protocol, CONSPICUITY))
    rec = r.subset(protocol == "recognise")
    rounding = {"viewing_distance_mm": distance_round_mm,
                "condition_alt_agl_m": altitude_round_m, "condition_speed_kt": None}
    binned: dict[str, dict[str, list[dict[str, Any]]]] = {}

    def levels_of(sub: Responses, which: str) -> dict[str, np.ndarray]:
        """Each trial's level of each condition (``condition_levels``)."""
        lv = {}
        for col, step in rounding.items():
            lv[col], bins = condition_levels(sub.num[col], step)
            if bins:
                binned.setdefault(which, {})[col] = bins
                log.warning("%s: %s takes %d values in the %s responses: cut into %d bins "
                            "of about equal trials, each analysed at its trials' mean (the "
                            "bins are in analysis.json)", allr.path, col,
                            sum(b["values"] for b in bins), which, len(bins))
        return lv

    # ---- experiment 1: conspicuity per condition
    in_view = dis.target_in_view
    used = dis.subset(in_view)
    alpha = used.num["eccentricity_deg"]
    dist = used.num["onscreen_distance_mm"]
    vd = used.num["viewing_distance_mm"]
    implied = np.degrees(np.arctan(dist / vd))
    protocols = used.text["protocol"]
    # (with the eyes on the fixation mark; a tracked arrow off the centre is another angle)
    bad_ecc = (np.abs(implied - alpha) > ECCENTRICITY_TOLERANCE_DEG) & (
        np.asarray(protocols, dtype=object) == "disappear")
    if bad_ecc.any():
        log.warning("%s: %d 'disappear' rows whose eccentricity_deg differs from "
                    "atan(onscreen_distance_mm / viewing_distance_mm) by more than %g deg "
                    "(first at line %d)", allr.path, int(bad_ecc.sum()),
                    ECCENTRICITY_TOLERANCE_DEG, int(used.line[np.argmax(bad_ecc)]))
    levels = levels_of(used, "conspicuity")
    vd_r = levels["viewing_distance_mm"]
    alt = levels["condition_alt_agl_m"]
    spd = levels["condition_speed_kt"]
    targets = used.text["condition_target"]
    beta = used.num["camera_gap_deg"]
    depth = used.num["target_depth_m"]
    people = used.text["participant"]
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i in range(len(used)):
        key = (protocols[i], targets[i], float(vd_r[i]), level_key(alt[i]), level_key(spd[i]))
        groups.setdefault(key, []).append(i)
    cons_rows: list[dict[str, Any]] = []
    for key in sorted(groups, key=_sort_key):
        m = np.asarray(groups[key], dtype=np.int64)
        a_m, a_lo, a_hi = mean_ci(alpha[m])
        a_md, a_mlo, a_mhi = median_ci(alpha[m], rng, n_boot)
        s_m, s_lo, s_hi = mean_ci(dist[m])
        s_md, s_mlo, s_mhi = median_ci(dist[m], rng, n_boot)
        gap = float(np.mean(np.tan(np.radians(alpha[m])) * vd[m]))
        known = m[np.isfinite(beta[m])]  # the camera's side, where the clip's fov is known
        b_m, b_lo, b_hi = mean_ci(beta[known])
        ground = np.tan(np.radians(beta[known])) * depth[known]
        ground = ground[np.isfinite(ground)]
        cons_rows.append(dict(zip(CONSPICUITY_FIELDS, (
            *key, int(m.size), a_m, a_lo, a_hi, a_md, a_mlo, a_mhi, s_m, s_lo, s_hi, s_md,
            s_mlo, s_mhi, gap, len({people[i] for i in m}), int(known.size), b_m, b_lo, b_hi,
            float(ground.mean()) if ground.size else None))))
    _write_csv(out / "conspicuity.csv", CONSPICUITY_FIELDS, cons_rows)

    # ---- critical gap: on the screen across viewing distances (one fit per
    # target and altitude), on the ground across altitudes (per target and
    # viewing distance), and whether one level predicts the others
    gap_fits = _gap_fits(used, levels, rng, n_boot=n_boot,
                         distance_round_mm=distance_round_mm, altitude_round_m=altitude_round_m,
                         min_plateau_levels=min_plateau_levels, tolerance=tolerance)
    cg_rows, check_rows = [], []
    for gf in gap_fits:
        checks = check_across_levels(gf.fit, gf.x, gf.g, clusters=gf.people)
        cg_rows.append(_gap_row(gf, checks))
        check_rows += [{"fit": gf.label, "target": gf.target, "variable": gf.fit.variable,
                        "unit": gf.fit.unit, **c} for c in checks]
    _write_csv(out / "critical_gap.csv", CRITICAL_GAP_FIELDS, cg_rows)
    _write_csv(out / "critical_gap_check.csv", CHECK_FIELDS, check_rows)

    # ---- experiment 2: recognition
    rec_rows, logistic = analyse_recognition(rec, levels_of(rec, "recognise"),
                                             binned.get("recognise", {}), n_bins)
    _write_csv(out / "recognition.csv", RECOGNITION_FIELDS, rec_rows)

    files = ["conspicuity.csv", "critical_gap.csv", "critical_gap_check.csv",
             "recognition.csv", "analysis.json"]
    panels = 0
    if plots:
        panels = _plot_critical_gap(out / "critical_gap.png", gap_fits)
        _plot_recognition(out / "recognition.png", rec_rows)
        files += ["critical_gap.png", "recognition.png"]

    n_rec = len(rec)
    k_rec = int(np.nansum(rec.recognised))
    summary: dict[str, Any] = {
        "input": allr.path,
        "rows": len(allr),
        "practice_rows_excluded": int(allr.practice.sum()),
        "reshown_rows": int((allr.reshown & ~allr.practice).sum()),
        "reshown_rows_excluded": bool(exclude_reshown),
        "ignored_columns": allr.extra_columns,
        "disappear": {
            "responses": len(dis), "used": len(used),
            "excluded_target_not_in_view": int((~in_view).sum()),
            "eccentricity_inconsistent_rows": int(bad_ecc.sum()),
            "conditions": len(cons_rows),
        },
        "critical_gap": {gf.label: gf.fit.as_dict() for gf in gap_fits},
        "critical_gap_figure": {"fits": len(gap_fits), "panels": panels},
        "binned_conditions": binned,
        "critical_gap_check": check_rows,
        "recognise": {
            "responses": n_rec, "recognised": k_rec,
            "accuracy": k_rec / n_rec if n_rec else None,
            "accuracy_ci": list(wilson_ci(k_rec, n_rec)) if n_rec else None,
            "by": by_factor(rec_rows),
            "logistic": logistic,
        },
        "settings": {"seed": seed, "n_boot": n_boot, "distance_round_mm": distance_round_mm,
                     "altitude_round_m": altitude_round_m, "tolerance": tolerance,
                     "n_bins": n_bins, "min_plateau_levels": min_plateau_levels},
        "out_dir": str(out),
        "files": files,
    }
    summary = _json_clean(summary)
    (out / "analysis.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return summary


def _sort_key(key: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple((0, "") if v is None else (1, v) for v in key)


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):  # as in the responses export
        return "1" if v else "0"
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def _write_csv(path: Path, fields: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = SafeWriter(f)  # a target or participant named "=..." is not run as a formula
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


def _plot_critical_gap(path: Path, all_fits: list[_GapData]) -> int:
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
