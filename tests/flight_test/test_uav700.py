"""Flight tests of the uav700 (docs/physics.md, Fixed-wing aircraft), flown from
scenarios/flight_test/ and judged from the logged ground truth only, against the
design equations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.analysis.flight import (
    circle_fit,
    events,
    isa_density,
    level_stall_speed_mps,
    model_numbers,
    stall_onset,
    steady_turn,
    turn_radius_m,
    vehicle_columns,
)
from cosim.core.units import KT_TO_MPS
from cosim.scenario import load_scenario
from cosim.sync import run_scenario

FT = Path(__file__).resolve().parents[2] / "scenarios" / "flight_test"


pytestmark = pytest.mark.integration  # long flights


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory):
    """Run each flight-test scenario once (inline backend) and hand out its folder."""
    done: dict[str, Path] = {}

    def fly(name: str) -> Path:
        if name not in done:
            out = tmp_path_factory.mktemp(name) / "run"
            res = run_scenario(load_scenario(FT / f"{name}.yaml"), out, backend="inline")
            assert res.ok, res.summary
            done[name] = out
        return done[name]

    return fly


def test_the_helpers_against_hand_computed_cases() -> None:
    a = np.linspace(0, 2 * np.pi, 50)
    assert circle_fit(3 + 250 * np.cos(a), -7 + 250 * np.sin(a)) == pytest.approx((3, -7, 250))
    assert float(isa_density(0.0)) == pytest.approx(1.225)
    assert float(isa_density(1000.0)) == pytest.approx(1.1117, abs=1e-4)
    # the uav700's sizing: 40 kg, 1.2 m2, CL_max 1.3 -> about 39 kt at sea level
    assert level_stall_speed_mps(40, 1.2, 1.3, 1.225) / KT_TO_MPS == pytest.approx(39.4, abs=0.1)
    assert turn_radius_m(200 * KT_TO_MPS, 45) == pytest.approx(1079.5, abs=0.5)


def test_model_numbers_come_from_the_model_file() -> None:
    m = model_numbers("uav700")
    assert m.mass_kg == pytest.approx(40.0, abs=0.05)
    assert m.wing_area_m2 == pytest.approx(1.2, abs=1e-3)
    assert m.clmax == 1.3
    # level stall at most 45 KCAS at maximum weight
    assert level_stall_speed_mps(m.mass_kg, m.wing_area_m2, m.clmax, 1.225) / KT_TO_MPS <= 45


@pytest.mark.parametrize("kt", [100, 150, 200])
def test_level_turn_radius_matches_v2_over_g_tan_phi(flown, kt: int) -> None:
    cols = vehicle_columns(flown("level_turns"), f"t{kt}")
    assert np.abs(cols["roll_deg"]).max() <= 45 + 2  # never beyond the limit by > 2 deg
    turn = steady_turn(cols, 45.0, tol_deg=1.0, min_s=30.0)
    assert turn is not None, "no steady 45-deg turn of 30 s"
    assert turn["speed_kt"] == pytest.approx(kt, abs=2)
    assert abs(turn["radius_error"]) < 0.05, turn  # within 5% of v^2/(g tan(phi))
    assert turn["alt_spread_m"] < 15  # level


def test_50_kt_held_30_m_above_the_ground(flown) -> None:
    c = vehicle_columns(flown("slow_low"), "slow")
    late = c["time_s"] >= 15
    kt = c["airspeed_mps"][late] / KT_TO_MPS
    assert np.all(np.abs(kt - 50) <= 3), (kt.min(), kt.max())
    assert np.all(np.abs(c["alt_agl_m"][late] - 30) <= 5)
    assert not events(flown("slow_low"), "stall")


def test_full_throttle_level_speed_reaches_200_ktas(flown) -> None:
    c = vehicle_columns(flown("acceleration"), "fast")
    late = c["time_s"] >= 100
    assert (c["airspeed_mps"][late] / KT_TO_MPS).min() >= 200
    assert np.all(np.abs(c["alt_msl_m"][late] - 914.4) < 10)  # level, at 3000 ft
    assert np.all(c["throttle"][c["time_s"] > 1] == 1.0)


def test_stall_speed_and_a_real_stall(flown) -> None:
    run = flown("stall")
    s = stall_onset(run, "stall", "uav700")
    assert abs(s["error"]) < 0.10, s  # within 10% of sqrt(2 m g / (rho S CL_max))
    c = vehicle_columns(run, "stall")
    after = (c["time_s"] >= s["time_s"]) & (c["time_s"] <= s["time_s"] + 10)
    assert c["alpha_deg"][after].max() > 18  # past the lift peak at 14 deg
    pitch_at_onset = c["pitch_deg"][after][0]
    assert c["pitch_deg"][after].min() < pitch_at_onset - 10  # the nose drops
    assert c["vd_mps"][after].max() > 8  # rapid descent
    assert c["alt_msl_m"][after][-1] < c["alt_msl_m"][after][0] - 30
    assert not events(run, "stall_protection")


def test_goto_5_km_reached_then_loitered(flown) -> None:
    run = flown("goto_loiter")
    reached = events(run, "goal_reached")
    assert len(reached) == 1
    c = vehicle_columns(run, "uav")
    d0 = np.hypot(3000 - c["north_m"][0], 4000 - c["east_m"][0])
    assert d0 == pytest.approx(5000, abs=1)
    late = c["time_s"] > reached[0]["time_s"] + 60
    d = np.hypot(c["north_m"][late] - 3000, c["east_m"][late] - 4000)
    assert np.all(np.abs(d - 800) < 80), (d.min(), d.max())
    assert np.all(np.abs(c["alt_agl_m"][late] - 400) < 10)
    assert (run / "track.png").stat().st_size > 10_000


def test_waypoint_square_flown_in_order(flown) -> None:
    run = flown("waypoints")
    assert [e["index"] for e in events(run, "waypoint_reached")] == [0, 1, 2]
    assert len(events(run, "goal_reached")) == 1
    c = vehicle_columns(run, "uav")
    first_pass = []
    for n, e in [(3000, 0), (3000, 3000), (0, 3000)]:
        d = np.hypot(c["north_m"] - n, c["east_m"] - e)
        assert d.min() < 400, (n, e, d.min())
        first_pass.append(c["time_s"][np.argmax(d < 400)])
    assert first_pass == sorted(first_pass)
