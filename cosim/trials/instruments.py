"""The human-factors instruments of a study: NASA-TLX after each block and
SAGAT freeze probes, their study-file keys and the answers to the TLX.

Owns the study keys ``tlx:`` and ``sagat:`` (read here, through the study
file's ``Reader``: every problem as ``file:line: path: message``), the six
TLX scales with their questions and anchors, the 15 pairwise comparisons,
the checking of a TLX answer posted by a browser and its scores. The SAGAT
questions, the true state at a freeze and the scoring of answers against it
are ``sagat``'s; storing is ``store``'s and serving ``server``'s.

NASA-TLX (Hart and Staveland 1988; Hart 2006): six scales rated 0 to 100 in
steps of 5 (the paper form's 21 marks), each a question with two anchors.
The raw TLX is the mean of the six ratings. With the weights, the
participant also chooses, of each of the 15 pairs of scales, the one that
contributed more to the workload of the task; a scale's weight is the number
of pairs it won (0 to 5, the six summing to 15), and the weighted TLX is the
sum of weight x rating over 15 (0 to 100).

Study keys::

    tlx: {after: block, weights: true}   # or after: session; weights: false (raw TLX)
    sagat:
      - at_s: 40                          # seconds into each live trial
        questions:
          - {id: where, kind: last_target, tolerance_m: 50}
          - {id: north, kind: count, sector: [[0, 0], [500, 0], [500, 500], [0, 500]]}
          - {id: fuel, kind: choice, which: lowest, of: fuel_kg}
          - {id: far, kind: choice, which: highest, of: distance_m, from: [0, 0]}

A block is the main (not practice) trials between two breaks
(``break_every``): ``after: block`` asks the TLX at each block's end (once,
at the session's end, when the study has no breaks); ``after: session``
once, after the last trial.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np

from cosim.errors import CosimError
from cosim.scenario.reader import Problems, Reader, describe
from cosim.trials.sagat import (
    CHOICE_OF,
    KINDS,
    MAX_COORD_M,
    MAX_PROBE_S,
    MAX_PROBES,
    MAX_QUESTIONS,
    MAX_SECTOR_VERTICES,
    MAX_TEXT_CHARS,
    WHICH,
    FreezeState,
    Probe,
    Question,
    check_answer,
    score,
)

#: the study file's keys read here
STUDY_KEYS = ("tlx", "sagat")
#: when the TLX is asked
TLX_AFTER = ("block", "session")
TLX_KEYS = ("after", "weights")
PROBE_KEYS = ("at_s", "questions")
QUESTION_KEYS = ("id", "kind", "text", "tolerance_m", "tolerance", "sector", "which", "of",
                 "from")
#: a question's id (a key of the answers the page posts)
QUESTION_ID = re.compile(r"[A-Za-z0-9_]{1,32}")
#: a rating's step and range (the paper form's 21 marks)
TLX_STEP, TLX_MAX = 5, 100
#: the seed stream of the pairs' order on the page (``tlx_pair_order``)
PAIRS_STREAM = 0x71C


class AnswerError(CosimError):
    """An answer posted by the participant's page that is not one."""


@dataclass(frozen=True)
class TlxScale:
    key: str
    title: str
    question: str
    low: str
    high: str


#: the six scales in the NASA-TLX form's order, its questions and anchors
TLX_SCALES: tuple[TlxScale, ...] = (
    TlxScale("mental", "Mental Demand", "How mentally demanding was the task?",
             "Very Low", "Very High"),
    TlxScale("physical", "Physical Demand", "How physically demanding was the task?",
             "Very Low", "Very High"),
    TlxScale("temporal", "Temporal Demand", "How hurried or rushed was the pace of the task?",
             "Very Low", "Very High"),
    TlxScale("performance", "Performance", "How successful were you in accomplishing what "
             "you were asked to do?", "Perfect", "Failure"),
    TlxScale("effort", "Effort", "How hard did you have to work to accomplish your level of "
             "performance?", "Very Low", "Very High"),
    TlxScale("frustration", "Frustration", "How insecure, discouraged, irritated, stressed, "
             "and annoyed were you?", "Very Low", "Very High"),
)
SCALE_KEYS = tuple(s.key for s in TLX_SCALES)
#: the 15 pairs of scales, each in the scales' order ("mental/physical", ...)
TLX_PAIRS: tuple[tuple[str, str], ...] = tuple(itertools.combinations(SCALE_KEYS, 2))


