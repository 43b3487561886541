"""Where a pool's start goes: N JSBSim aircraft (uav700 by default) built and
trimmed by the process pool over 2 workers (the driver builds the first
half, a spawned worker the second), in interleaved rounds, one child
process per measurement, for each source tree given (``--tree``, A/B: a
``git worktree`` of the commit to compare against, and this checkout).

Per pool: the whole start (``start s``, what ``cosim bench`` prints), the
driver's own build, the worker's own build (its log line), and the worker's
start-up (the start less its build: spawning Python, importing cosim and
numpy, unpacking its specs). Apart, one process builds ``--phases`` aircraft
with JSBSim's calls timed one by one (``FGFDMExec()``, ``load_model``,
initial conditions and ``run_ic``, ``do_trim``) and as cosim's ``Vehicle``;
``floor s`` is half the aircraft times JSBSim's own per-aircraft cost: what
one of the two processes needs at the least, with no start-up and nothing
of cosim's.

    python benchmarks/startup_cost.py --tree /tmp/base --tree . --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve()
_WORKER = re.compile(r"worker 1 \(pid \d+\): (\d+) vehicles built and trimmed in ([0-9.]+) s")


def _pool(n: int, model: str) -> dict[str, Any]:
    """In the child: one pool's start, split."""
    import logging

    from cosim.bench.fleet import bench_specs
    from cosim.fdm_pool import shard
    from cosim.fdm_pool.process import ProcessPool

    specs = bench_specs(n, model)
    logging.basicConfig(format="%(message)s")  # the worker logs its build like this
    logging.getLogger("cosim").setLevel(logging.DEBUG)
    logging.getLogger("cosim.jsbsim").setLevel(logging.WARNING)
    spans: list[float] = []
    build = shard.Shard.build.__func__  # type: ignore[attr-defined]

    def timed(cls: Any, *args: Any, **kw: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return build(cls, *args, **kw)
        finally:
            spans.append(time.perf_counter() - t0)

    shard.Shard.build = classmethod(timed)  # type: ignore[method-assign, assignment]
    t0 = time.perf_counter()
    pool = ProcessPool(specs, 1 / 120, workers=2)
    start_s = time.perf_counter() - t0
    pool.close()
    return {"start_s": start_s, "driver_build_s": spans[0]}


def _phases(n: int, model: str) -> dict[str, Any]:
    """In the child: JSBSim's calls timed one by one, then cosim's Vehicle."""
    import jsbsim

    from cosim.bench.fleet import bench_specs
    from cosim.core.units import FT_TO_M
    from cosim.vehicles.jsb import JSBSIM_ROOT, SYSTEMS_DIR, find_model, quiet_jsbsim
    from cosim.vehicles.jsbsim_model import Vehicle

    quiet_jsbsim()
    info = find_model(model)
    if info.source != "cosim" or info.profile.get("autopilot") == "attach":
        raise SystemExit(f"--phases times a project model with its own autopilot "
                         f"(uav700), not {model!r}")
    specs = bench_specs(n + 1, model)
    fps = 1.0 / FT_TO_M
    sums = dict.fromkeys(("ctor_ms", "load_ms", "ic_ms", "trim_ms"), 0.0)
    kept = []
    for s in specs[1:]:
        t = [time.perf_counter()]
        fdm = jsbsim.FGFDMExec(str(JSBSIM_ROOT))
        fdm.set_debug_level(0)
        fdm.disable_output()
        t.append(time.perf_counter())
        fdm.load_model_with_paths(s.model, s.aircraft_dir, str(JSBSIM_ROOT / "engine"),
                                  str(SYSTEMS_DIR))
        t.append(time.perf_counter())
        fdm.set_dt(1 / 120)
        prof = info.profile
        if "clmax" in prof:  # what new_fdm sets
            fdm["cosim/ap/clmax"] = float(prof["clmax"])
        for prop, value in (prof.get("properties") or {}).items():
            fdm[prop] = float(value)
        fdm["ic/lat-geod-deg"], fdm["ic/long-gc-deg"] = s.lat_deg, s.lon_deg
        fdm["ic/h-sl-ft"], fdm["ic/vt-fps"] = s.alt_msl_m * fps, s.airspeed_mps * fps
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        t.append(time.perf_counter())
        fdm.do_trim(1)
        t.append(time.perf_counter())
        kept.append(fdm)  # kept, as a shard keeps them
        for key, a, b in zip(sums, t, t[1:]):
            sums[key] += (b - a) * 1e3
    out = {k: v / n for k, v in sums.items()}
    del kept
    t0 = time.perf_counter()
    vehicles = [Vehicle(s, 1 / 120, ()) for s in specs[1:]]
    out["vehicle_ms"] = (time.perf_counter() - t0) / len(vehicles) * 1e3
    out["jsbsim_ms"] = sum(out[k] for k in sums)
    return out


def _child(what: str, tree: Path, n: int, model: str) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tree)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])}
    p = subprocess.run([sys.executable, str(HERE), "--child", what, "--vehicles", str(n),
                        "--model", model], env=env, capture_output=True, text=True,
                       cwd=str(tree), timeout=600)
    if p.returncode != 0:
        raise SystemExit(f"{tree}: the {what} measurement failed:\n{p.stderr[-3000:]}")
    r: dict[str, Any] = json.loads(p.stdout.strip().splitlines()[-1])
    if what == "pool":
        m = _WORKER.search(p.stderr)
        if m is None:
            raise SystemExit(f"{tree}: the worker's build time is not in its log:\n"
                             f"{p.stderr[-3000:]}")
        r["worker_build_s"] = float(m.group(2))
        r["worker_startup_s"] = r["start_s"] - r["worker_build_s"]
    r["load"] = os.getloadavg()[0]
    return r


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=1000, help="aircraft in the pool")
    ap.add_argument("--phases", type=int, default=100,
                    help="aircraft built with JSBSim's calls timed one by one (0: none)")
    ap.add_argument("--model", default="uav700")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--tree", action="append", type=Path, metavar="DIR",
                    help="a source tree to measure (repeat for A/B); default: this checkout")
    ap.add_argument("--json", type=Path, metavar="FILE")
    ap.add_argument("--child", choices=("pool", "phases"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.vehicles < 2 or a.rounds < 1 or a.phases < 0:
        ap.error("--vehicles must be at least 2, --rounds at least 1, --phases at least 0")
    if a.child:
        measure = _pool if a.child == "pool" else _phases
        print(json.dumps(measure(a.vehicles if a.child == "pool" else a.phases, a.model)))
        return 0
    trees = [t.resolve() for t in (a.tree or [HERE.parent.parent])]
    for t in trees:
        if not (t / "cosim" / "__init__.py").is_file():
            ap.error(f"--tree {t}: not a cosim source tree (no cosim/__init__.py)")
    runs: dict[str, list[dict[str, Any]]] = {str(t): [] for t in trees}
    for r in range(a.rounds):
        for t in (trees if r % 2 == 0 else trees[::-1]):  # interleaved, order alternating
            row = _child("pool", t, a.vehicles, a.model)
            if a.phases:
                row.update(_child("phases", t, a.phases, a.model))
                row["floor_s"] = a.vehicles / 2 * row["jsbsim_ms"] / 1e3
            runs[str(t)].append(row)
            print(f"round {r + 1} {t}: " + ", ".join(
                f"{k} {v:.3g}" for k, v in row.items()), flush=True)
    cols = ["start_s", "driver_build_s", "worker_startup_s", "worker_build_s", "floor_s",
            "ctor_ms", "load_ms", "ic_ms", "trim_ms", "vehicle_ms", "load"]
    print(f"\n{a.vehicles} {a.model}, 2 workers; medians of {a.rounds} rounds")
    print(f"{'tree':<28}" + "".join(f"{c:>17}" for c in cols))
    for t, rows in runs.items():
        med = {c: statistics.median(row[c] for row in rows) for c in cols if c in rows[0]}
        print(f"{Path(t).name[:27]:<28}" + "".join(
            f"{med[c]:>17.3f}" if c in med else f"{'-':>17}" for c in cols))
    if len(trees) > 1:
        first = runs[str(trees[0])]
        for t in trees[1:]:
            ratio = statistics.median(b["start_s"] / a_["start_s"]
                                      for a_, b in zip(first, runs[str(t)]))
            print(f"start s, {Path(t).name} / {trees[0].name}: median of the rounds' "
                  f"ratios {ratio:.3f}")
    if a.json:
        a.json.write_text(json.dumps({"vehicles": a.vehicles, "model": a.model, "runs": runs},
                                     indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
