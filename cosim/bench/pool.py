"""``cosim bench``: pool throughput against baselines measured in the same run.

For each fleet size N it measures, over the same number of physics ticks:

- ``serial``: the plain single-process loop over N FDMs (``fdm.run()`` back
  to back, no state reads, no orchestration): the speed-up denominator;
- ``ceiling``: W independent processes each stepping N/W FDMs with no
  communication at all: what W cores can do at best;
- ``pool``: the chosen backend through the full exchange (setpoints, states,
  lockstep barrier), as ``cosim run`` uses it;
- ``hot step``: one flight model stepped over and over with nothing in
  between, so that it stays in the CPU's caches; the cores the pool can use
  times that rate is the *hot-step limit*, what no exchange design can beat
  (each aircraft's memory must come back into the caches at its exchange:
  the distance between the ceiling and this limit is that refill).

The three are measured in interleaved rounds (pool, serial, ceiling, pool,
...) because shared machines drift in speed over minutes; ratios are the
median of the per-round ratios.

and reports aircraft-steps per second, the real-time factor, the pool's
start-up time (build + trim), its memory (the driver's growth and the workers'
peak resident sizes, per aircraft) and its per-exchange orchestration overhead
(exchange wall time minus the busiest shard's stepping time). Ratios are
computed from figures measured side by side, never against constants.

With ``whole_run`` it also flies each fleet as a whole ``cosim run`` (the
fleet told to loiter, so guidance works at every exchange, and states logged
at ``log_hz``) and reports that run's real-time factor and where its tick
loop's time went (``summary.json``'s ``time_split_s``): stepping (waiting for
the pool), commands and guidance, logging, and the rest (events, MAVLink,
cameras where a scenario has them).
"""

from __future__ import annotations

import json
import logging
import math
import os
import platform
import sys
import time
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as mp_wait
from pathlib import Path
from typing import Any

import numpy as np

from cosim.bench.fleet import ORIGIN, bench_specs, check_rates
from cosim.bench.plot import plot_scaling
from cosim.core import memory
from cosim.core import workers as worker_kit
from cosim.core.state import VehicleSpec
from cosim.errors import CosimError
from cosim.fdm_pool import get_backend, make_pool
from cosim.fdm_pool.process import default_workers, shard_bounds
from cosim.fdm_pool.shard import Shard
from cosim.vehicles import DEFAULT_CLASS
from cosim.vehicles.jsb import find_model

log = logging.getLogger(__name__)


