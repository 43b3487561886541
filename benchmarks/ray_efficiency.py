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

(A private local Ray is started unless ``RAY_ADDRESS`` names a cluster; on
a cluster the ray pool spreads over every machine and the ratio is no longer
like for like.)

Across a real network stack (root; ``tests/ray_netns.py``): ``--netns
DELAY_MS`` starts a Ray node with the CPUs in a network namespace of its
own, joined to the head's by a link delaying each way by DELAY_MS (netem on
a veth pair, or a relay where the kernel has no netem), and runs this script
again as the driver in the head's namespace, where the head has no CPU:
every vehicle of the ray pool is behind the other node's agent, each call
crossing the link, against the process pool in the driver:

    sudo python benchmarks/ray_efficiency.py --netns 0.2 --vehicles 1024 --control-hz 10
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: set in the driver run inside the head's namespace (``--netns``): the link
_NETNS_ENV = "COSIM_BENCH_NETNS_LINK"


def _segment(pool: Any, exchanges: int, k: int) -> float:
    t0 = time.perf_counter()
    for _ in range(exchanges):
        pool.step(k)
    return time.perf_counter() - t0


def measure(n: int, control_hz: float, seconds: float, rounds: int,
            workers: int | None, configs: list[str] | None = None,
            variants: dict[str, tuple[str, Callable[[], None]]] | None = None,
            ) -> dict[str, Any]:
    """``configs``: the names in ``CONFIGS`` to measure (default all; process
    always). ``variants``: more entries, name -> (the config whose pool they
    step, what to call before each of their segments); the configs' own
    segments are preceded by the call of ``variants[name + "@"]`` if given
    (its config named again)."""
    variants = dict(variants or {})
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
    # the agent's machine: the Ray call alone is measured to it
    on_ip = next((p.machines[-1] for name, p in pools.items() if name != "process"), None)
    entries: dict[str, tuple[str, Callable[[], None] | None]] = {
        **{name: (name, variants[name + "@"][1] if name + "@" in variants else None)
           for name in pools},
               **{name: v for name, v in variants.items() if not name.endswith("@")}}
    times.update((name, []) for name in entries)
    try:
        for pool in pools.values():
            _segment(pool, 3, k)  # warm-up
        names = list(entries)
        for r in range(rounds):  # each round in another order
            for name in names[r % len(names):] + names[:r % len(names)]:
                pool_name, before = entries[name]
                if before is not None:
                    before()
                times[name].append(_segment(pools[pool_name], exchanges, k))
        for name in pools:  # as the configs are: the Ray call alone is measured so
            restore = entries[name][1]
            if restore is not None:
                restore()
    finally:
        for pool in pools.values():
            pool.close()
    steps = n * exchanges * k
    width = len(pools["process"].layout)
    out: dict[str, Any] = {"vehicles": n, "control_hz": 120 / k, "agent_ip": on_ip,
                           "width": width, "workers": pools["process"].workers,
                           "ray_call_ms": ray_call_ms(n, width, on_ip=on_ip)}
    for name in entries:
        ratios = [p / r for p, r in zip(times["process"], times[name])]
        out[name] = {"steps_per_s": steps / min(times[name]),
                     "startup_s": startup[entries[name][0]],
                     "efficiency": statistics.median(ratios), "ratios": ratios,
                     "ms_per_exchange_extra": (min(times[name]) - min(times["process"]))
                     / exchanges * 1e3}
    return out


def ray_call_ms(n: int, width: int, calls: int = 300, on_ip: str | None = None) -> float:
    """The floor of an agent's exchange: a Ray actor call that returns an
    ``(n, width)`` float64 block and does nothing else (median ms), to an
    actor on the machine ``on_ip`` (default: wherever Ray puts it)."""
    import numpy as np
    import ray

    class Echo:
        def step(self, setpoints: Any, nsub: int) -> tuple[np.ndarray, list[float]]:
            return np.zeros((n, width)), [0.0]

    where = {"resources": {f"node:{on_ip}": 0.001}} if on_ip else {}
    actor: Any = ray.remote(Echo).options(num_cpus=0, **where).remote()
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
    ap.add_argument("--netns", type=float, metavar="DELAY_MS",
                    help="the ray pool on a Ray node in another network namespace, across a "
                         "link delaying each way by DELAY_MS (needs root)")
    a = ap.parse_args(argv)
    if a.netns is not None:
        if os.environ.get(_NETNS_ENV) is None:
            return _across_netns(a.netns, sys.argv[1:] if argv is None else argv, a.json)
        return _table_netns(a)
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


