"""What the live 3-D view costs: the same 100-aircraft run without a view
and with ``--record-view`` (the same logging as a live viewer: Rerun's file
sink), side by side, then the view at real time.

    python benchmarks/view_cost.py [--vehicles 100] [--sim-s 60] [--rounds 3]

Runs ``cosim run`` on a grid of uav700 (process backend, default workers,
as fast as possible), alternating without and with the view so machine noise
hits both alike, and prints each pair's tick-loop wall times
(``wall_time_s`` from summary.json) and their ratio; then one run at
``--realtime`` with the view on and the real-time factor it held
(``real_time_factor``: simulated seconds over the loop's wall seconds).
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
name: view-cost
origin: {{lat_deg: 37.0, lon_deg: -116.0, ground_alt_m: 1000}}
duration_s: {sim_s}
vehicles:
  - {{id: u, count: {n}, model: uav700, formation: {{type: grid, spacing_m: 300}},
     init: {{north_m: 0, east_m: 0, alt_agl_m: 400, heading_deg: 0, airspeed_kt: 80}}}}
schedule:
  - {{at_s: 0, vehicles: "u*", command: {{loiter: {{radius_m: 500}}}}}}
"""


def _run(scn: Path, out: Path, view: Path | None, realtime: bool = False) -> dict:
    cmd = [sys.executable, "-m", "cosim", "-q", "run", str(scn), "--out", str(out),
           "--overwrite", "--no-progress"]
    if view is not None:
        cmd += ["--record-view", str(view)]
    if realtime:
        cmd += ["--realtime"]
    subprocess.run(cmd, check=True)
    return json.loads((out / "summary.json").read_text())


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vehicles", type=int, default=100)
    p.add_argument("--sim-s", type=float, default=60.0)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--realtime-s", type=float, default=30.0,
                   help="simulated seconds of the real-time run (0: skip it)")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        scn = tmp / "s.yaml"
        scn.write_text(SCENARIO.format(n=a.vehicles, sim_s=a.sim_s))
        ratios = []
        print(f"{a.vehicles} uav700, {a.sim_s:g} s simulated, flat out")
        print("round  no view (s)  view (s)  ratio")
        for k in range(a.rounds):
            plain = _run(scn, tmp / "plain", None)["wall_time_s"]
            viewed = _run(scn, tmp / "viewed", tmp / "v.rrd")["wall_time_s"]
            ratios.append(viewed / plain)
            print(f"{k + 1:5d}  {plain:11.2f}  {viewed:8.2f}  {viewed / plain:5.3f}")
        size = (tmp / "v.rrd").stat().st_size / 1e6
        print(f"median ratio {statistics.median(ratios):.3f}; recording {size:.1f} MB")
        if a.realtime_s > 0:
            scn.write_text(SCENARIO.format(n=a.vehicles, sim_s=a.realtime_s))
            s = _run(scn, tmp / "rt", tmp / "rt.rrd", realtime=True)
            print(f"real time with the view: {a.realtime_s:g} s simulated, real-time factor "
                  f"{s['real_time_factor']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
