"""The NASA-TLX and SAGAT instruments: scores, study keys, the store and the
server's API (straight into the ASGI app, no socket)."""

from __future__ import annotations

import math
import re
import sqlite3
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from matplotlib.path import Path as MplPath
from test_server import PROFILE, _session, asgi, live_server, participant_page, small_study
from test_store import CLIPS, write_study

from cosim.errors import ConfigError
from cosim.scenario.reader import Problems
from cosim.scenario.yaml_lines import load_with_lines
from cosim.trials.instruments import (
    SCALE_KEYS,
    TLX_PAIRS,
    AnswerError,
    check_tlx_answer,
    parse_sagat,
    raw_tlx,
    tlx_blocks,
    tlx_pair_order,
    tlx_weights,
    weighted_tlx,
)
from cosim.trials.sagat import (
    FreezeState,
    Question,
    ScoringError,
    TargetAt,
    VehicleAt,
    from_state_log,
    inside_polygon,
    score,
)
from cosim.trials.server import make_app
from cosim.trials.store import Store
from cosim.trials.study import load_study

# a hand-worked TLX: the ratings, and the pairs won in the order
# mental > effort > temporal > performance > frustration > physical
RATINGS = {"mental": 70, "physical": 15, "temporal": 55, "performance": 30, "effort": 60,
           "frustration": 40}
ORDER = ["mental", "effort", "temporal", "performance", "frustration", "physical"]
PAIRS = {f"{a}/{b}": min(a, b, key=ORDER.index) for a, b in TLX_PAIRS}


# --- TLX ---
def test_tlx_scores_as_the_published_procedure_gives_them() -> None:
    """Raw: (70 + 15 + 55 + 30 + 60 + 40) / 6 = 45. Weights (pairs won): 5, 0,
    3, 2, 4, 1; weighted: (5*70 + 0*15 + 3*55 + 2*30 + 4*60 + 1*40) / 15 =
    855 / 15 = 57."""
    a = check_tlx_answer({"ratings": RATINGS, "pairs": PAIRS}, weights=True)
    assert a.weights == {"mental": 5, "physical": 0, "temporal": 3, "performance": 2,
                         "effort": 4, "frustration": 1}
    assert a.raw == 45.0 and raw_tlx(RATINGS) == 45.0
    assert a.weighted == pytest.approx(57.0, abs=1e-12)
    raw_only = check_tlx_answer({"ratings": RATINGS}, weights=False)
    assert (raw_only.raw, raw_only.weighted, raw_only.weights) == (45.0, None, None)