def _serial_loop(shard: Shard, ticks: int, k: int) -> float:
    """The plain loop: every FDM's ``run()`` back to back, and each batched
    model's step (and its state write, which its exchange cannot do without),
    ``k`` ticks at a time."""
    fdms = [v.fdm for v in shard.vehicles]
    batches = [(model, np.zeros((len(rows), shard.n_columns)))
               for _, model, rows in shard.batches]
    t0 = time.perf_counter()
    for _ in range(ticks // k):
        for f in fdms:
            run = f.run
            for _ in range(k):
                run()
        for model, block in batches:
            model.step(k)
            model.write_states(block)
    return time.perf_counter() - t0


#: physics steps per measurement of the hot step (a few ms), best of ``_HOT_BLOCKS``
_HOT_STEPS, _HOT_BLOCKS = 2000, 5


def _hot_step_s(shard: Shard) -> float | None:
    """Seconds per physics step of the shard's first flight model, stepped
    over and over with nothing in between (the best of a few blocks); None
    where the shard has none (a batched tier steps its rows together)."""
    fdm = next((getattr(v, "fdm", None) for v in shard.vehicles), None)
    if fdm is None:
        return None
    run = fdm.run
    best = math.inf
    for _ in range(_HOT_BLOCKS):
        t0 = time.perf_counter()
        for _ in range(_HOT_STEPS):
            run()
        best = min(best, time.perf_counter() - t0)
    return best / _HOT_STEPS


def _ceiling_worker(specs: list[VehicleSpec], dt_s: float, ticks: int, k: int,
                    conn: Connection) -> None:
    shard = Shard.build(specs, dt_s, ())
    conn.send(0.0)  # built: measurements may start
    while True:
        try:
            go = conn.recv()
        except EOFError:  # the driver is gone
            return
        if go is None:
            return
        conn.send(_serial_loop(shard, ticks, k))


class _Ceiling:
    """W independent processes that step their shards with no communication,
    one segment per ``segment()`` call (all start together; the slowest one
    sets the wall time).

    Each process has a pipe: the driver sends "go" to all, then waits for
    every result or for a process to end (its sentinel), with a timeout. So a
    dead ceiling process is a ``CosimError`` at once and a stuck one after
    the timeout, never a hang. (Not a ``multiprocessing.Barrier``: notifying
    a waiter that was killed blocks forever.)
    """

    def __init__(self, specs: list[VehicleSpec], dt_s: float, ticks: int, k: int,
                 workers: int, build_timeout_s: float | None = None) -> None:
        ctx = worker_kit.context()
        env = memory.allocator().child_env(os.environ)
        self.procs: list[Any] = []
        self.conns: list[Connection] = []
        try:
            for a, b in shard_bounds(len(specs), workers):
                mine, theirs = ctx.Pipe()
                # with the pool's workers' allocator and pages: the same memory
                p = worker_kit.start(_ceiling_worker, (specs[a:b], dt_s, ticks, k, theirs),
                                     name=f"cosim-ceiling-{len(self.procs)}", env=env)
                theirs.close()
                self.procs.append(p)
                self.conns.append(mine)
            # every shard built before anything is timed
            self._collect(build_timeout_s if build_timeout_s is not None
                          else 60.0 + 0.05 * len(specs), "build its vehicles")
        except BaseException:
            self.close()
            raise

    def _collect(self, timeout_s: float, what: str) -> list[float]:
        results = [0.0] * len(self.conns)
        pending = set(range(len(self.conns)))
        deadline = time.monotonic() + timeout_s
        while pending:
            left = deadline - time.monotonic()
            if left <= 0:
                raise CosimError(f"bench: ceiling process(es) {sorted(pending)} did not {what} "
                                 f"within {timeout_s:g} s")
            waitables: list[Any] = [self.conns[i] for i in pending]
            waitables += [self.procs[i].sentinel for i in pending]
            mp_wait(waitables, timeout=left)
            for i in sorted(pending):
                p = self.procs[i]
                if self.conns[i].poll():
                    try:
                        results[i] = self.conns[i].recv()
                        pending.discard(i)
                        continue
                    except (EOFError, OSError):  # closed or reset: it is gone
                        p.join(1.0)
                if p.exitcode is not None or not p.is_alive():
                    raise self._died(i, what)
        return results

    def _died(self, i: int, what: str) -> CosimError:
        p = self.procs[i]
        p.join(1.0)
        return CosimError(f"bench: ceiling process {i} (pid {p.pid}) ended with code "
                          f"{p.exitcode} (while waiting for it to {what})")

    def segment(self, timeout_s: float = 300.0) -> float:
        for i, c in enumerate(self.conns):
            try:
                c.send(True)
            except OSError:  # a broken pipe: it is gone
                raise self._died(i, "start a segment") from None
        return max(self._collect(timeout_s, "finish a segment"))

    def close(self) -> None:
        for c in self.conns:
            try:
                c.send(None)
            except OSError:  # it is gone already
                pass
        worker_kit.stop(self.procs, 5.0)
        for c in self.conns:
            c.close()


def _rss_kib(pid: int | str = "self", field: str = "VmRSS", table: str = "status") -> int:
    """One memory field of a process (KiB) from ``/proc/PID/TABLE``
    (``status``, or ``smaps_rollup`` for the huge pages); 0 where there is none."""
    try:
        with open(f"/proc/{pid}/{table}") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def bench_size(n: int, model: str, backend: str, workers: int | None, seconds: float,
               physics_hz: float, control_hz: float, baselines: bool = True,
               repeat: int = 3, vehicle_class: str | None = None,
               options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``repeat`` rounds; each round runs one segment of ``seconds`` simulated
    time on the pool, then on the serial loop, then on the ceiling processes,
    so the three are measured side by side under the same machine load.
    Rates are from each configuration's best segment; the ratios are the
    median of the per-round ratios."""
    dt = 1.0 / physics_hz
    k = check_rates(physics_hz, control_hz)
    ticks = max(k, math.ceil(seconds * physics_hz / k) * k)
    specs = bench_specs(n, model, vehicle_class=vehicle_class)
    steps = n * ticks
    res: dict[str, Any] = {"vehicles": n, "ticks": ticks, "sim_s": ticks * dt,
                           "exchange_every": k, "repeat": repeat}

    rss0 = _rss_kib()
    t0 = time.perf_counter()
    pool = make_pool(specs, dt, (), backend, workers, **(options or {}))
    res["startup_s"] = time.perf_counter() - t0
    # the pool's memory: what the driver grew by, and its worker processes' peaks
    mem_kib = max(_rss_kib() - rss0, 0) + sum(_rss_kib(p, "VmHWM") for p in pool.pids.values())
    # how much of it the kernel gave as huge pages (the driver's and the workers')
    pids: list[int | str] = ["self", *pool.pids.values()]
    res["huge_pages_mib"] = sum(_rss_kib(p, "AnonHugePages", "smaps_rollup")
                                for p in pids) / 1024
    res["pool_mib"] = mem_kib / 1024
    res["kib_per_aircraft"] = mem_kib / n
    w = pool.workers
    res["workers"] = w
    try:
        shard = Shard.build(specs, dt, ()) if baselines else None
        ceiling = _Ceiling(specs, dt, ticks, k, w) if baselines and w > 1 else None
    except BaseException:
        pool.close()
        raise
    walls: list[float] = []
    serials: list[float] = []
    ceils: list[float] = []
    hots: list[float] = []
    over: list[float] = []
    try:
        with pool:
            pool.step(k)  # warm-up exchange
            for _ in range(repeat):
                t0 = time.perf_counter()
                for _ in range(ticks // k):
                    e0 = time.perf_counter()
                    pool.step(k)
                    over.append(time.perf_counter() - e0 - max(pool.busy_s() or [0.0]))
                walls.append(time.perf_counter() - t0)
                if shard is not None:
                    serials.append(_serial_loop(shard, ticks, k))
                    hot = _hot_step_s(shard)
                    if hot is not None:
                        hots.append(hot)
                if ceiling is not None:  # no slower than 10x the pool, or it is stuck
                    ceils.append(ceiling.segment(timeout_s=60.0 + 10 * walls[-1]))
    finally:
        if ceiling is not None:
            ceiling.close()
    wall = min(walls)
    res["pool_s"] = wall
    res["pool_s_all"] = walls
    res["pool_steps_per_s"] = steps / wall
    res["pool_rtf"] = ticks * dt / wall
    res["overhead_us_per_exchange"] = float(np.median(over)) * 1e6
    res["overhead_us_per_exchange_p99"] = float(np.percentile(over, 99)) * 1e6
    if serials:
        res["serial_s"] = min(serials)
        res["serial_s_all"] = serials
        res["serial_steps_per_s"] = steps / min(serials)
        res["speedup_vs_serial"] = float(np.median([s / p for s, p in zip(serials, walls)]))
    if ceils:
        res["ceiling_s"] = min(ceils)
        res["ceiling_s_all"] = ceils
        res["ceiling_steps_per_s"] = steps / min(ceils)
        res["fraction_of_ceiling"] = float(np.median([c / p for c, p in zip(ceils, walls)]))
    if hots:
        # the cores the pool can keep busy, each stepping a hot flight model
        cores = min(w, default_workers())
        res["hot_step_us"] = min(hots) * 1e6
        res["hot_limit_steps_per_s"] = cores / min(hots)
        res["fraction_of_hot_limit"] = float(np.median(
            [steps / p / (cores / h) for h, p in zip(hots, walls)]))
    return res


#: the whole run's scenario: the bench's fleet, told to loiter after a second
_RUN_SCENARIO = """\
schema_version: 1
name: bench-{n}
origin: {{lat_deg: {lat}, lon_deg: {lon}, ground_alt_m: 0}}
rates: {{physics_hz: {physics_hz}, control_hz: {control_hz}, log_hz: {log_hz}}}
duration_s: {seconds}
vehicles:
  - {{id: b, class: {cls}, model: {model}, count: {n}, formation: {{type: grid, spacing_m: 300}},
     init: {{north_m: 0, east_m: 0, alt_agl_m: 1000, airspeed_kt: 100}}}}
schedule:
  - {{at_s: 1, vehicles: "*", command: {{loiter: {{radius_m: 1500}}, alt_agl_m: 1000}}}}
"""


#: how the tick loop's participants group in the bench's split (label prefix -> group)
_SPLIT_GROUPS = (("pool:", "stepping"), ("Guidance.", "guidance"), ("Schedule.", "guidance"),
                 ("StateLogger.", "logging"))


def whole_run(n: int, model: str, vehicle_class: str | None, backend: str,
              workers: int | None, seconds: float, physics_hz: float, control_hz: float,
              log_hz: float, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Fly ``n`` aircraft as a whole ``cosim run`` (in a temporary folder);
    its real-time factor, start-up and tick-loop time split (fractions)."""
    import tempfile

    from cosim.scenario import load_scenario
    from cosim.sync import Run

    cls = vehicle_class or find_model(model).profile.get("class", DEFAULT_CLASS)
    with tempfile.TemporaryDirectory(prefix="cosim-bench-") as tmp:
        path = Path(tmp) / "bench.yaml"
        path.write_text(_RUN_SCENARIO.format(
            n=n, lat=ORIGIN[0], lon=ORIGIN[1], physics_hz=physics_hz, control_hz=control_hz,
            log_hz=min(log_hz, control_hz), seconds=max(seconds, 2.0), cls=cls, model=model))
        res = Run(load_scenario(path), Path(tmp) / "run", backend=backend,
                  workers=workers, backend_options=options).run()
        if not res.ok:
            raise CosimError(f"cosim bench: the whole run of {n} aircraft failed: {res.error}")
    sm = res.summary
    loop = max(sm["wall_time_s"], 1e-9)
    split = dict.fromkeys(("stepping", "guidance", "logging", "other"), 0.0)
    for label, secs in sm.get("time_split_s", {}).items():
        group = next((g for prefix, g in _SPLIT_GROUPS if label.startswith(prefix)), "other")
        split[group] += secs / loop
    split["other"] += max(0.0, 1.0 - sum(split.values()))  # the loop's own time
    return {"run_rtf": sm["real_time_factor"], "run_startup_s": sm["startup_s"],
            "run_split": split, "run_time_split_s": sm.get("time_split_s", {}),
            "log_hz": min(log_hz, control_hz)}


#: what the columns of ``cosim bench`` mean (printed under the table)
COLUMNS = """\
columns: N aircraft; start s: building and trimming them all; KiB/ac: memory per aircraft
  (the driver's growth and the workers' peak resident size, over N); pool st/s: aircraft-steps
  a second through the pool (setpoints, stepping, states back, the lockstep barrier); RTF: the
  pool's real-time factor (simulated s / wall s); ovh us: per exchange, its wall time minus the
  busiest worker's stepping time (microseconds, median); serial st/s: one process stepping the
  same FDMs back to back, nothing else; x serial: pool / serial; ceil st/s: as many processes as
  workers stepping their share with no communication at all; of ceil: pool / ceiling; hot us:
  one physics step of one flight model kept hot in the caches (microseconds); of hot: pool / the
  hot-step limit (the cores the pool can use, each stepping hot flight models: what no exchange
  can beat)"""


WHOLE_COLUMNS = """
  run RTF: the real-time factor of a whole run (guidance, logging); step, guid, log, other: the
  share of its tick loop's time in each"""


def run_bench(vehicles: list[int], model: str = "c172p", backend: str = "process",
              workers: int | None = None, seconds: float = 5.0, physics_hz: float = 120.0,
              control_hz: float = 30.0, baselines: bool = True, repeat: int = 3,
              json_path: str | None = None, vehicle_class: str | None = None,
              plot_path: str | None = None, whole: bool = False,
              log_hz: float = 10.0, gym: bool = False,
              options: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Measure each fleet size (``bench_size``; with ``whole`` also
    ``whole_run``) and print a row for it; ``options``: the backend's own
    (``driver_steps=False``: a driver that only coordinates)."""
    check_rates(physics_hz, control_hz)
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    w = workers if workers is not None else get_backend(backend).default_workers()
    tier = vehicle_class or find_model(model).profile.get("class", DEFAULT_CLASS)
    print(f"cosim bench: model {model} ({tier}), backend {backend}, workers {w}, "
          f"{physics_hz:g} Hz physics, {control_hz:g} Hz exchange, best of {repeat} x "
          f"{seconds:g} s simulated per size", flush=True)
    mem = _memory_setup()
    print(f"memory: {mem['allocator']} in the workers; the driver "
          f"{'with' if mem['driver_huge_pages'] else 'without'} huge pages (transparent huge "
          f"pages: {mem['thp'] or 'unknown'})"
          + ("; the driver only coordinates" if (options or {}).get("driver_steps") is False
             else ""), flush=True)
    hdr = (f"{'N':>6} {'start s':>8} {'KiB/ac':>8} {'pool st/s':>11} {'RTF':>8} {'ovh us':>8} "
           f"{'serial st/s':>12} {'x serial':>9} {'ceil st/s':>11} {'of ceil':>8} "
           f"{'hot us':>7} {'of hot':>7}"
           + (f" | {'run RTF':>7} {'step':>5} {'guid':>5} {'log':>5} {'other':>5}"
              if whole else ""))
    print(hdr, flush=True)
    results = []
    for n in vehicles:
        r = bench_size(n, model, backend, workers, seconds, physics_hz, control_hz, baselines,
                       repeat, vehicle_class, options)
        if whole:
            r.update(whole_run(n, model, vehicle_class, backend, workers, seconds, physics_hz,
                               control_hz, log_hz, options))
        results.append(r)

        def f(key: str, fmt: str, r: dict[str, Any] = r) -> str:
            return format(r[key], fmt) if key in r else "-".rjust(int(fmt.split(".")[0]))

        print(f"{n:>6} {f('startup_s', '8.2f')} {f('kib_per_aircraft', '8.0f')} "
              f"{f('pool_steps_per_s', '11.0f')} "
              f"{f('pool_rtf', '8.2f')} {f('overhead_us_per_exchange', '8.0f')} "
              f"{f('serial_steps_per_s', '12.0f')} {f('speedup_vs_serial', '9.2f')} "
              f"{f('ceiling_steps_per_s', '11.0f')} {f('fraction_of_ceiling', '8.1%')} "
              f"{f('hot_step_us', '7.2f')} {f('fraction_of_hot_limit', '7.1%')}"
              + (f" | {r['run_rtf']:>7.2f} " + " ".join(
                  f"{r['run_split'][g]:>5.0%}" for g in ("stepping", "guidance", "logging",
                                                          "other")) if whole else ""),
              flush=True)
    print(COLUMNS + (WHOLE_COLUMNS if whole else ""), flush=True)
    gym_rows = _gym_reference(seconds, repeat, physics_hz, control_hz, backend,
                              workers) if gym else []
    if json_path:
        doc = {"model": model, "class": tier, "backend": backend, "workers": w,
               "physics_hz": physics_hz, "whole_run": whole, "log_hz": log_hz,
               "control_hz": control_hz, "seconds": seconds, "repeat": repeat,
               "options": options or {}, "memory": mem,
               "machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                           "cores": default_workers()},
               "results": results, **({"gym_reference": gym_rows} if gym else {})}
        Path(json_path).write_text(json.dumps(doc, indent=2) + "\n")
        print(f"wrote {json_path}")
    if plot_path:
        plot_scaling({f"{model} ({tier}), {backend}, {w} workers": results}, plot_path,
                     f"cosim bench, {physics_hz:g} Hz physics, {control_hz:g} Hz exchange")
        print(f"wrote {plot_path}")
    return results


def _memory_setup() -> dict[str, Any]:
    """The workers' allocator, whether the driver has huge pages, the
    kernel's mode (``cosim.core.memory``)."""
    alloc = memory.allocator()
    return {"allocator": alloc.describe(), "huge_pages": alloc.huge_pages,
            "driver_huge_pages": alloc.huge_pages and memory.driver_has_huge_pages(alloc),
            "thp": memory.thp_mode()}


#: the fleet sizes of the gymnasium reference
GYM_SIZES = (16, 64)


def _gym_reference(seconds: float, repeat: int, physics_hz: float, control_hz: float,
                   backend: str, workers: int | None) -> list[dict[str, Any]]:
    """gymnasium's AsyncVectorEnv (one uav700 per environment) against the
    pool at ``GYM_SIZES``, interleaved (``cosim.bench_gym``)."""
    from cosim.bench.gym import compare

    every = check_rates(physics_hz, control_hz)
    print(f"reference: gymnasium AsyncVectorEnv, one uav700 per environment, "
          f"{control_hz:g} Hz env.step, against the {backend} pool", flush=True)
    print(f"{'N':>6} {'gym st/s':>11} {'pool st/s':>11} {'pool/gym':>9}", flush=True)
    rows = []
    for n in GYM_SIZES:
        r = compare(n, seconds, repeat, physics_hz, every, backend, workers)
        rows.append(r)
        print(f"{n:>6} {r['gym_steps_per_s']:>11.0f} {r['pool_steps_per_s']:>11.0f} "
              f"{r['pool_over_gym']:>8.1f}x", flush=True)
    return rows
