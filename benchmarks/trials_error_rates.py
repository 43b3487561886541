"""How often the critical-gap analysis is right, over synthetic data sets
whose truth is known (the generators of tests/trials/test_analysis.py):

- ground gap constant above h0 = 100 m (12 participants with their own
  offsets, 4 trials an altitude): how often a plateau is found, every
  plateau level's check holds, and some level's check fails;
- the same with a 4 m step at 300 m: how often that level's check fails;
- screen gap rising with the viewing distance everywhere (15 trials a
  distance, 0.2 deg of noise): how often a plateau is wrongly claimed; and
  a true plateau: how often it is found.

    python benchmarks/trials_error_rates.py --sets 200
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "trials"))

from test_analysis import _arrays, _exp1_rows, _ground_rows, _model  # noqa: E402

from cosim.trials.analysis import (  # noqa: E402
    GapFit,
    check_across_levels,
    fit_critical_gap,
    fit_ground_gap,
)


def _ground(seed: int, step_m: float) -> tuple[GapFit, list[dict[str, Any]]]:
    rows = _ground_rows(seed=seed, person_sd_m=0.5, trials=4,
                        ground_gap=lambda h: _model(h) + (step_m if h == 300.0 else 0.0))
    h, b, depth, who = _arrays(rows)
    fit = fit_ground_gap(h, b, depth_m=depth, rng=np.random.default_rng(seed), n_boot=1,
                         clusters=who)
    return fit, check_across_levels(fit, h, np.tan(np.radians(b)) * depth, clusters=who)


def rates(sets: int) -> dict[str, int]:
    out = {"sets": sets, "ground_plateau": 0, "ground_all_hold": 0, "ground_any_fails": 0,
           "step_plateau": 0, "step_flagged": 0, "screen_false_plateau": 0,
           "screen_true_plateau_found": 0}
    for s in range(sets):
        fit, checks = _ground(1000 + s, 0.0)
        if fit.cg is not None:
            out["ground_plateau"] += 1
            out["ground_all_hold"] += all(c["verdict"] == "holds" for c in checks
                                          if c["level"] >= 100.0)
            out["ground_any_fails"] += any(c["verdict"] == "fails" for c in checks)
        fit, checks = _ground(2000 + s, 4.0)
        if fit.cg is not None:
            out["step_plateau"] += 1
            out["step_flagged"] += {c["level"]: c for c in checks}[300.0]["verdict"] == "fails"
        for plateau in (False, True):
            rows = _exp1_rows(seed=5000 + s, plateau=plateau, trials=15)
            d = np.array([float(r["viewing_distance_mm"]) for r in rows])
            a = np.array([float(r["eccentricity_deg"]) for r in rows])
            f = fit_critical_gap(d, a, rng=np.random.default_rng(s), n_boot=1,
                                 clusters=[r["participant"] for r in rows])
            if plateau:
                out["screen_true_plateau_found"] += f.status == "plateau"
            else:
                out["screen_false_plateau"] += f.cg is not None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", type=int, default=200, help="data sets per case (default 200)")
    a = ap.parse_args()
    if a.sets < 1:
        ap.error("--sets must be at least 1")
    r = rates(a.sets)
    n = r["sets"]
    print(f"ground gap constant above h0: plateau in {r['ground_plateau']} of {n}; every "
          f"plateau level holds in {r['ground_all_hold']}; some level fails in "
          f"{r['ground_any_fails']}")
    print(f"4 m step at 300 m: plateau in {r['step_plateau']} of {n}; the step flagged in "
          f"{r['step_flagged']}")
    print(f"screen gap rising everywhere: plateau claimed in {r['screen_false_plateau']} of "
          f"{n}; a true plateau found in {r['screen_true_plateau_found']} of {n}")


if __name__ == "__main__":
    main()
