"""The ray backend across a real network stack: a Ray node in another network
namespace, joined by a veth pair with netem's 0.2 ms each way (a relay's
where the kernel has no netem: ``tests.ray_netns``), and the driver in the
head's namespace, so every call to the agent crosses the link. The
conformance suite's bit-identity cases pass across it. Skipped unless root
with iproute2."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.ray_netns import PREFIX, NetnsPair, NetnsRayCluster, unavailable

pytestmark = [pytest.mark.integration,  # starts Ray across two namespaces
              pytest.mark.xdist_group("ray"),  # beside the other clusters' tests, not at once
              pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                                 reason="the ray backend needs Ray (pip install -e '.[test]')")]

REPO = Path(__file__).resolve().parents[2]
#: the conformance suite's cases run across the link (each builds 1 to 3 pools)
CASES = ("test_states_match_inline_bit_for_bit_at_every_exchange",
         "test_watched_rows_match_inline_stepped_at_the_watch_rate",
         "test_setpoints_reset_to_nan_and_nan_leaves_the_model_alone",
         "test_impact_and_divergence_freeze_that_vehicle_only",
         "test_a_killed_worker_is_workerdied_within_seconds")


@pytest.fixture(scope="module")
def netns_ray() -> Iterator[NetnsRayCluster]:
    """The cluster across two namespaces, removed with the namespaces after
    the module, whatever happened."""
    why = unavailable()
    if why:
        pytest.skip(f"the Ray cluster across network namespaces: {why}")
    pair = NetnsPair(delay_ms=0.2).start()
    try:
        cluster = NetnsRayCluster(pair)
        try:
            cluster.start()
            yield cluster
        finally:
            cluster.stop()
    finally:
        pair.stop()


def test_the_link_delays_each_way(netns_ray: NetnsRayCluster) -> None:
    # a round trip is two delays (netem's, or the relay's where the kernel has
    # no netem); a bare veth pair's is about 0.01 ms
    pair = netns_ray.pair
    assert pair.connect_ms() >= 2 * pair.delay_ms, pair.link


def test_the_conformance_suite_passes_across_the_link(netns_ray: NetnsRayCluster) -> None:
    pair = netns_ray.pair
    argv = [sys.executable, "-m", "pytest", "tests/fdm_pool/test_conformance.py",
            "--noconftest", "-p", "tests.fdm_pool.netns_driver", "-p", "no:cacheprovider",
            "-m", "", "-q", "-k", " or ".join(f"{c}[ray]" for c in CASES)]
    r = subprocess.run(pair.command(0, *argv), env=netns_ray.driver_env(), cwd=REPO,
                       capture_output=True, text=True, timeout=300)
    tail = (r.stdout + r.stderr)[-6000:]
    assert r.returncode == 0, tail
    assert re.search(rf"\b{len(CASES)} passed\b", r.stdout), tail


def test_the_efficiency_benchmark_runs_across_the_link(netns_ray: NetnsRayCluster,
                                                       tmp_path: Path) -> None:
    # the driver's half of ``ray_efficiency.py --netns`` on the module's cluster
    pair, out = netns_ray.pair, tmp_path / "r.json"
    argv = [sys.executable, "benchmarks/ray_efficiency.py", "--netns", "0.2", "--vehicles", "8",
            "--control-hz", "30", "--seconds", "0.2", "--rounds", "2", "--workers", "2",
            "--json", str(out)]
    r = subprocess.run(pair.command(0, *argv), cwd=REPO, capture_output=True, text=True,
                       env={**netns_ray.driver_env(), "COSIM_BENCH_NETNS_LINK": json.dumps(
                           {**pair.describe(), "summary": "test"})},
                       timeout=300)
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    (row,) = json.loads(out.read_text())
    assert row["vehicles"] == 8 and row["workers"] == 2 and "ray_agent" not in row
    assert row["agent_ip"] == pair.ips[1]  # every vehicle across the link
    for name in ("ray", "ray_no_delay"):  # the same pool, the link's delay on and off
        assert row[name]["steps_per_s"] > 0 and len(row[name]["ratios"]) == 2
    assert row["ray_call_ms"] > 0 and row["ray_call_ms_no_delay"] > 0


def _namespaces() -> str:
    return subprocess.run(["ip", "netns", "list"], capture_output=True, text=True,
                          timeout=30).stdout


def test_a_crashed_runs_namespaces_are_removed_first_and_ours_on_stop() -> None:
    why = unavailable()
    if why:
        pytest.skip(why)
    gone = subprocess.Popen(["true"])
    gone.wait()  # a process that is no more, as a crashed run's
    stale = f"{PREFIX}{gone.pid}-0b"
    subprocess.run(["ip", "netns", "add", stale], check=True, timeout=30)
    inside = subprocess.Popen(["ip", "netns", "exec", stale, "sleep", "60"])
    try:
        deadline = time.monotonic() + 10.0  # until it is in there
        while str(inside.pid) not in subprocess.run(
                ["ip", "netns", "pids", stale], capture_output=True, text=True,
                timeout=30).stdout.split() and time.monotonic() < deadline:
            time.sleep(0.02)
        pair = NetnsPair(delay_ms=0.2, relay=True).start()
        try:
            assert stale not in _namespaces()
            assert inside.wait(timeout=10) == -9  # what ran in it is killed
            assert all(ns in _namespaces() for ns in pair.ns)
            relay = pair._relay
            assert relay is not None and relay.poll() is None
        finally:
            pair.stop()
        assert not any(ns in _namespaces() for ns in pair.ns)
        assert relay.poll() is not None
    finally:
        inside.kill()
        subprocess.run(["ip", "netns", "del", stale], capture_output=True, timeout=30)
