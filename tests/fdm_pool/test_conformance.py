"""The conformance suite every pool backend passes: the ``Pool`` contract.

Run for every registered backend (``cosim.fdm_pool.backends``: the built-in
ones and any a package registers in the ``cosim.backends`` entry-point
group), and for the names in ``COSIM_CONFORMANCE_BACKENDS`` (comma
separated), which must be registered:

- the cases that concern the flight models (states, statuses, setpoints,
  builds, watched rows) fly the tiers mixed (``fleet``): JSBSim c172ps
  between rigid-body uav700s and c172ps (``fixed_wing_rigid``, a batched
  class), a vehicle of each tier diving, diverging, failing to trim or
  watched;
- bit-identical states against ``inline`` at every exchange, setpoints
  (including extreme ones) and every worker count included;
- statuses: ground impact and divergence freeze that vehicle only;
- setpoints reach the model and reset to NaN; NaN means "leave unchanged";
- misuse is a ``PoolStateError``; ``close`` can be called twice;
- a stop in the middle of an exchange (``close`` after ``send``) returns
  and leaves no worker process behind;
- a vehicle failing mid-exchange is a ``CosimError`` naming it and the tick;
- vehicles that cannot be built are reported together (``BuildError``);
- a worker process killed by the OS is a ``WorkerDied`` naming it, within
  seconds (backends with worker processes: ``Pool.pids``);
- watched rows (backends that take a ``watch``): their states inside each
  exchange equal ``inline``'s stepped at the watch's rate, and the states
  are the same as without a watch.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import time
from collections.abc import Callable

import numpy as np
import pytest

from cosim.bench.fleet import bench_specs
from cosim.core.state import VehicleSpec
from cosim.errors import BuildError, CosimError, PoolStateError, WorkerDied
from cosim.fdm_pool import STATE_FIELDS, STATE_INDEX, VehicleStatus, backends, make_pool
from cosim.fdm_pool.base import Watch
from tests.helpers import backend_ready

CH = ("fcs/throttle-cmd-norm", "fcs/aileron-cmd-norm", "fcs/elevator-cmd-norm")
DT = 1 / 120

_extra = [n for n in os.environ.get("COSIM_CONFORMANCE_BACKENDS", "").split(",") if n]
BACKENDS = list(dict.fromkeys(list(backends()) + _extra))


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    if request.param not in backends():
        pytest.fail(f"backend {request.param!r} is not registered (COSIM_CONFORMANCE_BACKENDS)")
    backend_ready(request, request.param)
    return str(request.param)


@pytest.fixture
def fleet(specs: Callable[..., list[VehicleSpec]]) -> Callable[..., list[VehicleSpec]]:
    """``fleet(n)``: the c172ps of ``specs`` on the odd rows, rigid-body
    aircraft (``fixed_wing_rigid``) at the same places on the even rows:
    uav700s (a turbine) on rows 0, 4, 8, ..., c172ps (a piston engine and
    propeller) on rows 2, 6, ..."""

    def make(n: int) -> list[VehicleSpec]:
        rigid = bench_specs(n, "uav700", vehicle_class="fixed_wing_rigid")
        piston = bench_specs(n, "c172p", vehicle_class="fixed_wing_rigid")
        return [(r if i % 4 == 0 else p) if i % 2 == 0 else s
                for i, (r, p, s) in enumerate(zip(rigid, piston, specs(n)))]

    return make


def worker_counts(backend: str) -> list[int | None]:
    """None (the backend's default), and 1 and 3 where it has workers."""
    return [None] + ([1, 3] if backends()[backend].default_workers() > 1
                     or backend == "process" else [])


def _drive(pool, steps: int = 50) -> list[np.ndarray]:
    out = []
    for i in range(steps):
        if i == 5:
            pool.setpoints[1, 0] = 0.3
        if i == 10:
            pool.setpoints[[0, 4], 1] = 0.25
        if i == 15:
            pool.setpoints[5, 2] = 1e6  # an extreme value: whatever it does, the same
        if i == 20:
            pool.setpoints[6, 0] = -np.inf
        if i == 30:
            pool.setpoints[4, 1] = 0.0
        out.append(pool.step(4).copy())
    return out


def _mismatches(a: np.ndarray, b: np.ndarray, ids: list[str]) -> list[str]:
    bad = np.argwhere(~((a == b) | (np.isnan(a) & np.isnan(b))))
    names = [f.name for f in STATE_FIELDS]
    return [f"{ids[i]}.{names[j] if j < len(names) else f'column {j}'}: {a[i, j]!r} != "
            f"{b[i, j]!r}" for i, j in bad[:10]]


def test_states_match_inline_bit_for_bit_at_every_exchange(fleet, backend: str) -> None:
    vs = fleet(7)
    with make_pool(vs, DT, CH, "inline") as ref:
        expected = [ref.states.copy()] + _drive(ref)
    assert not np.array_equal(expected[0], expected[-1])  # something moved
    for workers in worker_counts(backend):
        with make_pool(vs, DT, CH, backend, workers) as pool:
            assert pool.ids == [v.id for v in vs] and pool.n == 7
            got = [pool.states.copy()] + _drive(pool)
        for step, (e, g) in enumerate(zip(expected, got)):
            bad = _mismatches(e, g, pool.ids)
            assert not bad, f"{backend}, workers={workers}, exchange {step}: {bad}"


@pytest.mark.parametrize("pages", ["hugepages", "nohugepages"])
def test_states_match_inline_with_and_without_huge_pages(fleet, backend: str, pages: str,
                                                         monkeypatch) -> None:
    """The allocator's page size changes where the flight models' memory
    lies, never what they compute: bit-identical to ``inline`` either way
    (the workers start with the setting; this driver, started without it,
    gathers its own share into huge pages after building it)."""
    if len(worker_counts(backend)) == 1:
        pytest.skip(f"backend {backend!r} has no worker processes: it steps in this process, "
                    f"which started with its own allocator")
    monkeypatch.setenv("COSIM_ALLOCATOR", f"auto,{pages}")
    vs = fleet(7)
    with make_pool(vs, DT, CH, "inline") as ref:
        expected = [ref.states.copy()] + _drive(ref)
    with make_pool(vs, DT, CH, backend, 2) as pool:
        got = [pool.states.copy()] + _drive(pool)
    for step, (e, g) in enumerate(zip(expected, got)):
        bad = _mismatches(e, g, pool.ids)
        assert not bad, f"{backend}, {pages}, exchange {step}: {bad}"


# the rigid body's mass is made -inf on purpose: numpy says so as it sums it
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_impact_and_divergence_freeze_that_vehicle_only(fleet, backend: str) -> None:
    vs = fleet(6)  # of each tier: one dives, one diverges, one flies on
    dive, diverge, fly = [0, 1], [2, 3], [4, 5]
    for j in dive:
        vs[j] = dataclasses.replace(vs[j], alt_msl_m=40.0, initial_props=(
            ("fcs/throttle-cmd-norm", 0.0), ("fcs/elevator-cmd-norm", 0.6)))
    st = STATE_INDEX["status"]
    # each diverges one of the tiers: JSBSim's altitude, the rigid body's mass
    with make_pool(vs, DT, ("position/h-sl-ft", "propulsion/tank/contents-lbs"),
                   backend) as pool:
        pool.setpoints[diverge] = -np.inf
        pool.step(4)
        assert (pool.states[diverge, st] == VehicleStatus.DIVERGED).all()
        assert np.isfinite(pool.states[diverge]).all()  # frozen at its last finite state
        for _ in range(200):
            pool.step(4)
            if pool.states[dive, st].all():
                break
        assert (pool.states[dive, st] == VehicleStatus.GROUND_IMPACT).all()
        frozen, moving = pool.states[dive + diverge].copy(), pool.states[fly].copy()
        for _ in range(5):
            pool.step(4)
        assert np.array_equal(pool.states[dive + diverge], frozen)
        for i, row in zip(fly, moving):
            assert not np.array_equal(pool.states[i], row), pool.ids[i]
            assert pool.states[i, st] == VehicleStatus.ACTIVE, pool.ids[i]


def test_setpoints_reset_to_nan_and_nan_leaves_the_model_alone(fleet, backend: str) -> None:
    vs = fleet(2)
    with make_pool(vs, DT, CH, "inline") as ref, make_pool(vs, DT, CH, backend) as pool:
        for p in (ref, pool):
            p.setpoints[:, 0] = 0.123  # every tier
            p.step(4)
            assert np.isnan(p.setpoints).all()
        for _ in range(10):  # NaN everywhere: nothing written
            assert np.array_equal(ref.step(4), pool.step(4))
        assert pool.states.shape == (2, len(pool.layout)) and pool.tick == 44


def test_misuse_is_a_named_error_and_close_is_idempotent(specs, backend: str) -> None:
    pool = make_pool(specs(2), DT, (), backend)
    with pytest.raises(PoolStateError, match=r"cannot wait\(\).*ready"):
        pool.wait()
    pool.send(4)
    with pytest.raises(PoolStateError, match=r"cannot send\(\).*waiting"):
        pool.send(4)
    pool.wait()
    with pytest.raises(ValueError, match="nsub must be >= 1"):
        pool.send(0)
    pool.close()
    pool.close()
    with pytest.raises(PoolStateError, match="closed"):
        pool.step(4)


def test_a_stop_mid_exchange_returns_and_leaves_no_worker_behind(specs, backend: str) -> None:
    for workers in worker_counts(backend):
        pool = make_pool(specs(4), DT, CH, backend, workers)
        pids = list(pool.pids.values())
        pool.step(4)
        pool.setpoints[:, 0] = 0.5
        pool.send(40)  # and never wait: Ctrl-C arriving mid-exchange
        pool.close()
        with pytest.raises(PoolStateError, match="closed"):
            pool.wait()
        for pid in pids:  # reaped, not merely asked to stop
            with pytest.raises(ChildProcessError):
                os.waitpid(pid, os.WNOHANG)
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)


