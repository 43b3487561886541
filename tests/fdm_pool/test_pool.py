"""The pool's own parts and the process backend's particulars (its workers,
their logs and signals); what every backend must do is in test_conformance.py."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from cosim.errors import BuildError, PoolStateError, WorkerDied, WorkerError
from cosim.fdm_pool import (
    STATE_FIELDS,
    STATE_INDEX,
    InlinePool,
    ProcessPool,
    VehicleStatus,
)
from cosim.fdm_pool.process import shard_bounds
from cosim.vehicles.jsb import find_model, new_fdm

CH = ("fcs/throttle-cmd-norm", "fcs/aileron-cmd-norm")


def _drive(pool, steps: int = 60) -> list[np.ndarray]:
    out = []
    for i in range(steps):
        if i == 10:
            pool.setpoints[1, 0] = 0.3
        if i == 20:
            pool.setpoints[[0, 4], 1] = 0.25
        if i == 40:
            pool.setpoints[4, 1] = 0.0
        out.append(pool.step(4).copy())
    return out


def _mismatches(a: np.ndarray, b: np.ndarray, ids: list[str]) -> list[str]:
    bad = np.argwhere(~((a == b) | (np.isnan(a) & np.isnan(b))))
    names = [f.name for f in STATE_FIELDS]
    return [f"{ids[i]}.{names[j] if j < len(names) else f'column {j}'}: {a[i, j]!r} != "
            f"{b[i, j]!r}" for i, j in bad[:10]]


def test_shard_bounds_cover_everything_evenly() -> None:
    for n in (1, 5, 7, 128):
        for w in (1, 2, 3):
            b = shard_bounds(n, min(n, w))
            assert b[0][0] == 0 and b[-1][1] == n
            assert all(x[1] == y[0] for x, y in zip(b, b[1:]))
            sizes = [y - x for x, y in b]
            assert max(sizes) - min(sizes) <= 1


def test_setpoints_reach_jsbsim_and_reset_to_nan(specs) -> None:
    with InlinePool(specs(2), 1 / 120, CH) as pool:
        pool.setpoints[1, 0] = 0.123
        pool.step(4)
        assert np.isnan(pool.setpoints).all()
        fdms = [v.fdm for v in pool._shard.vehicles]
        assert fdms[1]["fcs/throttle-cmd-norm"] == pytest.approx(0.123)
        assert fdms[0]["fcs/throttle-cmd-norm"] != pytest.approx(0.123)


def test_state_columns_are_the_jsbsim_properties_in_si(specs) -> None:
    with InlinePool(specs(1), 1 / 120) as pool:
        pool.step(4)
        fdm = pool._shard.vehicles[0].fdm
        row = pool.states[0]
        assert len(pool.layout) > len(STATE_FIELDS)  # the fixed-wing's contact_force_n
        for j, f in enumerate(pool.layout):
            if f.prop:
                assert row[j] == fdm[f.prop] * f.scale, f.name
        assert row[STATE_INDEX["alt_msl_m"]] == pytest.approx(1000.0, abs=1.0)
        assert row[STATE_INDEX["airspeed_mps"]] == pytest.approx(51.44, abs=0.3)


def test_trimmed_start_is_steady(specs) -> None:
    """Trimmed to the initial state: a few seconds later still level at the same speed."""
    with InlinePool(specs(1, heading_deg=250.0), 1 / 120) as pool:
        s0 = pool.states[0].copy()
        for _ in range(90):
            pool.step(4)
        s = pool.states[0]
    assert s0[STATE_INDEX["yaw_deg"]] == pytest.approx(250.0, abs=1e-6)
    assert s[STATE_INDEX["alt_msl_m"]] == pytest.approx(1000.0, abs=3.0)
    assert s[STATE_INDEX["airspeed_mps"]] == pytest.approx(s0[STATE_INDEX["airspeed_mps"]],
                                                           abs=0.5)


def test_trim_failure_names_the_vehicle_inline_and_remote(specs) -> None:
    vs = specs(3)
    import dataclasses

    vs[2] = dataclasses.replace(vs[2], airspeed_mps=3.0)  # far below a C172's stall
    with pytest.raises(BuildError, match=r"vehicle 'b0002' \(c172p\): JSBSim could not trim"):
        InlinePool(vs, 1 / 120)
    with pytest.raises(BuildError) as ei:
        ProcessPool(vs, 1 / 120, workers=2)
    err = ei.value
    assert err.vehicles == ["b0002"] and err.total == 3
    assert "1 of 3 vehicles could not be built" in str(err)
    assert "3.0 m/s TAS" in str(err)


def _children(pid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(d))
    return out


def test_killed_worker_becomes_workerdied_within_5_s(specs) -> None:
    pool = ProcessPool(specs(6), 1 / 120, workers=3)
    try:
        pool.step(4)
        victim = pool.pids[2]
        os.kill(victim, signal.SIGKILL)
        t0 = time.monotonic()
        with pytest.raises(WorkerDied) as ei:
            for _ in range(10_000):
                pool.step(4)
        assert time.monotonic() - t0 < 5.0
        e = ei.value
        assert e.worker == 2 and e.pid == victim and e.exitcode == -signal.SIGKILL
        assert e.vehicles == ["b0004", "b0005"]
        assert "killed by SIGKILL" in str(e) and "b0004, b0005" in str(e)
        with pytest.raises(PoolStateError, match="failed"):
            pool.step(4)
        procs = list(pool._procs.values())
    finally:
        pool.close()
    assert procs and not any(p.is_alive() for p in procs)
    assert not [c for c in _children(os.getpid()) if c in {p.pid for p in procs}]


def _run_driver(tmp_path, ending: str, timeout: float) -> tuple[subprocess.CompletedProcess,
                                                                  list[int]]:
    """Run a script that opens a 3-worker pool, prints its children's pids and
    then does ``ending``; returns the finished process and those pids."""
    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent("""
        import os, signal, sys
        from cosim.bench.fleet import bench_specs
        from cosim.fdm_pool import ProcessPool
        if __name__ == "__main__":
            pool = ProcessPool(bench_specs(4), 1 / 120, workers=3)
            pool.step(4)
            print(" ".join(str(p) for p in pool.pids.values()), flush=True)
    """) + "    " + ending + "\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=timeout)
    return proc, [int(p) for p in proc.stdout.split()]


@pytest.mark.integration
def test_workers_exit_when_the_driver_is_killed(tmp_path) -> None:
    """No orphans: children notice their parent is gone and exit by themselves."""
    _, pids = _run_driver(tmp_path, "os.kill(os.getpid(), signal.SIGKILL)", 60)
    assert len(pids) == 2
    deadline = time.monotonic() + 5.0
    alive = pids
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [p for p in pids if os.path.exists(f"/proc/{p}")]
    assert not alive, f"orphaned workers still running: {alive}"


def test_jsbsim_console_is_silenced_in_workers(specs, capfd) -> None:
    with ProcessPool(specs(2), 1 / 120, workers=2) as pool:
        pool.step(4)
    new_fdm(find_model("c172p"), 1 / 120)
    out, err = capfd.readouterr()
    assert "JSBSim" not in out and "JSBSim" not in err


@pytest.mark.integration
def test_stopped_worker_becomes_workertimeout_not_a_hang(specs) -> None:
    from cosim.errors import WorkerTimeout

    pool = ProcessPool(specs(4), 1 / 120, workers=2)
    try:
        pool.step(4)
        victim = pool.pids[1]
        os.kill(victim, signal.SIGSTOP)
        t0 = time.monotonic()
        with pytest.raises(WorkerTimeout, match=r"worker 1 \(pid \d+\) did not finish tick 8 "
                                                r"within 0.5 s; its vehicles: b0002, b0003"):
            pool.step(4, timeout_s=0.5)
        assert time.monotonic() - t0 < 3.0
    finally:
        t0 = time.monotonic()
        pool.close()  # must get rid of the stopped process too
        assert time.monotonic() - t0 < 6.0
    assert not os.path.exists(f"/proc/{victim}") or \
        open(f"/proc/{victim}/stat").read().rsplit(")", 1)[1].split()[0] == "Z"


@pytest.mark.parametrize("model, drop_m", [("MD11", 25.0), ("B747", 20.0)])
def test_ground_impact_of_models_whose_gear_hangs_far_below_the_cg(specs, model: str,
                                                                    drop_m: float) -> None:
    """Airliner gear and wingtips lie metres from the CG: the ground check must
    not be skipped while they can touch (the margin includes the contact radius)."""
    import dataclasses

    m = find_model(model)
    vs = [dataclasses.replace(specs(1)[0], id=model, model=m.name, aircraft_dir=m.aircraft_dir,
                              model_source=m.source, alt_msl_m=drop_m, airspeed_mps=0.0,
                              trim=False)]
    st = STATE_INDEX["status"]
    with InlinePool(vs, 1 / 120) as pool:
        assert pool._shard.vehicles[0].contact_radius_m > 20.0  # nose gear to CG
        for _ in range(120):  # 4 s: the free fall takes about 2
            pool.step(4)
            if pool.states[0, st]:
                break
        assert pool.states[0, st] == VehicleStatus.GROUND_IMPACT


def test_contact_radius_is_the_farthest_contact_point_from_the_cg(specs) -> None:
    with InlinePool(specs(1), 1 / 120) as pool:
        v = pool._shard.vehicles[0]
    # c172p: the wingtip contacts, 214.8 in out and about 22 in above the CG
    assert v.contact_radius_m == pytest.approx(5.5, abs=0.1)


def test_a_failing_exchange_is_one_vehicleerror_naming_vehicle_and_tick(specs) -> None:
    """Inline and in the driver's own shard alike; it pickles intact."""
    import pickle

    from cosim.errors import VehicleError

    for make in (lambda v: InlinePool(v, 1 / 120, ("simulation/terminate",)),
                 lambda v: ProcessPool(v, 1 / 120, ("simulation/terminate",), workers=2)):
        with make(specs(4)) as pool:
            pool.step(4)
            pool.setpoints[1, 0] = 1.0
            with pytest.raises(VehicleError) as ei:
                pool.step(4)
        e = ei.value
        assert (e.vehicle, e.tick) == ("b0001", 4)
        assert str(e) == ("vehicle 'b0001' at tick 4: JSBSim run() returned False (the "
                          "simulation was told to terminate: simulation/terminate is set)")
        back = pickle.loads(pickle.dumps(e))
        assert (back.vehicle, back.tick, str(back)) == (e.vehicle, e.tick, str(e))


