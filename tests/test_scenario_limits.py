"""Scenario files are untrusted input: every limit in ``cosim.core.limits``
is a line-numbered config error (exit 2), found fast, never a traceback, a
hang, a silent change of the value or a file written outside the run folder."""

from __future__ import annotations

import json
import logging
import os
import re
import textwrap
import time
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.core import limits
from cosim.errors import ConfigError
from cosim.scenario import load_scenario, parse_scenario
from cosim.sweep.spec import SweepSpec, read_sweep

HEAD = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 20
seed: 3
"""
VEHICLE = ("  - {id: a, model: c172p, init: {north_m: 0, east_m: 0, alt_agl_m: 500, "
           "heading_deg: 0, airspeed_kt: 90}}\n")
LINE = re.compile(r"^s\.yaml:(\d+): ")


def scenario(*, head: str = HEAD, vehicles: str = VEHICLE, extra: str = "") -> str:
    return head + extra + "vehicles:\n" + vehicles


def refused(text: str, fragment: str, line: int | None = None) -> ConfigError:
    """Parsing ``text`` fails quickly with a problem containing ``fragment``
    (at ``line`` if given), every problem carrying its file line."""
    t0 = time.monotonic()
    with pytest.raises(ConfigError) as ei:
        parse_scenario(text, "s.yaml", check_properties=False)
    assert time.monotonic() - t0 < 5.0
    probs = ei.value.problems
    assert all(LINE.match(p) for p in probs), probs
    hits = [p for p in probs if fragment in p]
    assert hits, probs
    if line is not None:
        assert any(p.startswith(f"s.yaml:{line}: ") for p in hits), hits
    return ei.value


# --- files -------------------------------------------------------------------------

def test_a_device_is_never_read(capsys) -> None:
    t0 = time.monotonic()
    assert main(["validate", "/dev/zero"]) == 2
    assert time.monotonic() - t0 < 5.0
    assert "/dev/zero: cannot read scenario: not a regular file" in capsys.readouterr().err


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path: Path, capsys) -> None:
    big = tmp_path / "big.yaml"
    with open(big, "w") as f:
        f.write(scenario())
        f.write("junk:\n")
        line = "  k: 1\n"
        f.write(line * (limits.MAX_FILE_BYTES // len(line) + 1))
    t0 = time.monotonic()
    assert main(["validate", str(big)]) == 2
    assert time.monotonic() - t0 < 5.0
    assert f"a scenario file may have at most {limits.MAX_FILE_BYTES}" in \
        capsys.readouterr().err


def test_error_output_is_capped_with_a_count(tmp_path: Path, capsys) -> None:
    """Thousands of unknown keys print the first problems and how many more."""
    many = tmp_path / "many.yaml"
    many.write_text(scenario() + "".join(f"unknown_{i}: 1\n" for i in range(3000)))
    t0 = time.monotonic()
    assert main(["validate", str(many)]) == 2
    assert time.monotonic() - t0 < 10.0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == ConfigError.SHOWN + 1
    assert err[-1] == f"... and {3000 - ConfigError.SHOWN} more problems (3000 in all)"


# --- YAML structure --------------------------------------------------------------

def test_a_400_digit_number_is_a_line_numbered_error() -> None:
    refused(scenario(extra="seed_of_doom: 1" + "0" * 400 + "\n"),
            "a 401-digit number is too large", line=6)
    # also where a number is expected (it used to be an OverflowError)
    text = scenario(vehicles=VEHICLE.replace("heading_deg: 0", "heading_deg: 9" * 1 + "9" * 399))
    refused(text, "400-digit number is too large", line=7)


def test_a_number_of_thousands_of_digits_is_an_error_not_a_traceback() -> None:
    refused(scenario(extra="x: " + "7" * 6000 + "\n"), "6000-digit number is too large", 6)


def test_deep_nesting_is_refused_before_it_is_built() -> None:
    deep = "\n".join("  " * i + "- " for i in range(5000))
    refused(scenario(extra="x:\n" + textwrap.indent(deep, "  ") + "\n"),
            f"nested more than {limits.MAX_DEPTH} levels deep")
    flow = "x: " + "[" * 5000 + "]" * 5000 + "\n"
    refused(scenario(extra=flow), "", line=6)


def test_a_recursive_alias_is_refused() -> None:
    refused(scenario(extra="x: &a [*a]\n"), "recursive alias", line=6)
    refused(scenario(extra="x: &m {a: 1, b: {<<: *m}}\n"), "recursive alias")


def test_an_alias_bomb_is_counted_not_expanded() -> None:
    bomb = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 10):
        bomb.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]")
    t0 = time.process_time()  # the work, not the shared machine's load
    refused(scenario(extra="\n".join(bomb) + "\n"), "values once aliases are expanded")
    assert time.process_time() - t0 < 1.0
    refused(scenario(extra="".join(f"k{i}: &k{i} 1\n" for i in range(101))
                     + "l: [" + ", ".join(f"*k{i}" for i in range(101)) + "]\n"),
            f"more than {limits.MAX_ALIASES} aliases")


# --- placeholders ------------------------------------------------------------------

@pytest.mark.parametrize("expr, fragment", [
    ("10**10**10", "is too large"),
    ("9**9**7", "is too large"),
    ("'a'*10**10", "text repeated beyond"),
    ("2**62 * 4", "a whole number beyond"),
    ("'%0999999999d' % 1", "% takes numbers"),
    ("round(1.5, 10**9)", "round(x, n)"),
    ("-" * 300 + "1", "more than 200 terms"),
    ("1" * 600, "longer than 500 characters"),
])
def test_a_placeholder_beyond_the_limits_is_refused_in_well_under_a_second(
        expr: str, fragment: str) -> None:
    text = scenario(vehicles=VEHICLE.replace("heading_deg: 0", f"heading_deg: ${{{expr}}}"))
    t0 = time.process_time()  # the work, not the shared machine's load
    refused(text, fragment, line=7)
    assert time.process_time() - t0 < 0.5


def test_placeholders_within_the_limits_still_work() -> None:
    text = scenario(extra="sweep: {h: [10, 20]}\n",
                    vehicles=VEHICLE.replace("heading_deg: 0", "heading_deg: ${h * 2**3 + 1}"))
    scn = parse_scenario(text, "s.yaml", check_properties=False)
    assert scn.vehicles[0].heading_deg == 81.0


def test_a_sweep_with_too_many_combinations_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "s.yaml"
    values = ", ".join(str(i) for i in range(101))
    p.write_text(scenario(extra=f"sweep: {{a: [{values}], b: [{values}]}}\n"))
    with pytest.raises(ConfigError, match=r"s\.yaml:6: sweep: 10201 combinations; a sweep "
                                          r"may have at most 10000 runs"):
        read_sweep(p)


def test_sweep_run_folder_names_are_bounded_and_unique() -> None:
    spec = SweepSpec("s.yaml", {"label": ("x" * 300, "x" * 299 + "y")}, ("label",))
    a, b = (spec.folder(p) for p in spec.points())
    assert len(a) <= 120 and len(b) <= 120 and a != b
    assert re.fullmatch(r"[A-Za-z0-9_.=,+\-]+", a)


# --- names and ids that become file names ---------------------------------------------

@pytest.mark.parametrize("name", ["../../../x", "/abs/dir", "a/b", "..", "a\\b", "x\ty"])
def test_a_name_that_could_leave_its_folder_is_refused(name: str) -> None:
    refused(scenario(extra=f"name: {json.dumps(name)}\n"), "it names the run's folder", line=6)


def test_a_long_name_is_refused_and_odd_characters_become_safe() -> None:
    refused(scenario(extra=f"name: {'n' * 65}\n"), "expected 1 to 64 characters", line=6)
    scn = parse_scenario(scenario(extra="name: 'my run: 2 (test)'\n"), "s.yaml",
                         check_properties=False)
    assert scn.name == "my run: 2 (test)" and scn.folder_name == "my_run__2__test_"


def test_without_out_the_run_folder_is_inside_runs(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    p = tmp_path / "s.yaml"
    p.write_text(scenario(extra="name: 'a*b?c'\n"))
    assert main(["run", str(p), "--duration-s", "0.1", "--backend", "inline",
                 "--no-progress"]) == 0
    made = [x for x in tmp_path.rglob("summary.json")]
    assert len(made) == 1 and made[0].parent.parent == tmp_path / "runs"
    assert made[0].parent.name.startswith("a_b_c-")


@pytest.mark.parametrize("vid, fragment", [
    ("x" * 65, "at most 64 characters"),
    (".hidden", "must not start with '.'"),
    ("..", "must not start with '.'"),
    ("a/b", "may only contain letters"),
])
def test_vehicle_ids_are_bounded_in_length_and_characters(vid: str, fragment: str) -> None:
    refused(scenario(vehicles=VEHICLE.replace("id: a", f"id: {json.dumps(vid)}")),
            fragment, line=7)


def test_an_id_made_too_long_by_count_is_refused() -> None:
    v = ("  - {id: " + "v" * 62 + ", model: c172p, count: 200, formation: {type: line, "
         "spacing_m: 50}, init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, "
         "airspeed_kt: 90}}\n")
    refused(scenario(vehicles=v), "longer than 64 characters", line=7)


# --- numbers, positions, rates, durations ------------------------------------------

@pytest.mark.parametrize("old, new, fragment", [
    ("north_m: 0", "north_m: 1e300", "must be <= 1e+06"),
    ("east_m: 0", "east_m: -2e6", "must be >= -1e+06"),
    ("alt_agl_m: 500", "alt_agl_m: -300", "starts 300 m below the ground"),
    ("alt_agl_m: 500", "alt_msl_m: -10", "starts 410 m below the ground"),
    ("alt_agl_m: 500", "alt_agl_m: 2", "a trimmed start is in the air"),
    ("airspeed_kt: 90", "airspeed_kt: 0", "a trimmed start flies"),
])
def test_vehicle_starts_outside_the_bands_are_refused(old: str, new: str,
                                                      fragment: str) -> None:
    refused(scenario(vehicles=VEHICLE.replace(old, new)), fragment, line=7)


def test_a_vehicle_on_the_ground_needs_trim_false() -> None:
    v = VEHICLE.replace("alt_agl_m: 500", "alt_agl_m: 0").replace("airspeed_kt: 90",
                                                                   "airspeed_kt: 0")
    refused(scenario(vehicles=v), "a trimmed start")
    v = v.replace("model: c172p,", "model: c172p, trim: false,")
    scn = parse_scenario(scenario(vehicles=v), "s.yaml", check_properties=False)
    assert scn.vehicles[0].alt_msl_m == 400.0


def test_a_geodetic_start_far_from_the_origin_is_refused() -> None:
    v = VEHICLE.replace("north_m: 0, east_m: 0", "lat_deg: -33, lon_deg: 63")
    refused(scenario(vehicles=v), "km from the origin; at most 1000 km", line=7)


@pytest.mark.parametrize("old, new, fragment", [
    ("duration_s: 20", "duration_s: 1e300", "must be <= 2.592e+06"),
    ("physics_hz: 120", "physics_hz: 1e-9", "must be >= 10"),
    ("control_hz: 30", "control_hz: 1e-9", "must be >= 0.01"),
    ("seed: 3", "seed: 100000000000000000000000", "number is too large"),
    ("seed: 3", "seed: 4294967296", "must be <= 4294967295"),
])
def test_rates_durations_and_seeds_out_of_range_are_refused(old: str, new: str,
                                                            fragment: str) -> None:
    refused(scenario(head=HEAD.replace(old, new)), fragment)


def test_a_vehicle_random_seed_beyond_jsbsims_int_is_refused() -> None:
    v = VEHICLE.replace("airspeed_kt: 90}", "airspeed_kt: 90}, random_seed: 4294967296")
    refused(scenario(vehicles=v), f"must be <= {limits.MAX_VEHICLE_SEED}", line=7)


def test_a_tiny_duration_still_runs_one_exchange(tmp_path: Path) -> None:
    scn = parse_scenario(scenario(head=HEAD.replace("duration_s: 20", "duration_s: 1e-300")),
                         "s.yaml", check_properties=False)
    assert scn.total_ticks == scn.rates.control_every == 4


def test_any_number_is_bounded_even_without_its_own_range() -> None:
    swarm = ("swarm: {groups: [{name: g, vehicles: all, phases: [{behaviour: rendezvous, "
             "radius_m: 100, mu: 1e300}]}]}\n")
    refused(scenario(extra=swarm), "mu: 1e+300 is out of range", line=6)


def test_vehicle_count_is_bounded_with_the_memory_it_would_take() -> None:
    for count in (1_000_000_000, 100_000):
        v = VEHICLE.replace("model: c172p,", f"model: c172p, count: {count}, "
                                             f"formation: {{type: grid, spacing_m: 50}},")
        t0 = time.process_time()  # the work, not the shared machine's load
        refused(scenario(vehicles=v), f"must be <= {limits.MAX_VEHICLES}", line=7)
        assert time.process_time() - t0 < 1.0
    two = (VEHICLE.replace("model: c172p,", "model: c172p, count: 6000, formation: "
                                            "{type: grid, spacing_m: 50},")
           + VEHICLE.replace("id: a,", "id: b,").replace(
               "model: c172p,", "model: c172p, count: 6000, formation: "
                                "{type: grid, spacing_m: 50},").replace("north_m: 0",
                                                                        "north_m: 9000"))
    refused(scenario(vehicles=two), "MiB", line=8)


def test_stacked_vehicles_are_refused() -> None:
    v = VEHICLE.replace("model: c172p,", "model: c172p, count: 4, "
                                         "formation: {type: line, spacing_m: 0},")
    refused(scenario(vehicles=v), "4 vehicles would start on one point", line=7)
    # the same point from two entries
    refused(scenario(vehicles=VEHICLE + VEHICLE.replace("id: a", "id: b")),
            "vehicles 'a' and 'b' start 0.00 m apart", line=8)
    # a vertical stack is fine
    v = v.replace("spacing_m: 0}", "spacing_m: 0, alt_step_m: 30}")
    assert len(parse_scenario(scenario(vehicles=v), "s.yaml",
                              check_properties=False).vehicles) == 4


def test_aircraft_path_entries_must_hold_models(tmp_path: Path) -> None:
    refused(scenario(extra="aircraft_path: [/etc, ../../../../nonexistent]\n"),
            "holds no aircraft model", line=6)
    refused(scenario(extra="aircraft_path: [/etc, ../../../../nonexistent]\n"),
            "no such folder", line=6)
    mine = tmp_path / "planes" / "myplane"
    mine.mkdir(parents=True)
    (mine / "myplane.xml").write_text("<fdm_config/>")
    s = tmp_path / "s.yaml"
    s.write_text(scenario(extra="aircraft_path: planes\n"))
    assert load_scenario(s, check_properties=False).aircraft_path == (str(mine.parent),)


# --- deep validation and build failures ---------------------------------------------

# c172x: JSBSim's own model, without a cosim profile, so no envelope says before
# the build that it cannot fly at 4-5 kt (c172p's profile does: a static check)
UNTRIMMABLE = scenario(vehicles=VEHICLE + VEHICLE.replace("id: a", "id: b").replace(
    "airspeed_kt: 90", "airspeed_kt: 5").replace("north_m: 0", "north_m: 300").replace(
    "c172p", "c172x") + """\
  - id: c
    model: c172x
    count: 2
    formation: {type: line, spacing_m: 100}
    init: {north_m: 900, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 4}
