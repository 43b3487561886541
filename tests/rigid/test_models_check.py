"""``cosim models --check`` says, for each model, whether the rigid-body tier
compiles its files, and lists what it refuses by file, line and element."""

from __future__ import annotations

import re

import pytest

from cosim.cli import main


def test_check_of_one_model_says_the_rigid_tier_compiles_it(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models", "--check", "--model", "uav700"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^ok\s+yes\s+uav700\s", out, re.M), out


def test_check_lists_every_refusal_of_a_model_by_file_line_and_element(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models", "--check", "--model", "c172p"]) == 0  # JSBSim loads it
    out = capsys.readouterr().out
    assert re.search(r"^ok\s+no \(\d+\)\s+c172p\s", out, re.M), out
    refusals = [line for line in out.splitlines() if line.startswith("  c172p: ")]
    assert refusals, out
    assert all(re.match(r"  c172p: \S+\.xml:\d+: <[a-z_]+>", r) for r in refusals), refusals
    assert any("<piston_engine>" in r for r in refusals), refusals


def test_model_without_check_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models", "--model", "uav700"]) == 2
