"""A run folder is untrusted input to every command that reads it (export,
recover, plot, visibility, a sweep's tables): each damage below, on a copy
of a real run, ends in exit 2 with a message naming the file (and its line
or row) or in a clean result, never in a traceback, in memory filling up or
in a write outside the folder. ``test_fuzz_run_folders.py`` tries many more."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from cosim.cli import main
from cosim.logs import read_states

PART = "states.parquet/part-000000.parquet"
ALIAS_BOMB = "a0: &a0 [x, x, x, x, x, x, x, x]\n" + "".join(
    f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 8)}]\n" for i in range(1, 9))


def _cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    rc = main(list(args))
    return rc, capsys.readouterr().err


def _link(path: Path, target: str | Path) -> None:
    path.unlink()
    path.symlink_to(target)


def _set(run: Path, column: str, row: int, value: float) -> None:
    """Row ``row`` (0-based) of the states' ``column`` set to ``value``."""
    p = run / PART
    t = pq.read_table(p)
    a = t[column].to_numpy().astype(float)
    a[row] = value
    pq.write_table(t.set_column(t.schema.get_field_index(column), column, pa.array(a)), p)


# -- cosim export -------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["acmi", "kml", "czml"])
def test_export_never_reads_a_resolved_scenario_that_leads_to_dev_zero(
        run_copy: Callable[[], Path], capsys, fmt: str) -> None:
    run = run_copy()
    _link(run / "scenario.resolved.yaml", "/dev/zero")  # was read until MemoryError
    rc, err = _cli(capsys, "export", str(run), "--format", fmt)
    assert rc == 2
    assert re.search(r"scenario\.resolved\.yaml: leads outside the run folder \(to /dev/zero\)",
                     err), err


def test_export_refuses_an_alias_bomb_with_its_line(run_copy: Callable[[], Path],
                                                    capsys) -> None:
    run = run_copy()
    p = run / "scenario.resolved.yaml"
    p.write_text(ALIAS_BOMB + p.read_text())  # 8^9 values once expanded: was exported
    rc, err = _cli(capsys, "export", str(run), "--format", "kml")
    assert rc == 2
    assert re.search(r"scenario\.resolved\.yaml:8: more than 5000000 values once aliases are "
                     r"expanded", err), err


def test_export_checks_the_resolved_scenario_field_by_field(run_copy: Callable[[], Path],
                                                            capsys) -> None:
    run = run_copy()
    p = run / "scenario.resolved.yaml"
    text = p.read_text()
    assert "  lat_deg: 37.0\n" in text
    p.write_text(text.replace("  lat_deg: 37.0\n", "  lat_deg: .nan\n", 1))  # was 'nan' out
    rc, err = _cli(capsys, "export", str(run), "--format", "acmi")
    assert rc == 2
    assert re.search(r"scenario\.resolved\.yaml:6: origin\.lat_deg: expected a number from -90 "
                     r"to 90, got nan", err), err


@pytest.mark.parametrize("column,value,message", [
    ("time_s", 1e12, r"row 4: time_s is 1e\+12; expected 0 to 2592100$"),  # OverflowError
    ("lat_deg", 95.0, r"row 4: lat_deg is 95; expected -90 to 90 \(or NaN\)$"),
    ("alt_msl_m", float("inf"), r"row 4: alt_msl_m is inf; expected -1000000000 to 1000000000"),
])
def test_export_refuses_states_out_of_range_naming_the_row(
        run_copy: Callable[[], Path], capsys, column: str, value: float, message: str) -> None:
    run = run_copy()
    _set(run, column, 3, value)
    rc, err = _cli(capsys, "export", str(run), "--format", "kml")
    assert rc == 2
    assert re.search(re.escape(str(run / PART)) + ": " + message, err.strip()), err


def test_export_leaves_out_samples_whose_position_is_not_known(
        run_copy: Callable[[], Path], capsys) -> None:
    run = run_copy()
    _set(run, "alt_msl_m", 3, float("nan"))  # was written as 'nan' into the KML
    assert main(["export", str(run), "--format", "kml", "--rate-hz", "1000"]) == 0
    kml = (run / "track.kml").read_text()
    rows = read_states(run).num_rows
    assert "nan" not in kml and kml.count("<gx:coord>") == rows - 1


def test_export_names_a_missing_column(run_copy: Callable[[], Path], capsys) -> None:
    run = run_copy()
    pq.write_table(pq.read_table(run / PART).drop(["yaw_deg"]), run / PART)  # was KeyError
    rc, err = _cli(capsys, "export", str(run), "--format", "czml")
    assert rc == 2
    assert re.search(re.escape(str(run / PART)) + r": no column 'yaw_deg' \(this command reads "
                     r"time_s, vehicle, .*yaw_deg\)", err), err


