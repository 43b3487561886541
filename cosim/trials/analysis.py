"""Analysis of conspicuity trial responses: ``analyse(csv, out_dir)``.

Reads the responses CSV the trial server exports, drops practice rows (and,
when asked, trials shown again after a reload) and writes into ``out_dir``:

- ``conspicuity.csv``: experiment 1 ("disappear" and "track" protocols) per
  condition (``cosim.trials.conspicuity_table``);
- ``critical_gap.csv``, ``critical_gap_check.csv``, ``critical_gap.png``: the
  critical-gap relation ``CG = tan(alpha) * d = tan(beta) * h`` in its two
  planes, per protocol and target. On the screen: the on-screen distance
  (``tan(alpha) * d``, mm) against the viewing distance, per altitude when
  several; its critical gap and the threshold viewing distance ``d0``. On
  the ground: ``tan(beta) * h`` (m) against the altitude, per viewing
  distance when several, ``beta`` being the conspicuity angle seen from the
  camera (``camera_gap_deg``) and ``h`` the camera's depth to the target
  (``target_depth_m``; the altitude where unknown): for a nadir camera the
  distance on the ground between the point looked at and the target; its
  critical gap and the threshold altitude ``h0``. The fits a set of
  responses asks for are ``cosim.trials.critical_gap_fits``, each fit
  ``cosim.trials.critical_gap``, the check that one level predicts the
  others ``cosim.trials.critical_gap_check``. The two planes are not mixed:
  the screen's mm and the ground's metres are related only through a clip's
  camera and the display, which differ between studies;
- ``recognition.csv``, ``recognition.png``: experiment 2 ("recognise"
  protocol), accuracy against each condition and a logistic model
  (``cosim.trials.recognition``);
- ``analysis.json``: the summary ``analyse`` returns.

The CSV is untrusted and read by ``cosim.trials.responses`` (a regular file,
bounded, every row checked). The work is bounded whatever the file holds: a
condition with many distinct values is cut into bins
(``cosim.trials.conditions``), the critical-gap fits are limited
(``critical_gap_fits.MAX_FITS``) and so are the figure's panels
(``cosim.trials.figures``). Every CSV written is safe to open in a
spreadsheet (``cosim.trials.output``).

Owns only the order of the analysis and its summary; the statistics are in
the modules named above. It never talks to the trial server, renders or
runs a scenario.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import ConfigError
from cosim.trials.conditions import condition_levels
from cosim.trials.conspicuity_table import CONSPICUITY_FIELDS, conspicuity_rows
from cosim.trials.critical_gap_fits import (
    CHECK_FIELDS,
    CRITICAL_GAP_FIELDS,
    critical_gap_tables,
    gap_fits,
)
from cosim.trials.figures import plot_critical_gap, plot_recognition
from cosim.trials.output import json_clean, write_csv
from cosim.trials.recognition import RECOGNITION_FIELDS, analyse_recognition, recognition_summary
from cosim.trials.responses import CONSPICUITY, MAX_BYTES, MAX_ROWS, Responses, read_responses

log = logging.getLogger(__name__)

#: eccentricity_deg and atan(onscreen_distance_mm / viewing_distance_mm) further apart
#: than this are counted (and logged) as inconsistent
ECCENTRICITY_TOLERANCE_DEG = 0.5


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
    which it counts as constant (``cosim.trials.critical_gap.fit_gap``).
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
    implied = np.degrees(np.arctan(used.num["onscreen_distance_mm"] /
                                   used.num["viewing_distance_mm"]))
    # (with the eyes on the fixation mark; a tracked arrow off the centre is another angle)
    bad_ecc = (np.abs(implied - alpha) > ECCENTRICITY_TOLERANCE_DEG) & (
        np.asarray(used.text["protocol"], dtype=object) == "disappear")
    if bad_ecc.any():
        log.warning("%s: %d 'disappear' rows whose eccentricity_deg differs from "
                    "atan(onscreen_distance_mm / viewing_distance_mm) by more than %g deg "
                    "(first at line %d)", allr.path, int(bad_ecc.sum()),
                    ECCENTRICITY_TOLERANCE_DEG, int(used.line[np.argmax(bad_ecc)]))
    levels = levels_of(used, "conspicuity")
    cons_rows = conspicuity_rows(used, levels, rng, n_boot)
    write_csv(out / "conspicuity.csv", CONSPICUITY_FIELDS, cons_rows)

    # ---- critical gap: on the screen across viewing distances (one fit per
    # target and altitude), on the ground across altitudes (per target and
    # viewing distance), and whether one level predicts the others
    fits = gap_fits(used, levels, rng, n_boot=n_boot, distance_round_mm=distance_round_mm,
                    altitude_round_m=altitude_round_m, min_plateau_levels=min_plateau_levels,
                    tolerance=tolerance)
    cg_rows, check_rows = critical_gap_tables(fits)
    write_csv(out / "critical_gap.csv", CRITICAL_GAP_FIELDS, cg_rows)
    write_csv(out / "critical_gap_check.csv", CHECK_FIELDS, check_rows)

    # ---- experiment 2: recognition
    rec_rows, logistic = analyse_recognition(rec, levels_of(rec, "recognise"),
                                             binned.get("recognise", {}), n_bins)
    write_csv(out / "recognition.csv", RECOGNITION_FIELDS, rec_rows)

    files = ["conspicuity.csv", "critical_gap.csv", "critical_gap_check.csv",
             "recognition.csv", "analysis.json"]
    panels = 0
    if plots:
        panels = plot_critical_gap(out / "critical_gap.png", fits)
        plot_recognition(out / "recognition.png", rec_rows)
        files += ["critical_gap.png", "recognition.png"]

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
        "critical_gap": {gf.label: gf.fit.as_dict() for gf in fits},
        "critical_gap_figure": {"fits": len(fits), "panels": panels},
        "binned_conditions": binned,
        "critical_gap_check": check_rows,
        "recognise": recognition_summary(rec, rec_rows, logistic),
        "settings": {"seed": seed, "n_boot": n_boot, "distance_round_mm": distance_round_mm,
                     "altitude_round_m": altitude_round_m, "tolerance": tolerance,
                     "n_bins": n_bins, "min_plateau_levels": min_plateau_levels},
        "out_dir": str(out),
        "files": files,
    }
    summary = json_clean(summary)
    (out / "analysis.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return summary
