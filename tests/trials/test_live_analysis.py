"""cosim.trials.live_analysis: synthetic live sessions with known effects
(examples/live_synthetic.py: latency rising and detection falling with the
number of feeds, each participant with their own offset) scored by
live_scoring, and the effects
recovered within their intervals; the intervals are the t intervals over
participants; a categorical condition; the figures and tables written."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

from cosim.trials.conditions import MAX_LEVELS
from cosim.trials.live_analysis import (
    OTHER,
    ScoredSession,
    analyse_live,
    live_tables,
    target_rows,
)
from cosim.trials.live_scoring import score_session

REPO = Path(__file__).resolve().parents[2]
_SPEC = importlib.util.spec_from_file_location("live_synthetic",
                                               REPO / "examples" / "live_synthetic.py")
assert _SPEC is not None and _SPEC.loader is not None
syn = importlib.util.module_from_spec(_SPEC)  # the README's synthetic sessions
_SPEC.loader.exec_module(syn)
FEEDS, PARTICIPANTS, TARGETS = syn.FEEDS, syn.PARTICIPANTS, syn.TARGETS


@pytest.fixture(scope="module")
def sessions() -> list[ScoredSession]:
    return syn.sessions(11)


def test_scored_latencies_are_the_clicked_ones() -> None:
    truth, reports, lats = syn.session(np.random.default_rng(3), 4, 0.3)
    sc = score_session(truth, reports)
    assert [r.outcome for r in sc.reports].count("false_alarm") == 1
    got = sorted(r.latency_any_s for r in sc.reports if r.outcome == "hit")  # type: ignore
    assert got == pytest.approx(sorted(lats))
    assert all(r.error_px == pytest.approx(1.0) for r in sc.reports if r.outcome == "hit")
    assert len(sc.misses) == TARGETS - len(lats)


def test_effects_recovered_within_intervals(sessions: list[ScoredSession]) -> None:
    levels, effects = live_tables(target_rows(sessions))
    eff = {(e["measure"], e["condition"]): e for e in effects}
    lat = eff[("latency_any_s", "feeds")]
    assert lat["ci_lo"] <= syn.LAT_PER_FEED_S <= lat["ci_hi"]
    assert lat["ci_lo"] > 0.2  # latency shown to rise
    assert lat["participants"] == PARTICIPANTS and lat["df"] == PARTICIPANTS - 1
    same = eff[("latency_feed_s", "feeds")]  # each target shows in one feed only
    assert same["slope"] == pytest.approx(lat["slope"])
    det = eff[("detected", "feeds")]
    assert det["ci_lo"] <= syn.DET_PER_FEED <= det["ci_hi"] < 0
    for k in FEEDS:
        row = next(r for r in levels if r["measure"] == "latency_any_s"
                   and r["condition"] == "feeds" and r["level"] == k)
        assert row["ci_lo"] <= syn.LAT_0_S + syn.LAT_PER_FEED_S * k <= row["ci_hi"], row
        assert row["interval"] == "t over participants"
        row = next(r for r in levels if r["measure"] == "detected"
                   and r["condition"] == "feeds" and r["level"] == k)
        assert row["ci_lo"] <= syn.DET_0 + syn.DET_PER_FEED * k <= row["ci_hi"], row
        assert row["targets"] == PARTICIPANTS * TARGETS


def test_detection_interval_is_t_over_participants(sessions: list[ScoredSession]) -> None:
    """Every participant has as many targets at a level: the interval is the
    t interval of the participants' detection rates (scipy, independently)."""
    rows = target_rows(sessions)
    levels, _ = live_tables(rows)
    for k in FEEDS:
        rates = [np.mean([r["detected"] for r in rows if r["participant"] == f"p{p}"
                          and r["condition_feeds"] == str(k)]) for p in range(PARTICIPANTS)]
        lo, hi = stats.t.interval(0.95, PARTICIPANTS - 1, loc=np.mean(rates),
                                  scale=stats.sem(rates))
        row = next(r for r in levels if r["measure"] == "detected"
                   and r["condition"] == "feeds" and r["level"] == k)
        assert row["estimate"] == pytest.approx(np.mean(rates))
        assert (row["ci_lo"], row["ci_hi"]) == pytest.approx((max(lo, 0), min(hi, 1)))