def test_states_are_bounded_in_rows(run_copy: Callable[[], Path], capsys,
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Counted from the part's footer before it is read."""
    run = run_copy()
    monkeypatch.setattr("cosim.logs.runfolder.MAX_STATE_ROWS", 50)  # the run has 70
    rc, err = _cli(capsys, "plot", str(run))
    assert rc == 2
    assert re.search(re.escape(str(run / PART)) + ": the run's states hold more than 50 rows",
                     err), err


def test_export_writes_through_no_symlink_planted_at_its_temporary_file(
        run_copy: Callable[[], Path], tmp_path: Path) -> None:
    run = run_copy()
    secret = tmp_path / "outside" / "secret"
    secret.write_text("keep")
    for name in ("track.kml", "track.kml.part", "track.kml.tmp"):
        (run / name).symlink_to(secret)
    assert main(["export", str(run), "--format", "kml"]) == 0
    assert secret.read_text() == "keep"
    assert (run / "track.kml").is_file() and not (run / "track.kml").is_symlink()
    assert "<gx:Track>" in (run / "track.kml").read_text()


# -- cosim recover ------------------------------------------------------------------------
def _killed(run: Path) -> None:
    """Make the copy look like a killed run: its summary still says running."""
    s = json.loads((run / "summary.json").read_text())
    s.update(complete=False, stop_reason="running")
    (run / "summary.json").write_text(json.dumps(s))


def test_recover_never_reads_a_journal_that_leads_to_dev_zero(
        run_copy: Callable[[], Path], capsys) -> None:
    run = run_copy()
    _killed(run)
    (run / "states.parquet" / "_journal-000001.arrows").symlink_to("/dev/zero")  # StopIteration
    rc, err = _cli(capsys, "recover", str(run))
    assert rc == 2
    assert re.search(r"_journal-000001\.arrows: leads outside the run folder \(to /dev/zero\)",
                     err), err


def test_recover_never_reads_events_that_lead_to_dev_zero(run_copy: Callable[[], Path],
                                                          capsys) -> None:
    run = run_copy()
    _killed(run)
    _link(run / "events.jsonl", "/dev/zero")  # was read whole: MemoryError
    rc, err = _cli(capsys, "recover", str(run))
    assert rc == 2
    assert re.search(r"events\.jsonl: leads outside the run folder \(to /dev/zero\)", err), err


def test_recover_cuts_no_file_outside_the_folder(run_copy: Callable[[], Path],
                                                 tmp_path: Path, capsys) -> None:
    run = run_copy()
    _killed(run)
    outside = tmp_path / "outside" / "log.jsonl"
    outside.write_text('{"event": "a", "tick": 1}\n{"half a line')  # was cut back
    _link(run / "events.jsonl", outside)
    rc, err = _cli(capsys, "recover", str(run))
    assert rc == 2 and "events.jsonl: leads outside the run folder" in err
    assert outside.read_text().endswith('{"half a line')


def test_recover_rewrites_a_summary_nested_too_deep(run_copy: Callable[[], Path],
                                                    capsys) -> None:
    run = run_copy()
    (run / "summary.json").write_text("[" * 100_000 + "]" * 100_000)  # was RecursionError
    rc = main(["recover", str(run)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "found summary.json unreadable" in out and "nested more than 32 levels deep" in out
    s = json.loads((run / "summary.json").read_text())
    assert s["recovered"] is True and s["state_rows"] == 70 and s["ticks"] == 276


def test_recover_skips_and_reports_lines_that_are_not_events(run_copy: Callable[[], Path],
                                                             capsys) -> None:
    run = run_copy()
    _killed(run)
    with (run / "events.jsonl").open("a") as f:  # a tick of 401 digits: was OverflowError
        f.write('{"event": "stop", "tick": 1%s, "reason": "x"}\n[1, 2]\n' % ("0" * 400))
    rc = main(["recover", str(run)])
    out = capsys.readouterr().out
    assert rc == 0
    assert re.search(r"left out 2 line\(s\) of events\.jsonl that are not events \(the first: "
                     r".*events\.jsonl:4: tick: expected a whole number from 0 to", out), out
    s = json.loads((run / "summary.json").read_text())
    assert s["ticks"] == 276 and s["stop_reason"] == "completed"


# -- cosim plot ---------------------------------------------------------------------------
def test_plot_refuses_a_line_of_events_that_is_not_an_event(run_copy: Callable[[], Path],
                                                             capsys) -> None:
    run = run_copy()
    with (run / "events.jsonl").open("a") as f:
        f.write('["goal_reached", 5]\n')  # was TypeError
    rc, err = _cli(capsys, "plot", str(run))
    assert rc == 2
    assert re.search(r"events\.jsonl:4: expected an event \(a JSON object\), got "
                     r"\['goal_reached', 5\]", err), err


def test_plot_replaces_a_symlink_instead_of_writing_through_it(
        run_copy: Callable[[], Path], tmp_path: Path) -> None:
    run = run_copy()
    secret = tmp_path / "outside" / "secret.png"
    secret.write_bytes(b"keep")
    (run / "track.png").symlink_to(secret)  # savefig wrote through it
    assert main(["plot", str(run)]) == 0
    assert secret.read_bytes() == b"keep"
    assert (run / "track.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- cosim visibility ---------------------------------------------------------------------
def test_visibility_refuses_a_summary_nested_too_deep(run_copy: Callable[[], Path],
                                                      capsys) -> None:
    run = run_copy()
    (run / "summary.json").write_text("[" * 100_000 + "]" * 100_000)  # was RecursionError
    rc, err = _cli(capsys, "visibility", str(run))
    assert rc == 2
    assert re.search(r"summary\.json: nested more than 32 levels deep", err), err


def test_visibility_reads_no_ground_truth_outside_the_folder(
        run_copy: Callable[[], Path], tmp_path: Path, capsys) -> None:
    run = run_copy()
    outside = tmp_path / "outside" / "gt.csv"
    outside.write_text((run / "cameras" / "uav_nadir.gt.csv").read_text())
    s = json.loads((run / "summary.json").read_text())
    s["cameras"]["streams"][0]["ground_truth"] = "../outside/gt.csv"  # was read
    (run / "summary.json").write_text(json.dumps(s))
    rc, err = _cli(capsys, "visibility", str(run))
    assert rc == 2
    assert re.search(r"outside/gt\.csv: leads outside the run folder", err), err


@pytest.mark.parametrize("bad,message", [
    ('0,0.0,uav,nadir,"' + "x" * 200_000 + '",0\n',  # csv.Error: was a traceback
     r"uav_nadir\.gt\.csv:\d+: field larger than field limit"),
    ("1,nan,uav,nadir,truck,1\n", r"uav_nadir\.gt\.csv:\d+: time_s: expected 0 to 2592100 s, "
                                  r"got 'nan'"),
    ("1,0.1,uav,nadir,truck,7\n", r"uav_nadir\.gt\.csv:\d+: in_view: expected a whole number "
                                  r"from 0 to 1, got '7'"),
])
def test_visibility_names_the_line_of_a_bad_ground_truth_row(
        run_copy: Callable[[], Path], capsys, bad: str, message: str) -> None:
    run = run_copy()
    gt = run / "cameras" / "uav_nadir.gt.csv"
    lines = gt.read_text().splitlines(keepends=True)
    width = lines[0].count(",")
    gt.write_text("".join([*lines[:3], bad.rstrip("\n") + "," * (width - 5) + "\n", *lines[3:]]))
    rc, err = _cli(capsys, "visibility", str(run))
    assert rc == 2
    assert re.search(message, err), err


def test_visibility_writes_through_no_symlink_at_its_table(
        run_copy: Callable[[], Path], tmp_path: Path) -> None:
    run = run_copy()
    secret = tmp_path / "outside" / "secret.csv"
    secret.write_text("keep")
    (run / "visibility.csv.tmp").symlink_to(secret)  # write_csv wrote through it
    assert main(["visibility", str(run)]) == 0
    assert secret.read_text() == "keep"
    assert "uav,nadir,truck,1" in (run / "visibility.csv").read_text()


@pytest.mark.parametrize("change,message", [
    ({"scenario": None}, r"sweep\.json: scenario: expected the scenario's path"),  # KeyError
    ({"results": [{"run": "../elsewhere", "point": {}, "status": "completed",
                   "error": None}]}, r"results\[0\]\.run: expected a run folder's name"),
    ({"swept": {"speed_kt": [float("nan")]}}, r"swept: expected an object of lists of values"),
])
def test_visibility_checks_a_sweep_folder(tmp_path: Path, camera_run: Path, capsys,
                                          change: dict, message: str) -> None:
    sweep = {"scenario": "s.yaml", "runs": 1, "completed": 1, "wall_time_s": 1.0,
             "swept": {}, "results": [{"run": "run", "point": {}, "status": "completed",
                                       "error": None, "wall_s": 1.0}]}
    (tmp_path / "sweep").mkdir()
    (tmp_path / "sweep" / "sweep.json").write_text(json.dumps({**sweep, **change}))
    (tmp_path / "sweep" / "run").symlink_to(camera_run)  # (a run outside: refused too)
    rc, err = _cli(capsys, "visibility", str(tmp_path / "sweep"))
    assert rc == 2
    assert re.search(message, err), err
