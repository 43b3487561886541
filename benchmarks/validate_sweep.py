"""How long ``cosim validate`` takes on a sweep at the size limit (10,000
combinations), against loading every combination from scratch (what it did
before the file was parsed once and each part checked once per distinct
value), measured in the same run.

Three sweeps of 4 swept names (50 x 5 x 8 x 5 = 10,000 combinations): one
aircraft; 200 aircraft in formation; 200 aircraft whose seed also changes with
every combination. The baseline loads a sample of combinations and is
reported per combination beside ``cosim validate``'s whole-sweep figure.

    python benchmarks/validate_sweep.py [--sample 300]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from cosim.cli.validate import _validate_file
from cosim.scenario import load_scenario
from cosim.sweep.spec import read_sweep

SWEEP = """\
schema_version: 1
name: bench
origin: {{lat_deg: 37, lon_deg: -116, ground_alt_m: 1000}}
duration_s: 30
seed: {seed}
sweep:
  rep: {reps}
  alt_agl_m: [100, 120, 140, 160, 180]
  speed_kt: [60, 70, 80, 90, 100, 110, 120, 130]
  target: [truck, car, person, fire_truck, fire]
vehicles:
  - id: uav
    count: {count}
    model: uav700
    formation: {{type: line, spacing_m: 50}}
    init: {{north_m: 0, east_m: 0, alt_agl_m: ${{alt_agl_m}}, heading_deg: 0, airspeed_kt: 80}}
schedule:
  - {{at_s: ${{1 + rep / 100}}, vehicles: 'uav*', command: {{airspeed_kt: ${{speed_kt}}}}}}
targets:
  - {{id: t, kind: "${{target}}", north_m: 0, east_m: 0}}
cameras:
  views:
    - {{name: nadir, vehicles: uav0, mount: nadir, vfov_deg: 40, width_px: 320,
       height_px: 240, rate_hz: 10}}
"""

CASES = {
    "1 aircraft": {"count": 1, "seed": 1},
    "200 aircraft": {"count": 200, "seed": 1},
    "200 aircraft, seed swept": {"count": 200, "seed": "${rep}"},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=int, default=300,
                    help="combinations the from-scratch baseline loads (default 300)")
    a = ap.parse_args()
    print(f"{'sweep (10,000 combinations)':28s} {'validate s':>10s} {'ms/comb':>8s} "
          f"{'scratch ms/comb':>15s} {'speed-up':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, fmt in CASES.items():
            p = Path(tmp) / "sweep.yaml"
            p.write_text(SWEEP.format(reps=list(range(50)), **fmt).replace(
                "vehicles: uav0", "vehicles: " + ("uav" if fmt["count"] == 1 else "uav000")))
            points = read_sweep(p).points()
            t0 = time.perf_counter()
            _, n, _ = _validate_file(str(p), False, None)
            whole = time.perf_counter() - t0
            step = max(1, len(points) // a.sample)
            sample = points[::step]
            t0 = time.perf_counter()
            for point in sample:
                load_scenario(p, sweep_point=point)
            scratch = (time.perf_counter() - t0) / len(sample)
            per = whole / n
            print(f"{name:28s} {whole:10.1f} {per * 1e3:8.2f} {scratch * 1e3:15.2f} "
                  f"{scratch / per:7.1f}x")


if __name__ == "__main__":
    main()
