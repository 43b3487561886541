"""`cosim trials analyse` on a study's NASA-TLX and SAGAT answers: the raw
and weighted TLX per participant and block, the TLX against each condition
with t intervals over participants, and SAGAT accuracy per kind of question
and condition equal values worked out by hand (and scipy's t interval); bad
answers are refused with exit 2 and a message naming the answer."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
from scipy import stats
from test_live import PROFILE, live_study
from test_live_results import analyse_ok, csv_rows, live_session

from cosim.cli import main
from cosim.trials.instruments import SCALE_KEYS
from cosim.trials.store import Store
from cosim.trials.study import Study, load_study

STUDY = """\
name: instruments
protocol: live
scenarios:
  - {id: one, scenario: pair.yaml, feeds: [uav1/belly], conditions: {feeds: 1}}
  - {id: two, scenario: pair.yaml, feeds: [uav1/belly, uav2/belly], conditions: {feeds: 2}}
order: shuffle
tlx: {after: block, weights: true}
sagat:
  - at_s: 2
    questions:
      - {id: where, kind: last_target, tolerance_m: 50}
      - {id: n, kind: count, sector: [[0, 0], [100, 0], [100, 100], [0, 100]]}
"""
#: p1's block with one feed: raw (60 + 10 + 40 + 30 + 50 + 20) / 6 = 35; every pair won by
#: its first scale, weights 5, 4, 3, 2, 1, 0: weighted (300 + 40 + 120 + 60 + 50) / 15 = 38
VARIED = dict(zip(SCALE_KEYS, (60, 10, 40, 30, 50, 20)))
FIRST = {f"{a}/{b}": a for a, b in itertools.combinations(SCALE_KEYS, 2)}
FIRST_WEIGHTS = dict(zip(SCALE_KEYS, (5, 4, 3, 2, 1, 0)))
# (participant, its trials' conditions, its TLX per block (ratings; all equal if a number),
#  its SAGAT scores per trial: (where correct, n correct) or None for unscored)
PEOPLE: list[tuple[str, list[str], list[Any], list[Any]]] = [
    ("p1", ["one", "two"], [VARIED, 60], [(True, False), (True, True)]),
    ("p2", ["two", "one"], [55, 30], [(False, True), (True, False)]),
    ("p3", ["one", "two"], [40, 80], [None, (True, True)]),
]


def _sessions(store: Store, study: Study) -> dict[str, dict[str, Any]]:
    out = {}
    for who, conds, tlx, sagat in PEOPLE:
        s = out[who] = live_session(store, study, who, conds, breaks=True)
        for k, r in enumerate(tlx):
            ratings = r if isinstance(r, dict) else dict.fromkeys(SCALE_KEYS, r)
            store.record_instrument({
                "session": s["id"], "participant": who, "instrument": "tlx", "trial_index": k,
                "item": k, "answer": {"ratings": ratings, "pairs": FIRST,
                                      "weights": FIRST_WEIGHTS},
                "raw_tlx": None, "weighted_tlx": None})
        for ti, sc in enumerate(sagat):
            scores = None if sc is None else {
                q: {"correct": c, "error": 0.0, "truth": None} for q, c in zip(("where", "n"), sc)}
            store.record_instrument({
                "session": s["id"], "participant": who, "instrument": "sagat",
                "trial_index": ti, "item": 0, "answer": {"where": [0, 0], "n": 1},
                "scores": scores, "questions": None if sc is None else 2,
                "correct": None if sc is None else sum(sc)})
    return out


@pytest.fixture
def db(tmp_path: Path) -> tuple[Path, Path, dict[str, dict[str, Any]]]:
    study = live_study(tmp_path, STUDY)
    path = tmp_path / "i.sqlite"
    with Store(path) as store:
        sessions = _sessions(store, load_study(study))
    return study, path, sessions


def test_tlx_and_sagat_summaries_equal_the_hand_computed(
        db: tuple[Path, Path, dict[str, dict[str, Any]]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    study, path, s = db
    out = tmp_path / "a"
    printed = analyse_ok(path, study, out, capsys)
    assert ("instruments: 6 NASA-TLX blocks of 3 participants; SAGAT 7 of 10 questions "
            "answered correctly (1 probes' answers stored unscored, left out)") in printed
    blocks = {(r["participant"], r["block"]): (float(r["raw_tlx"]), float(r["weighted_tlx"]),
                                               r["condition_feeds"])
              for r in csv_rows(out / "tlx_blocks.csv")}
    assert blocks == {("p1", "0"): (35.0, 38.0, "1"), ("p1", "1"): (60.0, 60.0, "2"),
                      ("p2", "0"): (55.0, 55.0, "2"), ("p2", "1"): (30.0, 30.0, "1"),
                      ("p3", "0"): (40.0, 40.0, "1"), ("p3", "1"): (80.0, 80.0, "2")}
    levels = {(r["measure"], r["level"]): r for r in csv_rows(out / "tlx_levels.csv")}
    # one block a participant at each level: the t interval over the three participants
    for (measure, lvl), values in {("raw_tlx", "1"): [35, 30, 40],
                                   ("weighted_tlx", "1"): [38, 30, 40],
                                   ("raw_tlx", "2"): [60, 55, 80]}.items():
        r = levels[(measure, lvl)]
        lo, hi = stats.t.interval(0.95, 2, loc=sum(values) / 3, scale=stats.sem(values))
        assert float(r["estimate"]) == pytest.approx(sum(values) / 3)
        assert (float(r["ci_lo"]), float(r["ci_hi"])) == (pytest.approx(lo, abs=1e-3),
                                                          pytest.approx(hi, abs=1e-3))
        assert (r["blocks"], r["participants"], r["interval"]) == \
            ("3", "3", "t over participants")
    acc = {(r["kind"], r["condition"], r["level"]): (float(r["accuracy"]), r["questions"],
                                                     r["participants"])
           for r in csv_rows(out / "sagat_levels.csv")}
    # last_target: right 4 times of 5 (p2 wrong with two feeds); count: 3 of 5
    assert acc == {("last_target", "(all)", ""): (0.8, "5", "3"),
                   ("last_target", "feeds", "1"): (1.0, "2", "2"),
                   ("last_target", "feeds", "2"): (pytest.approx(2 / 3), "3", "3"),
                   ("count", "(all)", ""): (0.6, "5", "3"),
                   ("count", "feeds", "1"): (0.0, "2", "2"),
                   ("count", "feeds", "2"): (1.0, "3", "3")}
    assert len(csv_rows(out / "sagat_questions.csv")) == 10
    for name in ("tlx.png", "sagat.png"):
        assert (out / name).stat().st_size > 10_000


def test_a_block_of_mixed_conditions_is_left_out_of_them(tmp_path: Path) -> None:
    """With the TLX after the session, its one block has both conditions: no
    level of feeds holds it."""
    from cosim.trials.instrument_analysis import tlx_levels, tlx_rows

    study = load_study(live_study(tmp_path, STUDY.replace("after: block", "after: session")))
    with Store(tmp_path / "m.sqlite") as store:
        s = _sessions(store, study)["p1"]
        answers = store.instrument_answers(s["id"], "tlx")
    rows = tlx_rows(study, {s["id"]: s}, answers[:1])
    assert rows[0]["condition_feeds"] is None and rows[0]["trials"] == 2
    assert tlx_levels(rows) == []


@pytest.mark.parametrize("change, match", [
    (("tlx", {"ratings": {**dict.fromkeys(SCALE_KEYS, 50), "mental": 7}, "pairs": FIRST}),
     r"session \S+ tlx answer 0: ratings\.mental: expected 0\.\.100 in steps of 5, got 7"),
    (("tlx", {"ratings": dict.fromkeys(SCALE_KEYS, 50), "pairs": {**FIRST, "mental/physical":
                                                                  "effort"}}),
     r"tlx answer 0: pairs\.mental/physical: expected 'mental' or 'physical', got 'effort'"),
    (("sagat", {"where": {"correct": "yes"}}),
     r"sagat answer 0: where\.correct: expected true or false, got 'yes'"),
    (("sagat", {"fuel": {"correct": True}}),
     r"sagat answer 0: question 'fuel' is not one of probe 0's \(where, n\)"),
])
def test_bad_answers_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                             change: tuple[str, Any], match: str) -> None:
    import re

    study = live_study(tmp_path, STUDY)
    path = tmp_path / "b.sqlite"
    with Store(path) as store:
        st = load_study(study)
        s = store.create_session(
            participant="p9", study=st.name, protocol="live", display=PROFILE,
            order_method="shuffle", seed=1, session_number=0,
            trial_order=[{"index": 0, "practice": False, "clip": 0, "condition_id": "one",
                          "fingerprint": st.live[0].fingerprint, "break_before": False}])
        kind, value = change
        store.record_instrument({"session": s["id"], "participant": "p9", "instrument": kind,
                                 "trial_index": 0, "item": 0,
                                 "answer": value if kind == "tlx" else {},
                                 "scores": value if kind == "sagat" else None})
    assert main(["-q", "trials", "analyse", str(path), "--study", str(study), "--out",
                 str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert re.search(match, err) and "Traceback" not in err, err


def test_answers_of_another_study_refused(
        db: tuple[Path, Path, dict[str, dict[str, Any]]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    study, path, _ = db
    study.write_text(STUDY.split("tlx:")[0])  # no tlx: and no sagat:
    assert main(["-q", "trials", "analyse", str(path), "--study", str(study), "--out",
                 str(tmp_path / "a")]) == 2
    assert "asks no NASA-TLX (no tlx:): is it the study these answers belong to?" in \
        capsys.readouterr().err


def test_the_answers_analysed_are_bounded(
        db: tuple[Path, Path, dict[str, dict[str, Any]]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    import cosim.trials.instrument_analysis as ia

    study, path, _ = db
    monkeypatch.setattr(ia, "MAX_ANSWERS", 11)  # 6 TLX and 6 SAGAT answers
    assert main(["-q", "trials", "analyse", str(path), "--study", str(study), "--out",
                 str(tmp_path / "a")]) == 2
    assert "12 NASA-TLX and SAGAT answers: more than 11; analyse a copy" in \
        capsys.readouterr().err


def test_a_clip_studys_tlx_is_analysed_against_its_clips_conditions(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A clip study (sessions made by the trial server, so with its trial
    orders) whose clips name an altitude: each block of one clip has that
    clip's altitude, the raw TLX (no weights asked) is analysed against it,
    the weighted TLX is empty, and the clip responses' tables are still
    written."""
    from test_server import asgi, small_study

    from cosim.trials.server import make_app

    study = small_study(tmp_path, "protocol: disappear\nbreak_every: 1\norder: shuffle\n"
                                  "tlx: {after: block, weights: false}\n",
                        {"a": 150.0, "b": 120.0})
    study.write_text(study.read_text()
                     .replace("ground_truth: a.gt.csv}", "ground_truth: a.gt.csv, "
                                                          "conditions: {alt_agl_m: 100}}")
                     .replace("ground_truth: b.gt.csv}", "ground_truth: b.gt.csv, "
                                                          "conditions: {alt_agl_m: 300}}"))
    db = tmp_path / "c.sqlite"
    st = load_study(study)
    alt = {c.id: c.conditions[0][1] for c in st.clips}
    want: dict[str, list[float]] = {"100": [], "300": []}
    with Store(db) as store:
        app = make_app(study, store)
        for i, who in enumerate(("p1", "p2", "p3")):
            status, s = asgi(app, "POST", "/api/sessions", {"participant": who, **PROFILE})
            assert status == 201, s
            stored = store.session(s["id"])
            assert stored is not None
            for k, t in enumerate(stored["trial_order"]):
                v = 20 + 10 * i + (30 if alt[t["clip_id"]] == "300" else 0)
                want[alt[t["clip_id"]]].append(v)
                store.record_instrument({
                    "session": s["id"], "participant": who, "instrument": "tlx",
                    "trial_index": k, "item": k,
                    "answer": {"ratings": dict.fromkeys(SCALE_KEYS, v)}})
    out = tmp_path / "a"
    printed = analyse_ok(db, study, out, capsys)
    assert "instruments: 6 NASA-TLX blocks of 3 participants" in printed
    assert (out / "conspicuity.csv").is_file()
    assert {r["weighted_tlx"] for r in csv_rows(out / "tlx_blocks.csv")} == {""}
    got = {r["level"]: float(r["estimate"]) for r in csv_rows(out / "tlx_levels.csv")
           if r["measure"] == "raw_tlx" and r["condition"] == "alt_agl_m"}
    assert got == {"100": pytest.approx(30.0), "300": pytest.approx(60.0)}
    assert got == {k: pytest.approx(sum(v) / len(v)) for k, v in want.items()}