@dataclass(frozen=True)
class TlxSetting:
    after: str = "block"
    weights: bool = False


@dataclass(frozen=True)
class TlxAnswer:
    ratings: dict[str, int]
    #: each scale's wins among the 15 pairs; None without the weights
    weights: dict[str, int] | None

    @property
    def raw(self) -> float:
        return raw_tlx(self.ratings)

    @property
    def weighted(self) -> float | None:
        return None if self.weights is None else weighted_tlx(self.ratings, self.weights)


def raw_tlx(ratings: dict[str, int]) -> float:
    """The raw TLX: the mean of the six ratings."""
    return sum(ratings[k] for k in SCALE_KEYS) / len(SCALE_KEYS)


def tlx_weights(choices: dict[str, str]) -> dict[str, int]:
    """Each scale's weight: the pairs (``"a/b"`` -> the scale chosen) it won."""
    wins = dict.fromkeys(SCALE_KEYS, 0)
    for chosen in choices.values():
        wins[chosen] += 1
    return wins


def weighted_tlx(ratings: dict[str, int], weights: dict[str, int]) -> float:
    """The weighted TLX: sum of weight x rating over the 15 comparisons."""
    return sum(weights[k] * ratings[k] for k in SCALE_KEYS) / len(TLX_PAIRS)


def tlx_pair_order(seed: int, session_number: int, block: int) -> list[tuple[str, str]]:
    """The 15 pairs in the order (and left/right) the page shows them: drawn
    from the study's seed, so the same session's block shows the same."""
    rng = np.random.default_rng([seed, session_number, block, PAIRS_STREAM])
    out = []
    for i in rng.permutation(len(TLX_PAIRS)):
        a, b = TLX_PAIRS[int(i)]
        out.append((b, a) if rng.random() < 0.5 else (a, b))
    return out


