"""The fuel on board in the state log (``fuel_kg``): what a JSBSim
fixed-wing's tanks hold, burnt as it flies (the uav700 freezes its fuel
unless ``uav700/fuel-freeze`` is set to 0); NaN for the batched tier, whose
mass is constant. The operator's SAGAT questions of fuel are scored from it."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cosim.logs.runfolder import read_states
from cosim.scenario import load_scenario
from cosim.sync.runner import Run

REPO = Path(__file__).resolve().parents[2]
SCENARIO = """
schema_version: 1
name: fuel
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 10
seed: 3
vehicles:
  - id: jsb
    model: uav700
    set: {uav700/fuel-freeze: 0}
    init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}
  - id: fast
    model: uav700
    set: {uav700/fuel-freeze: 0}
    init: {north_m: 0, east_m: 500, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}
  - id: frozen
    model: uav700
    init: {north_m: 0, east_m: -500, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}
  - id: fleet
    class: fixed_wing_batched
    model: uav700
    init: {north_m: -500, east_m: 0, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}
"""


def _tanks_kg(xml: Path) -> float:
    """The fuel the aircraft file puts in its tanks (kg), read from its text."""
    total = 0.0
    for tank in re.findall(r"<tank\b.*?</tank>", xml.read_text(), flags=re.S):
        m = re.search(r'<contents\s+unit="(KG|LBS)">\s*([0-9.]+)\s*</contents>', tank)
        if m is not None:
            total += float(m.group(2)) * (1.0 if m.group(1) == "KG" else 0.45359237)
    return total


def test_a_jsbsim_fixed_wing_logs_the_fuel_its_tanks_hold_as_it_burns(
        write_scenario: Callable[[str, str], Path], tmp_path: Path) -> None:
    res = Run(load_scenario(write_scenario(SCENARIO, "fuel.yaml")), tmp_path / "run",
              backend="inline").run()
    assert res.ok, res.summary
    t = read_states(tmp_path / "run")
    who = np.array(t["vehicle"].cast("string").to_pylist())
    fuel = t["fuel_kg"].to_numpy()
    full = _tanks_kg(REPO / "aircraft" / "uav700" / "uav700.xml")
    assert full > 0
    for v in ("jsb", "fast"):
        f = fuel[who == v]
        assert np.isfinite(f).all() and abs(f[0] - full) < 1e-3 * full, (v, f[0], full)
        assert (np.diff(f) <= 0).all() and f[-1] < f[0]  # the engine burns it, never adds
    # the uav700's own default: its fuel frozen (a constant mass)
    assert (fuel[who == "frozen"] == fuel[who == "frozen"][0]).all()
    assert abs(fuel[who == "frozen"][0] - full) < 1e-3 * full
    assert np.isnan(fuel[who == "fleet"]).all()  # the batched tier has no fuel