def test_tlx_weights_count_each_scales_wins_whatever_the_choices() -> None:
    """Intransitive choices are the participant's to make: each scale's weight
    is its wins (0-5), the six summing to 15; equal weights give the raw TLX."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        choices = {f"{a}/{b}": (a, b)[rng.integers(2)] for a, b in TLX_PAIRS}
        w = tlx_weights(choices)
        assert sum(w.values()) == 15 and all(0 <= v <= 5 for v in w.values())
        for k in SCALE_KEYS:
            assert w[k] == sum(1 for c in choices.values() if c == k)
        r = {k: int(v) for k, v in zip(SCALE_KEYS, rng.integers(0, 21, 6) * 5)}
        assert weighted_tlx(r, w) == pytest.approx(
            sum(w[k] * r[k] for k in SCALE_KEYS) / 15, abs=1e-12)
    # a cyclic tournament: every scale wins 2 or 3 (3 + 3 + 3 + 2 + 2 + 2 = 15)
    cyc = {f"{a}/{b}": a if (SCALE_KEYS.index(b) - SCALE_KEYS.index(a)) % 6 <= 3 else b
           for a, b in TLX_PAIRS}
    assert sorted(tlx_weights(cyc).values()) == [2, 2, 2, 3, 3, 3]


def test_the_pairs_are_all_15_once_in_an_order_drawn_from_the_seed() -> None:
    order = tlx_pair_order(7, 2, 1)
    assert len(order) == 15 and {tuple(sorted(p, key=SCALE_KEYS.index)) for p in order} == \
        set(TLX_PAIRS)
    assert order == tlx_pair_order(7, 2, 1) and order != tlx_pair_order(7, 3, 1)


@pytest.mark.parametrize("body, weights, match", [
    ({"ratings": {**RATINGS, "mental": 52}}, False, r"ratings\.mental: expected 0\.\.100 in "
                                                   r"steps of 5, got 52"),
    ({"ratings": {**RATINGS, "effort": 105}}, False, r"ratings\.effort: .* got 105"),
    ({"ratings": {**RATINGS, "effort": -5}}, False, r"ratings\.effort: .* got -5"),
    ({"ratings": {**RATINGS, "effort": math.nan}}, False, r"ratings\.effort: .* got nan"),
    ({"ratings": {**RATINGS, "effort": "60"}}, False, r"ratings\.effort: .* got '60'"),
    ({"ratings": {**RATINGS, "effort": True}}, False, r"ratings\.effort: .* got True"),
    ({"ratings": {k: v for k, v in RATINGS.items() if k != "effort"}}, False,
     r"ratings: expected a rating of each of mental, physical"),
    ({"ratings": {**RATINGS, "boredom": 5}}, False, r"ratings: expected a rating of each"),
    ({"ratings": [70, 15]}, False, r"ratings: expected .* got a list"),
    ({"ratings": RATINGS, "pairs": PAIRS}, False, r"pairs: this study asks no pairwise"),
    ({"ratings": RATINGS}, True, r"pairs: expected a mapping of the 15 pairs"),
    ({"ratings": RATINGS, "pairs": {k: v for k, v in PAIRS.items() if k != "effort/frustration"}},
     True, r"pairs: expected the scale chosen of each of the 15 pairs 'a/b'; missing "
           r"\['effort/frustration'\]"),
    ({"ratings": RATINGS, "pairs": {**PAIRS, "mental/physical": "effort"}}, True,
     r"pairs\.mental/physical: expected 'mental' or 'physical', got 'effort'"),
    ({"ratings": RATINGS, "pairs": {**PAIRS, "physical/mental": "mental"}}, True,
     r"not pairs \['physical/mental'\]"),
])
def test_malformed_tlx_answers_are_refused(body: dict[str, Any], weights: bool,
                                           match: str) -> None:
    with pytest.raises(AnswerError, match=match):
        check_tlx_answer(body, weights)


def test_blocks_are_the_main_trials_between_breaks() -> None:
    trials = [{"index": 0, "practice": True, "break_before": False}] + [
        {"index": i, "practice": False, "break_before": i in (3, 5)} for i in range(1, 7)]
    assert tlx_blocks(trials, "block") == [[1, 2], [3, 4], [5, 6]]
    assert tlx_blocks(trials, "session") == [[1, 2, 3, 4, 5, 6]]


# --- study keys ---
def test_study_reads_tlx_and_leaves_other_studies_as_they_were(tmp_path: Path) -> None:
    st = load_study(write_study(tmp_path, "protocol: disappear\n" + CLIPS))
    assert st.tlx is None and st.sagat == ()
    st = load_study(write_study(tmp_path, "protocol: disappear\ntlx: {after: session, "
                                          "weights: true}\n" + CLIPS))
    assert st.tlx is not None and (st.tlx.after, st.tlx.weights) == ("session", True)
    st = load_study(write_study(tmp_path, "protocol: disappear\ntlx: true\n" + CLIPS))
    assert st.tlx is not None and (st.tlx.after, st.tlx.weights) == ("block", False)


@pytest.mark.parametrize("head, match", [
    ("tlx: {after: trial}\n", r"study\.yaml:2: tlx\.after: expected one of: block, session; "
                              r"got 'trial'"),
    ("tlx: {weights: 1}\n", r"study\.yaml:2: tlx\.weights: expected true or false, got 1"),
    ("tlx: {when: block}\n", r"study\.yaml:2: tlx\.when: unknown key"),
    ("tlx: 3\n", r"study\.yaml:2: tlx: expected a mapping, got 3"),
    ("sagat:\n  - {at_s: 10, questions: [{kind: count, sector: [[0, 0], [1, 0], [0, 1]]}]}\n",
     r"study\.yaml:2: sagat: freeze probes are asked during live trials \(`protocol: live`\), "
     r"not during disappear clips"),
])
def test_study_instrument_keys_are_refused_with_file_and_line(tmp_path: Path, head: str,
                                                             match: str) -> None:
    p = write_study(tmp_path, "protocol: disappear\n" + head + CLIPS)
    with pytest.raises(ConfigError, match=match):
        load_study(p)


def sagat_of(text: str) -> tuple[Any, list[str]]:
    """``parse_sagat`` of the YAML ``text`` (its ``sagat:`` value) and the problems."""
    data, lines, _ = load_with_lines(text)
    ctx = Problems("s.yaml", lines)
    probes = parse_sagat(ctx, data["sagat"])
    return probes, ctx.format()


PROBES = """\
sagat:
  - at_s: 40
    questions:
      - {id: where, kind: last_target, tolerance_m: 25}
      - {id: north, kind: count, sector: [[0, 0], [500, 0], [500, 500]], tolerance: 1}
      - {id: low, kind: choice, which: lowest, of: alt_agl_m}
  - at_s: 90
    questions:
      - {kind: choice, which: highest, of: distance_m, from: [100, -50], text: Who is out?}