def check_tlx_answer(d: dict[str, Any], weights: bool) -> TlxAnswer:
    """A TLX answer from a request body: ``ratings`` (each scale 0..100 in
    steps of 5) and, if the study asks the weights, ``pairs`` (every one of
    the 15 pairs ``"a/b"`` mapped to the scale chosen). ``AnswerError`` says
    what is wrong."""
    ratings = d.get("ratings")
    if not isinstance(ratings, dict) or set(ratings) != set(SCALE_KEYS):
        got = sorted(map(str, ratings))[:8] if isinstance(ratings, dict) else describe(ratings)
        raise AnswerError(f"ratings: expected a rating of each of {', '.join(SCALE_KEYS)}; "
                          f"got {got}"[:300])
    out: dict[str, int] = {}
    for k in SCALE_KEYS:
        v = ratings[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or not 0 <= v <= TLX_MAX or v % TLX_STEP:
            raise AnswerError(f"ratings.{k}: expected 0..{TLX_MAX} in steps of {TLX_STEP}, "
                              f"got {v!r}"[:300])
        out[k] = int(v)
    pairs = d.get("pairs")
    if not weights:
        if pairs is not None:
            raise AnswerError("pairs: this study asks no pairwise comparisons")
        return TlxAnswer(out, None)
    want = {f"{a}/{b}": (a, b) for a, b in TLX_PAIRS}
    if not isinstance(pairs, dict) or set(pairs) != set(want):
        missing = sorted(set(want) - set(pairs)) if isinstance(pairs, dict) else []
        extra = sorted(map(str, set(pairs) - set(want))) if isinstance(pairs, dict) else []
        raise AnswerError(f"pairs: expected the scale chosen of each of the {len(want)} pairs "
                          f"'a/b'; missing {missing[:4]}, not pairs {extra[:4]}"[:300]
                          if isinstance(pairs, dict) else
                          f"pairs: expected a mapping of the {len(want)} pairs 'a/b' to the "
                          f"scale chosen, got {describe(pairs)}"[:300])
    for name, (a, b) in want.items():
        if pairs[name] not in (a, b):
            raise AnswerError(f"pairs.{name}: expected {a!r} or {b!r}, got "
                              f"{pairs[name]!r}"[:300])
    return TlxAnswer(out, tlx_weights({k: pairs[k] for k in want}))


def tlx_blocks(trials: list[dict[str, Any]], after: str) -> list[list[int]]:
    """The blocks the TLX follows: lists of trial indices of the main (not
    practice) trials, split before each trial with a break (``after:
    block``), or all of them (``after: session``). ``trials``: a session's
    trial order (``index``, ``practice``, ``break_before``)."""
    blocks: list[list[int]] = []
    for t in trials:
        if t.get("practice"):
            continue
        if not blocks or (after == "block" and t.get("break_before")):
            blocks.append([])
        blocks[-1].append(int(t["index"]))
    return blocks


# --- the study keys -------------------------------------------------------------------------
def parse_tlx(ctx: Problems, spec: Any) -> TlxSetting | None:
    """The ``tlx:`` key: ``{after, weights}``, ``true`` (after each block,
    raw) or ``false`` (none)."""
    if spec is False or spec is None:
        return None
    if spec is True:
        return TlxSetting()
    r = Reader(ctx, spec, ("tlx",), TLX_KEYS)
    after = r.string("after", "block", choices=TLX_AFTER)
    return TlxSetting(after=after or "block", weights=r.boolean("weights", False))


def parse_sagat(ctx: Problems, spec: Any) -> tuple[Probe, ...]:
    """The ``sagat:`` key: a list of probes, each ``{at_s, questions}``."""
    if not isinstance(spec, list) or not spec:
        ctx.err(("sagat",), f"expected a list of probes ({{at_s, questions}}), got "
                            f"{describe(spec)}")
        return ()
    if len(spec) > MAX_PROBES:
        ctx.err(("sagat",), f"{len(spec)} probes; a study may have at most {MAX_PROBES}")
        return ()
    probes: list[Probe] = []
    for i, item in enumerate(spec):
        at = ("sagat", i)
        r = Reader(ctx, item, at, PROBE_KEYS)
        at_s = r.num("at_s", lo=0, lo_open=True, hi=MAX_PROBE_S)
        qs = r.d.get("questions")
        if not isinstance(qs, list) or not qs or len(qs) > MAX_QUESTIONS:
            got = f"{len(qs)}" if isinstance(qs, list) else describe(qs)
            ctx.err(at + ("questions",), f"expected a list of 1 to {MAX_QUESTIONS} questions, "
                                         f"got {got}")
            continue
        asked = [_question(ctx, q, at + ("questions", j), j) for j, q in enumerate(qs)]
        questions = [q for q in asked if q is not None]
        ids = [q.id for q in questions]
        twice = sorted({x for x in ids if ids.count(x) > 1})
        if twice:
            ctx.err(at + ("questions",), f"question ids given twice: {', '.join(twice)}")
        if at_s is not None and len(questions) == len(qs) and not twice:
            probes.append(Probe(index=i, at_s=float(at_s), questions=tuple(questions)))
    times = [p.at_s for p in probes]
    if times != sorted(set(times)):
        ctx.err(("sagat",), "the probes' at_s must rise from one probe to the next")
    return tuple(probes)


def check_probe_times(ctx: Problems, probes: tuple[Probe, ...],
                      durations: dict[str, float | None]) -> None:
    """A probe at or after the end of a live condition (``{id: duration_s}``;
    None: the scenario's own, not checked here) would never be asked: refused."""
    for p in probes:
        ends = {cid: d for cid, d in durations.items() if d is not None and p.at_s >= d}
        if ends:
            shown = ", ".join(f"{cid} ({d:g} s)" for cid, d in list(ends.items())[:5])
            ctx.err(("sagat", p.index, "at_s"), f"{p.at_s:g} s: not before the end of "
                                                f"condition {shown}: the probe would never be "
                                                f"asked")


def check_fuel_questions(ctx: Problems, probes: tuple[Probe, ...],
                         no_fuel: dict[str, tuple[str, ...]]) -> None:
    """A fuel question where a live condition (``{id: its vehicles whose
    class records no fuel}``) has aircraft without fuel could not be scored:
    refused."""
    lacking = {cid: ids for cid, ids in no_fuel.items() if ids}
    if not lacking:
        return
    shown = "; ".join(f"{cid}: {', '.join(ids[:5])}{' ...' if len(ids) > 5 else ''}"
                      for cid, ids in list(lacking.items())[:5])
    for p in probes:
        for j, q in enumerate(p.questions):
            if q.of == "fuel_kg":
                ctx.err(("sagat", p.index, "questions", j, "of"),
                        f"fuel_kg: aircraft of these conditions record no fuel (their class "
                        f"has none: a batched fixed-wing, a multirotor or a ground vehicle), "
                        f"so the answer could not be scored: {shown}")


def _question(ctx: Problems, d: Any, at: tuple[Any, ...], j: int) -> Question | None:
    before = len(ctx.problems)
    r = Reader(ctx, d, at, QUESTION_KEYS)
    kind = r.string("kind", choices=KINDS)
    qid = r.string("id", f"q{j}")
    if isinstance(qid, str) and not QUESTION_ID.fullmatch(qid):
        ctx.err(at + ("id",), f"{qid[:40]!r}: 1-32 letters, digits and '_'")
    text = r.string("text", "")
    if isinstance(text, str) and len(text) > MAX_TEXT_CHARS:
        ctx.err(at + ("text",), f"{len(text)} characters; at most {MAX_TEXT_CHARS}")
    allowed = {"last_target": {"tolerance_m"}, "count": {"sector", "tolerance"},
               "choice": {"which", "of", "from"}}.get(kind or "", set())
    for k in ("tolerance_m", "tolerance", "sector", "which", "of", "from"):
        if k in r.d and kind is not None and k not in allowed:
            ctx.err(at + (k,), f"not a key of a {kind} question (its keys: "
                               f"{', '.join(sorted(allowed))})")
    tol_m = r.num("tolerance_m", 50.0, lo=0, lo_open=True, hi=MAX_COORD_M)
    tol = r.integer("tolerance", 0, lo=0, hi=1000)
    sector: tuple[tuple[float, float], ...] = ()
    which = of = None
    point: tuple[float, float] | None = None
    if kind == "count":
        sector = _points(ctx, r.d.get("sector"), at + ("sector",), 3, MAX_SECTOR_VERTICES) \
            if "sector" in r.d else ()
        if "sector" not in r.d:
            ctx.err(at, "missing required key 'sector' (the polygon's corners, [north_m, "
                        "east_m] each)")
    elif kind == "choice":
        which = r.string("which", choices=WHICH)
        of = r.string("of", choices=CHOICE_OF)
        if of == "distance_m":
            if "from" not in r.d:
                ctx.err(at, "missing required key 'from' (the point [north_m, east_m] the "
                            "distance is from)")
            else:
                pts = _points(ctx, [r.d["from"]], at + ("from",), 1, 1)
                point = pts[0] if pts else None
        elif "from" in r.d and of is not None:
            ctx.err(at + ("from",), f"only a distance_m question has a point; this one asks "
                                    f"{of}")
    if len(ctx.problems) != before or kind is None:
        return None
    return Question(id=qid, kind=kind, text=text or "", tolerance_m=float(tol_m or 50.0),
                    tolerance=int(tol or 0), sector=sector, which=which, of=of, point=point)


def _points(ctx: Problems, v: Any, at: tuple[Any, ...], lo: int, hi: int
            ) -> tuple[tuple[float, float], ...]:
    """``[[north_m, east_m], ...]``, ``lo`` to ``hi`` points within
    ``MAX_COORD_M``."""
    if not isinstance(v, list) or not lo <= len(v) <= hi:
        ctx.err(at, f"expected {lo}{f' to {hi}' if hi != lo else ''} points [north_m, east_m], "
                    f"got {describe(v) if not isinstance(v, list) else f'{len(v)}'}")
        return ()
    out = []
    for p in v:
        if not (isinstance(p, list) and len(p) == 2 and all(
                not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)
                and abs(x) <= MAX_COORD_M for x in p)):
            ctx.err(at, f"expected a point [north_m, east_m] within +-{MAX_COORD_M:g} m, got "
                        f"{describe(p) if not isinstance(p, list) else repr(p)[:80]}")
            return ()
        out.append((float(p[0]), float(p[1])))
    return tuple(out)


