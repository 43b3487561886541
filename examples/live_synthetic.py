"""Synthetic live sessions from a known model, scored and analysed: for trying
the live sessions' analysis (and the README's figure) before any participant
has come.

Twelve participants each do a session at 1, 2, 4 and 9 feeds. A session has
TARGETS targets, each in view in one feed for 12 s from a known time; the
participant clicks a target's centre (1 px off) with probability
DET_0 + DET_PER_FEED * feeds, LAT_0_S + LAT_PER_FEED_S * feeds + their own
offset (sd 0.6 s) + noise (sd 0.5 s) after it first showed, and makes one
false alarm a session. Half of them are in an "orbit" condition, half in
"search", without effect. Every click is scored by
``cosim.trials.live_scoring`` against the sessions' ground truth.

    python examples/live_synthetic.py --out analysis/
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from cosim.trials.live_analysis import ScoredSession, analyse_live
from cosim.trials.live_scoring import Report, TargetFrame, score_session

RATE_HZ = 10.0
FEEDS = (1, 2, 4, 9)
PARTICIPANTS = 12
TARGETS = 10
LAT_0_S, LAT_PER_FEED_S = 1.0, 0.4
DET_0, DET_PER_FEED = 0.95, -0.05


def session(rng: np.random.Generator, k: int, offset_s: float
            ) -> tuple[list[TargetFrame], list[Report], list[float]]:
    """One session of ``k`` feeds: its ground truth, its reports and the
    latencies the participant clicked at (the module docstring's model)."""
    truth: list[TargetFrame] = []
    reports: list[Report] = []
    lats = []
    for j in range(TARGETS):
        feed = f"u{j % k}/cam"
        a = 20 + 40 * j  # the frame it comes into view
        cy = 60.0 + 25 * j  # targets apart
        for f in range(a - 10, a + 120):  # 10 frames out of view, then 12 s in view
            on = f >= a
            cx = 100.0 + f
            truth.append(TargetFrame(feed, f, f / RATE_HZ, f"t{j}", on,
                                     (cx - 5, cy - 5, cx + 5, cy + 5), (cx, cy),
                                     50.0 if on else 0.0, 1.0))
        if rng.random() < DET_0 + DET_PER_FEED * k:
            lat = max(0.2, LAT_0_S + LAT_PER_FEED_S * k + offset_s + rng.normal(0, 0.5))
            t = a / RATE_HZ + lat
            f = int(math.floor(t * RATE_HZ))  # the frame on screen at the click
            reports.append(Report(feed, f, 100.0 + f + 1.0, cy, t))
            lats.append(lat)
    reports.append(Report("u0/cam", 25, 600.0, 20.0, 3.0))  # on no target: a false alarm
    return truth, reports, lats


def sessions(seed: int = 11) -> list[ScoredSession]:
    """Every participant's session at every number of feeds, scored."""
    rng = np.random.default_rng(seed)
    out = []
    for p in range(PARTICIPANTS):
        offset_s = rng.normal(0, 0.6)
        behaviour = "search" if p % 2 else "orbit"
        for k in FEEDS:
            truth, reports, _ = session(rng, k, offset_s)
            out.append(ScoredSession(f"s{p}_{k}", f"p{p}",
                                     (("feeds", str(k)), ("behaviour", behaviour)),
                                     score_session(truth, reports)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="the analysis' folder")
    ap.add_argument("--seed", type=int, default=11)
    a = ap.parse_args()
    summary = analyse_live(sessions(a.seed), a.out)
    print(f"{summary['targets']} targets, {summary['detected']} detected; "
          f"{', '.join(summary['files'])} in {a.out}")


if __name__ == "__main__":
    main()
