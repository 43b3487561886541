"""The sweep: section and ${...} placeholders: values, types, errors with file:line."""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from cosim.core.units import KT_TO_MPS
from cosim.errors import ConfigError
from cosim.scenario import load_scenario
from cosim.sweep.spec import read_sweep

BASE = """\
schema_version: 1
name: pass-${target}
origin: {lat_deg: 37, lon_deg: -116, ground_alt_m: 1000}
duration_s: ${round(1200 / speed_kt, 1)}
sweep:
  speed_kt: [50, 100]
  alt_agl_m: [30, 300]
  target: [truck, fire_truck]
  vfov_deg: 40
vehicles:
  - {id: uav, model: uav700, init: {alt_agl_m: ${alt_agl_m}, heading_deg: 0,
                                    airspeed_kt: ${speed_kt}}}
schedule:
  - at_s: 0
    vehicles: uav
    command: {airspeed_kt: ${speed_kt}, alt_agl_m: ${max(alt_agl_m, 2 * vfov_deg)}}
"""

Write = Callable[..., Path]


def test_first_values_by_default_with_a_log_line(write_scenario: Write, caplog) -> None:
    p = write_scenario(BASE)
    with caplog.at_level(logging.INFO, logger="cosim.scenario"):
        scn = load_scenario(p, check_properties=False)
    assert "uses the first value of each swept name (speed_kt=50, alt_agl_m=30, " \
           "target=truck, vfov_deg=40)" in caplog.text
    assert scn.name == "pass-truck"  # embedded placeholder: text
    assert scn.duration_s == 24.0  # expression: a number
    v = scn.vehicles[0]
    assert v.airspeed_mps == pytest.approx(50 * KT_TO_MPS)
    assert v.alt_msl_m == pytest.approx(1030)
    assert scn.schedule[0].command is not None
    assert scn.schedule[0].command.alt_m == pytest.approx(80)  # max(30, 2 * 40)
    assert scn.sections["sweep"] == {"speed_kt": 50, "alt_agl_m": 30, "target": "truck",
                                     "vfov_deg": 40}


def test_a_given_point(write_scenario: Write) -> None:
    p = write_scenario(BASE)
    scn = load_scenario(p, check_properties=False,
                        sweep_point={"speed_kt": 100, "alt_agl_m": 300, "target": "fire_truck",
                                     "vfov_deg": 40})
    assert scn.name == "pass-fire_truck" and scn.duration_s == 12.0
    assert scn.vehicles[0].alt_msl_m == pytest.approx(1300)
    assert scn.schedule[0].command is not None
    assert scn.schedule[0].command.alt_m == pytest.approx(300)


def test_resolved_scenario_records_the_point_and_loads_again(write_scenario: Write,
                                                             tmp_path: Path) -> None:
    p = write_scenario(BASE)
    scn = load_scenario(p, check_properties=False,
                        sweep_point={"speed_kt": 100, "alt_agl_m": 30, "target": "truck",
                                     "vfov_deg": 40})
    resolved = tmp_path / "resolved.yaml"
    resolved.write_text(yaml.safe_dump(scn.resolved_dict(), sort_keys=False))
    assert "sweep:\n  speed_kt: 100\n" in resolved.read_text()
    back = load_scenario(resolved, check_properties=False)
    assert back.vehicles == scn.vehicles
    assert back.sections["sweep"]["speed_kt"] == 100


def test_spec_points_and_folders(write_scenario: Write) -> None:
    spec = read_sweep(write_scenario(BASE))
    assert spec.swept == ("speed_kt", "alt_agl_m", "target")
    pts = spec.points()
    assert len(pts) == 8
    assert pts[0] == {"speed_kt": 50, "alt_agl_m": 30, "target": "truck", "vfov_deg": 40}
    assert pts[1]["target"] == "fire_truck" and pts[-1]["speed_kt"] == 100  # last name fastest
    assert spec.folder(pts[0]) == "speed_kt=50,alt_agl_m=30,target=truck"
    assert spec.folder({"speed_kt": 2.5, "alt_agl_m": -3, "target": "a b/c"}) == \
        "speed_kt=2.5,alt_agl_m=-3,target=a_b_c"


