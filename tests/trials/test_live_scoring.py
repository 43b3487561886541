"""cosim.trials.live_scoring: hits, pixel errors and latencies of a synthetic
live session equal those computed independently from the targets' paths; a
false alarm, a duplicate and a miss are scored as such; the downlink's
delivered frames are the ones shown; bad reports and settings are refused."""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.renderer.datalink import DELIVERED_COLUMNS
from cosim.renderer.truth import GT_COLUMNS
from cosim.scenario.reader import Problems
from cosim.trials.live_scoring import (
    FeedBounds,
    Report,
    ReportError,
    ScoringSettings,
    feed_bounds,
    parse_report,
    read_scoring,
    score_session,
    score_stored,
    stored_reports,
)
from cosim.trials.live_truth import (
    SessionTruth,
    TargetFrame,
    combine,
    read_feed_truth,
    read_run_truth,
)

RATE_HZ = 10.0
FRAMES = 100
W, H = 640, 360


Path3 = Callable[[int], tuple[float, float, float]]


def _path(x0: float, y0: float, vx: float, vy: float, half: float) -> Path3:
    """A target's box centre and half size in frame f: x0 + vx f, y0 + vy f."""
    return lambda f: (x0 + vx * f, y0 + vy * f, half)


def gt_rows(feed_targets: dict[str, Any], link_every: int = 0) -> list[dict[str, str]]:
    """The ground-truth CSV rows of one feed: each target (name -> (path,
    first frame, last frame in view, frames with too few pixels)) over FRAMES
    frames; with ``link_every``, a downlink delivering every so many frames
    50 ms late."""
    rows = []
    for f in range(FRAMES):
        for name, (path, a, b, faint) in feed_targets.items():
            cx, cy, half = path(f)
            on = a <= f <= b
            r: dict[str, Any] = dict.fromkeys(GT_COLUMNS, "")
            r.update(frame=str(f), time_s=f"{f / RATE_HZ:.6f}", vehicle="v", camera="c",
                     target=name, in_view="1" if on else "0", fully_in_view="1" if on else "0",
                     bbox_x0_px=cx - half, bbox_y0_px=cy - half, bbox_x1_px=cx + half,
                     bbox_y1_px=cy + half, center_x_px=cx, center_y_px=cy,
                     pixels_on_target=(2 if f in faint else 40) if on else 0,
                     visible_fraction=1.0 if on else "")
            if link_every:
                sent = f % link_every == 0
                r.update(delivered_time_s=f"{f / RATE_HZ + 0.05:.6f}" if sent else "",
                         delivered_pixels_on_target=r["pixels_on_target"] if sent else "",
                         delivered_contrast="")
            rows.append({k: str(v) for k, v in r.items()})
    return rows


def write_gt(path: Path, rows: list[dict[str, str]]) -> Path:
    cols = list(GT_COLUMNS) + (list(DELIVERED_COLUMNS) if "delivered_time_s" in rows[0] else [])
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, cols)
        w.writeheader()
        w.writerows(rows)
    return path


A = _path(100.0, 100.0, 2.0, 1.0, 6.0)   # feed 1 frames 20-60 (20-22 faint), feed 2 15-50
A2 = _path(500.0, 300.0, -3.0, -1.0, 6.0)
B = _path(300.0, 200.0, 0.0, 0.5, 5.0)   # feed 2 frames 30-80
C = _path(50.0, 300.0, 1.0, 0.0, 4.0)    # feed 1 frames 10-14: 0.5 s, too short to miss
D = _path(400.0, 60.0, -1.0, 0.0, 8.0)   # feed 2 frames 40-70, never reported: a miss


@pytest.fixture
def truth(tmp_path: Path) -> SessionTruth:
    f1 = write_gt(tmp_path / "f1.gt.csv", gt_rows({
        "A": (A, 20, 60, {20, 21, 22}), "C": (C, 10, 14, set())}))
    f2 = write_gt(tmp_path / "f2.gt.csv", gt_rows({
        "A": (A2, 15, 50, set()), "B": (B, 30, 80, set()), "D": (D, 40, 70, set())}))
    return combine([read_feed_truth(f1, "u1/cam"), read_feed_truth(f2, "u2/cam")])


