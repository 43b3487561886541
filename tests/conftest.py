"""Shared fixtures (small vehicle sets and scenario files, a Ray cluster, the
browser) and the test tiers.

Tiers, by marker: ``fast`` (the default of ``python -m pytest``: everyday
work), ``integration`` (a Ray cluster, a browser, ground stations, benchmark
scripts, long flights: anything past a few seconds), both together being what
CI runs (``-m "fast or integration"``), and ``slow`` and ``bench`` on
request. A test is ``integration`` when it uses a fixture of
``INTEGRATION_FIXTURES`` or runs on a cluster backend, or is marked so by its
module or itself; ``fast`` when it is in no other tier."""

from __future__ import annotations

import dataclasses
import logging
import os
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from cosim.bench.fleet import bench_specs
from cosim.fdm_pool import VehicleSpec
from tests.helpers import CLUSTER_BACKENDS

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = REPO / "scenarios"
#: Debian's Chromium, which the browser tests drive through Playwright
#: (nothing downloads a browser build)
CHROMIUM = "/usr/bin/chromium"

#: the tiers after ``fast``, each a marker
OTHER_TIERS = ("integration", "slow", "bench")
#: a test using one of these fixtures is an integration test wherever it is
INTEGRATION_FIXTURES = frozenset({"chromium", *CLUSTER_BACKENDS.values()})
#: a fast test that took longer than this (set-up included) is named at the end
#: of the run: it belongs in the integration tier
FAST_LIMIT_S = 5.0


