"""MAVLink overhead: the same scenario with and without ``--mavlink``, side by side.

    python benchmarks/mavlink_overhead.py [--vehicles 100] [--sim-s 60] [--rounds 3]

Runs ``cosim run`` on a grid of c172p (process backend, default workers,
as fast as possible, default telemetry rates, tlogs on), alternating
without and with MAVLink (sent to a closed loopback port) so machine noise
hits both alike, and prints each pair's wall times (``wall_time_s`` from
summary.json: the tick loop, not the build) and the ratio. Issue 4's
target: at most +10% for 100 vehicles.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

SCENARIO = """
schema_version: 1
name: mavlink-overhead
origin: {{lat_deg: 37.0, lon_deg: -116.0, ground_alt_m: 1000}}
duration_s: {sim_s}
vehicles:
  - {{id: c, count: {n}, model: c172p, formation: {{type: grid, spacing_m: 300}},
     init: {{north_m: 0, east_m: 0, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 100}}}}
"""


def _wall_s(scn: Path, out: Path, mavlink: bool) -> float:
    cmd = [sys.executable, "-m", "cosim", "-q", "run", str(scn), "--out", str(out),
           "--overwrite", "--no-progress"]
    if mavlink:
        cmd += ["--mavlink", "udpout:127.0.0.1:9"]  # discard port: nobody listens
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return float(json.loads((out / "summary.json").read_text())["wall_time_s"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--sim-s", type=float, default=60.0)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        scn = Path(tmp) / "m.yaml"
        scn.write_text(SCENARIO.format(n=a.vehicles, sim_s=a.sim_s))
        ratios = []
        print(f"{a.vehicles} c172p, {a.sim_s:g} s simulated; wall_time_s of the tick loop")
        print("round  without   with     extra")
        for r in range(a.rounds):
            first_with = r % 2 == 1  # alternate the order too
            runs = {}
            for mav in ((True, False) if first_with else (False, True)):
                runs[mav] = _wall_s(scn, Path(tmp) / f"out-{int(mav)}", mav)
            ratio = runs[True] / runs[False]
            ratios.append(ratio)
            print(f"{r + 1:5d}  {runs[False]:7.2f}  {runs[True]:7.2f}  {ratio - 1:+7.1%}")
        print(f"median extra: {statistics.median(ratios) - 1:+.1%} "
              f"(min {min(ratios) - 1:+.1%}, max {max(ratios) - 1:+.1%})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