"""


def test_sagat_probes_are_read() -> None:
    probes, problems = sagat_of(PROBES)
    assert problems == []
    assert [p.at_s for p in probes] == [40.0, 90.0]
    where, north, low = probes[0].questions
    assert (where.kind, where.tolerance_m) == ("last_target", 25.0)
    assert north.sector == ((0, 0), (500, 0), (500, 500)) and north.tolerance == 1
    assert (low.which, low.of, low.shown_text) == ("lowest", "alt_agl_m",
                                                   "Which aircraft is lowest above the ground?")
    (far,) = probes[1].questions
    assert (far.id, far.point, far.shown_text) == ("q0", (100.0, -50.0), "Who is out?")
    assert far.page_view() == {"id": "q0", "kind": "choice", "text": "Who is out?",
                               "point": [100.0, -50.0]}


@pytest.mark.parametrize("text, match", [
    ("sagat: {at_s: 3}\n", r"s\.yaml:1: sagat: expected a list of probes"),
    ("sagat:\n  - {at_s: 0, questions: [{kind: last_target}]}\n",
     r"s\.yaml:2: sagat\[0\]\.at_s: must be > 0, got 0"),
    ("sagat:\n  - {at_s: 5, questions: []}\n",
     r"s\.yaml:2: sagat\[0\]\.questions: expected a list of 1 to 20 questions, got 0"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: guess}]}\n",
     r"s\.yaml:2: sagat\[0\]\.questions\[0\]\.kind: expected one of: last_target, count, "
     r"choice; got 'guess'"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: count}]}\n",
     r"s\.yaml:2: sagat\[0\]\.questions\[0\]: missing required key 'sector'"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: count, sector: [[0, 0], [1, 1]]}]}\n",
     r"sagat\[0\]\.questions\[0\]\.sector: expected 3 to 64 points \[north_m, east_m\], got 2"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: count, sector: [[0, 0], [1, .nan], [2, 0]]}]}\n",
     r"s\.yaml:2: sagat\[0\]\.questions\[0\]\.sector: expected a point \[north_m, east_m\] "
     r"within \+-1e\+06 m, got \[1, nan\]"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: choice, which: lowest, of: distance_m}]}\n",
     r"questions\[0\]: missing required key 'from'"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: choice, which: lowest, of: alt_agl_m, "
     "from: [0, 0]}]}\n", r"questions\[0\]\.from: only a distance_m question has a point"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: last_target, sector: [[0, 0], [1, 0], [0, 1]]}]}\n",
     r"questions\[0\]\.sector: not a key of a last_target question \(its keys: tolerance_m\)"),
    ("sagat:\n  - {at_s: 5, questions: [{id: wh\u00e9re, kind: last_target}]}\n",
     r"questions\[0\]\.id: 'wh\u00e9re': 1-32 letters, digits and '_'"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: choice, which: most, of: alt_agl_m}]}\n",
     r"questions\[0\]\.which: expected one of: lowest, highest; got 'most'"),
    ("sagat:\n  - {at_s: 5, questions: [{id: a, kind: last_target}, {id: a, kind: last_target}]}"
     "\n", r"sagat\[0\]\.questions: question ids given twice: a"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: last_target}]}\n"
     "  - {at_s: 5, questions: [{kind: last_target}]}\n",
     r"sagat: the probes' at_s must rise from one probe to the next"),
    ("sagat:\n  - {at_s: 5, questions: [{kind: last_target, text: " + "x" * 301 + "}]}\n",
     r"questions\[0\]\.text: 301 characters; at most 300"),
])
def test_sagat_keys_are_refused_with_their_line(text: str, match: str) -> None:
    probes, problems = sagat_of(text)
    assert any(re.search(match, m) for m in problems), problems


def test_too_many_probes_and_questions_are_refused() -> None:
    q = "{kind: last_target}"
    _, problems = sagat_of("sagat:\n" + "".join(f"  - {{at_s: {i + 1}, questions: [{q}]}}\n"
                                                for i in range(51)))
    assert problems == ["s.yaml:1: sagat: 51 probes; a study may have at most 50"]
    _, problems = sagat_of("sagat:\n  - {at_s: 1, questions: [" + ", ".join([q] * 21) + "]}\n")
    assert problems == ["s.yaml:2: sagat[0].questions: expected a list of 1 to 20 questions, "
                        "got 21"]


# --- SAGAT scoring against independently computed truth ---
def random_state(rng: np.random.Generator, n: int = 12) -> FreezeState:
    vehicles = tuple(VehicleAt(f"uav{i}", north_m=float(rng.uniform(-1000, 1000)),
                               east_m=float(rng.uniform(-1000, 1000)),
                               alt_msl_m=float(rng.uniform(100, 600)),
                               alt_agl_m=float(rng.uniform(50, 500)),
                               airspeed_mps=float(rng.uniform(20, 60)),
                               fuel_kg=float(rng.uniform(0, 8))) for i in range(n))
    targets = (TargetAt("truck", 120.0, -40.0, 31.5), TargetAt("car", -300.0, 250.0, 38.0),
               TargetAt("person", 10.0, 10.0, None), TargetAt("fire", 0.0, 900.0, 52.0))
    return FreezeState(time_s=40.0, vehicles=vehicles, targets=targets)


def test_sagat_scores_equal_an_independent_computation() -> None:
    rng = np.random.default_rng(11)
    # a concave sector (an L), counted by matplotlib's point-in-polygon test
    sector = ((-800.0, -800.0), (600.0, -800.0), (600.0, -200.0), (0.0, -200.0), (0.0, 700.0),
              (-800.0, 700.0))
    mpl = MplPath(np.array(sector))
    for trial in range(20):
        st = random_state(rng)
        ne = np.array([(v.north_m, v.east_m) for v in st.vehicles])
        # where was the last target seen: the car (38 s; the fire's 52 s is after the freeze)
        click = {"north_m": -290.0, "east_m": 230.0}
        s = score(Question("w", "last_target", tolerance_m=25.0), st, click)
        assert s.truth["target"] == "car"
        assert s.error == pytest.approx(math.dist((-290, 230), (-300, 250)), abs=1e-9)
        assert s.correct is True  # 22.4 m within 25 m
        count = int(mpl.contains_points(ne).sum())
        for answer in (count, count + 2):
            s = score(Question("c", "count", sector=sector, tolerance=1), st, answer)
            assert (s.truth, s.error, s.correct) == (count, float(answer - count),
                                                     answer == count)
        fuel = np.array([v.fuel_kg for v in st.vehicles])
        ids = [v.id for v in st.vehicles]
        q = Question("f", "choice", which="lowest", of="fuel_kg")
        best = ids[int(np.argmin(fuel))]
        assert score(q, st, best) == type(score(q, st, best))(True, 0.0, [best])
        other = ids[trial % len(ids)]
        s = score(q, st, other)
        assert s.correct == (other == best)
        assert s.error == pytest.approx(fuel[ids.index(other)] - fuel.min(), abs=1e-12)
        point = (100.0, -50.0)
        d = np.hypot(ne[:, 0] - point[0], ne[:, 1] - point[1])
        far = Question("d", "choice", which="highest", of="distance_m", point=point)
        assert score(far, st, ids[int(np.argmax(d))]).truth == [ids[int(np.argmax(d))]]
        assert score(far, st, other).error == pytest.approx(d.max() - d[ids.index(other)])
        low = Question("a", "choice", which="lowest", of="alt_agl_m")
        agl = np.array([v.alt_agl_m for v in st.vehicles])
        assert score(low, st, ids[int(np.argmin(agl))]).correct
    s = score(Question("f", "choice", which="lowest", of="fuel_kg"), st, "uav99")
    assert (s.correct, s.error) == (False, None)


def test_no_target_seen_yet_and_no_fuel_known() -> None:
    st = FreezeState(10.0, (VehicleAt("a", 0, 0, 100, 90, 30),),
                     (TargetAt("truck", 5, 5, 12.0),))
    s = score(Question("w", "last_target"), st, {"north_m": 5.0, "east_m": 5.0})
    assert (s.correct, s.error, s.truth) == (False, None, None)  # seen at 12 s: after 10 s
    with pytest.raises(ScoringError, match=r"question 'f' asks fuel_kg, which the state at the "
                                           r"freeze does not hold for 'a'"):
        score(Question("f", "choice", which="lowest", of="fuel_kg"), st, "a")


def test_polygon_rule_on_a_square() -> None:
    sq = ((0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0))
    assert inside_polygon(5, 5, sq) and not inside_polygon(15, 5, sq)
    assert not inside_polygon(5, -0.01, sq) and inside_polygon(9.99, 9.99, sq)


def test_the_state_at_a_freeze_is_each_vehicles_last_logged_row() -> None:
    """From a state log's table (ticks in order, vehicles within a tick):
    each vehicle's row at the last tick at or before the freeze."""
    rng = np.random.default_rng(5)
    names = ["u0", "u1", "u2"]
    rows = [(t / 10, v) for t in range(50) for v in names if not (v == "u2" and t > 20)]
    n = len(rows)
    cols = {c: rng.uniform(0, 100, n) for c in ("north_m", "east_m", "alt_msl_m", "alt_agl_m",
                                                 "airspeed_mps")}
    table = pa.table({"time_s": [r[0] for r in rows],
                      "vehicle": pa.array([r[1] for r in rows]).dictionary_encode(), **cols})
    st = from_state_log(table, 3.05)
    for v in st.vehicles:
        want = max(i for i, r in enumerate(rows) if r[1] == v.id and r[0] <= 3.05)
        assert rows[want][0] == (3.0 if v.id != "u2" else 2.0)
        assert (v.north_m, v.alt_agl_m, v.fuel_kg) == (cols["north_m"][want],
                                                       cols["alt_agl_m"][want], None)
    assert [v.id for v in st.vehicles] == names
    with_fuel = from_state_log(table.append_column("fuel_kg", pa.array(np.arange(n) * 1.0)), 0.0)
    assert [v.fuel_kg for v in with_fuel.vehicles] == [0.0, 1.0, 2.0]
    with pytest.raises(ScoringError, match=r"the state log lacks columns airspeed_mps"):
        from_state_log(table.drop_columns(["airspeed_mps"]), 1.0)


