"""Analysis of scored live sessions: detection and latency against conditions.

Each session (``ScoredSession``: its participant, its condition values and
its ``live_scoring.SessionScore``) gives one row per target that counted
(visible long enough, or hit: ``target_rows``): detected or not, and for a
detected target its first hit's latency from its first visibility in any
feed and in the clicked feed and its pixel error (each a measure).

``live_tables`` gives, for every condition the sessions carry (number of
feeds, altitude, speed, behaviour: whatever their ``conditions`` name),
each level's detection probability and mean latencies with intervals, and
for a numeric condition the slope of each measure on it. Participants are
not independent trials: with two or more, every interval is a t interval
with standard errors clustered by participant (``estimates.mean_estimate``
and ``estimates.slope_estimate``: a slope within participants); with one,
the detection probability has a Wilson interval and the rest trial-level
ones. A numeric condition with more than ``conditions.MAX_LEVELS`` values
is cut into bins (``conditions.condition_levels``); any other keeps its
``MAX_LEVELS - 1`` most common values and puts the rest in ``OTHER``.

The operator's tasking (the commands sent from the map, ``ScoredSession.
commands``) is a measure of workload a trial: its counts of go, orbit and
look commands, their total and the total a minute of the trial's simulated
time; ``tasking_tables`` gives its levels and slopes against the conditions
as ``live_tables`` does the targets' measures, from one row a trial.

``analyse_live`` writes the tables (``live_targets.csv``, ``live_sessions.csv``:
a session's counts of hits, duplicates, false alarms, misses and commands,
``live_levels.csv``, ``live_effects.csv``, ``live_tasking_levels.csv``,
``live_tasking_effects.csv``) and a figure a condition (``live_figures``),
with ``live_tasking.png`` where any trial has commands. It reads
no file, runs nothing and knows nothing of how sessions are stored.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.conditions import MAX_LEVELS, condition_levels
from cosim.trials.estimates import (
    cluster_ids,
    mean_estimate,
    slope_estimate,
    t_interval,
    wilson_ci,
)
from cosim.trials.live_scoring import SessionScore
from cosim.trials.output import write_csv

log = logging.getLogger(__name__)

#: the measures analysed: whether a target was detected (0/1), its first hit's
#: latencies (s) and pixel error (px)
MEASURES = ("detected", "latency_any_s", "latency_feed_s", "error_px")
TARGET_FIELDS = ("session", "participant", "target", "visible_s", "detected",
                 "latency_any_s", "latency_feed_s", "error_px")
SESSION_FIELDS = ("session", "participant", "hits", "duplicates", "false_alarms", "targets",
                  "misses", "duration_s", "go", "orbit", "look", "commands",
                  "commands_per_min")
#: the tasking measures, one value a trial: its commands, and those a minute
TASKING_MEASURES = ("commands", "commands_per_min")
#: each measure's unit in the effects' tables
UNITS = {"detected": "probability", "error_px": "px", "commands": "commands",
         "commands_per_min": "commands per minute"}
LEVEL_FIELDS = ("measure", "condition", "level", "targets", "participants", "estimate",
                "ci_lo", "ci_hi", "interval")
EFFECT_FIELDS = ("measure", "condition", "slope", "unit", "ci_lo", "ci_hi", "df",
                 "participants", "targets")
#: the most conditions analysed (each gets a figure)
MAX_CONDITIONS = 12
#: the level of a condition's values past the MAX_LEVELS - 1 most common
OTHER = "(other)"


@dataclass(frozen=True)
class ScoredSession:
    """One participant's session in one condition, scored."""

    session: str
    participant: str
    conditions: tuple[tuple[str, str], ...]
    score: SessionScore
    #: the actions of the commands the participant sent from the map, in order
    commands: tuple[str, ...] = ()
    #: the trial's simulated time (s; None: not known)
    duration_s: float | None = None


def target_rows(sessions: Sequence[ScoredSession]) -> list[dict[str, Any]]:
    """One row per target that counted in each session (``TARGET_FIELDS``
    and ``condition_<name>`` for each of the session's conditions; a session
    that names no ``feeds`` condition has its number of feeds as one)."""
    rows = []
    for s in sessions:
        conds = _conditions(s)
        for t in s.score.targets:
            if not t.eligible:
                continue
            rows.append({"session": s.session, "participant": s.participant,
                         "target": t.target, "visible_s": t.visible_s,
                         "detected": int(t.detected), "latency_any_s": t.latency_any_s,
                         "latency_feed_s": t.latency_feed_s, "error_px": t.error_px, **conds})
    return rows


