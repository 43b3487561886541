"""The mixed-world demo (scenarios/hetero/quad_guides_car.yaml): a car that
knows no obstacle learns each one when it enters the quadrotor's camera
footprint, before it gets there, plans around it, never enters one and
reaches its goal, while a fixed-wing loiters overhead; the same states, bit
for bit, inline and on 2 worker processes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.logs import read_states
from cosim.scenario import load_scenario
from cosim.sync import run_scenario
from cosim.world.obstacles import inside

SCENARIO = Path(__file__).resolve().parent.parent.parent / "scenarios/hetero/quad_guides_car.yaml"


pytestmark = pytest.mark.integration  # a long mixed flight


def test_the_scout_finds_the_obstacles_and_the_car_reaches_its_goal(tmp_path: Path) -> None:
    scn = load_scenario(SCENARIO)
    res = run_scenario(scn, tmp_path / "run", backend="inline")
    assert res.stop_reason == "completed", res.error
    other = run_scenario(scn, tmp_path / "process2", backend="process", workers=2)
    assert other.stop_reason == "completed", other.error
    a, b = read_states(tmp_path / "run"), read_states(tmp_path / "process2")
    assert a.column_names == b.column_names and a.num_rows == b.num_rows
    for col in a.column_names:  # value by value (the two files' dictionaries may differ)
        x, y = np.asarray(a[col].to_pylist()), np.asarray(b[col].to_pylist())
        same = np.array_equal(x, y, equal_nan=True) if x.dtype.kind == "f" \
            else np.array_equal(x, y)
        assert same, col
    events = [json.loads(x) for x in (tmp_path / "run/events.jsonl").read_text().splitlines()]
    found = {e["obstacle"]: e["time_s"] for e in events if e["event"] == "obstacle_discovered"}
    assert set(found) >= {"block_a", "block_b", "wall_c"}
    [goal] = [e for e in events if e["event"] == "goal_reached" and e["vehicle"] == "car"]
    assert goal["time_s"] < 110.0
    t = read_states(tmp_path / "run")
    car = np.array([v == "car" for v in t["vehicle"].to_pylist()])
    pts = np.stack([t["north_m"].to_numpy()[car], t["east_m"].to_numpy()[car]], axis=1)
    time_s = t["time_s"].to_numpy()[car]
    for o in scn.sections["obstacles"]:
        poly = np.array(o.polygon)
        assert not inside(poly, pts).any(), o.id
        if o.id in found:  # learnt before the car came within 15 m of it
            near = np.flatnonzero(np.hypot(*(pts[:, None, :] - poly[None]).transpose(2, 0, 1))
                                  .min(axis=1) < 15.0)
            assert near.size == 0 or found[o.id] < time_s[near[0]], o.id
    plane = np.array([v == "plane" for v in t["vehicle"].to_pylist()])
    assert (t["status"].to_numpy()[plane] == 0).all()
