"""The critical-gap fits a set of conspicuity responses asks for, and their tables.

Owns which fits are made (``gap_fits``: on the screen, one per protocol,
target and held altitude with at least two viewing distances; on the ground,
one per protocol, target and held viewing distance with at least two
altitudes; at most ``MAX_FITS``, more is refused), their labels, and the
rows of critical_gap.csv and critical_gap_check.csv (``critical_gap_tables``:
each fit's check across its levels). The fitting itself is
``cosim.trials.critical_gap``, the check ``cosim.trials.critical_gap_check``.

Responses in, fits and rows out: it reads no file, writes none and draws
nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.errors import ConfigError
from cosim.trials.conditions import level_key
from cosim.trials.critical_gap import GapFit, fit_gap
from cosim.trials.critical_gap_check import check_across_levels
from cosim.trials.responses import Responses

#: critical-gap fits one analysis makes at most (protocols x targets x held
#: conditions x the two planes); responses asking for more are refused
MAX_FITS = 200
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
class GapData:
    """One critical-gap fit and the trials it was made from."""

    label: str
    target: str
    protocol: str
    held: str  # what is the same for every trial of the fit ("" when nothing else varies)
    x: np.ndarray
    g: np.ndarray
    people: np.ndarray
    fit: GapFit


def gap_fits(used: Responses, levels: dict[str, np.ndarray], rng: np.random.Generator, *,
             n_boot: int, distance_round_mm: float, altitude_round_m: float,
             min_plateau_levels: int, tolerance: float) -> list[GapData]:
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
    out: list[GapData] = []
    for which, label, target, x_m, gap_m, people_m, protocol, held_text in jobs:
        variable, unit, name, step = (
            ("viewing distance d", "mm", "tan(alpha)*d", distance_round_mm)
            if which == "screen" else ("altitude h", "m", "tan(beta)*h", altitude_round_m))
        fit = fit_gap(x_m, gap_m, rng=rng, clusters=people_m, n_boot=n_boot,
                      min_plateau_levels=min_plateau_levels, round_to=step,
                      variable=variable, unit=unit, gap=name, tolerance=tolerance)
        out.append(GapData(label, target, protocol, held_text, x_m, gap_m, people_m, fit))
    return out


def critical_gap_tables(fits: list[GapData]) -> tuple[list[dict[str, Any]],
                                                       list[dict[str, Any]]]:
    """The rows of critical_gap.csv (one a fit) and critical_gap_check.csv
    (one a level of each fit): each fit checked across its levels
    (``check_across_levels``)."""
    cg_rows, check_rows = [], []
    for gf in fits:
        checks = check_across_levels(gf.fit, gf.x, gf.g, clusters=gf.people)
        cg_rows.append(_gap_row(gf, checks))
        check_rows += [{"fit": gf.label, "target": gf.target, "variable": gf.fit.variable,
                        "unit": gf.fit.unit, **c} for c in checks]
    return cg_rows, check_rows


def _gap_row(gf: GapData, checks: list[dict[str, Any]]) -> dict[str, Any]:
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