def session_rows(sessions: Sequence[ScoredSession]) -> list[dict[str, Any]]:
    """One row per session: its counts of reports by outcome, of targets
    that counted, of misses and of commands by action, with their total a
    minute (``SESSION_FIELDS``), and its conditions."""
    return [{"session": s.session, "participant": s.participant,
             **{f"{o}s": s.score.count(o) for o in ("hit", "duplicate", "false_alarm")},
             "targets": sum(t.eligible for t in s.score.targets),
             "misses": len(s.score.misses), "duration_s": s.duration_s,
             **{a: s.commands.count(a) for a in ("go", "orbit", "look")},
             "commands": len(s.commands),
             "commands_per_min": (60.0 * len(s.commands) / s.duration_s
                                  if s.duration_s else None),
             **_conditions(s)} for s in sessions]


def _conditions(s: ScoredSession) -> dict[str, Any]:
    """A session's ``condition_<name>`` values, with ``condition_feeds`` its
    number of feeds where it names none."""
    conds = {f"condition_{k}": v for k, v in s.conditions}
    if "condition_feeds" not in conds and s.score.feeds:
        conds["condition_feeds"] = str(len(s.score.feeds))
    return conds


def _values(rows: Sequence[dict[str, Any]], key: str) -> np.ndarray:
    return np.array([math.nan if r.get(key) is None else float(r[key]) for r in rows])


def numeric(values: Sequence[Any]) -> np.ndarray | None:
    """The values as numbers, None if any is not one."""
    try:
        out = np.array([float(v) for v in values])
    except (TypeError, ValueError):
        return None
    return out if np.isfinite(out).all() else None


def categories(values: list[str | None], name: str) -> tuple[list[Any], np.ndarray]:
    """(levels, each row's level) of a condition whose values are not numbers:
    the values, or past ``MAX_LEVELS`` the ``MAX_LEVELS - 1`` with the most
    rows and one level ``OTHER`` for the rest."""
    counts: dict[str, int] = {}
    for v in values:
        if v is not None:
            counts[v] = counts.get(v, 0) + 1
    if len(counts) <= MAX_LEVELS:
        return sorted(counts), np.array(values, dtype=object)
    kept = set(sorted(counts, key=lambda v: (-counts[v], v))[:MAX_LEVELS - 1])
    log.warning("condition %s takes %d values: the %d with the most targets analysed alone, "
                "the rest as %r", name, len(counts), MAX_LEVELS - 1, OTHER)
    lv = np.array([v if v is None or v in kept else OTHER for v in values], dtype=object)
    return [*sorted(kept), OTHER], lv


def level_estimate(measure: str, y: np.ndarray, who_names: np.ndarray, level: float
                    ) -> tuple[float, float, float, str]:
    """(estimate, lo, hi, how the interval was made) of ``y`` at one level."""
    who = cluster_ids(who_names, y.size)
    if who is None and measure == "detected":
        lo, hi = wilson_ci(int(y.sum()), y.size, level)
        return (float(y.mean()) if y.size else math.nan), lo, hi, "Wilson (one participant)"
    est = mean_estimate(y, who)
    if est is None:
        return (float(y.mean()) if y.size else math.nan), math.nan, math.nan, "too few"
    lo, hi = t_interval(est, level)
    if measure == "detected":
        lo, hi = max(lo, 0.0), min(hi, 1.0)
    return est[0], lo, hi, "t over participants" if who is not None else "t over targets"