# --- a session's instruments, as the server serves and stores them ------------------------
def tlx_page(study: Any, session: dict[str, Any], block: int, trial_index: int
             ) -> dict[str, Any]:
    """What the participant's page shows for the TLX of ``block``: the
    scales (questions and anchors) and, with weights, the 15 pairs in the
    session's order."""
    setting: TlxSetting = study.tlx
    pairs = tlx_pair_order(study.seed, session["session_number"], block) \
        if setting.weights else None
    return {"instrument": "tlx", "block": block, "trial_index": trial_index,
            "step": TLX_STEP, "max": TLX_MAX,
            "scales": [{"key": s.key, "title": s.title, "question": s.question, "low": s.low,
                        "high": s.high} for s in TLX_SCALES],
            "pairs": None if pairs is None else [list(p) for p in pairs]}


def pending_tlx(study: Any, session: dict[str, Any], answered: set[int],
                stored_blocks: set[int]) -> dict[str, Any] | None:
    """The TLX the session's page asks now (``tlx_page``): the first block
    whose trials all have their response (``answered``: trial indices) and
    no TLX stored (``stored_blocks``); None if none is due."""
    if study.tlx is None:
        return None
    for k, block in enumerate(tlx_blocks(session["trial_order"], study.tlx.after)):
        if k not in stored_blocks and all(i in answered for i in block):
            return tlx_page(study, session, k, block[-1])
    return None