# --- the store ---
def test_answers_are_stored_once_and_read_back(tmp_path: Path) -> None:
    db = tmp_path / "t.sqlite"
    with Store(db) as store:
        s = store.create_session(participant="p", study="s", protocol="disappear",
                                 display=PROFILE, order_method="shuffle", seed=1,
                                 session_number=0, trial_order=[])
        row = {"session": s["id"], "participant": "p", "instrument": "tlx", "trial_index": 3,
               "item": 0, "answer": {"ratings": RATINGS}, "raw_tlx": 45.0,
               "weighted_tlx": None}
        stored, created = store.record_instrument(row)
        assert created and stored["answer"] == {"ratings": RATINGS}
        again, created = store.record_instrument({**row, "raw_tlx": 99.0})
        assert not created and again == stored and again["raw_tlx"] == 45.0
        sg = {**row, "instrument": "sagat", "item": 1, "answer": {"n": 3}, "raw_tlx": None}
        sagat, _ = store.record_instrument(sg)
        store.score_instrument(sagat["id"], {"n": {"correct": True, "error": 0.0, "truth": 3},
                                             "m": {"correct": False, "error": 2.0, "truth": 1}})
        (back,) = store.instrument_answers(s["id"], "sagat")
        assert (back["correct"], back["questions"]) == (1, 2)
        assert back["scores"]["m"] == {"correct": False, "error": 2.0, "truth": 1}
        with pytest.raises(ConfigError, match=r"tlx answer 0 of trial 3 of session nope was "
                                              r"refused by the database"):
            store.record_instrument({**row, "session": "nope"})
    # a database made before the instruments: the table is added when it is opened
    con = sqlite3.connect(db)
    con.execute("DROP TABLE instrument_answers")
    con.commit()
    con.close()
    with Store(db) as store:
        assert store.instrument_answers() == []
        assert store.record_instrument(row)[1]


