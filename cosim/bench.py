"""``cosim bench``: pool throughput against baselines measured in the same run.

For each fleet size N it measures, over the same number of physics ticks:

- ``serial``: the plain single-process loop over N FDMs (``fdm.run()`` back
  to back, no state reads, no orchestration): the speed-up denominator;
- ``ceiling``: W independent processes each stepping N/W FDMs with no
  communication at all: what W cores can do at best;
- ``pool``: the chosen backend through the full exchange (setpoints, states,
  lockstep barrier), as ``cosim run`` uses it.

and reports aircraft-steps per second, the real-time factor, the pool's
start-up time (build + trim) and its per-exchange orchestration overhead
(exchange wall time minus the busiest shard's stepping time). Ratios are
computed from figures measured side by side, never against constants.
"""

from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from cosim.fdm_pool import make_pool
from cosim.fdm_pool.process import default_workers, shard_bounds
from cosim.fdm_pool.shard import Shard
from cosim.fdm_pool.spec import VehicleSpec
from cosim.geo import KT_TO_MPS, LocalFrame
from cosim.jsb import find_model
from cosim.scenario.formation import formation_offsets

log = logging.getLogger(__name__)


def bench_specs(n: int, model: str = "c172p", spacing_m: float = 300.0) -> list[VehicleSpec]:
    """N vehicles in a grid at 1000 m, 100 kt, heading north."""
    m = find_model(model)
    north, east = formation_offsets("grid", n, spacing_m, 0.0)
    lat, lon, _ = LocalFrame(37.4, -122.0, 0.0).ned_to_geodetic(north, east, 0.0)
    return [VehicleSpec(id=f"b{i:04d}", model=m.name, aircraft_dir=m.aircraft_dir,
                        model_source=m.source, lat_deg=float(lat[i]), lon_deg=float(lon[i]),
                        alt_msl_m=1000.0, heading_deg=0.0, airspeed_mps=100 * KT_TO_MPS,
                        random_seed=i) for i in range(n)]


def _serial_loop(shard: Shard, ticks: int, k: int) -> float:
    fdms = [v.fdm for v in shard.vehicles]
    t0 = time.perf_counter()
    for _ in range(ticks // k):
        for f in fdms:
            run = f.run
            for _ in range(k):
                run()
    return time.perf_counter() - t0


def _ceiling_worker(specs: list[VehicleSpec], dt_s: float, ticks: int, k: int,
                    ready: Any, go: Any, out: Any, i: int) -> None:
    shard = Shard.build(specs, dt_s, ())
    ready.release()
    go.wait()
    out[i] = _serial_loop(shard, ticks, k)


def _ceiling(specs: list[VehicleSpec], dt_s: float, ticks: int, k: int, workers: int) -> float:
    """Wall time of W independent processes stepping their shards (max over them)."""
    ctx = mp.get_context("spawn")
    ready, go = ctx.Semaphore(0), ctx.Event()
    out = ctx.RawArray("d", workers)
    procs = []
    for i, (a, b) in enumerate(shard_bounds(len(specs), workers)):
        p = ctx.Process(target=_ceiling_worker, daemon=True,
                        args=(specs[a:b], dt_s, ticks, k, ready, go, out, i))
        p.start()
        procs.append(p)
    for _ in procs:
        if not ready.acquire(timeout=600):
            raise RuntimeError("ceiling worker failed to start")
    go.set()
    for p in procs:
        p.join()
        if p.exitcode != 0:
            raise RuntimeError(f"ceiling worker exited with {p.exitcode}")
    return max(out[:])


def bench_size(n: int, model: str, backend: str, workers: int | None, seconds: float,
               physics_hz: float, control_hz: float, baselines: bool = True) -> dict[str, Any]:
    dt = 1.0 / physics_hz
    k = round(physics_hz / control_hz)
    ticks = max(k, math.ceil(seconds * physics_hz / k) * k)
    specs = bench_specs(n, model)
    steps = n * ticks
    res: dict[str, Any] = {"vehicles": n, "ticks": ticks, "sim_s": ticks * dt,
                           "exchange_every": k}

    t0 = time.perf_counter()
    pool = make_pool(specs, dt, (), backend, workers)
    res["startup_s"] = time.perf_counter() - t0
    w = pool.workers
    res["workers"] = w
    with pool:
        pool.step(k)  # warm-up exchange
        over = []
        t0 = time.perf_counter()
        for _ in range(ticks // k):
            e0 = time.perf_counter()
            pool.step(k)
            over.append(time.perf_counter() - e0 - max(pool.busy_s() or [0.0]))
        wall = time.perf_counter() - t0
    res["pool_s"] = wall
    res["pool_steps_per_s"] = steps / wall
    res["pool_rtf"] = ticks * dt / wall
    res["overhead_us_per_exchange"] = float(np.mean(over)) * 1e6
    res["overhead_us_per_exchange_p99"] = float(np.percentile(over, 99)) * 1e6

    if baselines:
        shard = Shard.build(specs, dt, ())
        serial = _serial_loop(shard, ticks, k)
        del shard
        res["serial_s"] = serial
        res["serial_steps_per_s"] = steps / serial
        res["speedup_vs_serial"] = serial / wall
        if w > 1:
            ceil = _ceiling(specs, dt, ticks, k, w)
            res["ceiling_s"] = ceil
            res["ceiling_steps_per_s"] = steps / ceil
            res["fraction_of_ceiling"] = ceil / wall
    return res


def run_bench(vehicles: list[int], model: str = "c172p", backend: str = "process",
              workers: int | None = None, seconds: float = 5.0, physics_hz: float = 120.0,
              control_hz: float = 30.0, baselines: bool = True,
              json_path: str | None = None) -> list[dict[str, Any]]:
    w = workers if workers is not None else (default_workers() if backend == "process" else 1)
    print(f"cosim bench: model {model}, backend {backend}, workers {w}, "
          f"{physics_hz:g} Hz physics, {control_hz:g} Hz exchange, {seconds:g} s simulated per "
          f"size", flush=True)
    hdr = (f"{'N':>6} {'start s':>8} {'pool st/s':>11} {'RTF':>8} {'ovh us':>8} "
           f"{'serial st/s':>12} {'x serial':>9} {'ceil st/s':>11} {'of ceil':>8}")
    print(hdr, flush=True)
    results = []
    for n in vehicles:
        r = bench_size(n, model, backend, workers, seconds, physics_hz, control_hz, baselines)
        results.append(r)

        def f(key: str, fmt: str, r: dict[str, Any] = r) -> str:
            return format(r[key], fmt) if key in r else "-"

        print(f"{n:>6} {f('startup_s', '8.2f')} {f('pool_steps_per_s', '11.0f')} "
              f"{f('pool_rtf', '8.2f')} {f('overhead_us_per_exchange', '8.0f')} "
              f"{f('serial_steps_per_s', '12.0f')} {f('speedup_vs_serial', '9.2f')} "
              f"{f('ceiling_steps_per_s', '11.0f')} {f('fraction_of_ceiling', '8.1%')}",
              flush=True)
    if json_path:
        doc = {"model": model, "backend": backend, "workers": w, "physics_hz": physics_hz,
               "control_hz": control_hz, "seconds": seconds,
               "machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                           "cores": default_workers()},
               "results": results}
        Path(json_path).write_text(json.dumps(doc, indent=2) + "\n")
        print(f"wrote {json_path}")
    return results