def test_categorical_condition_and_one_participant(sessions: list[ScoredSession]) -> None:
    levels, effects = live_tables(target_rows(sessions))
    beh = [r for r in levels if r["condition"] == "behaviour" and r["measure"] == "detected"]
    assert [r["level"] for r in beh] == ["orbit", "search"]
    assert not [e for e in effects if e["condition"] == "behaviour"]
    one = [s for s in sessions if s.participant == "p0"]
    levels, _ = live_tables(target_rows(one))
    row = next(r for r in levels if r["measure"] == "detected" and r["condition"] == "feeds")
    assert row["interval"] == "Wilson (one participant)"


def test_analyse_live_writes_tables_and_figures(sessions: list[ScoredSession],
                                                tmp_path: Path) -> None:
    summary = analyse_live(sessions, tmp_path)
    assert summary["files"] == ["live_targets.csv", "live_sessions.csv", "live_levels.csv",
                                "live_effects.csv", "live_tasking_levels.csv",
                                "live_tasking_effects.csv", "live_behaviour.png",
                                "live_feeds.png"]
    assert summary["reports"]["false_alarm"] == len(sessions)
    with open(tmp_path / "live_targets.csv", newline="") as f:
        got: list[dict[str, Any]] = list(csv.DictReader(f))
    assert len(got) == summary["targets"] == len(sessions) * TARGETS
    assert {"condition_feeds", "condition_behaviour"} <= set(got[0])
    for name in ("live_feeds.png", "live_behaviour.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_many_levels_bounded(sessions: list[ScoredSession]) -> None:
    """A condition of a value a session (48 names) keeps the 19 most common
    and one level for the rest; a numeric one of 48 values is cut into 20 bins."""
    rows = target_rows(sessions)
    for i, r in enumerate(rows):
        r["condition_pilot"] = f"name{i // TARGETS:02d}"
        r["condition_wind_mps"] = str(i // TARGETS)
    levels, effects = live_tables(rows)
    pilot = [r for r in levels if r["condition"] == "pilot" and r["measure"] == "detected"]
    assert len(pilot) == MAX_LEVELS and pilot[-1]["level"] == OTHER
    assert pilot[-1]["targets"] == (len(sessions) - MAX_LEVELS + 1) * TARGETS
    wind = [r for r in levels if r["condition"] == "wind_mps" and r["measure"] == "detected"]
    assert len(wind) == MAX_LEVELS
    assert sum(r["targets"] for r in wind) == len(rows)
    # every click is 1 px off its target's centre
    err = next(e for e in effects if e["measure"] == "error_px" and e["condition"] == "feeds")
    assert err["slope"] == pytest.approx(0.0, abs=1e-9) and err["unit"] == "px per unit of feeds"
    assert all(r["estimate"] == pytest.approx(1.0) for r in levels if r["measure"] == "error_px")


def test_session_counts(tmp_path: Path) -> None:
    """live_sessions.csv: each session's hits are the clicks the model made,
    its misses the targets it did not click, one false alarm each; its map
    commands counted by action, 3 in 90 s: 2 a minute."""
    rng = np.random.default_rng(4)
    truth, reports, lats = syn.session(rng, 2, 0.0)
    one = ScoredSession("s", "p", (("feeds", "2"),), score_session(truth, reports),
                        ("go", "look", "go"), 90.0)
    analyse_live([one], tmp_path, plots=False)
    with open(tmp_path / "live_sessions.csv", newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert row == {"session": "s", "participant": "p", "hits": str(len(lats)),
                   "duplicates": "0", "false_alarms": "1", "targets": str(TARGETS),
                   "misses": str(TARGETS - len(lats)), "duration_s": "90", "go": "2",
                   "orbit": "0", "look": "1", "commands": "3", "commands_per_min": "2",
                   "condition_feeds": "2"}


def test_number_of_feeds_from_the_ground_truth() -> None:
    """Sessions that name no feeds condition are analysed against their
    number of feeds, counted from their ground truth; a named one is kept."""
    rng = np.random.default_rng(8)
    plain = []
    for p in range(4):
        for k in (1, 4):
            truth, reports, _ = syn.session(rng, k, 0.0)
            plain.append(ScoredSession(f"s{p}{k}", f"p{p}", (("alt_agl_m", "100"),),
                                       score_session(truth, reports)))
    assert sorted({s.score.feeds for s in plain}) == [
        ("u0/cam",), ("u0/cam", "u1/cam", "u2/cam", "u3/cam")]
    levels, _ = live_tables(target_rows(plain))
    assert sorted({r["level"] for r in levels if r["condition"] == "feeds"}) == [1.0, 4.0]
    named = ScoredSession("s", "p", (("feeds", "nine"),), plain[0].score)
    assert {r["condition_feeds"] for r in target_rows([named])} == {"nine"}
