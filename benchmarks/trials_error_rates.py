"""How often the critical-gap analysis is right, over synthetic data sets
whose truth is known (the generators of tests/trials/test_analysis.py):

- ground gap constant above h0 = 100 m (12 participants with their own
  offsets, 4 trials an altitude): how often a plateau is found, every
  plateau level's check holds, and some level's check fails;
- the same with a 4 m step at 300 m: how often that level's check fails;
- screen gap rising with the viewing distance everywhere (15 trials a
  distance, 0.2 deg of noise): how often a plateau is wrongly claimed; and
  a true plateau: how often it is found;
- the critical gap's 95 % interval: how often it contains the true 12 m
  (participants' offsets sd 1.5 m around it) with 10, 12 and 24
  participants;
- one altitude (300 m) 7 % off, within the 10 % tolerance: how often its
  check "fails" (it must not: "fails" means shown to be off by more); and
  25 % off: how often it fails, and how often a correct altitude fails.

    python benchmarks/trials_error_rates.py --sets 200
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "trials"))

from test_analysis import (  # noqa: E402
    GROUND_CG_M,
    _arrays,
    _exp1_rows,
    _ground_rows,
    _model,
)

from cosim.trials.critical_gap import GapFit, fit_critical_gap, fit_ground_gap  # noqa: E402
from cosim.trials.critical_gap_check import check_across_levels  # noqa: E402


def _ground(seed: int, step_m: float, *, share: float = 0.0, people: int = 12,
            person_sd_m: float = 0.5, n_boot: int = 1) -> tuple[GapFit, list[dict[str, Any]]]:
    """A ground study whose gap at 300 m is off by ``step_m`` or by ``share``."""
    rows = _ground_rows(seed=seed, people=people, person_sd_m=person_sd_m, trials=4,
                        ground_gap=lambda h: _model(h) * (1.0 + (share if h == 300.0 else 0.0))
                        + (step_m if h == 300.0 else 0.0))
    h, b, depth, who = _arrays(rows)
    fit = fit_ground_gap(h, b, depth_m=depth, rng=np.random.default_rng(seed), n_boot=n_boot,
                         clusters=who)
    return fit, check_across_levels(fit, h, np.tan(np.radians(b)) * depth, clusters=who)


def coverage(sets: int, people: int) -> tuple[int, int]:
    """(studies whose CG interval contains the true gap, studies with a CG)."""
    covered = fits = 0
    for s in range(sets):
        fit, _ = _ground(10_000 + s, 0.0, people=people, person_sd_m=1.5, n_boot=300)
        if fit.cg_ci is not None:
            fits += 1
            covered += fit.cg_ci[0] <= GROUND_CG_M <= fit.cg_ci[1]
    return covered, fits


def off_level(sets: int, people: int, share: float) -> tuple[int, int, int]:
    """(plateaus found, the 300 m level "fails", a correct level "fails")
    with the 300 m gap ``share`` off."""
    found = bad = good = 0
    for s in range(sets):
        fit, checks = _ground(20_000 + s, 0.0, share=share, people=people)
        if fit.cg is None:
            continue
        found += 1
        bad += any(c["verdict"] == "fails" for c in checks if c["level"] == 300.0)
        good += any(c["verdict"] == "fails" for c in checks if c["level"] != 300.0)
    return found, bad, good


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
    for people in (10, 12, 24):
        covered, fits = coverage(n, people)
        print(f"CG interval, {people} participants: contains the true gap in {covered} of "
              f"{fits} ({covered / max(fits, 1):.3f})")
    for people in (12, 24):
        found, bad, good = off_level(n, people, 0.07)
        print(f"one altitude 7 % off, {people} participants: it fails in {bad} of {found}; a "
              f"correct altitude fails in {good}")
        found, bad, good = off_level(n, people, 0.25)
        print(f"one altitude 25 % off, {people} participants: it fails in {bad} of {found}; a "
              f"correct altitude fails in {good}")


if __name__ == "__main__":
    main()
