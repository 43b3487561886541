"""visible_s and passes from synthetic ground-truth CSVs."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path

import pytest

from cosim.conspicuity import passes, read_ground_truth, run_visibility, visibility
from cosim.conspicuity.visibility import GroundTruthError, GtRow, write_visibility_csv

GT_COLUMNS = ("frame", "time_s", "vehicle", "camera", "target", "in_view", "fully_in_view",
              "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px", "center_x_px",
              "center_y_px", "eccentricity_px", "eccentricity_deg", "angular_size_deg",
              "pixels_on_target", "range_m", "contrast")


def write_gt(path: Path, in_view: dict[str, Sequence[int]], rate_hz: float = 10.0,
             ecc: dict[str, Sequence[float]] | None = None, t0_s: float = 0.0) -> Path:
    """A ground-truth CSV: target -> per-frame in_view flags (frames 0..n-1)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=GT_COLUMNS, restval="")
        w.writeheader()
        n = max(len(v) for v in in_view.values())
        for frame in range(n):
            for target, flags in in_view.items():
                e = ecc[target][frame] if ecc else 1.0
                w.writerow({"frame": frame, "time_s": f"{t0_s + frame / rate_hz:.6f}",
                            "vehicle": "uav", "camera": "nadir", "target": target,
                            "in_view": flags[frame], "eccentricity_deg": e if flags[frame] else "",
                            "range_m": 100.0})
    return path


def test_passes_are_maximal_runs_and_visible_s_counts_frames(tmp_path: Path) -> None:
    flags = [0, 1, 1, 1, 0, 0, 1, 1, 0, 1]
    gt = write_gt(tmp_path / "a.gt.csv", {"truck": flags, "car": [0] * 10}, rate_hz=10)
    res = {tv.target: tv for tv in visibility(gt, rate_hz=10)}
    truck = res["truck"]
    assert [(p.first_frame, p.last_frame, p.frames) for p in truck.passes] == \
        [(1, 3, 3), (6, 7, 2), (9, 9, 1)]
    assert [p.visible_s for p in truck.passes] == pytest.approx([0.3, 0.2, 0.1])
    assert truck.visible_s == pytest.approx(0.6)
    assert truck.first_visible_s == pytest.approx(0.1)
    assert truck.last_visible_s == pytest.approx(0.9)
    assert truck.passes[0].last_visible_s == pytest.approx(0.3)
    car = res["car"]
    assert car.passes == () and car.visible_s == 0 and car.first_visible_s is None


def test_frame_period_from_times_when_rate_not_given(tmp_path: Path) -> None:
    gt = write_gt(tmp_path / "a.gt.csv", {"truck": [1, 1, 1, 1, 0]}, rate_hz=30)
    (tv,) = visibility(gt)
    assert tv.frame_period_s == pytest.approx(1 / 30, rel=1e-5)  # times have 6 decimals
    assert tv.visible_s == pytest.approx(4 / 30, rel=1e-5)


def test_a_missing_frame_splits_a_pass(tmp_path: Path) -> None:
    gt = write_gt(tmp_path / "a.gt.csv", {"truck": [1, 1, 1, 1, 1]})
    rows = read_ground_truth(gt)[("uav", "nadir", "truck")]
    del rows[2]
    assert [p.frames for p in passes(rows, 0.1)] == [2, 2]


def test_overhead_frame_is_least_eccentricity(tmp_path: Path) -> None:
    ecc = [9.0, 5.0, 1.0, 0.2, 3.0, 8.0]
    gt = write_gt(tmp_path / "a.gt.csv", {"t": [0, 1, 1, 1, 1, 1]}, ecc={"t": ecc}, t0_s=2.0)
    (tv,) = visibility(gt, rate_hz=10)
    (p,) = tv.passes
    assert p.overhead_frame == 3 and p.overhead_s == pytest.approx(2.3)
    assert p.min_eccentricity_deg == pytest.approx(0.2)


