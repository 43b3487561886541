"""cosim sweep: 2 x 2 short runs in parallel, their folders and tables."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import pytest

from cosim.cli import main
from tests.conspicuity.test_visibility import write_gt

SCENARIO = """\
schema_version: 1
origin: {lat_deg: 37, lon_deg: -116, ground_alt_m: 1000}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 0.5
sweep:
  speed_kt: [60, 100]
  target: [truck, fire_truck]
  alt_agl_m: 80
vehicles:
  - {id: uav, model: uav700, init: {alt_agl_m: ${alt_agl_m}, heading_deg: 0,
                                    airspeed_kt: ${speed_kt}}}
schedule:
  - {at_s: 0, vehicles: uav, command: {airspeed_kt: ${speed_kt}, alt_agl_m: ${alt_agl_m}}}
name: ${target}
"""

FOLDERS = ["speed_kt=60,target=truck", "speed_kt=60,target=fire_truck",
           "speed_kt=100,target=truck", "speed_kt=100,target=fire_truck"]


def _rows(p: Path) -> list[dict[str, str]]:
    with p.open() as f:
        return list(csv.DictReader(f))


@pytest.mark.integration
def test_sweep_2x2_runs_every_combination(tmp_path: Path, capsys) -> None:
    scn = tmp_path / "sweep.yaml"
    scn.write_text(SCENARIO)
    out = tmp_path / "out"
    assert main(["sweep", str(scn), "--out", str(out), "--jobs", "2"]) == 0
    assert "4 of 4 runs completed" in capsys.readouterr().out
    for name in FOLDERS:
        s = json.loads((out / name / "summary.json").read_text())
        assert s["stop_reason"] == "completed" and s["backend"] == "inline"
        assert s["scenario"] == name.split("target=")[1]  # the placeholder reached the run
    sweep = json.loads((out / "sweep.json").read_text())
    assert [r["run"] for r in sweep["results"]] == FOLDERS
    assert sweep["swept"] == {"speed_kt": [60, 100], "target": ["truck", "fire_truck"]}
    # the runs had no cameras: empty tables with the right columns
    with (out / "visibility.csv").open() as f:
        header = next(csv.reader(f))
    assert header[:7] == ["speed_kt", "target", "alt_agl_m", "visible_s", "first_visible_s",
                          "last_visible_s", "passes"]
    assert header.count("target") == 1 and header.count("speed_kt") == 1

    # a second sweep into the same folder needs --overwrite
    assert main(["sweep", str(scn), "--out", str(out)]) == 2
    assert "already holds a sweep" in capsys.readouterr().err

    # give every run a camera's ground truth (as the renderer writes it) and
    # rebuild the tables with `cosim visibility SWEEP_DIR`
    flags = {"speed_kt=60": [0, 1, 1, 1, 1, 0], "speed_kt=100": [0, 0, 1, 1, 0, 0]}
    for name in FOLDERS:
        write_gt(out / name / "cameras" / "uav_nadir.gt.csv",
                 {"truck": flags[name.split(",")[0]]}, rate_hz=10)
        (out / name / "cameras" / "uav_nadir.mkv").write_bytes(b"")
        s = json.loads((out / name / "summary.json").read_text())
        s["cameras"] = [{"vehicle": "uav", "camera": "nadir", "video": "cameras/uav_nadir.mkv",
                         "ground_truth": "cameras/uav_nadir.gt.csv", "frames": 6,
                         "rate_hz": 10, "width_px": 64, "height_px": 48, "hfov_deg": 50,
                         "vfov_deg": 40}]
        (out / name / "summary.json").write_text(json.dumps(s))
    assert main(["visibility", str(out)]) == 0
    vis = _rows(out / "visibility.csv")
    assert [(r["speed_kt"], r["target"], r["visible_s"], r["first_visible_s"],
             r["last_visible_s"]) for r in vis] == [
        ("60", "truck", "0.4", "0.1", "0.4"), ("60", "fire_truck", "0.4", "0.1", "0.4"),
        ("100", "truck", "0.2", "0.2", "0.3"), ("100", "fire_truck", "0.2", "0.2", "0.3")]
    assert float(vis[0]["alt_agl_m"]) == pytest.approx(80, abs=2)  # measured, not swept
    # the ground speed flown while in view, beside the commanded (swept) one, and the
    # flag when they differ by more than 1%, checked against the states themselves
    from cosim.logs import read_states

    for r in vis:
        t = read_states(out / r["run"]).to_pydict()
        win = [i for i, ts in enumerate(t["time_s"])
               if float(r["first_visible_s"]) - 1e-9 <= ts <= float(r["last_visible_s"]) + 1e-9]
        gs = sum(math.hypot(t["vn_mps"][i], t["ve_mps"][i]) for i in win) / len(win) / 0.514444
        assert float(r["flown_speed_kt"]) == pytest.approx(gs, abs=0.01)
        assert r["speed_off"] == ("true" if abs(gs - float(r["speed_kt"])) >
                                  0.01 * float(r["speed_kt"]) else "false")
    assert vis[1]["target_id"] == "truck" and vis[1]["run"] == FOLDERS[1]
    man = _rows(out / "manifest.csv")
    assert [r["run"] for r in man] == FOLDERS
    assert man[0]["video"] == f"{FOLDERS[0]}/cameras/uav_nadir.mkv"
    assert man[0]["ground_truth"] == f"{FOLDERS[0]}/cameras/uav_nadir.gt.csv"
    assert (man[3]["speed_kt"], man[3]["target"], man[3]["camera"]) == \
        ("100", "fire_truck", "nadir")

    # cosim visibility on one run folder: per-pass table
    assert main(["visibility", str(out / FOLDERS[2])]) == 0
    printed = capsys.readouterr().out
    assert "uav/nadir truck pass 1: visible 0.2 s (t = 0.2 .. 0.3 s, 2 frames)" in printed
    assert _rows(out / FOLDERS[2] / "visibility.csv")[0]["overhead_tick"] in ("24", "36")


def test_sweep_config_errors_before_any_run(tmp_path: Path, capsys) -> None:
    scn = tmp_path / "bad.yaml"
    scn.write_text(SCENARIO.replace("airspeed_kt: ${speed_kt}}}\nschedule",
                                    "airspeed_kt: ${speed * 2}}}\nschedule"))
    assert main(["sweep", str(scn), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{scn}:11: vehicles[0].init.airspeed_kt: cannot substitute ${{speed * 2}}: " \
           f"unknown name 'speed'" in err
    assert not (tmp_path / "o").exists()
    assert main(["sweep", str(scn), "--out", str(tmp_path / "o"), "--jobs", "0"]) == 2


def test_visibility_needs_a_run_folder(tmp_path: Path, capsys) -> None:
    assert main(["visibility", str(tmp_path)]) == 2
    assert "not a cosim run or sweep folder" in capsys.readouterr().err
    shutil.rmtree(tmp_path)
