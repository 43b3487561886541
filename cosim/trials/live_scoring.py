"""Scoring a live session's reports against the ground truth of its feeds.

A live session shows the participant several feeds (one camera of one
vehicle each, ``VEHICLE/CAMERA``); the participant reports a target by
clicking where they see it in a feed. Each report (``Report``) names the
feed, the frame that was on screen (the page knows which frame it drew), the
click's position in that frame's pixels (pixel centres at integers, as the
ground truth's boxes) and the click's time in session seconds, on the clock
of the ground truth's ``time_s`` (the run's time: a session paced at real
time starts its run at 0).

The rules (``ScoringSettings``; a study's ``scoring:`` mapping, read by
``read_scoring``):

- a target is **visible** in a frame of a feed when it is ``in_view`` with at
  least ``min_pixels_on_target`` unoccluded pixels and a ``visible_fraction``
  of at least ``min_visible_fraction`` (an unknown fraction counts as 0 when
  the setting is above 0); a feed with a downlink shows its delivered frames
  and pixels (``live_truth``, which reads the ground truth);
- a report is a **hit** on the target whose box in that frame, grown by
  ``tolerance_px`` on every side, holds the click (the target in view; of
  several, the one whose centre is nearest the click), with its pixel error:
  the distance from the click to the target's centre (the box's middle where
  the centre is not known);
- a report on a target already hit (in any feed) at most
  ``duplicate_window_s`` seconds before is a **duplicate** (no window: the
  whole session), otherwise a hit again;
- any other report is a **false alarm**;
- a hit's **latency** is from the target's first visibility in the clicked
  feed (``latency_feed_s``) and in any feed (``latency_any_s``) to the click;
  None when the target had not been visible there by the clicked frame;
- a target visible for at least ``min_visible_s`` without a break in one
  feed (its longest run of consecutive visible frames, times the feed's frame
  period) and never hit is a **miss**.

Reports from the browser are untrusted: ``parse_report`` bounds them (a
known feed, a whole frame number among the feed's, a finite position within
the frame, a finite time within the session) and refuses the rest with a
``ReportError`` saying what was wrong.

The clicks the live console stores become reports by ``stored_reports``;
``score_stored`` scores a trial from its run folder and its stored clicks.
Pure functions: the ground truth is read by ``live_truth``; it runs, serves
and stores nothing.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from statistics import median
from typing import Any

from cosim.errors import ConfigError
from cosim.scenario.reader import Problems, Reader
from cosim.trials.live_truth import (
    SessionTruth,
    TargetFrame,
    read_run_truth,
    session_truth,
)

log = logging.getLogger(__name__)

#: the keys of a study's ``scoring:`` mapping
SCORING_KEYS = ("tolerance_px", "duplicate_window_s", "min_pixels_on_target",
                "min_visible_fraction", "min_visible_s")
#: the largest tolerance (px) and times (s) a study may set
MAX_TOLERANCE_PX = 1000.0
MAX_WINDOW_S = 24 * 3600.0
OUTCOMES = ("hit", "duplicate", "false_alarm")
#: times within this (s) are equal (frame periods summed from float times)
_EPS_S = 1e-6


class ReportError(ConfigError):
    """A participant's report is malformed or out of the session's bounds."""


@dataclass(frozen=True)
class ScoringSettings:
    """How reports are scored (the module docstring gives the rules)."""

    #: how far outside a target's box (px, every side) a click still hits it
    tolerance_px: float = 10.0
    #: a report on a target hit at most this long before (s) is a duplicate;
    #: None: for the rest of the session
    duplicate_window_s: float | None = None
    #: the fewest unoccluded pixels for a target to count as visible
    min_pixels_on_target: int = 4
    #: the least visible fraction for a target to count as visible (0: any)
    min_visible_fraction: float = 0.0
    #: a target visible this long (s) without a break in one feed and never hit is a miss
    min_visible_s: float = 1.0


def read_scoring(ctx: Problems, d: Any, at: tuple[Any, ...] = ("scoring",)) -> ScoringSettings:
    """The settings of a study's ``scoring:`` mapping (problems go to ``ctx``
    with their path; a key left out keeps its default)."""
    r = Reader(ctx, d, at, SCORING_KEYS)
    dflt = ScoringSettings()
    tol = r.num("tolerance_px", dflt.tolerance_px, lo=0, hi=MAX_TOLERANCE_PX)
    window = r.num("duplicate_window_s", dflt.duplicate_window_s, lo=0, hi=MAX_WINDOW_S,
                   lo_open=True)
    px = r.integer("min_pixels_on_target", dflt.min_pixels_on_target, lo=1, hi=10**8)
    frac = r.num("min_visible_fraction", dflt.min_visible_fraction, lo=0, hi=1)
    vis = r.num("min_visible_s", dflt.min_visible_s, lo=0, hi=MAX_WINDOW_S)
    return ScoringSettings(
        tolerance_px=dflt.tolerance_px if tol is None else tol,
        duplicate_window_s=window,
        min_pixels_on_target=dflt.min_pixels_on_target if px is None else px,
        min_visible_fraction=dflt.min_visible_fraction if frac is None else frac,
        min_visible_s=dflt.min_visible_s if vis is None else vis)


@dataclass(frozen=True)
class Report:
    """One click of the participant: where in which frame of which feed, and when."""

    feed: str
    frame: int
    x_px: float
    y_px: float
    time_s: float


@dataclass(frozen=True)
class FeedBounds:
    """What a report on a feed may name: its frames (first to last, both
    included) and its size (px)."""

    first_frame: int
    last_frame: int
    width_px: int
    height_px: int


@dataclass(frozen=True)
class ScoredReport:
    report: Report
    outcome: str  # one of OUTCOMES
    target: str | None = None  # hit and duplicate
    error_px: float | None = None
    latency_feed_s: float | None = None  # hit
    latency_any_s: float | None = None


@dataclass(frozen=True)
class TargetScore:
    """One target over the session: how long it was visible (its longest
    unbroken run in one feed), when first, and its first hit if any."""

    target: str
    visible_s: float
    first_visible_s: float | None
    detected: bool
    eligible: bool  # visible at least min_visible_s, or hit
    latency_feed_s: float | None = None
    latency_any_s: float | None = None
    error_px: float | None = None


@dataclass(frozen=True)
class SessionScore:
    reports: tuple[ScoredReport, ...]
    targets: tuple[TargetScore, ...]
    settings: ScoringSettings = field(default_factory=ScoringSettings)
    #: the session's feeds (those its ground truth has frames of)
    feeds: tuple[str, ...] = ()

    def count(self, outcome: str) -> int:
        return sum(1 for r in self.reports if r.outcome == outcome)

    @property
    def misses(self) -> tuple[TargetScore, ...]:
        return tuple(t for t in self.targets if t.eligible and not t.detected)


def feed_bounds(truth: SessionTruth, sizes: Mapping[str, tuple[int, int]]
                ) -> dict[str, FeedBounds]:
    """Each feed's ``FeedBounds``: its first and last frame in the ground
    truth and its (width, height) from ``sizes``."""
    return {f: FeedBounds(min(fr), max(fr), *sizes[f]) for f, fr in truth.frames.items() if fr}


# ---- reports in


def parse_report(d: Any, feeds: Mapping[str, FeedBounds], duration_s: float) -> Report:
    """A report as the browser sends it (``{"feed", "frame", "x_px", "y_px",
    "time_s"}``), checked against the session: a ``ReportError`` saying what
    is wrong otherwise."""
    if not isinstance(d, dict):
        raise ReportError(f"report: expected an object with feed, frame, x_px, y_px, time_s, "
                          f"got {type(d).__name__}")
    keys = ("feed", "frame", "x_px", "y_px", "time_s")
    unknown = [str(k)[:40] for k in d if k not in keys]
    missing = [k for k in keys if k not in d]
    if unknown or missing:
        raise ReportError(f"report: expected the keys {', '.join(keys)}"
                          + (f"; missing {', '.join(missing)}" if missing else "")
                          + (f"; unknown {', '.join(unknown[:5])}" if unknown else ""))
    feed = d["feed"]
    if not isinstance(feed, str) or feed not in feeds:
        raise ReportError(f"report: feed: {str(feed)[:80]!r} is not one of this session's "
                          f"feeds ({', '.join(list(feeds)[:16])})")
    b = feeds[feed]
    frame = d["frame"]
    if isinstance(frame, bool) or not isinstance(frame, int) or \
            not b.first_frame <= frame <= b.last_frame:
        raise ReportError(f"report: frame: expected a whole number from {b.first_frame} to "
                          f"{b.last_frame} (the frames of {feed}), got {str(frame)[:40]!r}")

    def num(key: str, lo: float, hi: float, what: str) -> float:
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
            raise ReportError(f"report: {key}: expected a number from {lo:g} to {hi:g} "
                              f"({what}), got {str(v)[:40]!r}")
        return float(v)

    x = num("x_px", -0.5, b.width_px - 0.5, f"within {feed}'s {b.width_px} px width")
    y = num("y_px", -0.5, b.height_px - 0.5, f"within {feed}'s {b.height_px} px height")
    t = num("time_s", 0.0, duration_s, "seconds into the session")
    return Report(feed, frame, x, y, t)


def stored_reports(rows: Iterable[Mapping[str, Any]], truth: SessionTruth,
                   feeds: Mapping[str, FeedBounds], duration_s: float) -> list[Report]:
    """The clicks as the live console stores them (``feed_name``, ``frame``,
    ``x_px`` and ``y_px`` in the page's pixels of the frame, 0 at its left or
    top edge, and the page's ``click_time_ms`` and ``drawn_time_ms``) as
    reports: the position moved half a pixel onto the ground truth's (pixel
    centres at whole numbers), the time on the run's clock: when the frame
    was on screen there (``TargetFrame.time_s``) plus how long after the page
    drew it the click came (nothing added when the page did not say). Each
    is bounded as ``parse_report`` bounds a report; a frame the ground truth
    does not have is a ``ReportError``."""
    out = []
    for r in rows:
        at = truth.frames.get(r["feed_name"], {}).get(r["frame"])
        if at is None:
            raise ReportError(f"report {r.get('report_key', '')!s:.64}: frame {r['frame']!s:.20} "
                              f"of {r['feed_name']!s:.200} is not in the ground truth")
        click, drawn = r["click_time_ms"], r.get("drawn_time_ms")
        if not all(_is_number(v) for v in (click, 0.0 if drawn is None else drawn)):
            raise ReportError(f"report {r.get('report_key', '')!s:.64}: click_time_ms, "
                              f"drawn_time_ms: expected the page's times (ms), got "
                              f"{click!s:.40}, {drawn!s:.40}")
        after_s = 0.0 if drawn is None else (click - drawn) / 1000.0
        x, y = (v - 0.5 if _is_number(v) else v for v in (r["x_px"], r["y_px"]))
        out.append(parse_report({"feed": r["feed_name"], "frame": r["frame"], "x_px": x,
                                 "y_px": y, "time_s": at + after_s}, feeds, duration_s))
    return out


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


# ---- scoring


def visible(t: TargetFrame, s: ScoringSettings) -> bool:
    """Whether the target counts as visible in this frame (``s``'s thresholds)."""
    if not t.in_view or not t.pixels_on_target >= s.min_pixels_on_target:
        return False
    return s.min_visible_fraction <= 0 or t.visible_fraction >= s.min_visible_fraction


def _longest_runs(truth: SessionTruth, s: ScoringSettings
                  ) -> tuple[dict[str, float], dict[tuple[str, str], float]]:
    """(each target's longest unbroken visible run in one feed (s), the first
    time each (target, feed) is visible). A run is consecutive frames of the
    feed (as it shows them), each standing for the feed's frame period (the
    median step between its frames' times)."""
    seen: dict[tuple[str, str], list[int]] = {}
    first: dict[tuple[str, str], float] = {}
    for t in truth.rows:
        if visible(t, s):
            key = (t.target, t.feed)
            seen.setdefault(key, []).append(t.frame)
            first[key] = min(first.get(key, math.inf), t.time_s)
    longest: dict[str, float] = {}
    for feed, by_frame in truth.frames.items():
        order = sorted(by_frame)
        times = [by_frame[f] for f in order]
        steps = [b - a for a, b in zip(times, times[1:]) if b > a]
        period_s = median(steps) if steps else 0.0
        index = {f: i for i, f in enumerate(order)}
        for (target, f), fr in seen.items():
            if f != feed:
                continue
            idx = sorted({index[x] for x in fr})
            run = best = 1
            for a, b in zip(idx, idx[1:]):
                run = run + 1 if b == a + 1 else 1
                best = max(best, run)
            longest[target] = max(longest.get(target, 0.0), best * period_s)
    return longest, first


def _hit_target(rows: Sequence[TargetFrame], r: Report, tol_px: float
                ) -> tuple[TargetFrame, float] | None:
    """The target whose grown box holds the click (the nearest centre of
    several) and the click's distance to its centre."""
    best: tuple[TargetFrame, float] | None = None
    for t in rows:
        if not t.in_view or t.bbox_px is None:
            continue
        x0, y0, x1, y1 = t.bbox_px
        if not (x0 - tol_px <= r.x_px <= x1 + tol_px and y0 - tol_px <= r.y_px <= y1 + tol_px):
            continue
        cx, cy = t.center_px if t.center_px is not None else ((x0 + x1) / 2, (y0 + y1) / 2)
        err = math.hypot(r.x_px - cx, r.y_px - cy)
        if best is None or err < best[1]:
            best = (t, err)
    return best


def score_session(truth: SessionTruth | Sequence[TargetFrame], reports: Sequence[Report],
                  settings: ScoringSettings | None = None) -> SessionScore:
    """Every report scored (in time order) and every target in view at some
    time's outcome (the module docstring gives the rules); ``truth`` a
    session's, or its rows. A report naming a frame the ground truth does
    not have for its feed is a ``ReportError``."""
    s = settings or ScoringSettings()
    if not isinstance(truth, SessionTruth):
        truth = session_truth(truth)
    by_frame: dict[tuple[str, int], list[TargetFrame]] = {}
    for t in truth.rows:
        by_frame.setdefault((t.feed, t.frame), []).append(t)
    longest, first = _longest_runs(truth, s)
    first_any: dict[str, float] = {}
    for (target, _), t0 in first.items():
        first_any[target] = min(first_any.get(target, math.inf), t0)
    last_hit: dict[str, float] = {}
    first_hit: dict[str, ScoredReport] = {}
    scored: list[ScoredReport] = []
    for r in sorted(reports, key=lambda r: r.time_s):
        if r.frame not in truth.frames.get(r.feed, {}):
            raise ReportError(f"report at {r.time_s:g} s: frame {r.frame} of {r.feed} is not "
                              f"in the session's ground truth (not shown)")
        found = _hit_target(by_frame.get((r.feed, r.frame), []), r, s.tolerance_px)
        if found is None:
            scored.append(ScoredReport(r, "false_alarm"))
            continue
        t, err = found
        before = last_hit.get(t.target)
        if before is not None and (s.duplicate_window_s is None
                                   or r.time_s - before <= s.duplicate_window_s):
            scored.append(ScoredReport(r, "duplicate", t.target, err))
            continue
        last_hit[t.target] = r.time_s
        t_feed = first.get((t.target, r.feed), math.inf)
        t_any = first_any.get(t.target, math.inf)
        sr = ScoredReport(r, "hit", t.target, err,
                          r.time_s - t_feed if t_feed <= t.time_s else None,
                          r.time_s - t_any if t_any <= t.time_s else None)
        scored.append(sr)
        first_hit.setdefault(t.target, sr)
    targets = []
    for name in sorted({t.target for t in truth.rows}):
        vis_s = longest.get(name, 0.0)
        h = first_hit.get(name)
        targets.append(TargetScore(
            target=name, visible_s=vis_s, first_visible_s=first_any.get(name),
            detected=h is not None,
            eligible=h is not None or vis_s >= s.min_visible_s - _EPS_S,
            latency_feed_s=h.latency_feed_s if h else None,
            latency_any_s=h.latency_any_s if h else None, error_px=h.error_px if h else None))
    return SessionScore(tuple(scored), tuple(targets), s,
                        tuple(f for f, fr in truth.frames.items() if fr))


def score_stored(run_dir: str | Path, sizes: Mapping[str, tuple[int, int]],
                 rows: Iterable[Mapping[str, Any]], duration_s: float,
                 settings: ScoringSettings | None = None) -> SessionScore:
    """A live trial scored from its run folder: the ground truth of its
    feeds (``sizes``: each feed's (width, height) px, in the trial's order)
    and the clicks the console stored for it (``stored_reports``)."""
    truth = read_run_truth(run_dir, list(sizes))
    reports = stored_reports(rows, truth, feed_bounds(truth, sizes), duration_s)
    return score_session(truth, reports, settings)
