"""A whole run against the pool alone flying the same flight.

``cosim bench --whole-run`` sets a whole run beside a pool that flies with
its autopilot off, while the run's aircraft are told to loiter after a second
(the autopilot then runs inside every JSBSim step, a third more work per
step). Here, for each fleet size N, the bench's whole-run scenario (N uav700,
loiter from 1 s, states logged at 10 Hz) is flown

- as a whole run (``cosim.bench.pool.whole_run``: schedule, guidance, events,
  the state log, the tick loop), and
- through the pool alone: a pool of the same vehicles given, exchange by
  exchange, the setpoints the run wrote (recorded once beforehand from a run
  of the same scenario), and nothing else.

Both fly the same flight bit for bit (checked: the replay's last states equal
the last tick in the run's ``states.parquet``), so their ratio is what the
tick loop costs. Rounds are interleaved (run, pool, run, pool) and the ratio
is the median of the per-round ratios; the machine's load is printed with
each round.

    python benchmarks/whole_run_pool.py --vehicles 1024,2048 --control-hz 10
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


class _Recorder:
    """A participant that keeps the setpoints of every exchange as sent (read
    during the step, before the pool clears them)."""

    name = "setpoint_recorder"

    def __init__(self) -> None:
        self.run: Any = None
        self.sent: list[np.ndarray] = []

    def start(self, ctx: Any) -> None:
        pass

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        self.sent.append(self.run.pool.setpoints.copy())

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        return None

    def after_run(self, out_dir: Path) -> None:
        pass


def _scenario(folder: Path, n: int, seconds: float, control_hz: float) -> Any:
    from cosim.bench.fleet import ORIGIN
    from cosim.bench.pool import _RUN_SCENARIO  # the whole run cosim bench flies
    from cosim.scenario import load_scenario

    path = folder / "bench.yaml"
    path.write_text(_RUN_SCENARIO.format(
        n=n, lat=ORIGIN[0], lon=ORIGIN[1], physics_hz=120.0, control_hz=control_hz,
        log_hz=min(10.0, control_hz), seconds=seconds, cls="fixed_wing", model="uav700"))
    return load_scenario(path)


def _cpu_s(pids: list[int]) -> float:
    """CPU seconds the processes' threads have run (``/proc/PID/task/*/schedstat``)."""
    ns = 0
    for pid in pids:
        for task in Path(f"/proc/{pid}/task").iterdir():
            try:
                ns += int((task / "schedstat").read_text().split()[0])
            except (OSError, ValueError):  # a thread that ended meanwhile
                pass
    return ns / 1e9


class _Meter:
    """CPU seconds (the driver and its workers) and wall seconds from the end
    of the first exchange to the end of the last: the first one, cold after
    the build, is left out of both sides alike."""

    def __init__(self) -> None:
        self.pids: list[int] = []
        self.start: tuple[float, float] | None = None
        self.cpu_s = self.wall_s = 0.0

    def mark(self, last: bool) -> None:
        if self.start is None:
            self.start = (_cpu_s(self.pids), time.perf_counter())
        elif last:
            now = (_cpu_s(self.pids), time.perf_counter())
            self.cpu_s, self.wall_s = now[0] - self.start[0], now[1] - self.start[1]