# --- the server's API ---
def tlx_app(tmp_path: Path, store: Store, weights: bool) -> tuple[Any, dict[str, Any]]:
    study = write_study(tmp_path, f"protocol: disappear\nbreak_every: 1\norder: latin_square\n"
                                  f"tlx: {{after: block, weights: {str(weights).lower()}}}\n"
                        + CLIPS)
    app = make_app(study, store)
    status, s = asgi(app, "POST", "/api/sessions", {"participant": "p", **PROFILE})
    assert status == 201, s
    return app, s


def answer(app: Any, s: dict[str, Any], trial: int) -> None:
    status, r = asgi(app, "POST", f"/api/sessions/{s['id']}/responses",
                     {"trial_index": trial, "kind": "disappear", "key": "space",
                      "media_time_s": 0.2, "reaction_time_ms": 500.0})
    assert status == 201, r


def test_a_tlx_is_asked_after_each_block_stored_once_and_scored(tmp_path: Path) -> None:
    with Store(tmp_path / "t.sqlite") as store:
        app, s = tlx_app(tmp_path, store, weights=True)
        base = f"/api/sessions/{s['id']}"
        assert asgi(app, "GET", f"{base}/instrument") == (200, {"instrument": None})
        body = {"instrument": "tlx", "block": 0, "ratings": RATINGS, "pairs": PAIRS}
        status, r = asgi(app, "POST", f"{base}/instruments", body)
        assert (status, r) == (400, {"error": "block 0: its trials are not all answered yet"})
        answer(app, s, 0)
        status, p = asgi(app, "GET", f"{base}/instrument")
        assert (p["instrument"], p["block"], p["trial_index"]) == ("tlx", 0, 0)
        assert [x["key"] for x in p["scales"]] == list(SCALE_KEYS)
        assert p["scales"][3] == {"key": "performance", "title": "Performance",
                                  "question": "How successful were you in accomplishing what "
                                              "you were asked to do?",
                                  "low": "Perfect", "high": "Failure"}
        assert p["pairs"] == [list(x) for x in tlx_pair_order(0, 0, 0)]
        status, r = asgi(app, "POST", f"{base}/instruments", body)
        assert status == 201, r
        a = r["answer"]
        assert (a["raw_tlx"], a["weighted_tlx"], a["item"], a["trial_index"]) == (45.0, 57.0, 0, 0)
        assert a["answer"]["weights"]["mental"] == 5
        status, r = asgi(app, "POST", f"{base}/instruments",
                         {**body, "ratings": {**RATINGS, "mental": 0}})
        assert status == 200 and not r["created"] and r["answer"]["raw_tlx"] == 45.0
        assert asgi(app, "GET", f"{base}/instrument") == (200, {"instrument": None})
        answer(app, s, 1)
        assert asgi(app, "GET", f"{base}/instrument")[1]["block"] == 1
        (row,) = store.instrument_answers(s["id"])
        assert row["answer"]["ratings"] == RATINGS


@pytest.mark.parametrize("body, match", [
    ({"instrument": "nasa"}, r"instrument: expected 'tlx' or 'sagat', got 'nasa'"),
    ({"instrument": "tlx", "block": 2, "ratings": RATINGS}, r"block: expected 0\.\.1, got 2"),
    ({"instrument": "tlx", "block": True, "ratings": RATINGS}, r"block: expected 0\.\.1"),
    ({"instrument": "tlx", "block": 0, "ratings": {**RATINGS, "temporal": 57}},
     r"ratings\.temporal: expected 0\.\.100 in steps of 5, got 57"),
    ({"instrument": "tlx", "block": 0, "ratings": RATINGS, "pairs": PAIRS},
     r"pairs: this study asks no pairwise comparisons"),
    ({"instrument": "tlx", "block": 0, "ratings": {**RATINGS, "effort": 1e400}},
     r"ratings\.effort: expected 0\.\.100 in steps of 5, got inf"),  # JSON's Infinity
    ({"instrument": "sagat", "trial_index": 0, "probe": 0, "answers": {}},
     r"probe: this study has 0 SAGAT probes; no probe 0"),
])
def test_malformed_answers_are_refused_by_the_api(tmp_path: Path, body: dict[str, Any],
                                                  match: str) -> None:
    with Store(tmp_path / "t.sqlite") as store:
        app, s = tlx_app(tmp_path, store, weights=False)
        answer(app, s, 0)
        status, r = asgi(app, "POST", f"/api/sessions/{s['id']}/instruments", body)
        assert status == 400 and re.search(match, r["error"]), r
        assert store.instrument_answers() == []