def test_the_synthetic_answers_model_is_recovered(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """examples/instruments_synthetic.py: at every number of feeds the model's
    TLX (25 + 5 x feeds, plus the twelve participants' mean offset) and each
    kind's probability of a right answer lie within the intervals found."""
    import importlib.util
    import sys

    import numpy as np

    from cosim.trials.instrument_analysis import analyse_instruments

    path = Path(__file__).resolve().parents[2] / "examples" / "instruments_synthetic.py"
    spec = importlib.util.spec_from_file_location("instruments_synthetic", path)
    assert spec is not None and spec.loader is not None
    ex = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, ex)  # its dataclasses look themselves up
    spec.loader.exec_module(ex)
    st, sessions, answers = ex.synthetic(1)
    analyse_instruments(st, sessions, answers, tmp_path, plots=False)
    tlx = {r["level"]: r for r in csv_rows(tmp_path / "tlx_levels.csv")
           if r["measure"] == "raw_tlx"}
    # the offsets' mean is in every level's mean: the level's mean less the model's
    offsets = [float(tlx[str(k)]["estimate"]) - ex.TLX_0 - ex.TLX_PER_FEED * k
               for k in ex.FEEDS]
    assert float(np.ptp(offsets)) < 3.0, offsets  # the same offset at every level
    for k in ex.FEEDS:
        r = tlx[str(k)]
        assert float(r["ci_lo"]) <= ex.TLX_0 + ex.TLX_PER_FEED * k <= float(r["ci_hi"]), r
    for r in csv_rows(tmp_path / "sagat_levels.csv"):
        if r["condition"] == "feeds":
            a, b = ex.SAGAT[r["kind"]]
            assert float(r["ci_lo"]) <= a + b * int(r["level"]) <= float(r["ci_hi"]), r