def test_hits_errors_latencies_equal_the_paths(truth: SessionTruth) -> None:
    ax, ay, _ = A(35)
    bx, by, bh = B(50)
    reports = [
        Report("u1/cam", 35, ax + 3, ay + 4, 3.9),         # hit A, 5 px off
        Report("u2/cam", 40, *A2(40)[:2], 4.5),             # A again: a duplicate
        Report("u2/cam", 50, bx + bh + 7, by, 5.3),         # B, 7 px outside its box
        Report("u1/cam", 50, 600.0, 20.0, 5.5),             # nothing there: false alarm
    ]
    sc = score_session(truth, reports)
    out = [(r.outcome, r.target) for r in sc.reports]
    assert out == [("hit", "A"), ("duplicate", "A"), ("hit", "B"), ("false_alarm", None)]
    a, dup, b, _ = sc.reports
    # A: visible in feed 1 from frame 23 (20-22 have 2 px < 4), in feed 2 from frame 15
    assert a.error_px == pytest.approx(5.0)
    assert a.latency_feed_s == pytest.approx(3.9 - 2.3)
    assert a.latency_any_s == pytest.approx(3.9 - 1.5)
    assert dup.error_px == pytest.approx(0.0) and dup.latency_any_s is None
    assert b.error_px == pytest.approx(bh + 7)
    assert b.latency_feed_s == pytest.approx(5.3 - 3.0) == b.latency_any_s
    by_name = {t.target: t for t in sc.targets}
    assert [t.target for t in sc.misses] == ["D"]
    assert by_name["D"].visible_s == pytest.approx(3.1)  # frames 40-70
    assert not by_name["C"].eligible and by_name["C"].visible_s == pytest.approx(0.5)
    assert by_name["A"].visible_s == pytest.approx(3.8)  # feed 1's 23-60 beats feed 2's 15-50
    assert (sc.count("hit"), sc.count("duplicate"), sc.count("false_alarm")) == (2, 1, 1)


def test_tolerance_window_and_visibility_settings(truth: SessionTruth) -> None:
    bx, by, bh = B(50)
    outside = Report("u2/cam", 50, bx + bh + 7, by, 5.3)
    assert score_session(truth, [outside], ScoringSettings(tolerance_px=6.0)
                         ).reports[0].outcome == "false_alarm"
    for dx, dy in ((-1, 0), (0, -1), (0, 1)):  # each side: within the tolerance, then past it
        sides = [Report("u2/cam", 50, bx + dx * (bh + d), by + dy * (bh + d), 5.3)
                 for d in (9.9, 10.1)]
        assert [r.outcome for r in score_session(truth, sides).reports] == ["hit",
                                                                             "false_alarm"]
    again = [Report("u2/cam", 50, bx, by, 5.3), Report("u2/cam", 75, *B(75)[:2], 8.0)]
    assert [r.outcome for r in score_session(truth, again).reports] == ["hit", "duplicate"]
    windowed = score_session(truth, again, ScoringSettings(duplicate_window_s=2.0)).reports
    assert [r.outcome for r in windowed] == ["hit", "hit"]
    assert windowed[1].latency_any_s == pytest.approx(8.0 - 3.0)  # from its first visibility
    # with no reports every target visible long enough is a miss: A 3.8 s, B 5.1 s, D 3.1 s
    assert [t.target for t in score_session(truth, []).misses] == ["A", "B", "D"]
    assert [t.target for t in score_session(truth, [], ScoringSettings(min_visible_s=4.0)
                                            ).misses] == ["B"]
    # with 1 px enough, A is visible in feed 1 from frame 20
    a = score_session(truth, [Report("u1/cam", 35, *A(35)[:2], 3.9)],
                      ScoringSettings(min_pixels_on_target=1)).reports[0]
    assert a.latency_feed_s == pytest.approx(3.9 - 2.0)


def test_click_before_visibility_has_no_latency(truth: SessionTruth) -> None:
    """A hit on a frame where the target is in view but not yet visible
    enough (too few pixels) has no latency in that feed."""
    r = score_session(truth, [Report("u1/cam", 21, *A(21)[:2], 2.2)]).reports[0]
    assert r.outcome == "hit" and r.latency_feed_s is None
    assert r.latency_any_s == pytest.approx(2.2 - 1.5)  # seen in feed 2 since 1.5 s