def whole(n: int, seconds: float, control_hz: float, rec: _Recorder | None = None
          ) -> tuple[dict[str, Any], _Meter, np.ndarray]:
    """The scenario as a whole run (as ``cosim bench --whole-run`` flies it;
    with ``rec``, its setpoints recorded): its summary, its meter and its
    last logged tick's lat_deg and alt_msl_m (vehicle order)."""
    from cosim.logs import read_states
    from cosim.sync import Run

    meter = _Meter()
    with tempfile.TemporaryDirectory(prefix="cosim-wrp-") as tmp:
        scn = _scenario(Path(tmp), n, seconds, control_hz)
        row = {v.id: i for i, v in enumerate(scn.vehicles)}

        def progress(tick: int, total: int) -> None:
            if not meter.pids:
                assert run.pool is not None
                meter.pids = [os.getpid(), *run.pool.pids.values()]
            meter.mark(tick >= total)

        run = Run(scn, Path(tmp) / "run", progress=progress,
                  extra_participants=[rec] if rec is not None else [])
        if rec is not None:
            rec.run = run
        res = run.run()
        if not res.ok:
            raise SystemExit(f"whole_run_pool: the run of {n} aircraft failed: {res.error}")
        t = read_states(Path(tmp) / "run", ["tick", "vehicle", "lat_deg", "alt_msl_m"])
        t = t.filter(t["tick"].to_numpy() == res.ticks)
        order = np.argsort([row[v] for v in t["vehicle"].cast("string").to_pylist()])
        return res.summary, meter, np.stack(
            [t[c].to_numpy()[order] for c in ("lat_deg", "alt_msl_m")], axis=1)


def replay(n: int, seconds: float, control_hz: float, sent: list[np.ndarray]
           ) -> tuple[float, _Meter, np.ndarray]:
    """The pool alone through the recorded exchanges: its real-time factor,
    its meter and its last states' lat_deg and alt_msl_m."""
    from cosim.core.state import STATE_INDEX
    from cosim.fdm_pool import make_pool

    with tempfile.TemporaryDirectory(prefix="cosim-wrp-") as tmp:
        scn = _scenario(Path(tmp), n, seconds, control_hz)
    k = scn.rates.control_every
    meter = _Meter()
    with make_pool(scn.vehicles, scn.rates.dt_s, scn.channels, "process") as pool:
        meter.pids = [os.getpid(), *pool.pids.values()]
        t0 = time.perf_counter()
        for i, sp in enumerate(sent):
            pool.setpoints[:] = sp
            pool.step(k)
            meter.mark(i == len(sent) - 1)
        wall = time.perf_counter() - t0
        states = pool.states[:, [STATE_INDEX["lat_deg"], STATE_INDEX["alt_msl_m"]]].copy()
    return len(sent) * k / scn.rates.physics_hz / wall, meter, states


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(v) for v in text.split(",")]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"expected fleet sizes such as 1024,2048, got {text!r}")
    return sizes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=_sizes, default=[1024, 2048],
                    help="fleet sizes, comma-separated (default 1024,2048)")
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated per run")
    ap.add_argument("--control-hz", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args(argv)
    print(f"whole run against the pool alone: uav700, {a.control_hz:g} Hz exchange, "
          f"{a.seconds:g} s simulated, {a.rounds} interleaved rounds", flush=True)
    for n in a.vehicles:
        rec = _Recorder()
        _, _, last = whole(n, a.seconds, a.control_hz, rec)
        walls: list[float] = []
        cpus: list[float] = []
        for r in range(a.rounds):
            load = os.getloadavg()[0]
            summary, m_run, run_last = whole(n, a.seconds, a.control_hz)
            pool_rtf, m_pool, pool_last = replay(n, a.seconds, a.control_hz, rec.sent)
            if not (np.array_equal(pool_last, last) and np.array_equal(run_last, last)):
                print(f"N {n}: the replay's states differ from the run's", file=sys.stderr)
                return 1
            walls.append(summary["real_time_factor"] / pool_rtf)
            cpus.append(m_run.cpu_s / m_pool.cpu_s)
            split = {k: round(v, 3) for k, v in summary["time_split_s"].items() if v >= 0.001}
            rtf = summary["real_time_factor"]
            print(f"N {n} round {r + 1} (load {load:.1f}): RTF run {rtf:.3f}"
                  f" pool {pool_rtf:.3f} (run / pool {walls[-1]:.3f}); CPU s after the first "
                  f"exchange run {m_run.cpu_s:.2f} pool {m_pool.cpu_s:.2f} (run / pool "
                  f"{cpus[-1]:.3f}); run split s {split}", flush=True)
        print(f"N {n}: medians run / pool: real-time factor {statistics.median(walls):.3f}, "
              f"CPU {statistics.median(cpus):.3f} (load {os.getloadavg()[0]:.1f})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