def tlx_row(study: Any, session: dict[str, Any], body: dict[str, Any], answered: set[int]
            ) -> dict[str, Any]:
    """The store's row of a posted TLX answer (``{instrument: "tlx", block,
    ratings, pairs}``); ``AnswerError`` if the study asks none, the block is
    not one or not over, or the answer is malformed."""
    if study.tlx is None:
        raise AnswerError("this study asks no NASA-TLX")
    blocks = tlx_blocks(session["trial_order"], study.tlx.after)
    k = body.get("block")
    if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(blocks):
        raise AnswerError(f"block: expected 0..{len(blocks) - 1}, got {k!r}"[:200])
    if not all(i in answered for i in blocks[k]):
        raise AnswerError(f"block {k}: its trials are not all answered yet")
    a = check_tlx_answer(body, study.tlx.weights)
    answer: dict[str, Any] = {"ratings": a.ratings}
    if a.weights is not None:
        answer.update(pairs={f"{x}/{y}": body["pairs"][f"{x}/{y}"] for x, y in TLX_PAIRS},
                      weights=a.weights)
    return {"session": session["id"], "participant": session["participant"],
            "instrument": "tlx", "trial_index": blocks[k][-1], "item": k, "answer": answer,
            "raw_tlx": a.raw, "weighted_tlx": a.weighted}