def test_nearest_centre_of_overlapping_boxes(tmp_path: Path) -> None:
    p = write_gt(tmp_path / "o.gt.csv", gt_rows({
        "near": (_path(200.0, 200.0, 0, 0, 20.0), 0, 99, set()),
        "far": (_path(215.0, 200.0, 0, 0, 20.0), 0, 99, set())}))
    t = read_feed_truth(p, "f")
    r = score_session(t, [Report("f", 5, 205.0, 200.0, 1.0)]).reports[0]
    assert (r.target, r.error_px) == ("near", pytest.approx(5.0))
    r = score_session(t, [Report("f", 5, 210.0, 200.0, 1.0)]).reports[0]
    assert (r.target, r.error_px) == ("far", pytest.approx(5.0))


def test_downlink_shows_delivered_frames_only(tmp_path: Path) -> None:
    p = write_gt(tmp_path / "l.gt.csv", gt_rows({"B": (B, 30, 80, set())}, link_every=3))
    t = read_feed_truth(p, "f")
    assert set(t.frames["f"]) == set(range(0, FRAMES, 3))
    assert t.frames["f"][30] == pytest.approx(3.05)
    sc = score_session(t, [Report("f", 45, *B(45)[:2], 6.0)])
    # first delivered frame in view: 30, on screen at 3.05 s
    assert sc.reports[0].latency_feed_s == pytest.approx(6.0 - 3.05)
    assert sc.targets[0].visible_s == pytest.approx(17 * 0.3)  # frames 30, 33, ..., 78
    with pytest.raises(ReportError, match="frame 46 of f is not in the session's ground truth"):
        score_session(t, [Report("f", 46, *B(46)[:2], 6.0)])


def test_random_sessions_against_brute_force(tmp_path: Path) -> None:
    """Random boxes and clicks: each report's outcome, target and error as
    a brute force over the boxes (numpy) finds them."""
    rng = np.random.default_rng(5)
    spec: dict[str, Any] = {}
    for k in range(6):
        a = int(rng.integers(0, 60))
        x0, y0 = rng.uniform(50, 300, 2)
        vx, vy = rng.uniform(-1, 1, 2)
        spec[f"t{k}"] = (_path(x0, y0, vx, vy, float(rng.uniform(3, 15))), a,
                         a + int(rng.integers(5, 40)), set())
    t = read_feed_truth(write_gt(tmp_path / "r.gt.csv", gt_rows(spec)), "f")
    clicks = [(int(rng.integers(0, FRAMES)), *rng.uniform(0, 400, 2)) for _ in range(300)]
    reports = [Report("f", f, x, y, 100.0 + i) for i, (f, x, y) in enumerate(clicks)]
    sc = score_session(t, reports, ScoringSettings(tolerance_px=4.0))
    names = sorted(spec)
    hit_before: set[str] = set()
    for (f, x, y), got in zip(clicks, sc.reports):
        c = np.array([spec[n][0](f) for n in names])  # cx, cy, half
        on = np.array([spec[n][1] <= f <= spec[n][2] for n in names])
        inside = on & (np.abs(x - c[:, 0]) <= c[:, 2] + 4) & (np.abs(y - c[:, 1]) <= c[:, 2] + 4)
        if not inside.any():
            assert got.outcome == "false_alarm"
            continue
        d = np.where(inside, np.hypot(x - c[:, 0], y - c[:, 1]), np.inf)
        k = int(np.argmin(d))
        assert got.target == names[k] and got.error_px == pytest.approx(d[k])
        assert got.outcome == ("duplicate" if names[k] in hit_before else "hit")
        hit_before.add(names[k])


def test_bad_reports_refused() -> None:
    feeds = {"u1/cam": FeedBounds(0, 99, W, H)}
    ok = {"feed": "u1/cam", "frame": 3, "x_px": 10.0, "y_px": 20, "time_s": 1.5}
    assert parse_report(ok, feeds, 60.0) == Report("u1/cam", 3, 10.0, 20.0, 1.5)
    bad = [({**ok, "feed": "u9/cam"}, "feed: 'u9/cam' is not one of this session's feeds"),
           ({**ok, "frame": 100}, "frame: expected a whole number from 0 to 99"),
           ({**ok, "frame": 3.0}, "frame: expected a whole number"),
           ({**ok, "frame": True}, "frame: expected a whole number"),
           ({**ok, "x_px": float("nan")}, "x_px: expected a number from -0.5 to 639.5"),
           ({**ok, "y_px": 1e308}, "y_px: expected a number from -0.5 to 359.5"),
           ({**ok, "y_px": "3"}, "y_px: expected a number"),
           ({**ok, "time_s": float("inf")}, "time_s: expected a number from 0 to 60"),
           ({**ok, "time_s": -1}, "time_s: expected a number from 0 to 60"),
           ({k: v for k, v in ok.items() if k != "time_s"}, "missing time_s"),
           ({**ok, "extra": 1}, "unknown extra"),
           ([1, 2], "expected an object")]
    for d, msg in bad:
        with pytest.raises(ReportError, match=msg):
            parse_report(d, feeds, 60.0)


