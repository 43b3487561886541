"""Fixtures of the run-folder tests: a real short run to damage copies of."""

from __future__ import annotations

import functools
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from cosim.logs.writers import StateLog
from cosim.sweep.runner import load_point
from cosim.sweep.spec import read_sweep
from cosim.sync import Run

REPO = Path(__file__).resolve().parents[2]
EXP2 = REPO / "scenarios" / "conspicuity" / "altitude_speed.yaml"


@pytest.fixture(scope="session")
def camera_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished run with every kind of output file: 2.3 s of a uav700
    passing over a truck, its 64x48 nadir camera's video and ground truth
    (about a second to make). Tests copy it (``run_copy``), never change it."""
    point = dict(read_sweep(EXP2).points()[0])
    point.update(width_px=64, height_px=48, static=True, speed_kt=200, alt_agl_m=30)
    out = tmp_path_factory.mktemp("camera-run") / "run"
    # one states part whatever the machine's load (a part is written every 5 s
    # of wall time too, and the tests damage the one part)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("cosim.sync.runner.StateLog", functools.partial(StateLog, flush_s=3600.0))
        res = Run(load_point(EXP2, point), out, backend="inline").run()
    assert res.stop_reason == "completed", res.error
    assert [p.name for p in (out / "states.parquet").iterdir()] == ["part-000000.parquet"]
    return out


@pytest.fixture
def run_copy(camera_run: Path, tmp_path: Path) -> Callable[[], Path]:
    """``run_copy()``: a fresh copy of ``camera_run`` in ``tmp_path/run``,
    with ``tmp_path/outside`` beside it (for files a symlink points out to)."""

    def make() -> Path:
        shutil.copytree(camera_run, tmp_path / "run")
        (tmp_path / "outside").mkdir()
        return tmp_path / "run"

    return make
