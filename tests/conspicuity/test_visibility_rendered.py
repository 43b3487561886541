"""End to end: experiment 2's scenario rendered, visible_s against the formula."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.conspicuity import run_visibility
from cosim.sweep.runner import load_point
from cosim.sweep.spec import read_sweep
from cosim.sync import Run

REPO = Path(__file__).resolve().parents[2]
EXP2 = REPO / "scenarios" / "conspicuity" / "altitude_speed.yaml"


def _point(**values: object) -> dict:
    point = dict(read_sweep(EXP2).points()[0])
    point.update(width_px=64, height_px=48, static=True, **values)  # small and short
    return point


@pytest.mark.parametrize("speed_kt,alt_agl_m", [(200, 30), (100, 100), (50, 30)])
def test_straight_pass_visible_s_matches_formula(tmp_path: Path, speed_kt: int,
                                                 alt_agl_m: int) -> None:
    point = _point(speed_kt=speed_kt, alt_agl_m=alt_agl_m)
    scn = load_point(EXP2, point)
    res = Run(scn, tmp_path / "run", backend="inline").run()
    assert res.stop_reason == "completed", res.error
    (tv,) = run_visibility(tmp_path / "run")
    vfov, length_m = float(point["vfov_deg"]), float(point["target_length_m"])
    v_mps = speed_kt * 1852 / 3600
    expected_s = (2 * alt_agl_m * math.tan(math.radians(vfov / 2)) + length_m) / v_mps
    assert len(tv.passes) == 1
    assert abs(tv.visible_s - expected_s) <= tv.frame_period_s, (tv.visible_s, expected_s)
    # the static clip: the target enters the view 1 s after the start (within a frame)
    assert tv.first_visible_s == pytest.approx(1.0, abs=tv.frame_period_s + 1e-9)


@pytest.mark.integration
def test_sweep_with_cameras_2x2(tmp_path: Path, capsys) -> None:
    scn = tmp_path / "exp2_small.yaml"
    text = EXP2.read_text()
    for a, b in [("speed_kt: [50, 100, 200]", "speed_kt: [100, 200]"),
                 ("alt_agl_m: [30, 100, 200, 250, 300, 500]", "alt_agl_m: [30, 60]"),
                 ("target: [truck, fire_truck]", "target: fire_truck"),
                 ("static: false", "static: true"), ("width_px: 640", "width_px: 64"),
                 ("height_px: 480", "height_px: 48")]:
        assert a in text
        text = text.replace(a, b)
    scn.write_text(text)
    out = tmp_path / "exp2"
    assert main(["sweep", str(scn), "--out", str(out), "--jobs", "2"]) == 0
    with (out / "visibility.csv").open() as f:
        vis = list(csv.DictReader(f))
    assert [(r["speed_kt"], r["alt_agl_m"]) for r in vis] == \
        [("100", "30"), ("100", "60"), ("200", "30"), ("200", "60")]
    for r in vis:
        v_mps = float(r["speed_kt"]) * 1852 / 3600
        h = float(r["alt_agl_m"])
        expected_s = (2 * h * math.tan(math.radians(37.6 / 2)) + 10) / v_mps
        assert abs(float(r["visible_s"]) - expected_s) <= 1 / 30
        assert r["target"] == "fire_truck" and r["camera"] == "nadir"
    with (out / "manifest.csv").open() as f:
        man = list(csv.DictReader(f))
    assert len(man) == 4
    for m in man:
        assert (out / m["video"]).is_file() and (out / m["ground_truth"]).is_file()
        assert m["run"] == f"speed_kt={m['speed_kt']},alt_agl_m={m['alt_agl_m']}"
    assert json.loads((out / "sweep.json").read_text())["completed"] == 4
