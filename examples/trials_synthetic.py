"""A synthetic responses file, as `cosim trials export` writes one, from a
known model: for trying `cosim trials analyse` (and the README's figure)
before any participant has come.

- "disappear" trials: the conspicuity distance on the screen rises with the
  viewing distance up to d0 = 600 mm, then stays at the critical gap
  CG = 40 mm (a truck) or 60 mm (a fire truck), 0.2 deg of noise;
- "disappear" trials over altitudes, seen at 600 mm: the gap on the ground
  (tan(beta) * h, beta the angle at the camera) rises with the altitude up
  to h0 = 100 m, then stays at 12 m (a truck) or 18 m (a fire truck); every
  one of 12 participants has their own offset (sd 1.5 m), 1 m of noise;
- "recognise" trials: logit p = 2.5 - 1.2 * altitude / 100 m, speed without
  effect.

    python examples/trials_synthetic.py --out responses.csv
    cosim trials analyse responses.csv --out analysis/
"""

from __future__ import annotations

import argparse
import csv
import math

import numpy as np

from cosim.trials.responses import COLUMNS, OPTIONAL_COLUMNS

CG_MM = {"truck": 40.0, "fire_truck": 60.0}
D0_MM = 600.0
GROUND_CG_M = {"truck": 12.0, "fire_truck": 18.0}
H0_M = 100.0
#: the camera's focal length as drawn on the screen (a 640 px wide, 48.9 deg
#: camera filling a 520 mm, 1920 px wide screen): tan(beta) * F is the gap on it
F_SCREEN_MM = 428.0


def rows(seed: int) -> list[dict[str, object]]:
    rng = np.random.default_rng(seed)
    base = {"session": "synthetic", "practice": 0, "clip": "", "run": "", "key": "space",
            "target_in_view": 1, "screen_width_mm": 520, "screen_height_mm": 320,
            "screen_width_px": 1920, "screen_height_px": 1080, "video_time_s": 1.0,
            "frame": 30, "condition_speed_kt": "", "condition_alt_agl_m": "",
            "recognised": "", "target_angular_size_deg": 0.5}
    out = []
    for target, cg in CG_MM.items():
        for d in range(300, 1201, 100):
            for _ in range(30):
                gap = min(d * cg / D0_MM, cg)
                a = math.degrees(math.atan(gap / d)) + rng.normal(0.0, 0.2)
                out.append({**base, "protocol": "disappear", "condition_target": target,
                            "participant": f"p{rng.integers(12):02d}", "viewing_distance_mm": d,
                            "eccentricity_deg": round(a, 4),
                            "onscreen_distance_mm": round(math.tan(math.radians(a)) * d, 3),
                            "reaction_time_ms": int(rng.uniform(300, 1500))})
    person = rng.normal(0.0, 1.5, 12)
    for target, cg_m in GROUND_CG_M.items():
        for h in (30, 60, 100, 150, 200, 300, 500):
            for p in range(12):
                for _ in range(5):
                    g = max(min(h * cg_m / H0_M, cg_m) + person[p] + rng.normal(0.0, 1.0), 0.1)
                    mm = g / h * F_SCREEN_MM
                    out.append({**base, "protocol": "disappear", "condition_target": target,
                                "participant": f"p{p:02d}", "viewing_distance_mm": 600,
                                "condition_alt_agl_m": h,
                                "camera_gap_deg": round(math.degrees(math.atan(g / h)), 5),
                                "eccentricity_deg": round(math.degrees(math.atan(mm / 600)), 5),
                                "onscreen_distance_mm": round(mm, 3),
                                "reaction_time_ms": int(rng.uniform(300, 1500))})
    for h in (30, 100, 200, 300, 500):
        for v in (50, 100, 200):
            p_rec = 1.0 / (1.0 + math.exp(-(2.5 - 1.2 * h / 100.0)))
            for _ in range(40):
                out.append({**base, "protocol": "recognise", "condition_target": "truck",
                            "participant": f"p{rng.integers(12):02d}",
                            "condition_alt_agl_m": h, "condition_speed_kt": v,
                            "recognised": int(rng.random() < p_rec), "viewing_distance_mm": 600,
                            "target_angular_size_deg": round(2.0 * 30.0 / h, 4),
                            "eccentricity_deg": round(rng.uniform(0, 15), 3),
                            "onscreen_distance_mm": "",
                            "reaction_time_ms": int(rng.uniform(300, 1500))})
    for i, r in enumerate(out):
        r["trial_index"] = i
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    with open(a.out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(COLUMNS + OPTIONAL_COLUMNS), restval="")
        w.writeheader()
        w.writerows(rows(a.seed))
    print(a.out)


if __name__ == "__main__":
    main()
