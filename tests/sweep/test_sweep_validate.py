"""``cosim validate`` on a sweep: every combination checked, the file parsed
once and each part checked once per distinct input (``Memo``), with the same
result as a fresh load of each combination; a problem common to many
combinations said once."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.scenario import load_scenario, memo, schema
from cosim.scenario.memo import Memo
from cosim.scenario.schema import check_scenario
from cosim.sweep.spec import read_sweep

REPO = Path(__file__).resolve().parent.parent.parent

#: 4 x 5 x 6 x 2 = 240 combinations; the vehicles depend on alt_agl_m only
SWEEP = """\
schema_version: 1
name: big
origin: {lat_deg: 37, lon_deg: -116, ground_alt_m: 1000}
duration_s: ${20 + rep}
seed: ${rep}
sweep:
  rep: [0, 1, 2, 3]
  alt_agl_m: [100, 120, 140, 160, 180]
  speed_kt: [60, 70, 80, 90, 100, 110]
  target: [truck, car]
vehicles:
  - id: uav
    count: 20
    model: uav700
    formation: {type: line, spacing_m: 50}
    init: {north_m: 0, east_m: 0, alt_agl_m: ${alt_agl_m}, heading_deg: 0, airspeed_kt: 80}
schedule:
  - {at_s: 1, vehicles: 'uav*', command: {airspeed_kt: ${speed_kt}}}
targets:
  - {id: t, kind: "${target}", north_m: 0, east_m: 0}
"""


def test_each_part_is_checked_once_per_distinct_input(tmp_path: Path, monkeypatch,
                                                      capsys) -> None:
    p = tmp_path / "big.yaml"
    p.write_text(SWEEP)
    calls = {"vehicles": 0, "schedule": 0, "read": 0}
    for name in ("vehicles", "schedule"):
        real = getattr(schema, f"parse_{name}")

        def counted(*a, _real=real, _name=name, **k):
            calls[_name] += 1
            return _real(*a, **k)

        monkeypatch.setattr(schema, f"parse_{name}", counted)
    real_read = memo.read_scenario_text

    def read(path):
        calls["read"] += 1
        return real_read(path)

    monkeypatch.setattr(memo, "read_scenario_text", read)
    assert main(["validate", str(p)]) == 0
    assert "all 240 sweep combinations" in capsys.readouterr().out
    # 5 distinct vehicle sets (alt_agl_m); the schedule also varies with the
    # duration (rep) and the speed: 5 x 4 x 6
    assert calls == {"vehicles": 5, "schedule": 120, "read": 1}


@pytest.mark.parametrize("scenario", [
    "conspicuity/altitude_speed.yaml", "conspicuity/four_direction_pass.yaml",
    "xprize/fleet_sweep.yaml"])
@pytest.mark.integration
def test_shared_work_gives_what_a_fresh_load_gives(scenario: str, tmp_path: Path) -> None:
    """Bundled sweeps (with targets, cameras and the search's fires): each
    combination loaded through one shared ``Memo`` equals a fresh load."""
    path = REPO / "scenarios" / scenario
    memo = Memo()
    points = read_sweep(path).points()
    for point in points[:: max(1, len(points) // 8)]:
        shared = load_scenario(path, sweep_point=point, memo=memo)
        fresh = load_scenario(path, sweep_point=point)
        assert shared.resolved_dict() == fresh.resolved_dict()
        assert shared.vehicles == fresh.vehicles  # random seeds included
        assert shared.sections.keys() == fresh.sections.keys()
        for key in fresh.sections:
            assert repr(shared.sections[key]) == repr(fresh.sections[key]), key
        check_scenario(path, sweep_point=point, memo=memo)  # and no problem either way
    assert memo.hits > 0


def test_problems_are_the_same_with_shared_work(tmp_path: Path) -> None:
    """Combinations with problems (a start below the ground, a command outside
    the envelope, a target of an unknown kind) report exactly what a fresh
    load reports, also when an earlier combination had the same part."""
    p = tmp_path / "bad.yaml"
    p.write_text(SWEEP.replace("alt_agl_m: [100, 120, 140, 160, 180]",
                               "alt_agl_m: [100, -5000, 140]")
                 .replace("speed_kt: [60, 70, 80, 90, 100, 110]", "speed_kt: [60, 400]")
                 .replace("target: [truck, car]", "target: [truck, spaceship]"))

    def outcome(load, memo: Memo | None) -> tuple[list[str], int] | None:
        try:
            load(p, sweep_point=point, memo=memo)
        except ConfigError as e:
            return e.problems, e.more
        return None

    memo = Memo()
    bad = 0
    for point in read_sweep(p).points():
        fresh = outcome(load_scenario, None)
        assert outcome(load_scenario, memo) == fresh, point
        assert outcome(check_scenario, memo) == fresh, point
        bad += fresh is not None
    assert bad == 4 * 3 * 2 * 2 - 4 * 2 * 1 * 1  # all but 100 or 140 m, 60 kt, a truck
    assert memo.hits > 0


def test_a_problem_of_many_combinations_is_said_once(tmp_path: Path, capsys) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text(SWEEP.replace("speed_kt: [60, 70, 80, 90, 100, 110]",
                               "speed_kt: [60, 400, 500]")
                 .replace("alt_agl_m: [100, 120, 140, 160, 180]", "alt_agl_m: [100, 2]"))
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        # alt_agl_m=2: every combination with it (the vehicles fail there, so
        # their commands are not checked)
        f"sweep combinations rep=any, alt_agl_m=2, speed_kt=any, target=any (24 of 48): "
        f"{p}:16: vehicles[0].init.alt_agl_m: starts 2 m above the ground; a trimmed start "
        f"is in the air: at least 5 m (give trim: false for a vehicle on the ground)",
        f"sweep combinations rep=any, alt_agl_m=100, speed_kt=400, target=any (8 of 48): "
        f"{p}:18: schedule[0].command: airspeed 400.0 kt is outside the envelope of uav700 "
        f"(50..240 kt TAS)",
        f"sweep combinations rep=any, alt_agl_m=100, speed_kt=500, target=any (8 of 48): "
        f"{p}:18: schedule[0].command: airspeed 500.0 kt is outside the envelope of uav700 "
        f"(50..240 kt TAS)"]
    q = tmp_path / "unused.yaml"
    q.write_text(SWEEP.replace("seed: ${rep}\n", "").replace("${20 + rep}", "20"))
    assert main(["validate", str(q)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"every sweep combination: {q}:6: sweep.rep: 'rep' is swept over 4 values but no "
        f"placeholder uses it; write ${{rep}} where it belongs"]
