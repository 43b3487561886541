"""Analysis of a study's NASA-TLX and SAGAT answers: ``analyse_instruments``.

From the stored answers (``Store.instrument_answers`` rows), the sessions
they belong to and the study file:

- ``tlx_blocks.csv``: one row per TLX answer (a participant's block): its
  raw TLX (the mean of the six ratings) and, where the study asks the
  pairwise weights, its weighted TLX (sum of weight x rating over 15), both
  recomputed from the stored ratings and choices (``instruments``), and the
  block's conditions: a condition's value where every trial of the block
  has the same one, empty where they differ (that block is left out of that
  condition's levels);
- ``tlx_levels.csv``: each condition's levels with the mean raw and
  weighted TLX and their intervals;
- ``sagat_questions.csv``: one row per scored question of each probe: its
  kind (``last_target``, ``count``, ``choice``), whether it was answered
  correctly, its error and the trial's conditions;
- ``sagat_levels.csv``: accuracy per question kind, over all the answers
  (condition ``(all)``) and at each level of each condition;
- ``tlx.png`` and ``sagat.png`` (``instrument_figures``).

Participants are not independent: with two or more, every interval is a t
interval with errors clustered by participant (``estimates.mean_estimate``);
with one, the TLX has a t interval over its blocks and an accuracy a Wilson
interval (``live_analysis``'s rule for a level). A condition's levels are
grouped as the live analysis groups them (numbers binned past
``conditions.MAX_LEVELS``, other values past it kept the most common).

The database is untrusted: an answer whose session, block, probe, question
or condition the study does not have, or whose ratings are not ratings, is
a ``ConfigError`` naming the session and the answer. SAGAT answers stored
unscored (the console had no state to score them with) are counted, not
analysed. Tasking (commands sent by the operator) is not analysed here.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import ConfigError, CosimError
from cosim.trials.conditions import condition_levels
from cosim.trials.instruments import check_tlx_answer, tlx_blocks
from cosim.trials.live_analysis import MAX_CONDITIONS, categories, level_estimate, numeric
from cosim.trials.live_results import trial_condition
from cosim.trials.output import write_csv

log = logging.getLogger(__name__)

TLX_FIELDS = ("session", "participant", "block", "trials", "raw_tlx", "weighted_tlx")
TLX_MEASURES = ("raw_tlx", "weighted_tlx")
TLX_LEVEL_FIELDS = ("measure", "condition", "level", "blocks", "participants", "estimate",
                    "ci_lo", "ci_hi", "interval")
SAGAT_FIELDS = ("session", "participant", "trial_index", "probe", "at_s", "question", "kind",
                "correct", "error")
SAGAT_LEVEL_FIELDS = ("kind", "condition", "level", "questions", "participants", "accuracy",
                      "ci_lo", "ci_hi", "interval")
#: the condition of the SAGAT levels over all the answers
ALL = "(all)"
#: the most answers analysed
MAX_ANSWERS = 100_000


def trial_conditions(study: Any, session: Mapping[str, Any], trial_index: int
                     ) -> dict[str, str]:
    """A session's trial's conditions (its clip's, or its live condition's)
    as the study gives them; a ``ConfigError`` if the study has no such
    trial, clip or condition."""
    if study.protocol == "live":
        return dict(trial_condition(study, session, trial_index).conditions)
    order = session.get("trial_order") or []
    if not 0 <= trial_index < len(order) or not isinstance(order[trial_index], dict):
        raise ConfigError(f"session {session.get('id')}: no trial {trial_index} (it has "
                          f"{len(order)})")
    by_id = {c.id: c for c in study.all_clips}
    key = order[trial_index].get("clip_id")
    if key not in by_id:
        raise ConfigError(f"session {session.get('id')} trial {trial_index}: clip "
                          f"{str(key)[:200]!r} is not in the study {study.path}")
    return dict(by_id[key].conditions)


def _where(a: Mapping[str, Any]) -> str:
    return f"session {a.get('session')} {a.get('instrument')} answer {a.get('item')}"


def tlx_rows(study: Any, sessions: Mapping[str, Mapping[str, Any]],
             answers: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per TLX answer (``TLX_FIELDS`` and ``condition_<name>``)."""
    rows = []
    for a in answers:
        if a.get("instrument") != "tlx":
            continue
        if study.tlx is None:
            raise ConfigError(f"{_where(a)}: the study {study.path} asks no NASA-TLX (no "
                              f"tlx:): is it the study these answers belong to?")
        s = _session(sessions, a)
        blocks = tlx_blocks(s["trial_order"], study.tlx.after)
        k = a.get("item")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(blocks):
            raise ConfigError(f"{_where(a)}: block {k!r}: the session has blocks "
                              f"0..{len(blocks) - 1}"[:300])
        try:
            ans = check_tlx_answer(a.get("answer") or {}, study.tlx.weights)
        except CosimError as e:
            raise ConfigError(f"{_where(a)}: {e}") from None
        per_trial = [trial_conditions(study, s, i) for i in blocks[k]]
        names = sorted({n for c in per_trial for n in c})
        conds = {}
        for n in names:
            values = {c.get(n) for c in per_trial}
            conds[f"condition_{n}"] = values.pop() if len(values) == 1 else None
        rows.append({"session": s["id"], "participant": s["participant"], "block": k,
                     "trials": len(blocks[k]), "raw_tlx": ans.raw,
                     "weighted_tlx": ans.weighted, **conds})
    return rows