def test_feed_bounds(truth: SessionTruth) -> None:
    b = feed_bounds(truth, {"u1/cam": (W, H), "u2/cam": (320, 180)})
    assert b == {"u1/cam": FeedBounds(0, 99, W, H), "u2/cam": FeedBounds(0, 99, 320, 180)}


def test_bad_ground_truth_refused(tmp_path: Path) -> None:
    rows = gt_rows({"A": (A, 0, 9, set())})
    rows[4]["center_x_px"] = "inf"
    with pytest.raises(ConfigError, match=r"b\.gt\.csv:6: center_x_px: expected a finite"):
        read_feed_truth(write_gt(tmp_path / "b.gt.csv", rows), "f")
    rows = gt_rows({"A": (A, 0, 9, set())})
    rows[0]["in_view"] = "2"
    with pytest.raises(ConfigError, match=r"c\.gt\.csv:2: in_view: expected 0 or 1"):
        read_feed_truth(write_gt(tmp_path / "c.gt.csv", rows), "f")
    (tmp_path / "d.gt.csv").write_text("frame,time_s\n0,0\n")
    with pytest.raises(ConfigError, match="missing column.*target"):
        read_feed_truth(tmp_path / "d.gt.csv", "f")


def test_scoring_settings_read_and_refused() -> None:
    ctx = Problems("study.yaml", {})
    s = read_scoring(ctx, {"tolerance_px": 4, "duplicate_window_s": 5, "min_visible_s": 2})
    assert not ctx.problems
    assert s == ScoringSettings(tolerance_px=4.0, duplicate_window_s=5.0, min_visible_s=2.0)
    assert read_scoring(ctx, {}) == ScoringSettings()
    bad = Problems("study.yaml", {})
    read_scoring(bad, {"tolerance_px": -1, "min_visible_fraction": 2, "nope": 1,
                       "duplicate_window_s": 0, "min_pixels_on_target": 0.5})
    text = "\n".join(bad.format())
    for msg in ("tolerance_px: must be >= 0", "min_visible_fraction: must be <= 1",
                "unknown key 'nope'", "duplicate_window_s: must be > 0",
                "min_pixels_on_target"):
        assert msg in text, text


