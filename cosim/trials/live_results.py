"""A live study's stored trials scored, without a running console.

``score_trial(study, session, trial_index, reports, runs_dir)`` scores one
trial of a stored live session (``live_scoring.score_stored``) from its run
folder (``RUNS/SESSION/trialNNN``, ``RUNS`` the console's, by default
``STUDY-live`` beside the study) and its stored clicks, with the study's
``scoring:`` settings and its condition's duration (plus the margin the
console allows for a click on the last frame). ``scored_sessions(study,
store)`` does so for every trial of every live session that has run and
gives ``live_analysis.ScoredSession``s (one per session and trial, named
``SESSION/TRIAL``) with the trial's conditions, the actions of the commands
its participant sent from the map (``Store.live_commands``) and its
simulated time (its ``summary.json``'s ``sim_time_s``): what ``cosim trials
analyse`` hands to ``live_analysis.analyse_live``.

The store and the run folders are untrusted: a trial whose condition is no
longer in the study, whose run folder lacks a feed's ground truth or whose
stored clicks are not reports is a ``ConfigError`` naming the session and
the trial. It reads; it runs nothing and serves nothing.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.scenario import load_scenario
from cosim.trials.live_analysis import ScoredSession
from cosim.trials.live_scoring import SessionScore, score_stored
from cosim.trials.study import Study

log = logging.getLogger(__name__)

#: a click this long (s) after the run's end is scored (the page shows the last
#: frame until it hears of the end)
END_MARGIN_S = 5.0
#: the most trials ``scored_sessions`` scores, and stored clicks a trial may have
MAX_TRIALS = 10_000
MAX_REPORTS = 100_000
#: the largest run summary read (bytes)
MAX_SUMMARY_BYTES = 1_000_000


def runs_folder(study: Study) -> Path:
    """Where the console keeps a study's live runs: ``STUDY-live`` beside it."""
    return study.path.resolve().with_name(f"{study.path.stem}-live")


def trial_folder(runs_dir: Path, session_id: str, trial_index: int) -> Path:
    """The run folder of one trial of a session."""
    return runs_dir / session_id / f"trial{trial_index:03d}"


def score_trial(study: Study, session: Mapping[str, Any], trial_index: int,
                reports: Sequence[Mapping[str, Any]], runs_dir: Path | None = None
                ) -> SessionScore:
    """Trial ``trial_index`` of a stored live ``session`` scored from its run
    folder and its stored ``reports`` (``Store.live_reports`` rows; those of
    other trials are left out)."""
    cond = trial_condition(study, session, trial_index)
    folder = trial_folder(runs_dir or runs_folder(study), str(session["id"]), trial_index)
    where = f"session {session['id']} trial {trial_index}"
    try:
        duration_s = cond.duration_s or load_scenario(cond.scenario).duration_s
        rows = [r for r in reports if r.get("trial_index") == trial_index]
        if len(rows) > MAX_REPORTS:
            raise ConfigError(f"{len(rows)} stored clicks: more than {MAX_REPORTS} in one "
                              f"trial; not scored")
        return score_stored(folder, {f.name: (f.width_px, f.height_px) for f in cond.feeds},
                            rows, duration_s + END_MARGIN_S, study.scoring)
    except ConfigError as e:  # ReportError too
        raise ConfigError([f"{where}: {p}" for p in e.problems], e.more) from None


def trial_condition(study: Study, session: Mapping[str, Any], trial_index: int) -> Any:
    """The study's live condition of a session's trial; a ``ConfigError`` if
    the trial or its condition is not there."""
    order = session.get("trial_order") or []
    if not 0 <= trial_index < len(order) or not isinstance(order[trial_index], dict):
        raise ConfigError(f"session {session.get('id')}: no trial {trial_index} (it has "
                          f"{len(order)})")
    cid = order[trial_index].get("condition_id")
    by_id = {c.id: c for c in study.live}
    if cid not in by_id:
        raise ConfigError(f"session {session.get('id')} trial {trial_index}: condition "
                          f"{str(cid)[:200]!r} is not in the study {study.path} (it has: "
                          f"{', '.join(sorted(by_id)[:20])})")
    cond = by_id[cid]
    if order[trial_index].get("fingerprint") != cond.fingerprint:
        log.warning("session %s trial %d: condition %s's scenario changed since the session "
                    "was created; scored from its run folder's ground truth as it ran",
                    session.get("id"), trial_index, cid)
    return cond


@dataclass(frozen=True)
class LiveResults:
    """The scored trials and the trials left out (not run yet: no summary)."""

    sessions: tuple[ScoredSession, ...]
    not_run: tuple[str, ...]


def scored_sessions(study: Study, store: Any, runs_dir: Path | None = None) -> LiveResults:
    """Every trial of every stored live session of ``study`` that has run
    (its folder has its ``summary.json``), scored; practice trials left out."""
    runs = runs_dir or runs_folder(study)
    out: list[ScoredSession] = []
    not_run: list[str] = []
    for row in sorted(store.sessions(), key=lambda r: (r["created"], r["id"])):
        if row["protocol"] != "live":
            continue
        s = store.session(row["id"])
        reports = store.live_reports(s["id"])
        commands = store.live_commands(s["id"])
        for ti, t in enumerate(s["trial_order"]):
            if isinstance(t, dict) and t.get("practice"):
                continue
            if not (trial_folder(runs, s["id"], ti) / "summary.json").is_file():
                not_run.append(f"{s['id']}/{ti}")
                continue
            if len(out) >= MAX_TRIALS:
                raise ConfigError(f"the database has more than {MAX_TRIALS} live trials that "
                                  f"have run: analyse a copy with fewer sessions")
            score = score_trial(study, s, ti, reports, runs)
            cond = trial_condition(study, s, ti)
            actions = tuple(str(c["action"]) for c in commands if c["trial_index"] == ti)
            out.append(ScoredSession(f"{s['id']}/{ti}", str(s["participant"]),
                                     tuple(cond.conditions), score, actions,
                                     run_time_s(trial_folder(runs, s["id"], ti))))
    if not_run:
        log.info("%d live trials have not run (no run folder): %s", len(not_run),
                 ", ".join(not_run[:10]))
    return LiveResults(tuple(out), tuple(not_run))



def run_time_s(folder: Path) -> float | None:
    """A run folder's simulated time (s, its ``summary.json``'s
    ``sim_time_s``); None, with a warning, where it does not say."""
    path = folder / "summary.json"
    try:
        if path.stat().st_size > MAX_SUMMARY_BYTES:
            raise ValueError(f"larger than {MAX_SUMMARY_BYTES} bytes")
        v = json.loads(path.read_text()).get("sim_time_s")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or v <= 0:
            raise ValueError(f"sim_time_s is {v!r}, not a positive number")
        return float(v)
    except (OSError, ValueError, AttributeError) as e:
        log.warning("%s: no simulated time (%s); its commands a minute left out", path, e)
        return None