def sagat_rows(study: Any, sessions: Mapping[str, Mapping[str, Any]],
               answers: Sequence[Mapping[str, Any]]) -> tuple[list[dict[str, Any]], int]:
    """(one row per scored question of each SAGAT answer, ``SAGAT_FIELDS``
    and ``condition_<name>``; the answers not scored)."""
    rows, unscored = [], 0
    for a in answers:
        if a.get("instrument") != "sagat":
            continue
        s = _session(sessions, a)
        k = a.get("item")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(study.sagat):
            raise ConfigError(f"{_where(a)}: probe {k!r}: the study {study.path} has "
                              f"{len(study.sagat)} SAGAT probes"[:300])
        scores = a.get("scores")
        if scores is None:
            unscored += 1
            continue
        probe = study.sagat[k]
        kinds = {q.id: q.kind for q in probe.questions}
        if not isinstance(scores, dict):
            raise ConfigError(f"{_where(a)}: scores: expected an object of the questions' "
                              f"scores, got {type(scores).__name__}")
        ti = a.get("trial_index")
        conds = {f"condition_{n}": v for n, v in
                 trial_conditions(study, s, ti if isinstance(ti, int) else -1).items()}
        for qid, sc in scores.items():
            if qid not in kinds:
                raise ConfigError(f"{_where(a)}: question {str(qid)[:40]!r} is not one of "
                                  f"probe {k}'s ({', '.join(kinds)})")
            correct = sc.get("correct") if isinstance(sc, dict) else None
            if not isinstance(correct, bool):
                raise ConfigError(f"{_where(a)}: {qid}.correct: expected true or false, got "
                                  f"{correct!r}"[:300])
            err = sc.get("error")
            rows.append({"session": s["id"], "participant": s["participant"],
                         "trial_index": ti, "probe": k, "at_s": probe.at_s, "question": qid,
                         "kind": kinds[qid], "correct": int(correct),
                         "error": float(err) if numeric([err]) is not None else None,
                         **conds})
    return rows, unscored


def _session(sessions: Mapping[str, Mapping[str, Any]], a: Mapping[str, Any]
             ) -> Mapping[str, Any]:
    s = sessions.get(str(a.get("session")))
    if s is None:
        raise ConfigError(f"{_where(a)}: no such session in the database")
    return s


def _levels(rows: Sequence[Mapping[str, Any]], name: str) -> tuple[list[Any], np.ndarray]:
    """(levels, each row's level; None where the row has no value) of a
    condition, grouped as the live analysis groups them."""
    raw = [r.get(f"condition_{name}") for r in rows]
    has = np.array([v is not None and v != "" for v in raw], dtype=bool)
    nums = numeric([v for v, h in zip(raw, has) if h])
    if nums is not None and nums.size:
        lv = np.full(len(rows), None, dtype=object)
        binned, _ = condition_levels(nums)
        lv[has] = [float(x) for x in binned]
        return sorted(set(lv[has].tolist())), lv
    return categories([str(v) if h else None for v, h in zip(raw, has)], name)