def test_an_error_in_a_child_mid_run_is_a_workererror_naming_the_vehicle(specs) -> None:
    with ProcessPool(specs(4), 1 / 120, ("simulation/terminate",), workers=2) as pool:
        pool.step(4)
        pool.setpoints[3, 0] = 1.0
        with pytest.raises(WorkerError) as ei:
            pool.step(4)
    e = ei.value
    assert (e.worker, e.vehicle, e.tick) == (1, "b0003", 4)
    assert "VehicleError: vehicle 'b0003' at tick 4: JSBSim run() returned False" in \
        e.remote_traceback
    assert str(e).startswith("worker 1, vehicle 'b0003', tick 4: cosim.errors.VehicleError")


def test_a_traceback_longer_than_the_pipe_buffer_comes_back_promptly(specs) -> None:
    """The child flags the error before sending: the driver reads the pipe
    while the child writes, so a long traceback cannot block it."""
    import dataclasses

    vs = specs(2)
    vs[1] = dataclasses.replace(vs[1], id="x" * 200_000, airspeed_mps=3.0)  # cannot trim
    t0 = time.monotonic()
    with pytest.raises(BuildError) as ei:
        ProcessPool(vs, 1 / 120, workers=2, start_timeout_s=10.0)
    assert time.monotonic() - t0 < 5.0
    assert ei.value.vehicles == ["x" * 200_000] and "could not trim" in str(ei.value)