@pytest.hookimpl(tryfirst=True)  # before ``-m`` and pytest-xdist read the markers
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test gets the marker of its one tier, and its group for
    ``pytest -n N --dist loadgroup``: the tests that start Ray in one (one
    cluster, on one worker), each other file's in its own (a module fixture
    made once)."""
    for item in items:
        tiers = [tier for tier in OTHER_TIERS if item.get_closest_marker(tier)]
        if len(tiers) > 1:
            raise pytest.UsageError(f"{item.nodeid} is marked {' and '.join(tiers)}: "
                                    "a test is in one tier")
        fixtures = set(getattr(item, "fixturenames", ()))
        callspec = getattr(item, "callspec", None)
        on_cluster = bool(fixtures.intersection(CLUSTER_BACKENDS.values())) or (
            callspec is not None and callspec.params.get("backend") in CLUSTER_BACKENDS)
        if not tiers:  # the tier its fixtures or backend give, else fast
            item.add_marker("integration" if on_cluster
                            or fixtures.intersection(INTEGRATION_FIXTURES) else "fast")
        if not item.get_closest_marker("xdist_group"):
            item.add_marker(pytest.mark.xdist_group(
                "ray" if on_cluster else item.nodeid.split("::")[0]))


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist sends the worker's ids to its scheduler
def pytest_collection_finish(session: pytest.Session) -> None:
    """Each test's group at the end of its id, where ``--dist loadgroup``
    reads it. pytest-xdist 3.8 writes it to ``item._nodeid``, which pytest 9
    no longer reads: each test was then sent on its own, a file's module
    fixtures (a live server, a browser session) and the session's Ray
    cluster made once on each worker."""
    if not getattr(session.config.option, "loadgroup", False):  # set on xdist's workers
        return
    for item in session.items:
        nodeid = item.nodeid
        if nodeid.rfind("@") > nodeid.rfind("]") or not hasattr(item, "_id"):
            continue  # grouped already (pytest 8)
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        if names:
            item._id = type(item._id).parse(f"{nodeid}@{'_'.join(names)}")


def pytest_terminal_summary(terminalreporter: Any) -> None:
    """Name the fast tests that were not fast (set-up, call and tear-down)."""
    took: dict[str, float] = {}
    for reports in terminalreporter.stats.values():
        for rep in reports:
            if isinstance(rep, pytest.TestReport) and "fast" in rep.keywords:
                took[rep.nodeid] = took.get(rep.nodeid, 0.0) + rep.duration
    slow = sorted(((s, n) for n, s in took.items() if s > FAST_LIMIT_S), reverse=True)
    if slow:
        terminalreporter.write_sep("=", f"fast tests that took more than {FAST_LIMIT_S:g} s "
                                   "(mark them integration if they always do)", yellow=True)
        for s, n in slow:
            terminalreporter.write_line(f"{s:6.1f} s  {n}")


@pytest.fixture(autouse=True)
def _logging_as_it_was() -> Iterator[None]:
    """The root logger's handlers and level, and cosim.jsbsim's level, as
    they were before the test: ``cosim.cli.main`` called in the test's
    process configures logging for the process (a stream handler on the
    test's captured stderr, closed once the test ends; the root at INFO),
    which later tests on the same worker would otherwise inherit."""
    root, jsbsim = logging.getLogger(), logging.getLogger("cosim.jsbsim")
    handlers, root_level, jsbsim_level = root.handlers[:], root.level, jsbsim.level
    yield
    root.handlers[:] = handlers
    root.setLevel(root_level)
    jsbsim.setLevel(jsbsim_level)


@pytest.fixture(autouse=True, scope="session")
def _ground_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Tests keep cosim's cache folder (ground tiles, wrapped aircraft, MAVLink
    signing state) in a temporary folder, never the user's ~/.cache/cosim
    (subprocesses inherit the variable). Its ``fused/`` (the rigid tier's
    generated numba loops) is one folder for all of a session's pytest-xdist
    workers, in the session's temporary folder: a loop one worker compiled
    (seconds) the others load (files named for their content, written whole)."""
    if os.environ.get("COSIM_CACHE_DIR"):
        return
    root = tmp_path_factory.mktemp("cosim-cache")
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the workers' folders share a parent
        shared = tmp_path_factory.getbasetemp().parent / "cosim-fused"
        shared.mkdir(exist_ok=True)
        (root / "fused").symlink_to(shared, target_is_directory=True)
    os.environ["COSIM_CACHE_DIR"] = str(root)


@pytest.fixture
def specs() -> Callable[..., list[VehicleSpec]]:
    """``specs(n, **changes)``: n c172p vehicles in a grid at 1000 m, 100 kt."""

    def make(n: int, **changes: object) -> list[VehicleSpec]:
        return [dataclasses.replace(s, **changes) for s in bench_specs(n)]  # type: ignore[arg-type]

    return make


@pytest.fixture
def write_scenario(tmp_path: Path) -> Callable[[str, str], Path]:
    """``write_scenario(text, name="s.yaml")``: write dedented YAML, return its path."""

    def write(text: str, name: str = "s.yaml") -> Path:
        p = tmp_path / name
        p.write_text(textwrap.dedent(text).lstrip())
        return p

    return write


#: a small scenario exercising formation, schedule, ground impact and divergence
MIXED = """
schema_version: 1
name: mixed
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 6
seed: 7
vehicles:
  - id: a
    count: 5
    model: c172p
    formation: {type: grid, spacing_m: 120}
    init: {north_m: 100, east_m: -50, alt_agl_m: 700, heading_deg: 30, airspeed_kt: 95}
  - id: diver
    model: c172p
    set: {fcs/throttle-cmd-norm: 0.0, fcs/elevator-cmd-norm: 0.6}
    init: {north_m: -500, east_m: 0, alt_agl_m: 40, heading_deg: 0, airspeed_kt: 90}
  - id: nan
    model: c172x
    init: {north_m: 0, east_m: 800, alt_agl_m: 900, heading_deg: 270, airspeed_kt: 90}
schedule:
  - at_s: 1.0
    vehicles: [a1, a3]
    set: {fcs/throttle-cmd-norm: 0.2, fcs/aileron-cmd-norm: 0.3}
  - at_s: 2.0
    vehicles: nan
    set: {atmosphere/wind-north-fps: 1.0e9}  # a wind no model survives: it diverges
"""


@pytest.fixture
def mixed_scenario(write_scenario: Callable[[str, str], Path]) -> Path:
    return write_scenario(MIXED, "mixed.yaml")


@pytest.fixture(scope="session")
def chromium() -> str:
    """The browser's path; skipped where it is absent. A test using it is in
    the integration tier."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is absent (apt-get install chromium); the browser tests need it")
    return CHROMIUM


@pytest.fixture(scope="session")
def ray_cluster() -> Iterator[Any]:
    """A two-node Ray cluster on this machine (``tests.ray_cluster``), joined
    by this process: the ray backend runs on it. Skipped where Ray is not
    installed (the test extras install it)."""
    import importlib.util
    import os

    if importlib.util.find_spec("ray") is None:
        pytest.skip("the ray backend needs Ray (pip install -e '.[test]')")
    from tests.ray_cluster import LocalRayCluster

    cluster = LocalRayCluster(nodes=2).start()
    saved = {k: os.environ.get(k) for k in ("RAY_ADDRESS", "RAY_AUTH_MODE", "RAY_AUTH_TOKEN")}
    # before Ray is imported here: it reads its token once
    os.environ.update(RAY_ADDRESS=cluster.address, RAY_AUTH_MODE="token",
                      RAY_AUTH_TOKEN=cluster.env["RAY_AUTH_TOKEN"])
    import ray

    try:
        yield cluster
    finally:
        ray.shutdown()
        cluster.stop()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v

