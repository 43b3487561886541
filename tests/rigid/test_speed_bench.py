"""``benchmarks/rigid_speed.py`` runs end to end on a small fleet: both tiers
timed, and a pool of rigid aircraft, the figures written, the rigid
tier's autopilot engaged throughout (the script refuses to report
otherwise)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def test_the_speed_benchmark_reports_both_tiers(tmp_path: Path) -> None:
    out = tmp_path / "speed.json"
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "rigid_speed.py"),
                          "--vehicles", "20,40", "--jsbsim", "2", "--frames", "6",
                          "--rounds", "1", "--pool", "8", "--pool-seconds", "0.1",
                          "--json", str(out)],
                         capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["autopilot"] == "engaged" and doc["jsbsim_steps_per_s"] > 0
    assert [r["vehicles"] for r in doc["rigid"]] == [20, 40]
    assert all(r["steps_per_s"] > 0 and r["x_jsbsim"] > 0 for r in doc["rigid"])
    assert "x JSBSim" in res.stdout
    # through the pool, every autopilot engaged (the script checks the states)
    assert [(r["vehicles"], r["rtf"] > 0) for r in doc["pool"]] == [(8, True)]
    assert "RTF" in res.stdout


@pytest.mark.integration  # two tiers of the c172p timed: about 6 s
def test_the_speed_benchmark_takes_another_model(tmp_path: Path) -> None:
    """``--model c172p``: its piston engine and propeller, both tiers, the
    rigid autopilot engaged; an unknown model is a usage error."""
    out = tmp_path / "speed.json"
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "rigid_speed.py"),
                          "--model", "c172p", "--vehicles", "20", "--jsbsim", "2",
                          "--frames", "6", "--rounds", "1", "--json", str(out)],
                         capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["model"] == "c172p" and doc["rigid"][0]["steps_per_s"] > 0
    assert "model c172p" in res.stdout
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "rigid_speed.py"),
                          "--model", "c17"], capture_output=True, text=True, timeout=60,
                         check=False)
    assert res.returncode == 2 and "--model: unknown aircraft model 'c17'" in res.stderr


def test_bad_arguments_are_a_usage_error() -> None:
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "rigid_speed.py"),
                          "--vehicles", "0"], capture_output=True, text=True, timeout=60,
                         check=False)
    assert res.returncode == 2 and "positive numbers" in res.stderr
    res = subprocess.run([sys.executable, str(REPO / "benchmarks" / "rigid_speed.py"),
                          "--pool", "8,x"], capture_output=True, text=True, timeout=60,
                         check=False)
    assert res.returncode == 2 and "whole numbers" in res.stderr
