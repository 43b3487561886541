"""MAVLink overhead: the same scenario with and without ``--mavlink``, side by side.

    python benchmarks/mavlink_overhead.py [--vehicles 100] [--sim-s 60] [--rounds 3]

Runs ``cosim run`` on a grid of c172p (process backend, default workers,
as fast as possible, default telemetry rates, tlogs on), alternating
without and with MAVLink (sent to a closed loopback port) so machine noise
hits both alike, and prints each pair's wall times (``wall_time_s`` from
summary.json: the tick loop, not the build), the CPU time of all the run's
processes (steadier on a shared machine) and the ratios. The
target: at most +10% wall time for 100 vehicles.
"""

from __future__ import annotations

import argparse
import json
import resource
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


def _run(scn: Path, out: Path, mavlink: bool) -> tuple[float, float]:
    """(wall_time_s of the tick loop, CPU seconds of the run and its workers)."""
    cmd = [sys.executable, "-m", "cosim", "-q", "run", str(scn), "--out", str(out),
           "--overwrite", "--no-progress"]
    if mavlink:
        cmd += ["--mavlink", "udpout:127.0.0.1:9"]  # discard port: nobody listens
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return float(json.loads((out / "summary.json").read_text())["wall_time_s"]), cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--sim-s", type=float, default=60.0)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        scn = Path(tmp) / "m.yaml"
        scn.write_text(SCENARIO.format(n=a.vehicles, sim_s=a.sim_s))
        ratios, cpu_ratios = [], []
        print(f"{a.vehicles} c172p, {a.sim_s:g} s simulated; wall: the tick loop's "
              "wall_time_s; CPU: every process of the run, build included")
        print("round  wall without  with    extra   CPU without  with    extra")
        for r in range(a.rounds):
            first_with = r % 2 == 1  # alternate the order too
            runs = {}
            for mav in ((True, False) if first_with else (False, True)):
                runs[mav] = _run(scn, Path(tmp) / f"out-{int(mav)}", mav)
            (w0, c0), (w1, c1) = runs[False], runs[True]
            ratios.append(w1 / w0)
            cpu_ratios.append(c1 / c0)
            print(f"{r + 1:5d}  {w0:11.2f}  {w1:6.2f}  {w1 / w0 - 1:+6.1%}  {c0:11.2f}  "
                  f"{c1:6.2f}  {c1 / c0 - 1:+6.1%}")
        for what, xs in (("wall", ratios), ("CPU", cpu_ratios)):
            print(f"median extra {what}: {statistics.median(xs) - 1:+.1%} "
                  f"(min {min(xs) - 1:+.1%}, max {max(xs) - 1:+.1%})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