@pytest.mark.parametrize("alt_m,speed_mps,rate_hz", [(30, 25.7, 10), (300, 102.9, 30),
                                                     (500, 51.4, 15)])
def test_straight_pass_formula_within_one_frame(tmp_path: Path, alt_m: float,
                                                speed_mps: float, rate_hz: float) -> None:
    """The frame-count convention of ``visible_s`` against the formula, on
    synthetic flags (in view while the target's extent overlaps the footprint):
    it fails if ``visible_s`` counted the interval differently (last - first,
    or without the frame period). The rendered pass is checked end to end in
    test_visibility_rendered.py."""
    vfov_deg, length_m = 40.0, 8.0
    half_m = alt_m * math.tan(math.radians(vfov_deg / 2))
    x0_m = -(half_m + length_m / 2 + 3 * speed_mps)  # 3 s before entry
    n = int(2 * -x0_m / speed_mps * rate_hz) + 1
    flags = [int(abs(x0_m + speed_mps * f / rate_hz) < half_m + length_m / 2) for f in range(n)]
    gt = write_gt(tmp_path / "a.gt.csv", {"truck": flags}, rate_hz=rate_hz)
    (tv,) = visibility(gt, rate_hz=rate_hz)
    expected_s = (2 * alt_m * math.tan(math.radians(vfov_deg / 2)) + length_m) / speed_mps
    assert abs(tv.visible_s - expected_s) <= 1 / rate_hz
    assert len(tv.passes) == 1


def test_run_folder_uses_summary_cameras_and_writes_csv(tmp_path: Path) -> None:
    run = tmp_path / "run"
    write_gt(run / "cameras" / "uav_nadir.gt.csv", {"truck": [0, 1, 1, 0]}, rate_hz=10)
    (run / "summary.json").write_text(json.dumps({
        "physics_hz": 120,
        "cameras": [{"vehicle": "uav", "camera": "nadir", "video": "cameras/uav_nadir.mkv",
                     "ground_truth": "cameras/uav_nadir.gt.csv", "frames": 4, "rate_hz": 10,
                     "width_px": 64, "height_px": 48, "hfov_deg": 50, "vfov_deg": 40}]}))
    (tv,) = run_visibility(run)
    assert tv.visible_s == pytest.approx(0.2)
    out = write_visibility_csv(run)
    rows = list(csv.DictReader(out.open()))
    assert rows[0]["target"] == "truck" and rows[0]["pass"] == "1"
    assert float(rows[0]["visible_s"]) == pytest.approx(0.2)
    assert rows[0]["overhead_tick"] in ("12", "24")


def test_not_a_ground_truth_file(tmp_path: Path) -> None:
    bad = tmp_path / "x.gt.csv"
    bad.write_text("frame,time_s\n0,0\n")
    with pytest.raises(GroundTruthError, match=r"x.gt.csv: not a ground-truth file: missing "
                                               r"column\(s\) vehicle, camera, target, in_view"):
        visibility(bad)
    with pytest.raises(GroundTruthError, match="cannot read ground truth"):
        visibility(tmp_path / "missing.csv")


@pytest.mark.parametrize("xs,ys,way", [
    ((100, 101, 102), (10, 60, 110), "down"), ((100, 99, 97), (110, 60, 10), "up"),
    ((10, 60, 110), (50, 52, 49), "right"), ((110, 60, 10), (50, 47, 52), "left"),
    ((50, 50), (50, 50), ""),
])
def test_screen_direction_is_the_larger_move_of_the_centre(xs, ys, way) -> None:
    nan = float("nan")
    rows = [GtRow(frame=i, time_s=i / 10, in_view=True, center_x_px=x, center_y_px=y)
            for i, (x, y) in enumerate(zip(xs, ys))]
    rows.insert(0, GtRow(frame=-1, time_s=-0.1, in_view=True, center_x_px=nan,
                         center_y_px=nan))  # the centre unknown (clipped): skipped
    [p] = passes(rows, 0.1)
    assert p.screen_direction == way