""")


def test_validate_deep_builds_and_trims_every_vehicle(tmp_path: Path, capsys) -> None:
    p = tmp_path / "s.yaml"
    p.write_text(UNTRIMMABLE)
    assert main(["validate", str(p)]) == 0  # static checks pass
    capsys.readouterr()
    assert main(["validate", "--deep", "--workers", "2", str(p)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert [e.split(": vehicle ")[0] for e in err] == [f"{p}:8: vehicles[1]",
                                                       f"{p}:9: vehicles[2]",
                                                       f"{p}:9: vehicles[2]"]
    assert "'b' (c172x): JSBSim could not trim at 2.6 m/s TAS (5 kt)" in err[0]
    assert "'c0'" in err[1] and "'c1'" in err[2]
    p.write_text(scenario())
    assert main(["validate", "--deep", str(p)]) == 0
    assert "every vehicle built and trimmed" in capsys.readouterr().out


def test_run_reports_every_untrimmable_vehicle_at_once(tmp_path: Path, capsys) -> None:
    p = tmp_path / "s.yaml"
    p.write_text(UNTRIMMABLE)
    out = tmp_path / "run"
    assert main(["run", str(p), "--out", str(out), "--workers", "2", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "3 of 4 vehicles could not be built and trimmed" in err
    assert "vehicle 'b' (c172x): JSBSim could not trim at 2.6 m/s TAS (5 kt)" in err
    # the two that fail for the same reason are one line, JSBSim's reason in it
    assert re.search(r"vehicles c0, c1 \(c172x\): JSBSim could not trim at 2.1 m/s TAS "
                     r"\(4 kt\), 900.0 m MSL \(500.0 m above the ground\), heading 0.0 deg: "
                     r"Trim Failed", err)
    assert "cosim.jsbsim" not in err  # ... and JSBSim does not print it for each vehicle
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "error" and "BuildError" in summary["error"]


def test_validate_refuses_a_start_outside_the_envelope(tmp_path: Path, capsys) -> None:
    """A fixed-wing whose profile gives its envelope (the quickstart's c172p:
    55..140 kt) and starts trimmed below it is a static error, with its line,
    not a surprise of --deep or of the run."""
    quick = Path(__file__).resolve().parent.parent / "scenarios" / "quickstart.yaml"
    p = tmp_path / "slow.yaml"
    p.write_text(quick.read_text().replace("airspeed_kt: 100", "airspeed_kt: 20"))
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err  # said once for the entry, not for each of 5 vehicles
    assert re.search(r"slow\.yaml:15: vehicles\[0\]\.init: starts at 20\.0 kt, outside the "
                     r"envelope of c172p \(55\.\.140 kt TAS\)", err)
    p.write_text(quick.read_text().replace("airspeed_kt: 100", "airspeed_kt: 20")
                 .replace("model: c172p\n", "model: c172p\n    trim: false\n"))
    assert main(["validate", str(p)]) == 0  # not trimmed: no envelope to be in
    p.write_text(quick.read_text())
    assert main(["validate", str(p)]) == 0


def test_a_vehicle_in_error_is_not_also_missing(tmp_path: Path, capsys) -> None:
    """A misspelt model is one problem: the schedule, the swarm or the cameras
    naming that vehicle are not also told it matches nothing."""
    quick = Path(__file__).resolve().parent.parent / "scenarios" / "quickstart.yaml"
    p = tmp_path / "typo.yaml"
    p.write_text(quick.read_text().replace("model: c172p", "model: c172"))
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    assert "unknown aircraft model 'c172' (did you mean 'c172p'" in err
    assert "matches no vehicle" not in err and err.count("\n") == 1, err
    p.write_text(quick.read_text().replace("vehicles: c172-2", "vehicles: c172-9"))
    assert main(["validate", str(p)]) == 2  # a real mismatch is still said
    assert "'c172-9' matches no vehicle" in capsys.readouterr().err


def test_raw_writes_that_move_a_vehicle_are_refused(tmp_path: Path, capsys) -> None:
    """A ``set:`` may work the controls (a throttle cut, the elevator, the
    stall protection off) but not teleport the aircraft, set its speed or
    attitude, or give the autopilot a setpoint the commands' rule would
    refuse (the ground as the altitude), nor push a control beyond its range."""
    quick = (Path(__file__).resolve().parent.parent / "scenarios" / "quickstart.yaml"
             ).read_text()
    p = tmp_path / "s.yaml"
    for write, fragment in (
            ("position/h-sl-ft: 0", "'position/h-sl-ft' would move the vehicle by decree"),
            ("velocities/v-north-fps: 9000", "'velocities/v-north-fps' would move"),
            ("attitude/phi-rad: 3", "'attitude/phi-rad' would move"),
            ("ic/h-sl-ft: 0", "'ic/h-sl-ft' would move"),
            ("simulation/dt: 1", "'simulation/dt' would move"),
            ("cosim/ap/alt-cmd-ft: 0", "'cosim/ap/alt-cmd-ft' is an autopilot setpoint"),
            ("cosim/ap/speed-cmd-kt: 900", "'cosim/ap/speed-cmd-kt' is an autopilot setpoint"),
            ("fcs/throttle-cmd-norm: 1e9", "normalised control: 0 to 1, got 1e+09"),
            ("fcs/elevator-cmd-norm: -3", "normalised control: -1 to 1, got -3"),
            ("atmosphere/wind-north-fps: 1.0e308", "1e+308 is out of range")):
        p.write_text(quick.replace("fcs/throttle-cmd-norm: 0.0", write))
        assert main(["validate", str(p)]) == 2, write
        err = capsys.readouterr().err
        assert re.search(rf"s\.yaml:19: schedule\[0\]\.set\.{re.escape(write.split(':')[0])}: "
                         rf".*{re.escape(fragment)}", err), err
        # a vehicle's own set: (written after its trim) follows the same rule
        p.write_text(quick.replace("    set: {fcs/throttle-cmd-norm: 0.0}\n", "").replace(
            "    model: c172p\n", f"    model: c172p\n    set: {{{write}}}\n"))
        assert main(["validate", str(p)]) == 2, write
        err = capsys.readouterr().err
        assert f"vehicles[0].set.{write.split(':')[0]}: " in err and fragment in err, err
    p.write_text(quick.replace("fcs/throttle-cmd-norm: 0.0", "fcs/throttle-cmd-norm: 0.0, "
                               "fcs/elevator-cmd-norm: -0.5, cosim/ap/stall-protect: 0"))
    assert main(["validate", str(p)]) == 0, capsys.readouterr().err


def test_a_long_build_shows_progress(caplog, specs) -> None:
    from cosim.fdm_pool.base import BuildProgress

    caplog.set_level(logging.INFO, logger="cosim.fdm_pool")
    progress = BuildProgress(10, every_s=0.0)
    progress(3)
    progress(10)  # the end is not announced: the caller says "ready"
    assert [r.getMessage() for r in caplog.records] == [
        "building: 3 of 10 vehicles built and trimmed (0 s)"]
    caplog.clear()
    from cosim.fdm_pool import ProcessPool

    monkey = BuildProgress.__init__.__defaults__
    try:
        BuildProgress.__init__.__defaults__ = (0.0,)
        with ProcessPool(specs(6), 1 / 120, workers=2):
            pass
    finally:
        BuildProgress.__init__.__defaults__ = monkey
    counts = [int(m.group(1)) for r in caplog.records
              if (m := re.match(r"building: (\d+) of 6", r.getMessage()))]
    assert counts and counts == sorted(counts) and max(counts) < 6


def test_limits_are_documented_in_the_readme() -> None:
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    section = readme.split("## Limits", 1)[1].split("\n## ", 1)[0]
    for value in (f"{limits.MAX_FILE_BYTES // 1024 // 1024} MiB", str(limits.MAX_DEPTH),
                  str(limits.MAX_ALIASES), f"{limits.MAX_VEHICLES:,}",
                  f"{limits.MAX_ALL_VEHICLES:,}",
                  f"{limits.MIB_PER_VEHICLE} MiB", f"{limits.MAX_DISTANCE_M / 1000:,.0f} km"):
        assert value in section, value
    assert os.path.basename(limits.__file__) in section


def test_exponent_numbers_are_numbers_in_flow_style_too() -> None:
    """libyaml marks plain scalars with style '' (PyYAML's own parser: None)."""
    v = VEHICLE.replace("alt_agl_m: 500", "alt_agl_m: 5e2")
    scn = parse_scenario(scenario(vehicles=v), "s.yaml", check_properties=False)
    assert scn.vehicles[0].alt_msl_m == 900.0


@pytest.mark.parametrize("camera, fragment", [
    ("{name: c, width_px: 100000, height_px: 480}", "must be <= 8192"),
    ("{name: c, width_px: 8192, height_px: 8192}", "67.1 Mpx a frame; at most 33.2 Mpx"),
    ("{name: c, rate_hz: 1e-300}", "must be >= 0.01"),
    ("{name: " + "c" * 65 + "}", "at most 64 characters"),
    ("{name: .c}", "must not start with '.'"),
])
def test_camera_settings_that_would_fail_at_start_are_refused(camera: str,
                                                              fragment: str) -> None:
    refused(scenario(extra=f"cameras: [{camera}]\n"), fragment, line=6)


@pytest.mark.parametrize("section, fragment", [
    ("cameras: {views: [{name: c}], max_in_flight: 1000000}", "must be <= 1024"),
    ("cameras: {views: [{name: c}], render_workers: 100000}", "must be <= 64"),
    ("targets: [{kind: truck, north_m: 1e7, east_m: 0}]", "must be <= 1e+06"),
    ("targets: [{kind: truck, north_m: 0, east_m: 0, length_m: 1e8}]", "must be <= 1000"),
    ("targets: [{id: ../t, kind: truck, north_m: 0, east_m: 0}]", "may only contain"),
    ("ground: {tile_px: 100000}", "must be <= 4096"),
])
def test_renderer_sections_are_bounded(section: str, fragment: str) -> None:
    refused(scenario(extra=section + "\n"), fragment, line=6)
