"""A plan flown by the simulator: two batched uav700s follow their plans as
ordinary ``waypoints`` commands, and their cameras' swaths, computed from the
logged tracks, cover the search area."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from shapely.geometry import LineString
from shapely.ops import unary_union

from cosim.core.units import KT_TO_MPS
from cosim.coverage import area_polygon, completion_s, plan_coverage, swath_m, turn_radius_m
from cosim.scenario import load_scenario
from cosim.sync import Run

LAT0, LON0 = 37.4, -122.0


pytestmark = pytest.mark.integration  # a plan flown to its end


def test_two_aircraft_flying_their_plans_cover_the_area(tmp_path: Path) -> None:
    area = area_polygon([(0, 0), (0, 3_000), (2_000, 3_000), (2_000, 0)])  # 6 km2
    v = 100 * KT_TO_MPS
    swath = swath_m(260.0, 60.0)  # 300 m
    # planned at 20 degrees of bank, flown with 35 allowed: room to follow the path
    plan = plan_coverage(area, 2, swath, turn_radius_m(v, 20.0), base_ne=(-800.0, -800.0))
    duration = math.ceil(completion_s(plan, v) * 1.15)
    lines = []
    for k, a in enumerate(plan.aircraft):
        wps = ", ".join(f"{{north_m: {n:.1f}, east_m: {e:.1f}}}" for n, e in
                        a.waypoints_ne(turn_step_m=150.0))
        lines.append(f"  - {{at_s: 0.5, vehicles: [s{k}], command: {{bank_limit_deg: 35, "
                     f"waypoints: [{wps}]}}}}")
    text = f"""\
schema_version: 1
origin: {{lat_deg: {LAT0}, lon_deg: {LON0}, ground_alt_m: 0}}
rates: {{physics_hz: 120, control_hz: 10, log_hz: 5}}
duration_s: {duration}
vehicles:
  - {{id: s, count: 2, class: fixed_wing_batched, model: uav700,
     formation: {{type: line, spacing_m: 150}},
     init: {{north_m: -800, east_m: -800, alt_agl_m: 260, airspeed_kt: 100, heading_deg: 45}}}}
schedule:
{chr(10).join(lines)}
"""
    f = tmp_path / "search.yaml"
    f.write_text(text)
    res = Run(load_scenario(f), tmp_path / "run", backend="inline").run()
    assert res.ok, res.error
    t = pq.read_table(tmp_path / "run" / "states.parquet")
    who = np.array(t.column("vehicle").to_pylist())
    north, east = (t.column(c).to_numpy() for c in ("north_m", "east_m"))
    agl = t.column("alt_agl_m").to_numpy()
    seen = []
    for vid in ("s0", "s1"):
        mine = who == vid
        assert mine.sum() > 100
        track = LineString(np.column_stack([east[mine], north[mine]]))
        seen.append(track.buffer(swath / 2, cap_style="flat"))
        assert abs(agl[mine][-1] - 260.0) < 30.0  # kept its altitude
    covered = unary_union(seen).intersection(area).area / area.area
    assert covered > 0.97, covered
