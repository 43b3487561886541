"""The ray backend beyond the conformance suite (which it passes on the same
two-node cluster): a lost machine's vehicles, or a lost worker's under an
agent, rebuilt from their last states and flying on as they were,
``strict``, failures named by machine, nothing left running after
``close``, and whole runs."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from cosim.errors import AgentLost, ConfigError, MachineWorkerDied
from cosim.fdm_pool import STATE_INDEX, VehicleSpec, VehicleStatus, make_pool
from cosim.fdm_pool.base import Watch
from cosim.fdm_pool.process import shard_bounds
from cosim.fdm_pool.ray_cluster import RayPool
from cosim.scenario import load_scenario
from cosim.sync import Run
from cosim.vehicles.resume import NOT_RESTORED
from tests.helpers import same_states

pytestmark = pytest.mark.usefixtures("ray_cluster")

DT = 1 / 120
CH = ("fcs/throttle-cmd-norm", "position/h-sl-ft")
ST = STATE_INDEX["status"]


def _ray_pool(specs: list[VehicleSpec], dt_s: float, channels: tuple[str, ...],
              workers: int, **options: Any) -> RayPool:
    """``make_pool`` of the ray backend, typed as what it is."""
    pool = make_pool(specs, dt_s, channels, "ray", workers, **options)
    assert isinstance(pool, RayPool)
    return pool


def _gone(pid: int, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_a_lost_agent_is_replaced_from_the_last_states_and_the_run_goes_on(specs) -> None:
    # every vehicle watched at 2 ticks: the gathered rows follow the rebuild too
    watch = Watch(tuple(range(6)), every=2, max_nsub=4)
    pool = _ray_pool(specs(6), DT, CH, 2, watch=watch)
    with pool:
        # two machines (one host): this process steps its own machine's share,
        # an agent the other's
        assert len(pool.machines) == 2 and pool.machines[0] == pool.machines[1]
        assert list(pool.agents) == [0]
        held = pool.agent_vehicles[0]
        assert held in (["b0000", "b0001", "b0002"], ["b0003", "b0004", "b0005"])
        a, b, c = (0, 1, 2) if held[0] == "b0000" else (3, 4, 5)
        pool.setpoints[a, 1] = 1e308  # the agent's first vehicle diverges and is frozen
        pool.setpoints[b, 0] = 0.3  # its second one's throttle: must survive the rebuild
        pool.step(4)
        assert pool.states[a, ST] == VehicleStatus.DIVERGED
        for _ in range(20):
            before = pool.step(4).copy()
        victim = pool.agents[0]
        os.kill(victim, signal.SIGKILL)
        assert _gone(victim)
        after = pool.step(4).copy()  # no error: rebuilt on the same machine
        assert pool.agents[0] != victim
        kind, fields = pool.notices.pop()
        assert kind == "pool_recovered" and fields["bit_exact"] is False
        assert fields["vehicles"] == 2 and fields["frozen"] == 1
        assert fields["vehicle_ids"] == [held[b - a], held[c - a]]
        assert fields["frozen_ids"] == [held[0]] and fields["cause"] == "agent_lost"
        assert np.array_equal(after[a], before[a])  # the frozen one kept as it was
        assert np.array_equal(pool.watched[1, a], before[a])
        assert np.array_equal(pool.watched[1], after)  # the last chunk is the exchange's
        # the others go on from where they were: within one exchange's flight
        i = STATE_INDEX
        for r in (b, c):
            moved = np.hypot(after[r, i["lat_deg"]] - before[r, i["lat_deg"]],
                             (after[r, i["lon_deg"]] - before[r, i["lon_deg"]])
                             * np.cos(np.radians(before[r, i["lat_deg"]]))) * 111_320.0
            assert 0.0 < moved < 2 * before[r, i["airspeed_mps"]] * 4 * DT + 1.0
            assert abs(after[r, i["alt_msl_m"]] - before[r, i["alt_msl_m"]]) < 2.0
            assert after[r, ST] == VehicleStatus.ACTIVE
        assert after[b, i["throttle"]] == pytest.approx(0.3)  # its setpoint replayed
        for _ in range(10):
            pool.step(4)
        assert (pool.states[[b, c], ST] == VehicleStatus.ACTIVE).all() and not pool.notices


def test_an_agent_whose_vehicles_are_all_frozen_is_not_replaced(specs) -> None:
    pool = _ray_pool(specs(4), DT, CH, 2)
    with pool:
        held = pool.agent_vehicles[0]
        rows = [int(v[1:]) for v in held]
        pool.setpoints[rows, 1] = 1e308  # both diverge
        pool.step(4)
        frozen = pool.states[rows].copy()
        os.kill(pool.agents[0], signal.SIGKILL)
        for _ in range(5):
            pool.step(4)
        kind, fields = pool.notices.pop()
        assert kind == "pool_recovered" and fields["vehicles"] == 0 and fields["frozen"] == 2
        assert fields["vehicle_ids"] == [] and fields["frozen_ids"] == held
        assert not pool.agents and np.array_equal(pool.states[rows], frozen)


#: the autopilot's setpoints: a turn at 30 deg of bank, altitude and speed held
AP = {"cosim/ap/engage": 1.0, "cosim/ap/heading-hold": 1.0, "cosim/ap/heading-cmd-deg": 200.0,
      "cosim/ap/bank-limit-deg": 30.0, "cosim/ap/alt-hold": 1.0,
      "cosim/ap/alt-cmd-ft": 1050.0 / 0.3048, "cosim/ap/speed-hold": 1.0,
      "cosim/ap/speed-cmd-kt": 95.0}


def test_rebuilt_vehicles_fly_on_as_they_were(specs) -> None:
    # the same turn on the cluster and inline, every tick watched; the agent's
    # machine lost mid-turn: its vehicles go on from the attitude, rates and
    # autopilot state they had, not wings level
    ch = (*AP, "cosim/ap/throttle-bias")
    watch = Watch(tuple(range(4)), every=1, max_nsub=4)
    i = STATE_INDEX
    att = [i["roll_deg"], i["pitch_deg"], i["yaw_deg"]]
    pool = _ray_pool(specs(4), DT, ch, 2, watch=watch)
    with make_pool(specs(4), DT, ch, "inline", watch=watch) as ref, pool:
        rows = [int(v[1:]) for v in pool.agent_vehicles[0]]
        for p in (ref, pool):
            p.setpoints[:, :len(AP)] = list(AP.values())
            p.setpoints[:, -1] = p.states[:, i["throttle"]]
        for _ in range(90):  # 3 s: rolled into the turn, at its bank limit
            before = pool.step(4).copy()
            assert np.array_equal(before, ref.step(4))
        assert (np.abs(before[rows, i["roll_deg"]]) > 25).all()
        os.kill(pool.agents[0], signal.SIGKILL)
        after, want = pool.step(4).copy(), ref.step(4).copy()
        kind, fields = pool.notices.pop()
        assert kind == "pool_recovered" and fields["vehicle_ids"] == [f"b{r:04d}" for r in rows]
        assert fields["not_restored"] == list(NOT_RESTORED)
        # what is not carried over (the engine's speed, mostly) changes the angular
        # accelerations by well under 1 rad/s2: over one exchange (33 ms) that moves
        # a rate by < 0.03 rad/s (2 deg/s) and an angle by < 0.03 deg; a rebuild
        # from heading and speed alone was 30 deg off in roll at once
        assert np.abs(after[rows][:, att] - want[rows][:, att]).max() < 0.03
        got, exp = pool.watched[:4, rows][..., att], ref.watched[:4, rows][..., att]
        rate_got = np.diff(np.concatenate([before[rows][None, :, att], got]), axis=0) / DT
        rate_exp = np.diff(np.concatenate([before[rows][None, :, att], exp]), axis=0) / DT
        assert np.abs(rate_got - rate_exp).max() < 2.0  # deg/s, at every tick
        assert np.abs(after[rows, i["airspeed_mps"]] - want[rows, i["airspeed_mps"]]).max() \
            < 0.1
        for _ in range(60):  # and 2 s on, the same turn: no roll-out, no new path
            after, want = pool.step(4), ref.step(4)
        assert np.abs(after[rows, i["roll_deg"]] - want[rows, i["roll_deg"]]).max() < 1.0
        moved = np.hypot(after[rows, i["lat_deg"]] - want[rows, i["lat_deg"]],
                         (after[rows, i["lon_deg"]] - want[rows, i["lon_deg"]])
                         * np.cos(np.radians(want[rows, i["lat_deg"]]))) * 111_320.0
        assert moved.max() < 2.0, moved


def test_a_worker_lost_under_an_agent_is_rebuilt_and_named(specs) -> None:
    import ray

    # four workers: two on this machine (one of them a child process), two
    # behind the agent (one a child of it): both machines have a worker 1
    pool = _ray_pool(specs(6), DT, CH, 4)
    with pool:
        pool.step(4)
        held = pool.agent_vehicles[0]
        share = pool._shares[0]
        (child,) = ray.get(share.handle.worker_pids.remote())
        agent = pool.agents[0]
        os.kill(child, signal.SIGKILL)
        for _ in range(3):
            pool.step(4)  # no error: the agent's share rebuilt
        kind, fields = pool.notices.pop()
        assert kind == "pool_recovered" and fields["cause"] == "worker_died"
        assert fields["machine"] == "127.0.0.2" and fields["node"] == share.node.id
        assert fields["agent"] == 0 and fields["vehicle_ids"] == held
        lost = held[shard_bounds(len(held), 2)[1][0]:]  # the agent's worker 1's
        assert fields["reason"] == (f"its worker 1 (pid {child} there) killed by SIGKILL; "
                                    f"that worker's vehicles: {', '.join(lost)}")
        assert pool.agents[0] != agent and _gone(agent)  # stopped, its other worker first
        assert (pool.states[:, ST] == VehicleStatus.ACTIVE).all()
        # a worker of the driver's own share stops the run, named as this machine's
        assert pool._local is not None
        (local,) = pool._local.pids.values()
        os.kill(local, signal.SIGKILL)
        with pytest.raises(MachineWorkerDied, match=rf"^worker 1 \(pid {local}\) on machine "
                                                    rf"127\.0\.0\.2 \(node [0-9a-f]{{12}}, "
                                                    rf"the driver's own share\) killed by "
                                                    rf"SIGKILL at tick \d+; its vehicles: "):
            for _ in range(1000):
                pool.step(4)


def test_strict_names_the_machine_of_a_lost_worker(specs) -> None:
    import ray

    pool = _ray_pool(specs(4), DT, (), 4, strict=True)
    with pool:
        pool.step(4)
        held = pool.agent_vehicles[0]
        (child,) = ray.get(pool._shares[0].handle.worker_pids.remote())
        os.kill(child, signal.SIGKILL)
        with pytest.raises(MachineWorkerDied, match=rf"^worker 1 \(pid {child}\) on machine "
                                                    rf"127\.0\.0\.2 \(node [0-9a-f]{{12}}, "
                                                    rf"agent 0\) killed by SIGKILL at tick 4; "
                                                    rf"its vehicles: {held[1]}$"):
            pool.step(4)
        assert not pool.notices


def test_strict_stops_with_an_error_naming_the_machine(specs) -> None:
    pool = _ray_pool(specs(4), DT, (), 2, strict=True)
    try:
        pool.step(4)
        os.kill(pool.agents[0], signal.SIGKILL)
        with pytest.raises(AgentLost) as ei:
            for _ in range(1000):
                pool.step(4)
        msg = str(ei.value)
        assert "machine 127.0.0.2" in msg and ", ".join(pool.agent_vehicles[0]) in msg, msg
        assert ei.value.worker == 0 and not pool.notices
    finally:
        pool.close()


def test_close_leaves_nothing_running_on_any_machine(specs) -> None:
    import ray

    # four workers over two machines: the agent runs two, one of them in a child
    pool = _ray_pool(specs(6), DT, CH, 4, local_share=False)
    agents = list(pool.agents.values())
    assert len(agents) == 2
    workers = [pid for s in pool._shares for pid in ray.get(s.handle.worker_pids.remote())]
    assert len(workers) == 2  # each agent steps one shard itself
    pool.step(4)
    pool.close()
    for pid in agents + workers:
        assert _gone(pid), f"pid {pid} still runs after close()"


def test_options_reach_the_backend_that_takes_them(specs) -> None:
    with pytest.raises(ConfigError, match=r"process backend takes no option 'address'"):
        make_pool(specs(2), DT, (), "process", address="127.0.0.1:1")
    from cosim.fdm_pool.ray_connect import connect

    connect()  # the session's cluster (RAY_ADDRESS)
    with pytest.raises(ConfigError, match=r"already joined the Ray cluster at .*cannot also "
                                          r"join 127.0.0.9:1"):
        make_pool(specs(2), DT, (), "ray", address="127.0.0.9:1")


def test_a_run_on_the_cluster_logs_the_same_states_as_inline(mixed_scenario: Path,
                                                              tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    res = {b: Run(scn, tmp_path / b, backend=b).run() for b in ("inline", "ray")}
    assert res["ray"].ok and res["ray"].summary["backend"] == "ray", res["ray"].error
    assert res["ray"].summary["workers"] == 2
    a, b = (pq.read_table(tmp_path / k / "states.parquet") for k in ("inline", "ray"))
    assert a.num_rows > 0 and same_states(a, b)


def test_the_efficiency_benchmark_runs_on_the_cluster() -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import ray_efficiency

    # one ray pool at a time here: each agent holds its machine's only CPU
    r = ray_efficiency.measure(8, 30.0, 0.2, 2, 2, configs=["ray_agent"])
    assert r["vehicles"] == 8 and r["workers"] == 2 and r["ray_call_ms"] > 0
    assert "ray" not in r
    for name in ("process", "ray_agent"):
        assert r[name]["steps_per_s"] > 0 and len(r[name]["ratios"]) == 2
    assert r["process"]["efficiency"] == 1.0


def _running(pid: int) -> bool:
    """Alive and not a zombie (one whose parent is gone may never be reaped here)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_nothing_is_left_running_when_the_driver_is_killed(tmp_path: Path) -> None:
    import subprocess
    import sys
    import textwrap

    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent("""
        import os, signal
        import ray
        from cosim.bench.fleet import bench_specs
        from cosim.fdm_pool import make_pool
        if __name__ == "__main__":
            pool = make_pool(bench_specs(6), 1 / 120, (), "ray", 4, local_share=False)
            pool.step(4)
            pids = list(pool.agents.values()) + [
                p for s in pool._shares for p in ray.get(s.handle.worker_pids.remote())]
            print(" ".join(map(str, pids)), flush=True)
            os.kill(os.getpid(), signal.SIGKILL)
    """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=180)
    pids = [int(p) for p in proc.stdout.split()]
    assert len(pids) == 4, proc.stderr[-3000:]  # two agents, a worker each
    deadline = time.monotonic() + 30.0
    alive = pids
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [p for p in pids if _running(p)]
    assert not alive, f"left running after the driver was killed: {alive}"
