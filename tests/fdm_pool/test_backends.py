"""Backends are found by name: cosim's own and any a package registers in
the ``cosim.backends`` entry-point group; the CLI and ``cosim bench`` list
them instead of naming them, and a registered one passes the conformance
suite."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.errors import ConfigError
from cosim.fdm_pool import backend_names, backends, get_backend, make_pool
from tests.helpers import install_out_of_tree

REPO = Path(__file__).resolve().parent.parent.parent

EXAMPLE = REPO / "examples" / "traced_backend"


def test_the_builtin_backends_are_found_by_name(specs) -> None:
    assert backend_names()[:2] == ["inline", "process"]
    assert list(backends())[:2] == ["inline", "process"]
    assert get_backend("process").default_workers() >= 1
    assert get_backend("inline").default_workers() == 1
    with pytest.raises(ConfigError,
                       match=r"unknown backend .gpu.; available: inline, process, ray"):
        make_pool(specs(1), 1 / 120, backend="gpu")


@pytest.mark.integration
def test_an_out_of_tree_backend_registers_runs_and_passes_the_conformance_suite(
        tmp_path: Path) -> None:
    """The example package (``examples/traced_backend``, a thin wrapper over
    inline), installed with pip into a temporary folder."""
    site = install_out_of_tree(tmp_path / "pkg", "cosim-traced-backend",
                               {"cosim_traced": (EXAMPLE / "cosim_traced.py").read_text()},
                               {"cosim.backends": {"traced": "cosim_traced:TracedPool"}})
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(site), *os.environ.get("PYTHONPATH", "").split(os.pathsep)]).rstrip(os.pathsep),
        "COSIM_CONFORMANCE_BACKENDS": "traced"}

    def cosim(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "cosim", *args], capture_output=True,
                              text=True, env=env, timeout=300, cwd=tmp_path)

    assert "{inline,process,ray,traced}" in cosim("run", "--help").stdout
    out = tmp_path / "run"
    r = cosim("run", str(REPO / "scenarios" / "quickstart.yaml"), "--backend", "traced",
              "--duration-s", "2", "--out", str(out), "--no-progress")
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "summary.json").read_text())["backend"] == "traced"
    # its own log line: 2 s at the 30 Hz exchange rate
    assert "traced: 60 exchanges of 5 vehicles" in r.stderr
    r = cosim("bench", "--vehicles", "2", "--seconds", "0.2", "--repeat", "1", "--backend",
              "traced", "--no-baselines")
    assert r.returncode == 0, r.stderr
    assert "backend traced, workers 1" in r.stdout
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        str(REPO / "tests" / "fdm_pool" / "test_conformance.py"), "-k",
                        "traced"], capture_output=True, text=True, env=env, timeout=600,
                       cwd=REPO)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert " passed" in r.stdout and "failed" not in r.stdout
