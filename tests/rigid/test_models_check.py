"""``cosim models --check`` says, for each model, whether the rigid-body tier
compiles its files, and lists what it refuses by file, line and element."""

from __future__ import annotations

import re

import pytest

from cosim.cli import main


@pytest.mark.parametrize("model", ["uav700", "c172p"])
def test_check_of_one_model_says_the_rigid_tier_compiles_it(
        capsys: pytest.CaptureFixture[str], model: str) -> None:
    assert main(["models", "--check", "--model", model]) == 0
    out = capsys.readouterr().out
    assert re.search(rf"^ok\s+yes\s+{model}\s", out, re.M), out


def test_check_lists_every_refusal_of_a_model_by_file_line_and_element(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models", "--check", "--model", "c182"]) == 0  # JSBSim loads it
    out = capsys.readouterr().out
    assert re.search(r"^ok\s+no \(\d+\)\s+c182\s", out, re.M), out
    refusals = [line for line in out.splitlines() if line.startswith("  c182: ")]
    assert refusals, out
    assert all(re.match(r"  c182: \S+\.xml:\d+: <[a-z_]+>", r) for r in refusals), refusals
    assert any("prop_81in2v.xml:9: <minrpm>: not supported in a propeller" in r
               for r in refusals), refusals  # its constant-speed propeller


def test_model_without_check_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["models", "--model", "uav700"]) == 2
