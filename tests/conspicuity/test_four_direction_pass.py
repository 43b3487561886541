"""Experiment 1 as the study flew it: the quadrotor passes over the target
flying north, east, south and west with its camera on a stabilised nadir
gimbal, and the target crosses the image down, left, up and right (read
from the per-frame ground truth), passing within a few pixels of the
centre."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.conspicuity import passes, read_ground_truth
from cosim.scenario import load_scenario
from cosim.sync import run_scenario

SCENARIO = Path(__file__).resolve().parent.parent.parent / \
    "scenarios/conspicuity/four_direction_pass.yaml"


pytestmark = pytest.mark.integration  # rendered passes


@pytest.mark.parametrize("heading,way", [(0, "down"), (90, "left"), (180, "up"),
                                         (270, "right")])
def test_the_target_crosses_the_screen_in_the_passes_direction(tmp_path: Path, heading: int,
                                                              way: str) -> None:
    point = {"heading_deg": heading, "target": "truck", "speed_mps": 5, "alt_agl_m": 60,
             "width_px": 160, "height_px": 120, "vfov_deg": 40, "lead_s": 4, "tail_s": 2}
    scn = load_scenario(SCENARIO, sweep_point=point)
    res = run_scenario(scn, tmp_path / "run", backend="inline")
    assert res.stop_reason == "completed", res.error
    gt = read_ground_truth(tmp_path / "run" / "cameras" / "quad_nadir.gt.csv")
    [p] = passes(gt[("quad", "nadir", "truck")], 1 / 30)
    assert p.screen_direction == way
    assert p.min_eccentricity_deg < 1.0  # straight over it