def test_placeholder_errors_name_file_and_line(write_scenario: Write) -> None:
    text = BASE.replace("${max(alt_agl_m, 2 * vfov_deg)}", "${alt_agl_m + altitude}")
    text = text.replace("duration_s: ${round(1200 / speed_kt, 1)}", "duration_s: ${1 / (}")
    text = text.replace("  vfov_deg: 40\n", "  vfov_deg: 40\n  unused_m: [1, 2]\n")
    text = text.replace("name: pass-${target}", "name: pass-${__import__('os')}")
    p = write_scenario(text)
    with pytest.raises(ConfigError) as e:
        load_scenario(p, check_properties=False)
    msgs = e.value.problems
    assert f"{p}:2: name: cannot substitute ${{__import__('os')}}: not allowed in a " \
           f"placeholder: \"__import__('os')\"" in msgs[0]
    assert any(m.startswith(f"{p}:4: duration_s: cannot substitute ${{1 / (}}: not a valid "
                            f"expression") for m in msgs)
    assert f"{p}:10: sweep.unused_m: 'unused_m' is swept over 2 values but no placeholder " \
           f"uses it; write ${{unused_m}} where it belongs" in msgs
    assert any(m.startswith(f"{p}:17: schedule[0].command.alt_agl_m: cannot substitute "
                            f"${{alt_agl_m + altitude}}: unknown name 'altitude'; sweep names: "
                            f"speed_kt, alt_agl_m, target, vfov_deg, unused_m") for m in msgs)
    lines = [int(m.split(":")[1]) for m in msgs]
    assert lines == sorted(lines)


def test_bad_sweep_sections(write_scenario: Write) -> None:
    text = BASE.replace("  target: [truck, fire_truck]\n",
                        "  target: [truck, truck]\n  9lives: [1]\n  nested: [[1, 2]]\n"
                        "  empty: []\n  bad: ${speed_kt}\n")
    p = write_scenario(text)
    with pytest.raises(ConfigError) as e:
        read_sweep(p)
    msgs = str(e.value)
    assert f"{p}:8: sweep.target: value truck is listed twice" in msgs
    assert f"{p}:9: sweep.9lives: sweep name '9lives' must be an identifier" in msgs
    assert f"{p}:10: sweep.nested[0]: expected a number, a string or a boolean, got [1, 2]" \
        in msgs
    assert f"{p}:11: sweep.empty: expected at least one value" in msgs
    assert "placeholders are not allowed in the sweep: section" in msgs
    with pytest.raises(ConfigError, match=r":12: sweep.bad: placeholders are not allowed"):
        load_scenario(p, check_properties=False)


def test_placeholder_without_a_sweep_section(write_scenario: Write) -> None:
    text = BASE.split("sweep:")[0] + BASE.split("  vfov_deg: 40\n")[1]
    p = write_scenario(text)
    with pytest.raises(ConfigError, match=r"s.yaml:2: name: cannot substitute \$\{target\}: "
                                          r"unknown name 'target'; sweep names: none"):
        load_scenario(p, check_properties=False)


def test_placeholder_in_a_key(write_scenario: Write) -> None:
    p = write_scenario(BASE.replace("  - {id: uav,", "  - {${target}: 1, id: uav,"))
    with pytest.raises(ConfigError, match=r"s.yaml:11: vehicles\[0\]: placeholders are not "
                                          r"substituted in keys: '\$\{target\}'"):
        load_scenario(p, check_properties=False)


def test_expression_results_must_be_finite(write_scenario: Write) -> None:
    p = write_scenario(BASE.replace("${round(1200 / speed_kt, 1)}", "${1 / (speed_kt - 50)}"))
    with pytest.raises(ConfigError, match=r"s.yaml:4: duration_s: cannot substitute "
                                          r"\$\{1 / \(speed_kt - 50\)\}: ZeroDivisionError"):
        load_scenario(p, check_properties=False)


def test_a_name_only_in_the_branch_not_taken_still_counts_as_used(write_scenario: Write
                                                                   ) -> None:
    text = BASE.replace("duration_s: ${round(1200 / speed_kt, 1)}",
                        "duration_s: ${30 if mode == 'short' else long_s}").replace(
        "  vfov_deg: 40\n", "  vfov_deg: 40\n  mode: short\n  long_s: [60, 90]\n")
    scn = load_scenario(write_scenario(text), check_properties=False)
    assert scn.duration_s == 30


def test_only_runs_the_combinations_its_expression_allows(write_scenario: Write) -> None:
    text = BASE.replace("  vfov_deg: 40\n",
                        "  vfov_deg: 40\n  only: \"target == 'truck' or speed_kt > 50\"\n")
    spec = read_sweep(write_scenario(text))
    pts = spec.points()
    assert len(pts) == 6  # the two fire-truck runs at 50 kt left out
    assert all(p["target"] == "truck" or p["speed_kt"] == 100 for p in pts)
    assert "only" not in spec.swept and "only" not in spec.values
    assert load_scenario(write_scenario(text), check_properties=False).sections["sweep"] == \
        pts[0]


@pytest.mark.parametrize("only,message", [
    ("speed_kt + 1", "must be true or false, got 51 at speed_kt=50"),
    ("speed > 50", "cannot evaluate"),
    ("speed_kt > 500", "leaves no combination to run"),
    ("[1]", "expected an expression"),
])
def test_a_bad_only_is_refused_with_its_line(write_scenario: Write, only: str,
                                             message: str) -> None:
    p = write_scenario(BASE.replace("  vfov_deg: 40\n", f"  vfov_deg: 40\n  only: {only}\n"))
    with pytest.raises(ConfigError, match=f"{p}:10: sweep.only: .*{re.escape(message)}"):
        read_sweep(p)