def test_sagat_answers_are_checked_stored_and_scored_against_the_freeze(tmp_path: Path) -> None:
    probes, problems = sagat_of(PROBES)
    assert problems == []
    study = replace(load_study(write_study(tmp_path, "protocol: disappear\n" + CLIPS)),
                    sagat=probes)
    st = FreezeState(40.0, (VehicleAt("a", 300, 100, 300, 201, 30),
                            VehicleAt("b", 100, 400, 300, 200, 30),
                            VehicleAt("c", -50, 100, 300, 204, 30)),
                     (TargetAt("truck", 120.0, -40.0, 31.5),))
    asked: list[tuple[int, int]] = []
    with Store(tmp_path / "t.sqlite") as store:
        app = make_app(study, store)
        status, s = asgi(app, "POST", "/api/sessions", {"participant": "p", **PROFILE})
        base = f"/api/sessions/{s['id']}"
        status, page = asgi(app, "GET", f"{base}/sagat/0")
        assert status == 200 and [q["id"] for q in page["questions"]] == ["where", "north",
                                                                          "low"]
        assert "tolerance" not in str(page) and page["questions"][1]["sector"][1] == [500, 0]
        assert asgi(app, "GET", f"{base}/sagat/2") == (
            404, {"error": "probe: this study has 2 SAGAT probes; no probe 2"})
        good = {"where": {"north_m": 110.0, "east_m": -40.0}, "north": 1, "low": "a"}
        for bad, match in [
                ({**good, "north": -1}, r"answers\.north: expected a whole number 0\.\.100000"),
                ({**good, "north": 2.5}, r"answers\.north: expected a whole number"),
                ({**good, "where": {"north_m": 1.0}}, r"answers\.where: expected \{north_m, "
                                                      r"east_m\}"),
                ({**good, "where": {"north_m": 1.0, "east_m": 2e6}}, r"answers\.where"),
                ({**good, "low": "<b>"}, r"answers\.low: expected an aircraft's id"),
                ({"where": good["where"]}, r"answers: expected an answer to each of where, "
                                           r"north, low")]:
            status, r = asgi(app, "POST", f"{base}/instruments",
                             {"instrument": "sagat", "trial_index": 1, "probe": 0,
                              "answers": bad})
            assert status == 400 and re.search(match, r["error"]), r

        def freeze_state(session: dict[str, Any], trial: int, probe: Any) -> FreezeState:
            asked.append((trial, probe.index))
            return st

        app.state.instruments.freeze_state = freeze_state
        status, r = asgi(app, "POST", f"{base}/instruments",
                         {"instrument": "sagat", "trial_index": 1, "probe": 0, "answers": good})
        assert status == 201, r
        assert asked == [(1, 0)]
        sc = r["answer"]["scores"]
        assert sc["where"] == {"correct": True, "error": 10.0,
                               "truth": {"target": "truck", "north_m": 120.0, "east_m": -40.0}}
        # the triangle (0,0) (500,0) (500,500) holds a (300, 100) alone
        truth_north = int(MplPath(np.array([[0, 0], [500, 0], [500, 500]])).contains_points(
            np.array([[300, 100], [100, 400], [-50, 100]])).sum())
        assert sc["north"] == {"correct": True, "error": 0.0, "truth": truth_north} and \
            truth_north == 1
        assert sc["low"] == {"correct": False, "error": 1.0, "truth": ["b"]}
        assert r["answer"]["questions"] == 3


# --- the participant's page (headless Debian chromium) ---
def test_a_tlx_on_the_participant_page_is_filled_in_and_stored(tmp_path: Path,
                                                               chromium: str) -> None:
    """After the session's last trial the page asks the six scales (no mark
    chosen, "Next" only once all six are), then the 15 pairs one at a time;
    the stored ratings, weights and scores are those of the clicks."""
    study = small_study(tmp_path, "protocol: disappear\ntlx: {after: session, weights: true}\n",
                        {"a": 150.0})
    with live_server(study) as server:
        s = _session(server, "p-tlx")
        server.request("POST", f"/api/sessions/{s['id']}/state", {"state": "running"})
        with participant_page(server, s, chromium=chromium) as page:
            page.keyboard.press("Space")  # the clip plays to its end, no press: then the TLX
            page.wait_for_function("document.body.dataset.phase === 'tlx'")
            assert page.locator(".tlx .scale").count() == 6
            assert page.locator(".tlx .tick.chosen").count() == 0
            assert page.locator(".scale[data-scale=temporal] .tick").count() == 21
            assert page.evaluate("getComputedStyle(document.body).cursor") == "default"
            for key, v in RATINGS.items():
                assert page.is_disabled("button.next")
                page.click(f".scale[data-scale={key}] .tick[data-value='{v}']")
            page.screenshot(path=str(tmp_path / "tlx_scales.png"))
            page.click("button.next")
            shown = []
            for k in range(15):
                form = page.locator(f".pairs[data-pair='{k}']")
                form.wait_for()
                a, b = (form.locator("button").nth(i).get_attribute("data-scale")
                        for i in range(2))
                shown.append((a, b))
                if k == 0:
                    page.screenshot(path=str(tmp_path / "tlx_pair.png"))
                form.locator(f"button[data-scale={min(a, b, key=ORDER.index)}]").click()
            page.wait_for_function("document.body.dataset.phase === 'finished'")
        (row,) = server.store.instrument_answers(s["id"])
    assert shown == tlx_pair_order(0, 0, 0)
    assert row["answer"]["ratings"] == RATINGS and row["answer"]["pairs"] == PAIRS
    assert row["answer"]["weights"] == {"mental": 5, "physical": 0, "temporal": 3,
                                        "performance": 2, "effort": 4, "frustration": 1}
    assert (row["raw_tlx"], row["weighted_tlx"], row["item"]) == (45.0, 57.0, 0)


