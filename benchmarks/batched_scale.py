"""How many batched fixed-wings (class ``fixed_wing_batched``, the uav700)
fly in real time: for each fleet size, a full ``cosim run`` (process backend,
one worker per core) of a grid of aircraft told to loiter at 10 s, with the
exchange at 10 Hz and logging at 1 Hz. Reports the real-time factor of the
tick loop (``summary.json``), the time to load and check the scenario, the
pool's start-up, the whole command's wall time and the peak memory of the
driver and its workers together, per aircraft.

    python benchmarks/batched_scale.py --vehicles 1000,10000,100000
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

SCENARIO = """\
schema_version: 1
origin: {{lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}}
rates: {{physics_hz: 120, control_hz: {control_hz}, log_hz: 1}}
duration_s: {seconds}
vehicles:
  - {{id: uav, class: fixed_wing_batched, model: uav700, count: {n},
     formation: {{type: grid, spacing_m: 150}},
     init: {{north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}}}
schedule:
  - {{at_s: 1, vehicles: "*", command: {{loiter: {{radius_m: 1500}}, alt_agl_m: 400,
                                          airspeed_kt: 110}}}}
"""


def _peak_rss(proc: subprocess.Popen[bytes], stop: threading.Event, out: list[int]) -> None:
    """Sample the process tree's resident memory every 0.2 s; keep the peak."""
    p = psutil.Process(proc.pid)
    peak = 0
    while not stop.is_set():
        try:
            tree = [p, *p.children(recursive=True)]
            peak = max(peak, sum(q.memory_info().rss for q in tree if q.is_running()))
        except psutil.Error:
            pass
        time.sleep(0.2)
    out.append(peak)


def one(n: int, seconds: float, control_hz: float, tmp: Path) -> dict[str, float]:
    path = tmp / f"scale{n}.yaml"
    path.write_text(SCENARIO.format(n=n, seconds=seconds, control_hz=control_hz))
    out = tmp / f"run{n}"
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(path), "--out", str(out),
                             "--overwrite"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stop, peak = threading.Event(), []  # type: ignore[var-annotated]
    sampler = threading.Thread(target=_peak_rss, args=(proc, stop, peak))
    sampler.start()
    _, err = proc.communicate()
    wall = time.perf_counter() - t0
    stop.set()
    sampler.join()
    if proc.returncode != 0:
        raise RuntimeError(f"{n} aircraft: cosim run failed: {err.decode()[-2000:]}")
    s = json.loads((out / "summary.json").read_text())
    return {"aircraft": n, "real_time_factor": s["real_time_factor"],
            "startup_s": s["startup_s"], "loop_s": s["wall_time_s"], "command_s": wall,
            "peak_mib": peak[0] / 2**20, "kib_per_aircraft": peak[0] / 1024 / n}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", default="1000,10000,100000",
                    help="fleet sizes, comma separated (default: %(default)s)")
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds")
    ap.add_argument("--control-hz", type=float, default=10.0, help="the exchange rate")
    ap.add_argument("--json", type=Path, help="write the figures here")
    a = ap.parse_args(argv)
    sizes = [int(x) for x in a.vehicles.split(",") if x.strip()]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            r = one(n, a.seconds, a.control_hz, Path(tmp))
            rows.append(r)
            print(json.dumps(r), flush=True)
    print(f"\n{os.cpu_count()} cores, {a.seconds:g} s simulated, exchange {a.control_hz:g} Hz, "
          f"log 1 Hz\n")
    print("| aircraft | real-time factor | pool start-up (s) | whole command (s) "
          "| peak memory (MiB) | per aircraft (KiB) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['aircraft']:,} | {r['real_time_factor']:.2f} | {r['startup_s']:.1f} "
              f"| {r['command_s']:.0f} | {r['peak_mib']:.0f} | {r['kib_per_aircraft']:.1f} |")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