def test_a_vehicle_failing_mid_exchange_is_named_with_the_tick(specs, backend: str) -> None:
    for workers in worker_counts(backend):
        with make_pool(specs(4), DT, ("simulation/terminate",), backend, workers) as pool:
            pool.step(4)
            pool.setpoints[3, 0] = 1.0  # JSBSim's run() returns False
            with pytest.raises(CosimError) as ei:
                pool.step(4)
            with pytest.raises(PoolStateError, match="failed"):
                pool.step(4)
        assert "b0003" in str(ei.value) and "tick 4" in str(ei.value), str(ei.value)


def test_every_vehicle_that_cannot_be_built_is_reported_at_once(fleet, backend: str) -> None:
    vs = fleet(5)
    for j in (0, 3):  # a rigid body and a JSBSim c172p
        vs[j] = dataclasses.replace(vs[j], airspeed_mps=2.0 + j)  # far below any stall
    for workers in worker_counts(backend):
        with pytest.raises(BuildError, match=r"2 of 5 vehicles could not be built") as ei:
            make_pool(vs, DT, (), backend, workers)
        assert ei.value.vehicles == ["b0000", "b0003"], (backend, workers)
        assert "'b0000' (uav700): the rigid-body tier could not trim at 2.0 m/s" in str(
            ei.value), str(ei.value)


