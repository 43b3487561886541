"""The code stays ruff- and mypy-clean (both come with the test extras)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("tool", [["ruff", "check", "cosim", "tests", "benchmarks"],
                                  ["mypy", "cosim"]], ids=["ruff", "mypy"])
def test_clean(tool: list[str]) -> None:
    try:
        __import__(tool[0])
    except ImportError:
        pytest.skip(f"{tool[0]} is not installed (pip install -e '.[test]')")
    proc = subprocess.run([sys.executable, "-m", *tool], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
