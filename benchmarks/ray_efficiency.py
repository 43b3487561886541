"""The ray backend against the process backend on the same machine: the
same uav700s (120 Hz physics) on each pool, built side by side and stepped
in turn for segments of the same simulated time, so all see the same machine
load; efficiency = the pool's aircraft-steps/s over process's (the median of
the per-round ratios). Two ray pools: as it runs by default (the driver's
own machine's share in the driver, so on one machine there is no agent and
the difference is Ray's presence), and with that share behind an agent
(``local_share=False``) as every other machine's is: the difference is then
what a remote machine costs, a Ray call per exchange carrying the setpoints
out and the states back.

    python benchmarks/ray_efficiency.py --vehicles 256 1024 --control-hz 30 10

(``--backend ray`` starts a private local Ray unless ``RAY_ADDRESS`` names a
cluster; on a cluster the ray pool spreads over every machine and the ratio
is no longer like for like.)
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from typing import Any


def _segment(pool: Any, exchanges: int, k: int) -> float:
    t0 = time.perf_counter()
    for _ in range(exchanges):
        pool.step(k)
    return time.perf_counter() - t0


def measure(n: int, control_hz: float, seconds: float, rounds: int,
            workers: int | None, configs: list[str] | None = None) -> dict[str, Any]:
    """``configs``: the names in ``CONFIGS`` to measure (default all; process
    always)."""
    from cosim.bench.fleet import bench_specs
    from cosim.fdm_pool import make_pool

    k = round(120 / control_hz)
    exchanges = max(1, round(seconds * 120 / k))
    specs = bench_specs(n, "uav700")
    pools: dict[str, Any] = {}
    startup: dict[str, float] = {}
    for name, backend, opts in CONFIGS:
        if configs is not None and name != "process" and name not in configs:
            continue
        t0 = time.perf_counter()
        pools[name] = make_pool(specs, 1 / 120, (), backend, workers, **opts)
        startup[name] = time.perf_counter() - t0
    times: dict[str, list[float]] = {name: [] for name in pools}
    try:
        for pool in pools.values():
            _segment(pool, 3, k)  # warm-up
        names = list(pools)
        for r in range(rounds):  # each round in another order
            for name in names[r % len(names):] + names[:r % len(names)]:
                times[name].append(_segment(pools[name], exchanges, k))
    finally:
        for pool in pools.values():
            pool.close()
    steps = n * exchanges * k
    out: dict[str, Any] = {"vehicles": n, "control_hz": 120 / k,
                           "workers": pools["process"].workers,
                           "ray_call_ms": ray_call_ms(n, len(pools["process"].layout))}
    for name in pools:
        ratios = [p / r for p, r in zip(times["process"], times[name])]
        out[name] = {"steps_per_s": steps / min(times[name]), "startup_s": startup[name],
                     "efficiency": statistics.median(ratios), "ratios": ratios,
                     "ms_per_exchange_extra": (min(times[name]) - min(times["process"]))
                     / exchanges * 1e3}
    return out


def ray_call_ms(n: int, width: int, calls: int = 300) -> float:
    """The floor of an agent's exchange: a Ray actor call that returns an
    ``(n, width)`` float64 block and does nothing else (median ms)."""
    import numpy as np
    import ray

    class Echo:
        def step(self, setpoints: Any, nsub: int) -> tuple[np.ndarray, list[float]]:
            return np.zeros((n, width)), [0.0]

    actor = ray.remote(Echo).options(num_cpus=0).remote()
    try:
        ray.get(actor.step.remote(None, 4))
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            ray.get(actor.step.remote(None, 4))
            times.append(time.perf_counter() - t0)
        return statistics.median(times) * 1e3
    finally:
        ray.kill(actor)


#: (name, backend, options)
CONFIGS: list[tuple[str, str, dict[str, Any]]] = [
    ("process", "process", {}), ("ray", "ray", {}),
    ("ray_agent", "ray", {"local_share": False})]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, nargs="+", default=[256, 1024])
    ap.add_argument("--control-hz", type=float, nargs="+", default=[30.0, 10.0])
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated per segment")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--workers", type=int, help="both pools' (default: the process default)")
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args(argv)
    rows = []
    print(f"{'N':>6} {'Hz':>4} {'process st/s':>13} | {'ray: st/s':>10} {'eff.':>6} | "
          f"{'ray, agent: st/s':>16} {'eff.':>6} {'+ms/exch':>8} {'call ms':>7} | "
          f"{'start p/r/a s':>14}",
          flush=True)
    for n in a.vehicles:
        for hz in a.control_hz:
            r = measure(n, hz, a.seconds, a.rounds, a.workers)
            rows.append(r)
            p, y, g = r["process"], r["ray"], r["ray_agent"]
            print(f"{n:>6} {r['control_hz']:>4.0f} {p['steps_per_s']:>13,.0f} | "
                  f"{y['steps_per_s']:>10,.0f} {y['efficiency']:>6.1%} | "
                  f"{g['steps_per_s']:>16,.0f} {g['efficiency']:>6.1%} "
                  f"{g['ms_per_exchange_extra']:>8.2f} {r['ray_call_ms']:>7.2f} | "
                  f"{p['startup_s']:.1f}/"
                  f"{y['startup_s']:.1f}/{g['startup_s']:.1f}", flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
