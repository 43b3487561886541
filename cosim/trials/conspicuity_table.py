"""Experiment 1 per condition: the conspicuity angle and distance of each
protocol, target, viewing distance, altitude and speed (the rows of
conspicuity.csv, ``CONSPICUITY_FIELDS``).

Each row: n, participants, mean and median conspicuity angle alpha (deg)
and conspicuity distance (mm on the screen), means with a 95 % t interval,
medians with a 95 % percentile bootstrap interval; and, where the clips'
field of view is known, the mean angle beta seen from the camera and the
gap on the ground ``tan(beta) * h`` (m).

Responses in, rows out: it reads no file, writes none, fits no critical gap
(``cosim.trials.critical_gap_fits``) and draws nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.trials.conditions import level_key
from cosim.trials.estimates import mean_ci, median_ci
from cosim.trials.responses import Responses

CONSPICUITY_FIELDS = (
    "protocol", "target", "viewing_distance_mm", "alt_agl_m", "speed_kt", "n",
    "alpha_mean_deg", "alpha_mean_ci_lo_deg", "alpha_mean_ci_hi_deg",
    "alpha_median_deg", "alpha_median_ci_lo_deg", "alpha_median_ci_hi_deg",
    "distance_mean_mm", "distance_mean_ci_lo_mm", "distance_mean_ci_hi_mm",
    "distance_median_mm", "distance_median_ci_lo_mm", "distance_median_ci_hi_mm",
    "gap_mean_mm", "participants", "beta_n", "beta_mean_deg", "beta_mean_ci_lo_deg",
    "beta_mean_ci_hi_deg", "ground_gap_mean_m",
)


def conspicuity_rows(used: Responses, levels: dict[str, np.ndarray], rng: np.random.Generator,
                     n_boot: int) -> list[dict[str, Any]]:
    """One row a condition of the conspicuity responses ``used`` (the target
    in view), in the order of their keys; ``levels``: each trial's level of
    the viewing distance, altitude and speed (``condition_levels``);
    ``rng`` and ``n_boot`` for the medians' bootstrap."""
    alpha = used.num["eccentricity_deg"]
    dist = used.num["onscreen_distance_mm"]
    vd = used.num["viewing_distance_mm"]
    protocols = used.text["protocol"]
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
    return cons_rows


def _sort_key(key: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple((0, "") if v is None else (1, v) for v in key)
