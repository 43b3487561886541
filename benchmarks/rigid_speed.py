"""The rigid-body tier's speed against the JSBSim tier's, in the same run and
one process each (what a core does): ``N`` uav700 (or ``--model``'s aircraft,
e.g. the c172p) at 120 Hz with the cosim
autopilot engaged (heading, altitude and speed holds, a new heading every
10 s so the loops work), aircraft-steps a second, best of ``--rounds``
blocks of ``--frames`` frames. The JSBSim tier is timed on fewer aircraft
(its cost grows linearly: ``--jsbsim`` of them, each stepped in turn as a
worker steps its share), the rigid tier at each size of ``--vehicles``
(one vectorised frame for all).

    python benchmarks/rigid_speed.py --vehicles 1000,4000,10000,20000 --json out.json

``--pool N,N,...`` also flies N rigid aircraft through the process pool (one
worker a core, 30 Hz exchange) with the autopilot engaged through its
setpoint channels (heading, altitude and speed holds; a new heading each
timed round of ``--pool-seconds``), and reports the best round's real-time
factor: how many fly in real time on the
machine's cores with everything an exchange costs.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
AP = {"cosim/ap/engage": 1.0, "cosim/ap/heading-hold": 1.0, "cosim/ap/alt-hold": 1.0,
      "cosim/ap/alt-cmd-ft": 3300.0, "cosim/ap/speed-hold": 1.0,
      "cosim/ap/speed-cmd-kt": 110.0}


def rigid(n: int, frames: int, rounds: int, model: str = "uav700") -> float:
    """Aircraft-steps a second of ``n`` rigid ``model`` aircraft in one process."""
    from cosim.rigid.aircraft import compile_aircraft, position_ecef
    from cosim.vehicles.fixed_wing_rigid import model_files
    from cosim.vehicles.jsb import find_model

    m = find_model(model)
    ac = compile_aircraft(*model_files(m.aircraft_dir, m.name, m.source, m.profile))
    props = ac.new_props(n)
    loc = position_ecef(47.0 + np.arange(n) * 1e-3, np.full(n, 8.0), np.full(n, 3000.0))
    props["cosim/ap/qbar-ref-psf"] = np.full(n, 34.0)
    if not ac.trim_level(props, loc, np.zeros(n), np.full(n, 100 * 1.68781)).all():
        raise SystemExit("the rigid tier did not trim")
    for k, v in AP.items():
        props[k] = np.full(n, v)
    best = float("inf")
    t_sim = 0.0
    for r in range(rounds + 1):
        props["cosim/ap/heading-cmd-deg"] = np.full(n, 90.0 * (r % 4))
        t = time.perf_counter()
        for _ in range(frames):
            ac.run(props, 1 / 120)
        if r:  # the first block warms up (numba's cache, the loops settling)
            best = min(best, time.perf_counter() - t)
        t_sim += frames / 120
    if not np.all(props["cosim/ap/engage"] == 1.0) or np.isnan(props["position/h-sl-ft"]).any():
        raise SystemExit("the rigid tier's autopilot did not stay engaged")
    return n * frames / best


def jsbsim(n: int, frames: int, rounds: int, model: str = "uav700") -> float:
    """Aircraft-steps a second of ``n`` JSBSim ``model`` aircraft stepped in turn."""
    from cosim.vehicles.jsb import find_model, new_fdm

    fdms = []
    for i in range(n):
        fdm = new_fdm(find_model(model), 1 / 120)
        fdm["ic/lat-geod-deg"], fdm["ic/long-gc-deg"] = 47.0 + i * 1e-3, 8.0
        fdm["ic/h-sl-ft"], fdm["ic/vt-fps"] = 3000.0, 100 * 1.68781
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        fdm.do_trim(1)
        for k, v in AP.items():
            fdm[k] = v
        fdms.append(fdm)
    best = float("inf")
    for r in range(rounds + 1):
        for fdm in fdms:
            fdm["cosim/ap/heading-cmd-deg"] = 90.0 * (r % 4)
        t = time.perf_counter()
        for fdm in fdms:
            run = fdm.run
            for _ in range(frames):
                run()
        if r:
            best = min(best, time.perf_counter() - t)
    return n * frames / best


def pool(n: int, seconds: float, rounds: int, model: str = "uav700") -> dict[str, float]:
    """``n`` rigid ``model`` aircraft through the process pool, the autopilot
    engaged through the setpoint channels: the best round's real-time factor."""
    from cosim.bench.fleet import bench_specs
    from cosim.core.state import STATE_INDEX
    from cosim.fdm_pool import make_pool

    channels = tuple(AP) + ("cosim/ap/heading-cmd-deg",)
    heading = len(AP)
    specs = bench_specs(n, model, vehicle_class="fixed_wing_rigid")
    k = 4  # 120 Hz physics, 30 Hz exchange
    ticks = max(k, round(seconds * 120 / k) * k)
    best = float("inf")
    t0 = time.perf_counter()
    with make_pool(specs, 1 / 120, channels, "process") as p:
        start_s = time.perf_counter() - t0
        for j, v in enumerate(AP.values()):
            p.setpoints[:, j] = v
        p.setpoints[:, heading] = 90.0
        p.step(k)  # the setpoints in, a warm-up exchange
        for r in range(rounds):
            p.setpoints[:, heading] = 90.0 * (r % 4)
            t = time.perf_counter()
            for _ in range(ticks // k):
                p.step(k)
            best = min(best, time.perf_counter() - t)
        if not np.all(p.states[:, STATE_INDEX["ap_engaged"]] == 1.0):
            raise SystemExit("the pool's autopilots did not stay engaged")
        workers = p.workers
    return {"vehicles": n, "workers": workers, "startup_s": start_s,
            "rtf": ticks / 120 / best, "steps_per_s": n * ticks / best}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="uav700",
                    help="the aircraft, one the rigid tier compiles (default %(default)s)")
    ap.add_argument("--vehicles", default="1000,4000,10000,20000",
                    help="rigid-tier sizes, comma-separated (default %(default)s)")
    ap.add_argument("--jsbsim", type=int, default=64,
                    help="JSBSim aircraft timed (default %(default)s)")
    ap.add_argument("--frames", type=int, default=60, help="frames a block (default 60)")
    ap.add_argument("--rounds", type=int, default=5, help="timed blocks (default 5)")
    ap.add_argument("--pool", default="",
                    help="also these sizes through the process pool, autopilot engaged, "
                         "comma-separated (e.g. 8192,16384)")
    ap.add_argument("--pool-seconds", type=float, default=2.0,
                    help="simulated seconds a pool round (default %(default)s)")
    ap.add_argument("--json", type=Path, help="write the figures here")
    a = ap.parse_args(argv)
    try:
        sizes = [int(x) for x in a.vehicles.split(",") if x]
        pools = [int(x) for x in a.pool.split(",") if x]
    except ValueError:
        ap.error("--vehicles and --pool take comma-separated whole numbers")
    if not sizes or min(sizes + pools) < 1 or a.jsbsim < 1 or a.frames < 1 or a.rounds < 1 \
            or not a.pool_seconds > 0:
        ap.error("--vehicles, --pool, --jsbsim, --frames, --rounds and --pool-seconds take "
                 "positive numbers")
    from cosim.errors import CosimError
    from cosim.vehicles.jsb import find_model

    try:
        find_model(a.model)
    except CosimError as e:
        ap.error(f"--model: {e}")
    print(f"model {a.model}, 120 Hz, the autopilot engaged")
    ref = jsbsim(a.jsbsim, a.frames, a.rounds, a.model)
    print(f"JSBSim tier : {a.jsbsim:6d} aircraft  {ref:12,.0f} aircraft-steps/s a core")
    rows = []
    for n in sizes:
        v = rigid(n, a.frames, a.rounds, a.model)
        rows.append({"vehicles": n, "steps_per_s": v, "x_jsbsim": v / ref})
        print(f"rigid tier  : {n:6d} aircraft  {v:12,.0f} aircraft-steps/s a core  "
              f"{v / ref:5.1f} x JSBSim  {v / 120:8,.0f} aircraft in real time a core")
        sys.stdout.flush()
    pooled = []
    for n in pools:
        row = pool(n, a.pool_seconds, a.rounds, a.model)
        pooled.append(row)
        print(f"rigid pool  : {n:6d} aircraft  {row['steps_per_s']:12,.0f} aircraft-steps/s on "
              f"{row['workers']} workers  RTF {row['rtf']:5.2f}  (started in "
              f"{row['startup_s']:.1f} s)")
        sys.stdout.flush()
    if a.json:
        a.json.write_text(json.dumps({
            "benchmark": "rigid_speed", "model": a.model, "date": time.strftime("%Y-%m-%d"),
            "machine": platform.machine(), "python": platform.python_version(),
            "physics_hz": 120, "autopilot": "engaged", "jsbsim_vehicles": a.jsbsim,
            "jsbsim_steps_per_s": ref, "rigid": rows, "pool": pooled}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
