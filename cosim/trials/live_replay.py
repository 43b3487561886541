"""A live session's trials replayed from their logged commands.

``replay_session(store, session_id, runs_dir, out_dir, trial=None)`` finds
the run folders of a stored live session's trials (``live_results.
trial_folder``) and runs each again with ``cosim.sync.replay.replay_run``:
its recorded scenario, unpaced, with the participant's commands applied at
the ticks its ``commands.jsonl`` logged, into ``out_dir/trialNNN``; each
result says whether the states and every camera's video came out
identical. ``cosim trials replay`` prints them. A session that is not
there, not a live one, or has no trial that has run is a ``ConfigError``
saying so. It serves nothing and scores nothing.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.trials.live_results import trial_folder

log = logging.getLogger(__name__)

#: the longest session id looked up (the store's ids are 12 characters)
MAX_SESSION_ID = 32


@dataclass(frozen=True)
class TrialReplay:
    """One trial's replay: where it ran from and to, and the result."""

    trial_index: int
    run_dir: Path
    out_dir: Path
    identical: bool
    differences: tuple[str, ...]


def default_runs_dir(db: str) -> Path | None:
    """Where the console keeps the runs of the study whose database is the
    SQLite file ``db`` (``STUDY.sqlite`` beside ``STUDY.yaml``: ``STUDY-live``
    beside both); None for a database URL."""
    if "://" in db:
        return None
    p = Path(db).expanduser().resolve()
    return p.with_name(f"{p.stem}-live")


def session_trials(store: Any, session_id: str, runs_dir: Path,
                   trial: int | None = None) -> tuple[dict[str, Any], list[int]]:
    """(the stored live session, the indices of its trials to replay: ``trial``
    or every one that has run); ``ConfigError`` if none."""
    s = store.session(session_id) if 0 < len(session_id) <= MAX_SESSION_ID else None
    if s is None:
        raise ConfigError(f"no session {session_id[:40]!r} in the database")
    if s["protocol"] != "live":
        raise ConfigError(f"session {session_id}: a {s['protocol']} session; only a live "
                          f"session's trials run scenarios to replay")
    n = len(s["trial_order"])
    if trial is not None:
        if not 0 <= trial < n:
            raise ConfigError(f"--trial: session {session_id} has trials 0..{n - 1}, "
                              f"not {trial}")
        folder = trial_folder(runs_dir, session_id, trial)
        if not (folder / "summary.json").is_file():
            raise ConfigError(f"session {session_id} trial {trial}: no run folder ({folder} "
                              f"has no summary.json): it has not run, or give its study's "
                              f"run folders (--runs DIR)")
        return s, [trial]
    ran = [i for i in range(n) if (trial_folder(runs_dir, session_id, i) /
                                   "summary.json").is_file()]
    if not ran:
        raise ConfigError(f"session {session_id}: none of its {n} trials has a run folder in "
                          f"{runs_dir / session_id}: none has run, or give its study's run "
                          f"folders (--runs DIR)")
    return s, ran


def replay_session(store: Any, session_id: str, runs_dir: Path, out_dir: Path,
                   trial: int | None = None, progress: bool = False) -> list[TrialReplay]:
    """Each trial of the session that has run (or ``trial``) replayed into
    ``out_dir/trialNNN`` (see the module docstring)."""
    _, trials = session_trials(store, session_id, runs_dir, trial)
    from cosim.sync.replay import replay_run

    out: list[TrialReplay] = []
    for ti in trials:
        src = trial_folder(runs_dir, session_id, ti)
        dst = out_dir / f"trial{ti:03d}"
        log.info("session %s trial %d: replaying %s into %s", session_id, ti, src, dst)
        res = replay_run(src, dst, progress=progress)
        out.append(TrialReplay(ti, src, dst, bool(res.identical), tuple(res.differences)))
    return out