def tasking_tables(sessions: Sequence[ScoredSession], level: float = 0.95
                   ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(levels, effects) of the tasking measures (``TASKING_MEASURES``)
    against the conditions, one row a trial (``targets`` counts trials)."""
    return live_tables(session_rows(sessions), level, TASKING_MEASURES)


def live_tables(rows: Sequence[dict[str, Any]], level: float = 0.95,
                measures: Sequence[str] = MEASURES
                ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(levels, effects): each condition's levels with every measure's
    estimate and interval, and each numeric condition's slope of every
    measure (``EFFECT_FIELDS``)."""
    names = sorted({k[len("condition_"):] for r in rows for k in r
                    if k.startswith("condition_")})
    if len(names) > MAX_CONDITIONS:
        log.warning("%d conditions: the first %d analysed (%s)", len(names), MAX_CONDITIONS,
                    ", ".join(names[:MAX_CONDITIONS]))
        names = names[:MAX_CONDITIONS]
    who_all = np.array([str(r["participant"]) for r in rows], dtype=object)
    level_rows: list[dict[str, Any]] = []
    effect_rows: list[dict[str, Any]] = []
    for name in names:
        raw = [r.get(f"condition_{name}") for r in rows]
        has = np.array([v is not None and v != "" for v in raw])
        nums = numeric([v for v, h in zip(raw, has) if h])
        if nums is not None:
            x = np.full(len(rows), math.nan)
            x[has], _ = condition_levels(nums)
            keys: list[Any] = sorted(set(x[has].tolist()))
            lv = x
        else:
            keys, lv = categories([str(v) if h else None for v, h in zip(raw, has)], name)
        for measure in measures:
            y = _values(rows, measure)
            for k in keys:
                sel = has & (lv == k) & np.isfinite(y)
                est, lo, hi, how = level_estimate(measure, y[sel], who_all[sel], level)
                level_rows.append({"measure": measure, "condition": name, "level": k,
                                   "targets": int(sel.sum()),
                                   "participants": len(set(who_all[sel])), "estimate": est,
                                   "ci_lo": lo, "ci_hi": hi, "interval": how})
            if nums is None or len(keys) < 2:
                continue
            sel = has & np.isfinite(y)
            who = cluster_ids(who_all[sel], int(sel.sum()))
            slope = slope_estimate(x[sel], y[sel], who)
            lo, hi = t_interval(slope, level)
            unit = UNITS.get(measure, "s")
            effect_rows.append({"measure": measure, "condition": name,
                                "slope": slope[0] if slope else math.nan,
                                "unit": f"{unit} per unit of {name}", "ci_lo": lo, "ci_hi": hi,
                                "df": slope[2] if slope else math.nan,
                                "participants": len(set(who_all[sel])),
                                "targets": int(sel.sum())})
    return level_rows, effect_rows


def analyse_live(sessions: Sequence[ScoredSession], out_dir: str | Path, *,
                 level: float = 0.95, plots: bool = True) -> dict[str, Any]:
    """Write ``live_targets.csv``, ``live_sessions.csv``, ``live_levels.csv``,
    ``live_effects.csv`` and (with ``plots``) ``live_<condition>.png`` into ``out_dir``; return a
    summary (counts, files)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = target_rows(sessions)
    conds = sorted({k for r in rows for k in r if k.startswith("condition_")})
    write_csv(out / "live_targets.csv", (*TARGET_FIELDS, *conds), rows)
    per_session = session_rows(sessions)
    write_csv(out / "live_sessions.csv",
              (*SESSION_FIELDS, *sorted({k for r in per_session for k in r
                                         if k.startswith("condition_")})), per_session)
    level_rows, effect_rows = live_tables(rows, level)
    write_csv(out / "live_levels.csv", LEVEL_FIELDS, level_rows)
    write_csv(out / "live_effects.csv", EFFECT_FIELDS, effect_rows)
    task_levels, task_effects = tasking_tables(sessions, level)
    write_csv(out / "live_tasking_levels.csv", LEVEL_FIELDS, task_levels)
    write_csv(out / "live_tasking_effects.csv", EFFECT_FIELDS, task_effects)
    files = ["live_targets.csv", "live_sessions.csv", "live_levels.csv", "live_effects.csv",
             "live_tasking_levels.csv", "live_tasking_effects.csv"]
    if plots:
        from cosim.trials.live_figures import plot_condition, plot_tasking

        if any(s.commands for s in sessions):
            plot_tasking(out / "live_tasking.png", task_levels, task_effects, level)
            files.append("live_tasking.png")

        for name in sorted({r["condition"] for r in level_rows}):
            fname = f"live_{_safe(name)}.png"
            plot_condition(out / fname, name, [r for r in level_rows if r["condition"] == name],
                           [r for r in effect_rows if r["condition"] == name], level)
            files.append(fname)
    return {"sessions": len(sessions), "participants": len({s.participant for s in sessions}),
            "targets": len(rows), "detected": sum(r["detected"] for r in rows),
            "reports": {o: sum(s.score.count(o) for s in sessions)
                        for o in ("hit", "duplicate", "false_alarm")},
            "commands": {a: sum(s.commands.count(a) for s in sessions)
                         for a in ("go", "orbit", "look")},
            "files": files}


def _safe(name: str) -> str:
    """A condition's name as part of a file name."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)[:60] or "condition"
