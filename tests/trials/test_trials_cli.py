"""`cosim trials` from the command line: analyse a synthetic responses file
made from known critical gaps (examples/trials_synthetic.py) and find them;
refuse to listen beyond this machine without --public."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import main

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.integration
def test_analyse_finds_the_critical_gaps_the_responses_were_made_with(tmp_path: Path,
                                                                    capsys) -> None:
    csv_path = tmp_path / "responses.csv"
    subprocess.run([sys.executable, str(REPO / "examples" / "trials_synthetic.py"), "--out",
                    str(csv_path)], check=True, capture_output=True)
    assert main(["-q", "trials", "analyse", str(csv_path), "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    got = {m[0]: (float(m[1]), float(m[2])) for m in
           re.findall(r"critical gap, (\w+): plateau: CG ([\d.]+) mm .*?d0 = (\d+) mm", out)}
    assert set(got) == {"truck", "fire_truck"}
    assert abs(got["truck"][0] - 40.0) < 1.5 and abs(got["fire_truck"][0] - 60.0) < 2.0
    assert all(abs(d0 - 600.0) <= 20.0 for _, d0 in got.values())
    alt = re.search(r"alt_per_100m: ([+-][\d.]+)", out)
    assert alt is not None and -1.6 < float(alt.group(1)) < -0.9  # made with -1.2
    for name in ("conspicuity.csv", "critical_gap.png", "recognition.png", "analysis.json"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    ground = re.search(r"critical gap, truck \(ground\): plateau: CG ([\d.]+) m .*holds at "
                       r"(\d+) of (\d+)", out)
    assert ground is not None and abs(float(ground[1]) - 12.0) < 1.0, out  # made with 12 m
    assert ground[2] == ground[3]
    # a stricter tolerance asks more of the same data: no longer shown constant
    assert main(["-q", "trials", "analyse", str(csv_path), "--out", str(tmp_path / "b"),
                 "--tolerance", "0.02"]) == 0
    assert "critical gap, truck: inconclusive" in capsys.readouterr().out
    assert main(["-q", "trials", "analyse", str(csv_path), "--out", str(tmp_path / "c"),
                 "--tolerance", "0"]) == 2
    assert "tolerance must be in (0, 1]" in capsys.readouterr().err


def test_serve_refuses_other_machines_without_public(tmp_path: Path, capsys) -> None:
    study = tmp_path / "s.yaml"
    study.write_text("schema_version: 1\nname: s\nprotocol: disappear\nclips: []\n")
    assert main(["-q", "trials", "serve", str(study), "--host", "0.0.0.0"]) == 2
    assert "--public" in capsys.readouterr().err


@pytest.mark.integration
def test_tracked_dot_responses_are_conspicuity_angles_too(tmp_path: Path, capsys) -> None:
    """The "track" protocol's angles (from the dot the eyes follow) are
    analysed as the fixation protocol's: the same gaps come out."""
    src = tmp_path / "responses.csv"
    subprocess.run([sys.executable, str(REPO / "examples" / "trials_synthetic.py"), "--out",
                    str(src)], check=True, capture_output=True)
    tracked = tmp_path / "tracked.csv"
    tracked.write_text(src.read_text().replace(",disappear,", ",track,"))
    assert ",track," in tracked.read_text()
    assert main(["-q", "trials", "analyse", str(tracked), "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"critical gap, truck: plateau: CG 39\.\d mm", out), out


def test_a_studys_default_database_is_kept_out_of_the_repository() -> None:
    """`cosim trials serve studies/exp2.yaml` (the README's) writes participants'
    responses to studies/exp2.sqlite and SQLite's files beside it: git ignores
    them all, so `git add` cannot publish them."""
    from cosim.trials.server import default_db

    if not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    db = default_db(REPO / "studies" / "exp2.yaml")
    assert db == REPO / "studies" / "exp2.sqlite"
    for name in (db.name, f"{db.name}-wal", f"{db.name}-shm", f"{db.name}-journal"):
        path = db.with_name(name).relative_to(REPO)
        r = subprocess.run(["git", "-C", str(REPO), "check-ignore", "--no-index", "-q",
                            str(path)], check=False)
        assert r.returncode == 0, f"git does not ignore {path}"
