"""A consensus swarm over a mixed group: fixed-wings loiter at their goals,
quadrotors hover at theirs, cars drive to theirs and stay on the ground;
the group closes on its centroid (rendezvous) with every class commanded by
the same DO_REPOSITION messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.logs import read_states
from cosim.scenario import parse_scenario
from cosim.sync import run_scenario

BODY = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 60
vehicles:
  - {id: quad, model: F450, count: 2, formation: {type: line, spacing_m: 200, bearing_deg: 90},
     init: {north_m: 150, east_m: -100, alt_agl_m: 30}}
  - {id: car, class: ground, count: 2, formation: {type: line, spacing_m: 200, bearing_deg: 90},
     init: {north_m: -150, east_m: -100}}
  - {id: uav, model: uav700, count: 2, formation: {type: line, spacing_m: 600, bearing_deg: 90},
     init: {north_m: 0, east_m: -300, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}}
swarm:
  rate_hz: 1
  groups:
    - name: mixed
      vehicles: all
      phases:
        - {behaviour: rendezvous, mu: 1.0, k_s: 0.05, radius_m: 20, timeout_s: 55}
"""


pytestmark = pytest.mark.integration  # a long mixed flight


def test_a_mixed_group_closes_on_its_centroid_each_class_its_own_way(tmp_path: Path) -> None:
    scn = parse_scenario(BODY, str(tmp_path / "mixed.yaml"), check_properties=False)
    res = run_scenario(scn, tmp_path / "run", backend="inline")
    assert res.stop_reason == "completed", res.error
    t = read_states(tmp_path / "run")
    names = np.asarray(t["vehicle"].to_pylist()).astype(str)
    last = int(t["tick"].to_numpy().max())
    # the cars and the quadrotors closed on one point (the group's centroid,
    # which the planes' loiters move about): their spread at least halved
    low = np.char.startswith(names, "quad") | np.char.startswith(names, "car")
    ticks = t["tick"].to_numpy()

    def spread(tick: int) -> float:
        m = low & (ticks == tick)
        n, e = t["north_m"].to_numpy()[m], t["east_m"].to_numpy()[m]
        return float(np.hypot(n - n.mean(), e - e.mean()).max())

    assert spread(last) < 0.5 * spread(0), (spread(0), spread(last))
    cars = np.char.startswith(names, "car")
    assert np.all(t["alt_agl_m"].to_numpy()[cars] == 0.0)  # on the ground
    quads = np.char.startswith(names, "quad") & (t["time_s"].to_numpy() > 5)
    assert np.abs(t["alt_agl_m"].to_numpy()[quads] - 30.0).max() < 1.0  # at their layer
    uavs = np.char.startswith(names, "uav")
    assert (t["status"].to_numpy()[uavs] == 0).all()
    assert (t["airspeed_mps"].to_numpy()[uavs] > 20).all()  # flying, not stopped
    summary = json.loads((tmp_path / "run/summary.json").read_text())
    assert summary["mavlink"]["counters"]["commands_refused"] == 0
    assert summary["mavlink"]["counters"]["commands_unsafe"] == 0