def test_export_writes_the_instruments_a_row_per_block_or_probe(tmp_path: Path) -> None:
    """``cosim trials export DB --out CSV --instruments CSV``: a TLX's ratings
    and weights a column each; a probe's correct answers once scored."""
    import csv

    from cosim.cli import main

    db = tmp_path / "t.sqlite"
    with Store(db) as store:
        s = store.create_session(participant="-p1", study="s", protocol="disappear",
                                 display=PROFILE, order_method="shuffle", seed=1,
                                 session_number=0, trial_order=[])
        a = check_tlx_answer({"ratings": RATINGS, "pairs": PAIRS}, weights=True)
        base = {"session": s["id"], "participant": "-p1", "trial_index": 4}
        store.record_instrument({**base, "instrument": "tlx", "item": 0, "raw_tlx": a.raw,
                                 "weighted_tlx": a.weighted,
                                 "answer": {"ratings": a.ratings, "weights": a.weights}})
        scored, _ = store.record_instrument({**base, "instrument": "sagat", "item": 0,
                                             "answer": {"n": 2}})
        store.score_instrument(scored["id"], {"n": {"correct": True, "error": 0.0, "truth": 2}})
        store.record_instrument({**base, "instrument": "sagat", "item": 1, "answer": {"n": 5}})
    out, inst = tmp_path / "r.csv", tmp_path / "i.csv"
    assert main(["-q", "trials", "export", str(db), "--out", str(out), "--instruments",
                 str(inst)]) == 0
    tlx, sagat0, sagat1 = csv.DictReader(inst.open())
    assert tlx["participant"] == "'-p1"  # a spreadsheet would read -p1 as a formula
    assert {k: int(tlx[f"rating_{k}"]) for k in SCALE_KEYS} == RATINGS
    assert [int(tlx[f"weight_{k}"]) for k in SCALE_KEYS] == [5, 0, 3, 2, 4, 1]
    assert (float(tlx["raw_tlx"]), float(tlx["weighted_tlx"])) == (45.0, 57.0)
    assert (tlx["sagat_correct"], sagat0["sagat_correct"], sagat0["sagat_questions"]) == (
        "", "1", "1")
    assert (sagat1["item"], sagat1["sagat_correct"], sagat1["rating_mental"]) == ("1", "", "")


#: in the participant's page: probe 0 of its session asked through the probe form
#: (instruments.js), the map's click standing in as (110, -40); its answers posted
ASK_PROBE = """async () => {
  const sid = new URLSearchParams(location.search).get("session");
  const base = `/api/sessions/${sid}`;
  const probe = await (await fetch(`${base}/sagat/0`)).json();
  const box = document.getElementById("message");
  box.hidden = false;
  CosimInstruments.sagat(box, probe, 0, ["a", "b", "c"],
                         async () => ({ north_m: 110, east_m: -40 }))
    .then((body) => fetch(`${base}/instruments`, {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body) }))
    .then((r) => r.json()).then((j) => { window.probeStored = j; });
}"""


