"""What an exchange costs a JSBSim vehicle, in one process (no pool, no
driver): one shard of N uav700s at 1000 m stepped through ``Shard.exchange``
for the same simulated time with the exchange every k physics ticks (k = 60,
12, 4, 1: 2, 10, 30 and 120 Hz at 120 Hz physics), in interleaved rounds;
and, apart, the cost of reading one vehicle's state row (``raw_state``) and
of stepping one FDM k ticks with nothing else in between (the same FDM over
and over, so it stays in the CPU's caches); the state row is also read by
property name, JSBSim's other access paths, for comparison.

The difference between the per-exchange cost and the state read is the price
of switching FDMs: each aircraft's JSBSim objects (about 0.45 MiB) fall out
of the caches while the other N-1 step, and come back on its next exchange.

    python benchmarks/exchange_cost.py --vehicles 256
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=256)
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated per round")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    from cosim.bench.fleet import bench_specs
    from cosim.fdm_pool.shard import Shard

    n = a.vehicles
    sh = Shard.build(bench_specs(n, "uav700"), 1 / 120, ())
    out = np.zeros((n, sh.n_columns))
    ticks = int(120 * a.seconds)
    ks = (60, 12, 4, 1)
    per_step: dict[int, list[float]] = {k: [] for k in ks}
    for _ in range(a.rounds):
        for k in ks:
            t0 = time.perf_counter()
            for _ in range(ticks // k):
                sh.exchange(None, k, out)
            per_step[k].append((time.perf_counter() - t0) / (ticks * n) * 1e6)
    v = sh.vehicles[0]
    t0 = time.perf_counter()
    for _ in range(2000):
        v.raw_state()
    read_us = (time.perf_counter() - t0) / 2000 * 1e6
    # the same row by property name, through JSBSim's two name lookups
    from cosim.core.state import STATE_FIELDS

    names = [f.prop for f in STATE_FIELDS if f.prop is not None and v.fdm.get_property_manager()
             .hasNode(f.prop)]
    by_name = {}
    for label, get in (("fdm[name]", v.fdm.__getitem__),
                       ("fdm.get_property_value(name)", v.fdm.get_property_value)):
        t0 = time.perf_counter()
        for _ in range(2000):
            [get(n) for n in names]
        by_name[label] = (time.perf_counter() - t0) / 2000 * 1e6
    t0 = time.perf_counter()
    for _ in range(200):
        v.step(12, False)
    hot_us = (time.perf_counter() - t0) / (200 * 12) * 1e6
    base = statistics.median(per_step[60])
    print(f"{n} uav700 in one process, {a.seconds:g} s simulated x {a.rounds} rounds "
          f"(medians)\n")
    print("| exchange | us per vehicle-step | us per vehicle-exchange above 2 Hz |")
    print("|---|---|---|")
    for k in ks:
        m = statistics.median(per_step[k])
        extra = (m - base) * 120 / (120 / k - 2) if k != 60 else 0.0
        print(f"| {120 / k:g} Hz | {m:.2f} | {extra:.1f} |")
    print(f"\nreading one state row: {read_us:.1f} us (resolved property nodes, cosim's way; "
          + ", ".join(f"by name with {k}: {us:.1f} us" for k, us in by_name.items())
          + f"); one physics step of one FDM kept hot in the caches: {hot_us:.2f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