def _names(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    names = sorted({k[len("condition_"):] for r in rows for k in r
                    if k.startswith("condition_")})
    if len(names) > MAX_CONDITIONS:
        log.warning("%d conditions: the first %d analysed", len(names), MAX_CONDITIONS)
    return names[:MAX_CONDITIONS]


def _estimate_rows(rows: Sequence[Mapping[str, Any]], measure: str, as_proportion: bool,
                   groups: Sequence[tuple[str, Any, np.ndarray]], level: float
                   ) -> list[dict[str, Any]]:
    """Each (condition, level, rows selected)'s estimate of ``measure``."""
    y = np.array([np.nan if r.get(measure) is None else float(r[measure]) for r in rows])
    who = np.array([str(r["participant"]) for r in rows], dtype=object)
    out = []
    for cond, lvl, sel in groups:
        sel = sel & np.isfinite(y)
        est, lo, hi, how = level_estimate("detected" if as_proportion else measure, y[sel],
                                           who[sel], level)
        out.append({"condition": cond, "level": lvl, "n": int(sel.sum()),
                    "participants": len(set(who[sel])), "estimate": est, "ci_lo": lo,
                    "ci_hi": hi, "interval": how})
    return out


def _groups(rows: Sequence[Mapping[str, Any]]) -> list[tuple[str, Any, np.ndarray]]:
    """(condition, level, rows at it) of every condition's levels."""
    out = []
    for name in _names(rows):
        keys, lv = _levels(rows, name)
        out += [(name, k, np.array([v == k for v in lv], dtype=bool)) for k in keys]
    return out


def tlx_levels(rows: Sequence[Mapping[str, Any]], level: float = 0.95
               ) -> list[dict[str, Any]]:
    """Mean raw and weighted TLX at each level of each condition."""
    out = []
    groups = _groups(rows)
    for m in TLX_MEASURES:
        for e in _estimate_rows(rows, m, False, groups, level):
            out.append({"measure": m, "blocks": e.pop("n"), **e})
    return out


def sagat_levels(rows: Sequence[Mapping[str, Any]], level: float = 0.95
                 ) -> list[dict[str, Any]]:
    """Accuracy of each kind of question over all answers and at each level
    of each condition."""
    out = []
    for kind in sorted({r["kind"] for r in rows}):
        sub = [r for r in rows if r["kind"] == kind]
        groups = [(ALL, "", np.ones(len(sub), dtype=bool)), *_groups(sub)]
        for e in _estimate_rows(sub, "correct", True, groups, level):
            n = e.pop("n")
            out.append({"kind": kind, "questions": n, "accuracy": e.pop("estimate"), **e})
    return out


def analyse_instruments(study: Any, sessions: Sequence[Mapping[str, Any]],
                        answers: Sequence[Mapping[str, Any]], out_dir: str | Path, *,
                        level: float = 0.95, plots: bool = True) -> dict[str, Any]:
    """Write the TLX and SAGAT tables and figures (module docstring) into
    ``out_dir``; return a summary (counts, files). ``sessions``: the
    store's sessions with their ``trial_order``."""
    if len(answers) > MAX_ANSWERS:
        raise ConfigError(f"{len(answers)} NASA-TLX and SAGAT answers: more than {MAX_ANSWERS}; "
                          f"analyse a copy of the database with fewer sessions")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    by_id = {str(s["id"]): s for s in sessions}
    tlx = tlx_rows(study, by_id, answers)
    sagat, unscored = sagat_rows(study, by_id, answers)
    files = []
    tlx_lv = tlx_levels(tlx, level)
    sagat_lv = sagat_levels(sagat, level)
    for name, fields, rows in (
            ("tlx_blocks.csv", TLX_FIELDS, tlx), ("tlx_levels.csv", TLX_LEVEL_FIELDS, tlx_lv),
            ("sagat_questions.csv", SAGAT_FIELDS, sagat),
            ("sagat_levels.csv", SAGAT_LEVEL_FIELDS, sagat_lv)):
        conds = sorted({k for r in rows for k in r if k.startswith("condition_")})
        write_csv(out / name, (*fields, *conds), rows)
        files.append(name)
    if plots:
        from cosim.trials.instrument_figures import plot_sagat, plot_tlx

        plot_tlx(out / "tlx.png", tlx, tlx_lv, level)
        plot_sagat(out / "sagat.png", sagat_lv, level)
        files += ["tlx.png", "sagat.png"]
    return {"tlx_blocks": len(tlx), "participants": len({r["participant"] for r in tlx}),
            "sagat_questions": len(sagat), "sagat_correct": sum(r["correct"] for r in sagat),
            "sagat_unscored": unscored, "files": files}
