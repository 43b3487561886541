"""cosim.trials.live_analysis: synthetic live sessions with known effects
(latency rising and detection falling with the number of feeds, each
participant with their own offset) scored by live_scoring, and the effects
recovered within their intervals; the intervals are the t intervals over
participants; a categorical condition; the figures and tables written."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

from cosim.trials.live_analysis import ScoredSession, analyse_live, live_tables, target_rows
from cosim.trials.live_scoring import Report, TargetFrame, score_session

RATE_HZ = 10.0
FEEDS = (1, 2, 4, 9)
PARTICIPANTS = 12
TARGETS = 10
LAT_0_S, LAT_PER_FEED_S = 1.0, 0.4
DET_0, DET_PER_FEED = 0.95, -0.05


def session(rng: np.random.Generator, k: int, offset_s: float, behaviour: str
            ) -> tuple[list[TargetFrame], list[Report], list[float]]:
    """A session of ``k`` feeds and TARGETS targets, each visible for 12 s
    in one feed from a known time; the participant clicks each one's centre
    with probability DET_0 + DET_PER_FEED k, LAT_0_S + LAT_PER_FEED_S k +
    ``offset_s`` + noise after it first showed, and makes one false alarm.
    Returns the truth, the reports and the latencies clicked."""
    truth: list[TargetFrame] = []
    reports: list[Report] = []
    lats = []
    for j in range(TARGETS):
        feed = f"u{j % k}/cam"
        a = 20 + 40 * j
        for f in range(a - 10, a + 120):  # 10 frames out of view, then 12 s in view
            on = f >= a
            cx, cy = 100.0 + f, 60.0 + 25 * j  # targets apart
            truth.append(TargetFrame(feed, f, f / RATE_HZ, f"t{j}", on,
                                     (cx - 5, cy - 5, cx + 5, cy + 5), (cx, cy),
                                     50.0 if on else 0.0, 1.0))
        if rng.random() < DET_0 + DET_PER_FEED * k:
            lat = max(0.2, LAT_0_S + LAT_PER_FEED_S * k + offset_s + rng.normal(0, 0.5))
            t = a / RATE_HZ + lat
            f = int(math.floor(t * RATE_HZ))  # the frame on screen at the click
            reports.append(Report(feed, f, 100.0 + f + 1.0, 60.0 + 25 * j, t))
            lats.append(lat)
    f = 25
    reports.append(Report("u0/cam", f, 600.0, 20.0, f / RATE_HZ + 0.5))  # a false alarm
    return truth, reports, lats


@pytest.fixture(scope="module")
def sessions() -> list[ScoredSession]:
    rng = np.random.default_rng(11)
    out = []
    for p in range(PARTICIPANTS):
        offset = rng.normal(0, 0.6)
        for k in FEEDS:
            truth, reports, _ = session(rng, k, offset, "search" if p % 2 else "orbit")
            out.append(ScoredSession(f"s{p}_{k}", f"p{p}",
                                     (("feeds", str(k)),
                                      ("behaviour", "search" if p % 2 else "orbit")),
                                     score_session(truth, reports)))
    return out


def test_scored_latencies_are_the_clicked_ones() -> None:
    truth, reports, lats = session(np.random.default_rng(3), 4, 0.3, "search")
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
    assert lat["ci_lo"] <= LAT_PER_FEED_S <= lat["ci_hi"]
    assert lat["ci_lo"] > 0.2  # latency shown to rise
    assert lat["participants"] == PARTICIPANTS and lat["df"] == PARTICIPANTS - 1
    same = eff[("latency_feed_s", "feeds")]  # each target shows in one feed only
    assert same["slope"] == pytest.approx(lat["slope"])
    det = eff[("detected", "feeds")]
    assert det["ci_lo"] <= DET_PER_FEED <= det["ci_hi"] < 0
    for k in FEEDS:
        row = next(r for r in levels if r["measure"] == "latency_any_s"
                   and r["condition"] == "feeds" and r["level"] == k)
        assert row["ci_lo"] <= LAT_0_S + LAT_PER_FEED_S * k <= row["ci_hi"], row
        assert row["interval"] == "t over participants"
        row = next(r for r in levels if r["measure"] == "detected"
                   and r["condition"] == "feeds" and r["level"] == k)
        assert row["ci_lo"] <= DET_0 + DET_PER_FEED * k <= row["ci_hi"], row
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
    assert summary["files"] == ["live_targets.csv", "live_levels.csv", "live_effects.csv",
                                "live_behaviour.png", "live_feeds.png"]
    assert summary["reports"]["false_alarm"] == len(sessions)
    with open(tmp_path / "live_targets.csv", newline="") as f:
        got: list[dict[str, Any]] = list(csv.DictReader(f))
    assert len(got) == summary["targets"] == len(sessions) * TARGETS
    assert {"condition_feeds", "condition_behaviour"} <= set(got[0])
    for name in ("live_feeds.png", "live_behaviour.png"):
        assert (tmp_path / name).stat().st_size > 10_000
