"""Shared fixtures: small vehicle sets and scenario files."""

from __future__ import annotations

import dataclasses
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from cosim.bench.fleet import bench_specs
from cosim.fdm_pool import VehicleSpec

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = REPO / "scenarios"


@pytest.fixture(autouse=True, scope="session")
def _ground_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Tests keep cosim's cache folder (ground tiles, wrapped aircraft, MAVLink
    signing state) in a temporary folder, never the user's ~/.cache/cosim
    (subprocesses inherit the variable)."""
    import os

    os.environ.setdefault("COSIM_CACHE_DIR", str(tmp_path_factory.mktemp("cosim-cache")))


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