@pytest.mark.parametrize("verbosity, expect", [("-vvv", True), ("-q", False)])
def test_workers_log_like_the_driver(tmp_path, verbosity: str, expect: bool) -> None:
    """A child's records (its JSBSim output too) follow the driver's levels and format."""
    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent(f"""
        from cosim.bench.fleet import bench_specs
        from cosim.cli import setup_logging
        from cosim.fdm_pool import ProcessPool
        if __name__ == "__main__":
            setup_logging(verbose={verbosity.count("v")}, quiet={verbosity == "-q"})
            # every vehicle in the child: whatever is logged about them comes from it
            with ProcessPool(bench_specs(1), 1 / 120, workers=1, driver_steps=False) as pool:
                pool.step(4)
    """))
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0, p.stderr
    fmt = re.compile(r"^\d\d:\d\d:\d\d DEBUG cosim\.")
    worker = [ln for ln in p.stderr.splitlines() if "worker 0 (pid" in ln]
    banner = [ln for ln in p.stderr.splitlines() if "JSBSim Flight Dynamics Model" in ln]
    if expect:
        assert len(worker) == 1 and fmt.match(worker[0]), p.stderr
        assert len(banner) == 1 and fmt.match(banner[0]) and "cosim.jsbsim" in banner[0]
    else:
        assert p.stderr == "" and p.stdout == ""


def test_worker_errors_list_at_most_ten_vehicles() -> None:
    from cosim.errors import WorkerTimeout

    ids = [f"v{i:02d}" for i in range(12)]
    died = str(WorkerDied(1, 99, -9, ids, 40))
    late = str(WorkerTimeout(1, 99, ids, 40, 0.5, "finish tick 44"))
    shown = "v00, v01, v02, v03, v04, v05, v06, v07, v08, v09, ... (12 in all)"
    assert died.endswith(f"its vehicles: {shown}") and late.endswith(f"its vehicles: {shown}")
    assert str(WorkerDied(1, 99, -9, ids[:2], 40)).endswith("its vehicles: v00, v01")


@pytest.mark.integration
def test_a_pool_left_open_does_not_hang_the_interpreter_exit(tmp_path) -> None:
    """Children ignore SIGTERM, so multiprocessing's exit handler (terminate,
    then join) alone would wait for them forever: the pool closes itself first."""
    proc, pids = _run_driver(tmp_path, "pass  # exit with the pool still open", 30)
    assert proc.returncode == 0, proc.stderr
    assert len(pids) == 2 and not [p for p in pids if os.path.exists(f"/proc/{p}")]


def test_a_driver_that_only_coordinates_gives_the_same_states() -> None:
    """driver_steps=False: every shard in a worker process (two here), the
    driver steps none; the states are inline's, bit for bit."""
    from cosim.bench.fleet import bench_specs

    specs = bench_specs(5)
    with InlinePool(specs, 1 / 120) as ref:
        want = [ref.step(4).copy() for _ in range(15)]
    with ProcessPool(specs, 1 / 120, workers=2, driver_steps=False) as pool:
        assert sorted(pool.pids) == [0, 1] and len(pool.busy_s()) == 2
        got = [pool.step(4).copy() for _ in range(15)]
    for w, g in zip(want, got):
        np.testing.assert_array_equal(w, g)