def sagat_page(study: Any, probe: int) -> dict[str, Any]:
    """What the page asks at probe ``probe`` (never the answers)."""
    if not 0 <= probe < len(study.sagat):
        raise AnswerError(f"probe: this study has {len(study.sagat)} SAGAT probes; no "
                          f"probe {probe}")
    p: Probe = study.sagat[probe]
    return {"instrument": "sagat", "probe": probe, "at_s": p.at_s,
            "questions": [q.page_view() for q in p.questions]}


def sagat_row(study: Any, session: dict[str, Any], body: dict[str, Any]) -> dict[str, Any]:
    """The store's row of posted SAGAT answers (``{instrument: "sagat",
    trial_index, probe, answers: {question id: answer}}``), unscored;
    ``AnswerError`` says what is wrong."""
    ti, k = body.get("trial_index"), body.get("probe")
    n = len(session["trial_order"])
    if isinstance(ti, bool) or not isinstance(ti, int) or not 0 <= ti < n:
        raise AnswerError(f"trial_index: expected 0..{n - 1}, got {ti!r}"[:200])
    if isinstance(k, bool) or not isinstance(k, int):
        raise AnswerError(f"probe: expected a probe number, got {k!r}"[:200])
    sagat_page(study, k)  # in range
    probe: Probe = study.sagat[k]
    answers = body.get("answers")
    ids = [q.id for q in probe.questions]
    if not isinstance(answers, dict) or set(answers) != set(ids):
        got = sorted(map(str, answers))[:8] if isinstance(answers, dict) else describe(answers)
        raise AnswerError(f"answers: expected an answer to each of {', '.join(ids)}; got "
                          f"{got}"[:300])
    try:
        checked = {q.id: check_answer(q, answers[q.id]) for q in probe.questions}
    except ValueError as e:
        raise AnswerError(f"answers.{e}") from None
    return {"session": session["id"], "participant": session["participant"],
            "instrument": "sagat", "trial_index": ti, "item": k, "answer": checked}


def score_probe(probe: Probe, state: FreezeState, answers: dict[str, Any]
                ) -> dict[str, dict[str, Any]]:
    """Each question's score (``sagat.score``) as the store keeps it."""
    out = {}
    for q in probe.questions:
        s = score(q, state, answers[q.id])
        out[q.id] = {"correct": s.correct, "error": s.error, "truth": s.truth}
    return out


# --- the answers as CSV (``cosim trials export --instruments``) ---------------------------
#: the columns of the instruments' CSV, in order: a row per TLX block or SAGAT probe
EXPORT_COLUMNS = ("session", "participant", "instrument", "trial_index", "item", "raw_tlx",
                  "weighted_tlx", *(f"rating_{k}" for k in SCALE_KEYS),
                  *(f"weight_{k}" for k in SCALE_KEYS), "sagat_correct", "sagat_questions")


def write_instruments_csv(rows: list[dict[str, Any]], f: TextIO) -> None:
    """Instrument answers (``Store.instrument_answers()`` rows) as CSV with
    ``EXPORT_COLUMNS``: a TLX's ratings and weights a column each (weights
    empty without them), a probe's count of correct answers of those scored
    (both empty until scored). Text a spreadsheet would run as a formula is
    neutralised (``spreadsheet.SafeWriter``)."""
    from cosim.trials.spreadsheet import SafeWriter

    w = SafeWriter(f)
    w.writerow(EXPORT_COLUMNS)
    for r in rows:
        a = r["answer"] if r["instrument"] == "tlx" else {}
        ratings, weights = a.get("ratings", {}), a.get("weights") or {}
        cells = [r["session"], r["participant"], r["instrument"], r["trial_index"], r["item"],
                 r["raw_tlx"], r["weighted_tlx"], *(ratings.get(k) for k in SCALE_KEYS),
                 *(weights.get(k) for k in SCALE_KEYS), r["correct"], r["questions"]]
        w.writerow(["" if c is None else repr(c) if isinstance(c, float) else str(c)
                    for c in cells])