@pytest.mark.integration
def test_real_run_ground_truth(tmp_path: Path) -> None:
    """The flyover's ground truth (17 s: the truck passes under the camera, the
    fire truck comes into view at the end): a click near the truck's centre 10
    frames after it first shows, a click on bare ground and no click on the
    fire truck score as the CSV read directly says: a hit with the offset as
    its error and the frames' time difference (and 0.2 s) as its latency, a
    false alarm, and a miss."""
    from cosim.cli import main

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "run"
    assert main(["run", str(repo / "scenarios/cameras/flyover.yaml"), "--backend", "inline",
                 "--duration-s", "17", "--out", str(out), "--no-progress"]) == 0
    with open(out / "cameras" / "uav1_belly.gt.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    s = ScoringSettings()

    def seen(r: dict[str, str]) -> bool:
        return r["in_view"] == "1" and float(r["pixels_on_target"]) >= s.min_pixels_on_target

    truck = [r for r in rows if r["target"] == "truck1"]
    first = next(i for i, r in enumerate(truck) if seen(r))
    at = truck[first + 10]
    cx, cy = float(at["center_x_px"]), float(at["center_y_px"])
    click_s = float(at["time_s"]) + 0.2
    fire = [r for r in rows if r["target"] == "firetruck1"]
    runs, n = [], 0
    for r in fire:
        n = n + 1 if seen(r) else 0
        runs.append(n)
    assert max(runs) * 0.1 >= s.min_visible_s  # long enough to be missed
    truth = read_run_truth(out, ["uav1/belly"])
    b = feed_bounds(truth, {"uav1/belly": (640, 480)})["uav1/belly"]
    assert (b.first_frame, b.last_frame) == (0, len(truck) - 1)
    reports = [parse_report({"feed": "uav1/belly", "frame": int(at["frame"]), "x_px": cx + 2,
                             "y_px": cy - 1, "time_s": click_s}, {"uav1/belly": b}, 17.0),
               Report("uav1/belly", int(at["frame"]), 5.0, 5.0, click_s + 1)]
    sc = score_session(truth, reports)
    hit, fa = sc.reports
    assert (hit.outcome, hit.target, fa.outcome) == ("hit", "truck1", "false_alarm")
    assert hit.error_px == pytest.approx(math.sqrt(5))
    expected_s = click_s - float(truck[first]["time_s"])
    assert hit.latency_feed_s == pytest.approx(expected_s) == hit.latency_any_s
    assert expected_s == pytest.approx(1.2, abs=1e-6)
    assert [t.target for t in sc.misses] == ["firetruck1"]
    with pytest.raises(ConfigError, match="no ground truth for feed 'uav2/belly'.*uav1/belly"):
        read_run_truth(out, ["uav2/belly"])
    # the same clicks as the console stores them: the page's pixels, 0.2 s after drawing
    stored = [{"feed_name": "uav1/belly", "frame": int(at["frame"]), "x_px": cx + 2.5,
               "y_px": cy - 0.5, "click_time_ms": 5200.0, "drawn_time_ms": 5000.0}]
    again = score_stored(out, {"uav1/belly": (640, 480)}, stored, 17.0)
    assert again.reports[0] == hit and again.misses == sc.misses


def test_stored_reports_on_the_run_clock(truth: SessionTruth) -> None:
    """A click as the console stores it: page pixels (0 at the frame's edge)
    half a pixel off the ground truth's, the time the clicked frame's plus the
    page's click - draw interval."""
    feeds = {"u1/cam": FeedBounds(0, 99, W, H), "u2/cam": FeedBounds(0, 99, W, H)}
    ax, ay, _ = A(35)
    rows = [{"report_key": "k1", "feed_name": "u1/cam", "frame": 35, "x_px": ax + 3.5,
             "y_px": ay + 4.5, "click_time_ms": 10_400.0, "drawn_time_ms": 10_000.0},
            {"report_key": "k2", "feed_name": "u2/cam", "frame": 60, "x_px": 0.0, "y_px": H,
             "click_time_ms": 20_000.0, "drawn_time_ms": None}]
    got = stored_reports(rows, truth, feeds, 60.0)
    assert got == [Report("u1/cam", 35, ax + 3, ay + 4, 3.5 + 0.4),
                   Report("u2/cam", 60, -0.5, H - 0.5, 6.0)]
    sc = score_session(truth, got)
    assert sc.reports[0].error_px == pytest.approx(5.0)
    assert sc.reports[0].latency_feed_s == pytest.approx(3.9 - 2.3)
    with pytest.raises(ReportError, match="report k3: frame 100 of u1/cam is not in the ground"):
        stored_reports([{**rows[0], "report_key": "k3", "frame": 100}], truth, feeds, 60.0)
    with pytest.raises(ReportError, match="x_px: expected a number from -0.5 to 639.5"):
        stored_reports([{**rows[0], "x_px": W + 1.0}], truth, feeds, 60.0)
    with pytest.raises(ReportError, match="y_px: expected a number .* got 'None'"):
        stored_reports([{**rows[0], "y_px": None}], truth, feeds, 60.0)
    with pytest.raises(ReportError, match="report k1: click_time_ms, drawn_time_ms: expected"):
        stored_reports([{**rows[0], "click_time_ms": "soon"}], truth, feeds, 60.0)


def test_runs_breaks_fractions_and_windows() -> None:
    """A target visible 1 s, hidden 1 s, visible 1 s has a longest run of 1 s
    (not 2); a visible fraction under the setting is not visible; a second
    click within the window is a duplicate, after it a hit."""
    def tf(f: int, on: bool, frac: float = 1.0) -> TargetFrame:
        return TargetFrame("f", f, f / RATE_HZ, "T", on, (10.0, 10.0, 20.0, 20.0),
                           (15.0, 15.0), 30.0 if on else 0.0, frac if on else math.nan)

    gap = [tf(f, 10 <= f < 20 or 30 <= f < 40) for f in range(50)]
    assert score_session(gap, []).targets[0].visible_s == pytest.approx(1.0)
    assert score_session(gap, [], ScoringSettings(min_visible_s=1.5)).misses == ()
    faint = [tf(f, 10 <= f < 40, 0.3 if f < 25 else 0.8) for f in range(50)]
    half = ScoringSettings(min_visible_fraction=0.5)
    assert score_session(faint, [], half).targets[0].first_visible_s == pytest.approx(2.5)
    assert score_session(faint, []).targets[0].first_visible_s == pytest.approx(1.0)
    clicks = [Report("f", 12, 15.0, 15.0, 1.5), Report("f", 35, 15.0, 15.0, 4.0)]
    for window_s, second in ((3.0, "duplicate"), (2.0, "hit")):
        got = score_session(gap, clicks, ScoringSettings(duplicate_window_s=window_s)).reports
        assert [r.outcome for r in got] == ["hit", second]


@pytest.mark.integration
def test_real_run_through_a_datalink(tmp_path: Path) -> None:
    """The flyover with a 5 Hz downlink 150 ms late (12 s): the feed is its
    delivered frames, each on screen at its delivered_time_s, and a click on
    the truck is timed from its first delivered frame with enough delivered
    pixels, as the CSV read directly says; a click naming a frame the link
    did not deliver is refused."""
    from cosim.cli import main

    repo = Path(__file__).resolve().parents[2]
    text = (repo / "scenarios/cameras/flyover.yaml").read_text()
    linked = text.replace("rate_hz: 10}", "rate_hz: 10, datalink: {bitrate_kbps: 2000, "
                                          "rate_hz: 5, latency_ms: 150}}")
    assert linked != text
    (tmp_path / "linked.yaml").write_text(linked)
    out = tmp_path / "run"
    assert main(["run", str(tmp_path / "linked.yaml"), "--backend", "inline",
                 "--duration-s", "12", "--out", str(out), "--no-progress"]) == 0
    with open(out / "cameras" / "uav1_belly.gt.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["target"] == "truck1"]
    shown = [r for r in rows if r["delivered_time_s"]]
    assert [int(r["frame"]) for r in shown] == list(range(0, len(rows), 2))
    first = next(i for i, r in enumerate(shown) if r["in_view"] == "1" and
                 int(r["delivered_pixels_on_target"]) >= ScoringSettings().min_pixels_on_target)
    at = shown[first + 3]
    click_s = float(at["delivered_time_s"]) + 0.3
    truth = read_run_truth(out, ["uav1/belly"])
    assert dict(truth.frames["uav1/belly"]) == {
        int(r["frame"]): float(r["delivered_time_s"]) for r in shown}
    sc = score_session(truth, [Report("uav1/belly", int(at["frame"]),
                                      float(at["center_x_px"]), float(at["center_y_px"]),
                                      click_s)])
    hit = sc.reports[0]
    assert (hit.outcome, hit.target, hit.error_px) == ("hit", "truck1", 0.0)
    assert hit.latency_feed_s == pytest.approx(click_s - float(shown[first]["delivered_time_s"]))
    assert hit.latency_feed_s == pytest.approx(3 * 0.2 + 0.3)
    with pytest.raises(ReportError, match=r"frame 1 of uav1/belly is not in the session's"):
        score_session(truth, [Report("uav1/belly", 1, 5.0, 5.0, 1.0)])


def test_random_reports_are_parsed_or_refused() -> None:
    """Seeded random JSON values in every field of a report: each parses
    within the session's bounds or is a ReportError, never another exception."""
    import random

    feeds = {"u1/cam": FeedBounds(0, 99, W, H)}
    values: list[Any] = [None, True, False, 0, -1, 3, 99, 100, 2**70, 0.5, -0.5, 639.5, 640.0,
                         1e308, float("nan"), float("inf"), "", "u1/cam", "3", [], {}, [1],
                         {"a": 1}]
    rng = random.Random(5)
    ok = 0
    for _ in range(2000):
        d = {"feed": "u1/cam", "frame": 3, "x_px": 10.0, "y_px": 20.0, "time_s": 1.0}
        for k in rng.sample(list(d), rng.randrange(1, 4)):
            d[k] = rng.choice(values)
        try:
            r = parse_report(d, feeds, 60.0)
        except ReportError:
            continue
        ok += 1
        assert 0 <= r.frame <= 99 and -0.5 <= r.x_px <= W - 0.5 and -0.5 <= r.y_px <= H - 0.5
        assert 0 <= r.time_s <= 60.0 and all(map(math.isfinite, (r.x_px, r.y_px, r.time_s)))
    assert 0 < ok < 2000
