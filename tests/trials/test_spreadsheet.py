"""CSV injection: text a spreadsheet would run as a formula is neutralised in
every CSV the trials commands write (the analysis' tables, the export), and
numbers stay numbers."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.trials.analysis import analyse
from cosim.trials.spreadsheet import FORMULA_START, safe_cell
from cosim.trials.store import Store
from tests.trials.test_analysis import _exp1_rows, _exp2_rows, _write
from tests.trials.test_store import DISPLAY, _response

FORMULAS = ["=HYPERLINK(\"http://x\",\"y\")", "+1+cmd|' /C calc'!A0", "-2+3", "@SUM(A1:A9)",
            "\t=1+1", "\r=1+1", "=", "-", "- 5", "-1.5.2", "-inf", "-nan"]
NUMBERS = ["-1.5", "+2e-3", "-0", "-.5", "-3.", "1e5", "-1E+300", "12", "0.25"]


@pytest.mark.parametrize("cell", FORMULAS)
def test_a_formula_gets_a_leading_quote(cell: str) -> None:
    assert safe_cell(cell) == "'" + cell


@pytest.mark.parametrize("cell", NUMBERS + ["truck", "p01", "'=already", " =x", "a=b", ""])
def test_numbers_and_plain_text_are_left_alone(cell: str) -> None:
    assert safe_cell(cell) == cell


def _cells(path: Path) -> list[str]:
    with open(path, newline="") as f:
        return [c for row in csv.reader(f) for c in row]


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def test_analysis_tables_hold_no_formula(tmp_path: Path) -> None:
    """Targets and participants named as formulas: every table the analysis
    writes holds them quoted; its negative numbers (slopes, differences,
    logistic coefficients) are still numbers."""
    target = "=HYPERLINK(\"http://x\",\"y\")"
    rows = _exp1_rows(seed=4, trials=6, targets=(target,))
    for r in rows:
        r["participant"] = "@" + r["participant"]
    rec = _exp2_rows(seed=4, reps=6)
    for r in rec:
        r["condition_target"] = "-cmd"
    src = _write(tmp_path / "r.csv", rows + rec)
    analyse(src, tmp_path / "out", n_boot=20, plots=False)
    negative = 0
    for name in ("conspicuity.csv", "critical_gap.csv", "critical_gap_check.csv",
                 "recognition.csv"):
        cells = _cells(tmp_path / "out" / name)
        bad = [c for c in cells if c.startswith(FORMULA_START) and not _is_number(c)]
        assert not bad, (name, bad[:5])
        negative += sum(c.startswith("-") and _is_number(c) for c in cells)
    assert negative > 0  # numbers are not quoted
    assert "'" + target in _cells(tmp_path / "out" / "conspicuity.csv")
    assert "'-cmd" in _cells(tmp_path / "out" / "recognition.csv")


def test_export_holds_no_formula_and_keeps_numbers(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A participant id and a target typed as formulas are exported quoted; a
    negative number (a condition, a time) is exported as it was; the export
    analyses as before."""
    db = tmp_path / "t.sqlite"
    who = "=cmd|' /C calc'!A0"
    with Store(db) as store:
        s = store.create_session(participant=who, study="s", protocol="disappear",
                                 display=DISPLAY, order_method="shuffle", seed=1,
                                 session_number=0, trial_order=[{"index": 0}, {"index": 1}])
        store.record_response(_response(s["id"], 1, participant=who, condition_target="@x",
                                        condition_speed_kt="-5", video_time_s=-0.5))
    out = tmp_path / "responses.csv"
    assert main(["-q", "trials", "export", str(db), "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    with open(out, newline="") as f:
        row = next(csv.DictReader(f))
    assert (row["participant"], row["condition_target"]) == ("'" + who, "'@x")
    assert (row["condition_speed_kt"], row["video_time_s"]) == ("-5", "-0.5")
    # the experimenter's download (the server's /api/export.csv) writes the same
    from cosim.trials.store import export_csv

    again = export_csv(db, tmp_path / "download.csv")
    assert again.read_text() == out.read_text()
    assert main(["-q", "trials", "analyse", str(out), "--out", str(tmp_path / "a")]) == 2
    assert "condition_speed_kt: expected a value in [0, 10000], got '-5'" in \
        capsys.readouterr().err  # read back as the number it is