def test_a_sagat_probe_asked_through_the_probe_form_is_stored(
        tmp_path: Path, chromium: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The form the live console's page is to use: the map's point, a count
    typed (an empty or negative one is not taken) and an aircraft chosen are
    posted and stored as given."""
    import cosim.trials.server as server_module

    probes, _ = sagat_of(PROBES)
    study = small_study(tmp_path, "protocol: disappear\n", {"a": 150.0})
    read = server_module.load_study
    monkeypatch.setattr(server_module, "load_study", lambda p: replace(read(p), sagat=probes))
    with live_server(study) as server:
        s = _session(server, "p-sagat")
        with participant_page(server, s, chromium=chromium) as page:
            page.evaluate(ASK_PROBE)
            page.locator(".sagat[data-question=north] input").wait_for()
            assert page.evaluate("getComputedStyle(document.body).cursor") == "default"
            page.click(".sagat button.next")  # empty: not taken
            page.fill(".sagat input", "-2")
            page.click(".sagat button.next")  # negative: not taken
            assert page.locator(".sagat[data-question=north]").count() == 1
            page.fill(".sagat input", "2")
            page.click(".sagat button.next")
            page.locator(".sagat[data-question=low] button").first.wait_for()
            assert page.locator(".sagat button.choice").all_inner_texts() == ["a", "b", "c"]
            page.click(".sagat button.choice >> text=b")
            page.wait_for_function("window.probeStored !== undefined")
            stored = page.evaluate("window.probeStored")
        assert stored.get("created") is True, stored
        (row,) = server.store.instrument_answers(s["id"], "sagat")
    assert (row["trial_index"], row["item"], row["scores"]) == (0, 0, None)
    assert row["answer"] == {"where": {"north_m": 110.0, "east_m": -40.0}, "north": 2,
                             "low": "b"}


def test_last_sightings_equal_a_brute_force_search() -> None:
    """Each target's latest frame at or before the freeze in which it counts
    as visible (in view, enough pixels, enough of it unoccluded), any feed."""
    from cosim.trials.live_scoring import ScoringSettings, TargetFrame
    from cosim.trials.sagat import last_sightings

    rng = np.random.default_rng(2)
    frames = [TargetFrame(feed=f"u{k % 3}/belly", frame=k, time_s=round(k * 0.1, 1),
                          target=f"t{rng.integers(4)}", in_view=bool(rng.random() < 0.7),
                          bbox_px=None, center_px=None,
                          pixels_on_target=float(rng.integers(0, 12)),
                          visible_fraction=float(rng.random())) for k in range(400)]
    settings = ScoringSettings(min_pixels_on_target=5, min_visible_fraction=0.3)
    for freeze_s in (0.0, 7.35, 21.0, 50.0):
        want: dict[str, float] = {}
        for f in frames:
            if (f.time_s <= freeze_s and f.in_view and f.pixels_on_target >= 5
                    and f.visible_fraction >= 0.3):
                want[f.target] = max(want.get(f.target, -1.0), f.time_s)
        assert last_sightings(frames, freeze_s, settings) == want


@pytest.mark.integration
def test_the_state_at_a_freeze_of_a_real_run(tmp_path: Path) -> None:
    """The flyover, 12 s: the state 11 s in, from its run folder, is the
    aircraft's last logged row by then (read back by pyarrow) and the truck
    where the scenario puts it, last seen when its ground-truth CSV, read
    directly, last shows it visible by then; a click 10 m off it is scored
    10 m, and the aircraft is the lowest of one."""
    import csv

    import pyarrow.parquet as pq

    from cosim.cli import main
    from cosim.trials.sagat import freeze_state_from_run

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "run"
    assert main(["-q", "run", str(repo / "scenarios/cameras/flyover.yaml"), "--backend",
                 "inline", "--duration-s", "12", "--out", str(out), "--no-progress"]) == 0
    st = freeze_state_from_run(out, ["uav1/belly"], 11.0,
                               {"truck1": (0.0, 0.0), "firetruck1": (300.0, 15.0)})
    log = pq.read_table(out / "states.parquet").to_pydict()  # the parts, read by pyarrow
    i = max(k for k, time_s in enumerate(log["time_s"]) if time_s <= 11.0 + 1e-9)
    (v,) = st.vehicles
    assert (v.id, v.north_m, v.east_m, v.alt_agl_m) == (
        "uav1", log["north_m"][i], log["east_m"][i], log["alt_agl_m"][i])
    assert 10.9 < log["time_s"][i] <= 11.0
    with open(out / "cameras" / "uav1_belly.gt.csv", newline="") as f:
        seen = [(r["target"], float(r["time_s"])) for r in csv.DictReader(f)
                if r["in_view"] == "1" and float(r["pixels_on_target"]) >= 4
                and float(r["time_s"]) <= 11.0]
    last = max(seen, key=lambda x: x[1])
    assert last[0] == "truck1"
    t = st.last_target()
    assert t is not None and (t.id, t.last_seen_s) == last
    s = score(Question("w", "last_target", tolerance_m=5.0), st,
              {"north_m": 6.0, "east_m": -8.0})
    assert (s.error, s.correct) == (10.0, False)
    assert score(Question("a", "choice", which="lowest", of="alt_agl_m"), st, "uav1").correct
    # 5 s in, no target has been on the screen yet: nothing to be right about
    early = freeze_state_from_run(out, ["uav1/belly"], 5.0, {"truck1": (0.0, 0.0)})
    assert early.last_target() is None and min(time_s for _, time_s in seen) > 5.0



def test_a_live_study_reads_its_probes_and_refuses_one_after_a_trials_end(
        tmp_path: Path) -> None:
    from test_live import live_study

    body = ("name: live_sagat\nprotocol: live\ntlx: {after: session}\nscenarios:\n"
            "  - {id: two, scenario: pair.yaml, feeds: 2, duration_s: 120}\n"
            "  - {id: one, scenario: pair.yaml, feeds: 1}\n" + PROBES)
    st = load_study(live_study(tmp_path, body))
    assert [p.at_s for p in st.sagat] == [40.0, 90.0] and st.tlx is not None
    # 'two' cut to 60 s: the second probe, 90 s in, comes after its end ('one' runs the
    # scenario's own duration, not checked)
    with pytest.raises(ConfigError, match=r"study\.yaml:13: sagat\[1\]\.at_s: 90 s: not before "
                                          r"the end of condition two \(60 s\): the probe would "
                                          r"never be asked"):
        load_study(live_study(tmp_path, body.replace("duration_s: 120", "duration_s: 60")))