def _across_netns(delay_ms: float, argv: list[str], json_path: str | None) -> int:
    """The namespaces and the cluster across them, and this script run again
    as the driver in the head's namespace; 2 if they cannot be made here."""
    repo = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(repo))
    from tests.ray_netns import NetnsPair, NetnsRayCluster, unavailable

    why = unavailable()
    if why:
        print(f"ray_efficiency.py --netns: {why}", file=sys.stderr)
        return 2
    pair = NetnsPair(delay_ms=delay_ms).start()
    try:
        rtt_ms = pair.connect_ms(50)
        link = (f"{pair.link}, {delay_ms:g} ms each way, TCP connect round trip "
                f"{rtt_ms:.3f} ms, load {os.getloadavg()[0]:.1f}")
        print(f"link: {link}", flush=True)
        cluster = NetnsRayCluster(pair, cpus=os.cpu_count() or 1)
        try:
            cluster.start()
            r = subprocess.run(pair.command(0, sys.executable, __file__, *argv), cwd=repo,
                               env={**cluster.driver_env(),
                                    _NETNS_ENV: json.dumps({**pair.describe(), "summary": link})})
        finally:
            cluster.stop()
    finally:
        pair.stop()
    print(f"load after: {os.getloadavg()[0]:.1f}")
    if json_path and r.returncode == 0:
        rows = json.loads(Path(json_path).read_text())
        for row in rows:
            row.update(link=pair.link, delay_ms=delay_ms, connect_rtt_ms=rtt_ms)
        Path(json_path).write_text(json.dumps(rows, indent=1))
    return r.returncode


def _table_netns(a: argparse.Namespace) -> int:
    """The driver's side of ``--netns``: process against every vehicle behind
    the other namespace's agent."""
    rows = []
    link = json.loads(os.environ[_NETNS_ENV])
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.ray_netns import set_delay

    def on() -> None:
        set_delay(link, True)

    def off() -> None:
        set_delay(link, False)

    print(f"{'N':>6} {'Hz':>4} {'process st/s':>13} | {'remote: st/s':>12} {'eff.':>6} "
          f"{'+ms/exch':>8} {'call ms':>7} | {'no delay: st/s':>14} {'eff.':>6} "
          f"{'call ms':>7} | {'start p/r s':>11}", flush=True)
    delayed = float(link["delay_ms"]) > 0  # else a bare veth pair: nothing to turn off
    for n in a.vehicles:
        for hz in a.control_hz:
            r = measure(n, hz, a.seconds, a.rounds, a.workers, configs=["ray"],
                        variants={"ray@": ("ray", on), "ray_no_delay": ("ray", off)}
                        if delayed else None)
            rows.append(r)
            p, y = r["process"], r["ray"]
            line = (f"{n:>6} {r['control_hz']:>4.0f} {p['steps_per_s']:>13,.0f} | "
                    f"{y['steps_per_s']:>12,.0f} {y['efficiency']:>6.1%} "
                    f"{y['ms_per_exchange_extra']:>8.2f} {r['ray_call_ms']:>7.2f} | ")
            if delayed:
                off()
                r["ray_call_ms_no_delay"] = ray_call_ms(n, r["width"], on_ip=r["agent_ip"])
                z = r["ray_no_delay"]
                line += (f"{z['steps_per_s']:>14,.0f} {z['efficiency']:>6.1%} "
                         f"{r['ray_call_ms_no_delay']:>7.2f} | ")
            else:
                line += f"{'-':>14} {'-':>6} {'-':>7} | "
            print(f"{line}{p['startup_s']:.1f}/{y['startup_s']:.1f}", flush=True)
            for name in ("ray", "ray_no_delay")[:1 + delayed]:
                print(f"    {name} ratios: {' '.join(f'{x:.2f}' for x in r[name]['ratios'])}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