def test_a_killed_worker_is_workerdied_within_seconds(specs, backend: str) -> None:
    # a backend that can recover from a lost worker is told not to (``strict``)
    opts = {"strict": True} if "strict" in backends()[backend].options else {}
    pool = make_pool(specs(4), DT, (), backend, 2 if backend == "process" else None, **opts)
    try:
        pids = dict(pool.pids)
        if not pids:
            pytest.skip(f"backend {backend!r} has no worker processes")
        pool.step(4)
        worker, victim = sorted(pids.items())[-1]
        os.kill(victim, signal.SIGKILL)
        t0 = time.monotonic()
        with pytest.raises(WorkerDied) as ei:
            for _ in range(100_000):
                pool.step(4)
        assert time.monotonic() - t0 < 5.0
        # the process backend knows the signal (tests/fdm_pool/test_pool.py); a
        # remote one may not, but says which worker, which process
        assert ei.value.pid == victim and f"pid {victim}" in str(ei.value), str(ei.value)
    finally:
        pool.close()


def test_watched_rows_match_inline_stepped_at_the_watch_rate(fleet, backend: str) -> None:
    if "watch" not in backends()[backend].options:
        pytest.skip(f"backend {backend!r} takes no watch")
    vs = fleet(7)
    # b0003 and b0004 (one of each tier) dive into the ground: an impact
    # inside an exchange, watched
    for j in (3, 4):
        vs[j] = dataclasses.replace(vs[j], alt_msl_m=40.0, initial_props=(
            ("fcs/throttle-cmd-norm", 0.0), ("fcs/elevator-cmd-norm", 0.6)))
    watch = Watch((1, 3, 4, 6), every=2, max_nsub=6)
    rows = list(watch.rows)

    def drive(pool, nsub: int, steps: int) -> list[np.ndarray]:
        out = []
        for _ in range(steps):
            tick = pool.tick
            if tick == 12:
                pool.setpoints[1, 0] = 0.3
            if tick == 24:
                pool.setpoints[[0, 6], 1] = 0.25
            if tick == 36:
                pool.setpoints[5, 2] = 1e6  # an unwatched vehicle goes wild
            out.append(pool.step(nsub).copy())
        return out

    with make_pool(vs, DT, CH, "inline") as ref:
        fine = drive(ref, 2, 180)  # every 2 ticks
    with make_pool(vs, DT, CH, "inline") as ref:
        coarse = drive(ref, 6, 60)  # what the watched pool must give as its states
    st = STATE_INDEX["status"]
    assert (fine[-1][[3, 4], st] == VehicleStatus.GROUND_IMPACT).all()  # the dives ended
    for workers in worker_counts(backend):
        with make_pool(vs, DT, CH, backend, workers, watch=watch) as pool:
            for e in range(60):
                states = drive(pool, 6, 1)[0]
                bad = _mismatches(coarse[e], states, pool.ids)
                assert not bad, f"{backend}, workers={workers}: states changed: {bad}"
                assert pool.watched_count == 3
                for c in range(3):
                    want = fine[3 * e + c][rows]
                    got = pool.watched[c]
                    bad = _mismatches(want, got, [pool.ids[r] for r in rows])
                    assert not bad, (f"{backend}, workers={workers}, exchange {e}, "
                                     f"chunk {c}: {bad}")
            for nsub in (3, 8):  # not a multiple of the watch's rate; too long
                with pytest.raises(ValueError, match=f"nsub {nsub} does not fit"):
                    pool.send(nsub)
