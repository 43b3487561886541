"""`cosim trials analyse` on a live study: the stored sessions' trials are
scored from their run folders (ground truth written like a run's) and
analysed; the targets' outcomes, latencies and pixel errors equal those
worked out by hand from the synthetic paths below; bad or missing data is
refused with exit 2 and a message saying what and where."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest
from test_live import PROFILE, live_study
from test_live_scoring import gt_rows, write_gt

from cosim.cli import main
from cosim.trials.live_results import runs_folder, trial_folder
from cosim.trials.store import Store
from cosim.trials.study import Study, load_study

STUDY = """\
name: live_results
protocol: live
scenarios:
  - {id: one, scenario: pair.yaml, feeds: [uav1/belly], conditions: {feeds: 1}}
  - {id: two, scenario: pair.yaml, feeds: [uav1/belly, uav2/belly], conditions: {feeds: 2}}
order: shuffle
"""
# in uav1/belly the truck sits at (80, 60), half size 5, in view frames 10-40 (1.0-4.0 s);
# in uav2/belly the car at (40, 30), half size 4, frames 20-45 (2.0-4.5 s); 10 Hz
TRUCK: tuple[Any, int, int, set[int]] = (lambda f: (80.0, 60.0, 5.0), 10, 40, set())
CAR: tuple[Any, int, int, set[int]] = (lambda f: (40.0, 30.0, 4.0), 20, 45, set())


def live_session(store: Store, study: Study, who: str, conds: list[str],
                 breaks: bool = False) -> dict[str, Any]:
    """A stored live session of ``study``'s conditions ``conds`` in that
    order (with ``breaks``, a break before every trial but the first)."""
    by_id = {c.id: c for c in study.live}
    order = [{"index": i, "practice": False, "clip": i, "condition_id": c,
              "fingerprint": by_id[c].fingerprint, "break_before": breaks and i > 0}
             for i, c in enumerate(conds)]
    return store.create_session(participant=who, study=study.name, protocol="live",
                                display=PROFILE, order_method="shuffle", seed=1,
                                session_number=0, trial_order=order)


def _run(study: Study, sid: str, ti: int, feeds: dict[str, Any]) -> None:
    """A trial's run folder as the console leaves it: summary.json naming each
    camera's ground truth."""
    folder = trial_folder(runs_folder(study), sid, ti)
    (folder / "cameras").mkdir(parents=True)
    cams = []
    for feed, targets in feeds.items():
        v, c = feed.split("/")
        write_gt(folder / "cameras" / f"{v}_{c}.gt.csv", gt_rows(targets))
        cams.append({"vehicle": v, "camera": c, "ground_truth": f"cameras/{v}_{c}.gt.csv"})
    (folder / "summary.json").write_text(json.dumps({"cameras": cams}))


def _click(store: Store, s: dict[str, Any], ti: int, key: str, feed: str, frame: int,
           x_px: float, y_px: float, after_ms: float = 0.0) -> None:
    """A click ``after_ms`` after the page drew ``frame`` (pixel edges at whole
    numbers: ``x_px`` 80.5 is the truth's 80)."""
    store.record_live_report({
        "session": s["id"], "participant": s["participant"], "trial_index": ti,
        "condition": s["trial_order"][ti]["condition_id"], "report_key": key, "feed": 0,
        "feed_name": feed, "frame": frame, "x_px": x_px, "y_px": y_px,
        "click_time_ms": 1000.0 + after_ms, "drawn_time_ms": 1000.0, "run": "r"})


@pytest.fixture
def live_db(tmp_path: Path) -> tuple[Path, Path, dict[str, dict[str, Any]]]:
    study_path = live_study(tmp_path, STUDY)
    study = load_study(study_path)
    db = tmp_path / "live.sqlite"
    one = {"uav1/belly": {"truck1": TRUCK}}
    two = {"uav1/belly": {"truck1": TRUCK}, "uav2/belly": {"car": CAR}}
    with Store(db) as store:
        p1 = live_session(store, study, "p1", ["one", "two"])
        p2 = live_session(store, study, "p2", ["two", "one"])
        p3 = live_session(store, study, "p3", ["one", "two"])  # never run
        _run(study, p1["id"], 0, one)
        _run(study, p1["id"], 1, two)
        _run(study, p2["id"], 0, two)
        _run(study, p2["id"], 1, one)
        # p1, one feed: the truck at frame 15 (1.5 s) clicked 200 ms later, dead centre
        # (latency 1.7 - 1.0 = 0.7 s); a click on nothing at frame 30: a false alarm
        _click(store, p1, 0, "a", "uav1/belly", 15, 80.5, 60.5, 200.0)
        _click(store, p1, 0, "b", "uav1/belly", 30, 10.5, 10.5)
        # p1, two feeds: the truck at frame 20 (latency 1.0 s); the car never: a miss
        _click(store, p1, 1, "a", "uav1/belly", 20, 80.5, 60.5)
        # p2, two feeds: the truck at frame 12 + 100 ms, 3 px right and 4 down (error 5 px,
        # latency 0.3 s); again at frame 30 (a duplicate); the car at frame 25 (0.5 s after
        # 2.0 s, its first sight in any feed and in its own)
        _click(store, p2, 0, "a", "uav1/belly", 12, 83.5, 64.5, 100.0)
        _click(store, p2, 0, "b", "uav1/belly", 30, 80.5, 60.5)
        _click(store, p2, 0, "c", "uav2/belly", 25, 40.5, 30.5)
        # p2, one feed: nothing clicked: the truck (in view 3.1 s) a miss
    return study_path, db, {"p1": p1, "p2": p2, "p3": p3}


def csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def analyse_ok(db: Path, study: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """``cosim trials analyse DB --study STUDY --out OUT``, which succeeds; its print-out."""
    assert main(["-q", "trials", "analyse", str(db), "--study", str(study), "--out",
                 str(out)]) == 0
    return capsys.readouterr().out


def _num(v: str) -> float | None:
    return None if v == "" else round(float(v), 9)


def test_analyse_scores_the_stored_live_sessions(
        live_db: tuple[Path, Path, dict[str, dict[str, Any]]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    study, db, s = live_db
    out = tmp_path / "a"
    printed = analyse_ok(db, study, out, capsys)
    assert ("live: 4 trials scored of 2 participants: 4 of 6 targets detected; 4 hits, "
            "1 duplicates, 1 false alarms; 2 trials not run (no run folder)") in printed
    p1, p2 = s["p1"]["id"], s["p2"]["id"]
    got = {(r["session"], r["target"]): (r["detected"], _num(r["latency_any_s"]),
                                         _num(r["latency_feed_s"]), _num(r["error_px"]),
                                         r["condition_feeds"])
           for r in csv_rows(out / "live_targets.csv")}
    assert got == {
        (f"{p1}/0", "truck1"): ("1", 0.7, 0.7, 0.0, "1"),
        (f"{p1}/1", "truck1"): ("1", 1.0, 1.0, 0.0, "2"),
        (f"{p1}/1", "car"): ("0", None, None, None, "2"),
        (f"{p2}/0", "truck1"): ("1", 0.3, 0.3, 5.0, "2"),
        (f"{p2}/0", "car"): ("1", 0.5, 0.5, 0.0, "2"),
        (f"{p2}/1", "truck1"): ("0", None, None, None, "1"),
    }
    sessions = {r["session"]: (r["hits"], r["duplicates"], r["false_alarms"], r["misses"])
                for r in csv_rows(out / "live_sessions.csv")}
    assert sessions == {f"{p1}/0": ("1", "0", "1", "0"), f"{p1}/1": ("1", "0", "0", "1"),
                        f"{p2}/0": ("2", "1", "0", "0"), f"{p2}/1": ("0", "0", "0", "1")}
    # detection against feeds: 1 of 2 trucks with one feed; 3 of 4 targets with two
    det = {r["level"]: (float(r["estimate"]), r["participants"], r["interval"])
           for r in csv_rows(out / "live_levels.csv")
           if r["measure"] == "detected" and r["condition"] == "feeds"}
    assert det == {"1": (0.5, "2", "t over participants"),
                   "2": (0.75, "2", "t over participants")}
    assert (out / "live_feeds.png").stat().st_size > 0
    assert not (out / "conspicuity.csv").exists()  # no clip analysis of a live study


def test_live_data_missing_or_bad_is_refused(
        live_db: tuple[Path, Path, dict[str, dict[str, Any]]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    study, db, s = live_db
    argv = ["-q", "trials", "analyse", str(db), "--out", str(tmp_path / "a")]
    assert main(argv) == 2
    assert "live.sqlite: holds live sessions: give their study (--study STUDY.yaml)" \
        in capsys.readouterr().err
    assert main([*argv, "--runs", str(tmp_path)]) == 2
    assert "--runs: give the live study too" in capsys.readouterr().err
    csv_path = tmp_path / "r.csv"
    csv_path.write_text("session\n")
    assert main(["-q", "trials", "analyse", str(csv_path), "--study", str(study), "--out",
                 str(tmp_path / "a")]) == 2
    assert "is analysed from its database" in capsys.readouterr().err
    # a click on a frame the run's ground truth does not have
    with Store(db) as store:
        _click(store, s["p2"], 1, "z", "uav1/belly", 150, 5.5, 5.5)
    assert main([*argv, "--study", str(study)]) == 2
    err = capsys.readouterr().err
    assert f"session {s['p2']['id']} trial 1: report z: frame 150 of uav1/belly is not in " \
           f"the ground truth" in err and "Traceback" not in err
    # a run folder without one of its feeds' ground truth
    folder = trial_folder(runs_folder(load_study(study)), s["p2"]["id"], 1)
    (folder / "summary.json").write_text(json.dumps({"cameras": []}))
    assert main([*argv, "--study", str(study)]) == 2
    assert (f"session {s['p2']['id']} trial 1: " in (err := capsys.readouterr().err)
            and "no ground truth for feed 'uav1/belly'" in err)
    # a session whose condition the study no longer has
    body = study.read_text().replace("id: one,", "id: uno,")
    study.write_text(body)
    assert main([*argv, "--study", str(study)]) == 2
    assert "trial 0: condition 'one' is not in the study" in capsys.readouterr().err


@pytest.mark.integration  # a live run of four seconds, and the same run without the console
def test_a_real_live_trial_is_analysed_as_the_console_scores_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A trial run by the console (no browser: clicks posted as its page
    posts them) and analysed by `cosim trials analyse` from the run folder the
    console left: the truck's hit has the pixel error the ground truth of the
    same scenario run without the console gives, and the targets' outcomes
    and latencies are those the console's own score gives."""
    import math
    import time

    from test_live import _start, _truck, _wait_over
    from test_server import _session, live_server

    from cosim.scenario import load_scenario
    from cosim.sync.runner import run_scenario

    study = live_study(tmp_path)  # one condition: two feeds, uav1/belly and uav2/belly
    assert run_scenario(load_scenario(tmp_path / "pair.yaml"), tmp_path / "alone").ok
    truck = _truck(tmp_path / "alone" / "cameras" / "uav1_belly.gt.csv")
    frame = sorted(truck)[2]
    x, y = truck[frame]["center_x_px"] + 3.5, truck[frame]["center_y_px"] + 0.5
    with live_server(study) as server:
        sid = _session(server, "p1")["id"]
        _start(server, sid)
        deadline = time.monotonic() + 60
        for key, feed, fr, px in (("t", 0, frame, (x, y)), ("f", 1, 2, (1.5, 1.5))):
            while True:  # once the console has sent that frame
                status, out = server.request("POST", f"/api/sessions/{sid}/live/reports", {
                    "trial_index": 0, "report_key": key, "feed": feed, "frame": fr,
                    "x_px": px[0], "y_px": px[1], "click_time_ms": 5250.0,
                    "drawn_time_ms": 5000.0})
                if status == 201 or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            assert status == 201, out
        _wait_over(server, sid)
        status, score = server.request("GET", f"/api/sessions/{sid}/live/score?trial_index=0")
        assert status == 200, score
    out = tmp_path / "a"
    printed = analyse_ok(study.with_suffix(".sqlite"), study, out, capsys)
    assert "live: 1 trials scored of 1 participants" in printed
    got = {r["target"]: r for r in csv_rows(out / "live_targets.csv")}
    hit = got["truck1"]
    assert hit["detected"] == "1"
    assert float(hit["error_px"]) == pytest.approx(3.0, abs=1e-3)  # 3 px right of its centre
    want = {t["target"]: t for t in score["targets"] if t["eligible"]}
    assert set(got) == set(want)
    for name, t in want.items():
        r = got[name]
        assert r["detected"] == str(int(t["detected"]))
        for k in ("latency_any_s", "latency_feed_s", "error_px"):
            assert (r[k] == "" if t[k] is None
                    else math.isclose(float(r[k]), t[k], abs_tol=1e-6)), (name, k)
    (s,) = csv_rows(out / "live_sessions.csv")
    assert (s["session"], s["hits"], s["false_alarms"], s["misses"]) == \
        (f"{sid}/0", str(score["hits"]), str(score["false_alarms"]), str(score["misses"]))
    assert score["false_alarms"] == 1


def test_the_work_is_bounded(live_db: tuple[Path, Path, dict[str, dict[str, Any]]],
                             tmp_path: Path, capsys: pytest.CaptureFixture[str],
                             monkeypatch: pytest.MonkeyPatch) -> None:
    """More trials that have run, or more clicks in a trial, than the limits
    are refused (exit 2), not scored."""
    import cosim.trials.live_results as lr

    study, db, s = live_db
    argv = ["-q", "trials", "analyse", str(db), "--study", str(study), "--out",
            str(tmp_path / "a")]
    monkeypatch.setattr(lr, "MAX_REPORTS", 2)  # p2's trial 0 has 3
    assert main(argv) == 2
    assert (f"session {s['p2']['id']} trial 0: 3 stored clicks: more than 2 in one trial; "
            f"not scored") in capsys.readouterr().err
    monkeypatch.setattr(lr, "MAX_REPORTS", 3)
    monkeypatch.setattr(lr, "MAX_TRIALS", 3)  # four have run
    assert main(argv) == 2
    assert "the database has more than 3 live trials that have run" in capsys.readouterr().err
