"""The instruments on the live console's page (``static/live_instruments.js``,
``live_freeze``): a SAGAT probe freezes the live run at its time, the page
blanks the feeds and the map and asks its questions, the answers are scored
against the state at the freeze; the NASA-TLX after the block. Headless
Debian Chromium and uvicorn on 127.0.0.1 (an ephemeral port), as
tests/trials/test_live.py."""

from __future__ import annotations

import json
import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from test_live import (
    _same_states,
    _session,
    _start,
    _truck,
    _wait_over,
    browser_page,
    live_study,
)
from test_server import live_server

FREEZE_S = 2.8
STUDY = f"""\
name: live_instruments
protocol: live
scenarios:
  - {{id: two, scenario: pair.yaml, feeds: [uav1/belly, uav2/belly], conditions: {{feeds: 2}}}}
order: shuffle
tlx: {{after: block, weights: true}}
sagat:
  - at_s: {FREEZE_S}
    questions:
      - {{id: where, kind: last_target, tolerance_m: 50}}
      - {{id: north, kind: count, sector: [[0, -100], [1000, -100], [1000, 30], [0, 30]]}}
      - {{id: far, kind: choice, which: highest, of: distance_m, from: [0, 0]}}
      - {{id: low, kind: choice, which: lowest, of: alt_agl_m}}
      - {{id: fuel, kind: choice, which: lowest, of: fuel_kg}}
"""
#: the participant's TLX: ratings, and in each pair the scale earlier in PREFER
RATINGS = {"mental": 70, "physical": 10, "temporal": 85, "performance": 40, "effort": 60,
           "frustration": 25}
PREFER = ["temporal", "mental", "effort", "frustration", "performance", "physical"]

COVERED = """([sel, panel]) => {
  const r = document.querySelector(sel).getBoundingClientRect();
  const hit = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
  return document.getElementById(panel).contains(hit);
}"""


def _answer_tlx(page: Any, picture: Path) -> None:
    page.wait_for_selector("#instrument[data-kind='tlx'] .tlx .scale", timeout=60_000)
    page.screenshot(path=str(picture))
    for key, v in RATINGS.items():
        page.click(f".scale[data-scale='{key}'] .tick[data-value='{v}']")
    page.click(".tlx button.next")
    for k in range(15):
        page.wait_for_selector(f".tlx.pairs[data-pair='{k}']")
        a, b = page.eval_on_selector_all(".tlx.pairs button.choice",
                                         "bs => bs.map((b) => b.dataset.scale)")
        pick = a if PREFER.index(a) < PREFER.index(b) else b
        page.click(f".tlx.pairs button.choice[data-scale='{pick}']")


@pytest.mark.integration  # a live run of 4 s, frozen on the way, and a browser
def test_a_freeze_asks_the_probe_on_a_blank_page_and_scores_it_against_the_run(
        tmp_path: Path, chromium: str) -> None:
    """At 2.8 s the run is paused (the map's clock stops), the page covers
    the feeds and the map and asks the probe's five questions; the answers
    are stored and scored against the aircraft at the freeze's tick as the
    same scenario's run without the console logs them, and the truck where
    the scenario puts it (seen in uav1's feed before the freeze). The run
    then goes on to its end, its states those of the run never paused. After
    the block's one trial the page asks the NASA-TLX with its 15 pairs:
    stored with the raw and weighted scores of a hand computation."""
    from cosim.scenario import load_scenario
    from cosim.sync.runner import run_scenario

    study = live_study(tmp_path, STUDY)
    alone = run_scenario(load_scenario(tmp_path / "pair.yaml"), tmp_path / "alone")
    assert alone.ok
    with live_server(study) as server:
        sid = _session(server, "p1")["id"]
        with browser_page(chromium, viewport=(1000, 500)) as page:
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{server.url}/live?session={sid}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            _start(server, sid)
            page.wait_for_function("document.body.dataset.freeze === '0'", timeout=60_000)
            # the feeds and the map are covered; the run stands still
            assert page.evaluate(COVERED, ["canvas[data-feed='0']", "instrument"])
            assert page.evaluate(COVERED, ["#map", "instrument"])
            clock = page.text_content("#clock")
            status, now = server.request("GET", f"/api/sessions/{sid}/live/freeze")
            assert status == 200 and now["freeze"]["time_s"] == FREEZE_S, now
            assert [q["id"] for q in now["freeze"]["questions"]] == ["where", "north", "far",
                                                                    "low", "fuel"]
            assert "truth" not in str(now)  # the page is never told the answers
            # the experimenter sees why the run stands still
            status, v = server.request("GET", f"/api/sessions/{sid}/live")
            assert status == 200 and v["live"]["running"] and v["live"]["paused"], v
            desk = page.context.browser.new_context().new_page()
            desk.goto(f"{server.url}/")
            assert desk.text_content(".live-paused", timeout=10_000) == \
                " paused: the participant is answering a SAGAT probe"
            desk.context.close()
            time.sleep(1.0)
            assert page.text_content("#clock") == clock
            page.screenshot(path=str(tmp_path / "freeze.png"))
            # the blank map: the live map's last view (centre, scale), grown to the sector
            view = page.evaluate("window.live.view")
            n0, n1, e0, e1 = page.evaluate("window.liveInstruments.asked[0].extent_ne_m")
            half_m = view["w"] / 2 / view["s"]
            assert n0 <= min(view["cn"] - half_m, 0) and n1 >= max(view["cn"] + half_m, 1000)
            assert e0 <= min(view["ce"] - half_m, -100) and e1 >= max(view["ce"] + half_m, 30)
            assert n1 - n0 == pytest.approx(e1 - e0) and n1 - n0 == pytest.approx(
                max(view["cn"] + half_m, 1000) - min(view["cn"] - half_m, 0))
            # a reload asks the same probe again (its answer is stored once)
            page.reload()
            page.wait_for_function("document.body.dataset.freeze === '0'", timeout=30_000)
            assert page.text_content("#clock") == clock
            # where: a click on the blank map 5 m north and 5 m east of the origin
            page.wait_for_selector("[data-question='where']")
            x, y = page.evaluate("window.liveInstruments.toPixel(5, 5)")
            m_per_px = 100 / (page.evaluate("window.liveInstruments.toPixel(5, 105)")[0] - x)
            page.mouse.click(x, y)
            page.wait_for_selector("[data-question='north']")
            page.screenshot(path=str(tmp_path / "count.png"))
            page.fill("[data-question='north'] input", "2")
            page.click("[data-question='north'] button.next")
            page.wait_for_selector("[data-question='far']")
            page.click("[data-question='far'] button.choice:text-is('uav2')")
            page.wait_for_selector("[data-question='low']")
            page.click("[data-question='low'] button.choice:text-is('uav1')")
            page.wait_for_selector("[data-question='fuel']")
            page.click("[data-question='fuel'] button.choice:text-is('uav2')")
            page.wait_for_function("window.liveInstruments.posted.some((p) => "
                                   "p.body.instrument === 'sagat' && p.status === 201)")
            page.wait_for_function("document.body.dataset.freeze === undefined")
            page.wait_for_function("document.body.dataset.phase === 'ended'", timeout=60_000)
            _answer_tlx(page, tmp_path / "tlx.png")
            page.wait_for_function("window.liveInstruments.posted.some((p) => "
                                   "p.body.instrument === 'tlx' && p.status === 201)")
            assert not errors, errors
        v = _wait_over(server, sid)
        assert v["live"]["paused"] is False
        deadline = time.monotonic() + 10
        while (sagat := server.store.instrument_answers(sid, "sagat"))[0]["scores"] is None:
            assert time.monotonic() < deadline, "the probe was not scored"
            time.sleep(0.1)
        (tlx,) = server.store.instrument_answers(sid, "tlx")
    folder = Path(v["trials"][0]["run"])
    summary = json.loads((folder / "summary.json").read_text())
    freeze_tick = math.ceil(FREEZE_S * 120 / 4) * 4  # the first exchange at or after it
    assert summary["sagat_freezes"]["freezes"] == [
        {"probe": 0, "tick": freeze_tick, "time_s": freeze_tick / 120}]
    assert summary["stop_reason"] == "completed" and summary["paused_s"] >= 1.0
    # the pause is not lateness: no tick of the paced run was as late as the pause is long
    assert summary["realtime"]["lateness_ms_max"] < 1000 * summary["paused_s"]
    _same_states(folder, tmp_path / "alone")  # paused or not, the same states
    # the scores, from the run without the console: its aircraft at the freeze's tick
    t = pq.read_table(tmp_path / "alone" / "states.parquet").to_pydict()
    at = {t["vehicle"][i]: {k: t[k][i] for k in ("north_m", "east_m", "alt_agl_m", "fuel_kg")}
          for i in range(len(t["tick"])) if t["tick"][i] == freeze_tick}
    assert sorted(at) == ["uav1", "uav2"]
    count = sum(0 < a["north_m"] < 1000 and -100 < a["east_m"] < 30 for a in at.values())
    dist = {k: math.hypot(a["north_m"], a["east_m"]) for k, a in at.items()}
    low = min(a["alt_agl_m"] for a in at.values())
    (row,) = sagat
    answer, scores = row["answer"], row["scores"]
    assert answer["north"] == 2 and answer["far"] == "uav2" and answer["low"] == "uav1"
    # (the click lands on a whole pixel of the page)
    assert answer["where"] == pytest.approx({"north_m": 5.0, "east_m": 5.0},
                                            abs=1.5 * m_per_px)
    assert scores["north"] == {"correct": count == 2, "error": 2.0 - count, "truth": count}
    assert scores["far"]["truth"] == [max(dist, key=dist.__getitem__)]
    assert scores["far"]["correct"] == (scores["far"]["truth"] == ["uav2"])
    assert scores["far"]["error"] == pytest.approx(max(dist.values()) - dist["uav2"], abs=1e-9)
    assert scores["low"]["correct"] == (at["uav1"]["alt_agl_m"] == low)
    assert scores["low"]["error"] == pytest.approx(at["uav1"]["alt_agl_m"] - low, abs=1e-9)
    # where: the truck (at the origin), in view in uav1's feed before the freeze
    truck = _truck(tmp_path / "alone" / "cameras" / "uav1_belly.gt.csv")
    assert any(r["time_s"] <= FREEZE_S for r in truck.values())
    d = math.hypot(answer["where"]["north_m"], answer["where"]["east_m"])
    assert scores["where"] == {"correct": d <= 50, "error": pytest.approx(d, abs=1e-9),
                               "truth": {"target": "truck1", "north_m": 0.0, "east_m": 0.0}}
    # fuel: the fuel on board at the freeze as the run logged it (each tank's, burnt)
    fuel = {k: a["fuel_kg"] for k, a in at.items()}
    assert all(0.0 < f < t["fuel_kg"][0] + 1e-9 for f in fuel.values()), fuel
    assert scores["fuel"]["truth"] == sorted(k for k, f in fuel.items()
                                             if f == min(fuel.values()))
    assert scores["fuel"]["correct"] == ("uav2" in scores["fuel"]["truth"])
    assert scores["fuel"]["error"] == pytest.approx(fuel["uav2"] - min(fuel.values()), abs=1e-12)
    assert row["correct"] == sum(s["correct"] for s in scores.values()) and row["questions"] == 5
    # the TLX: raw = the mean of the six; weights = each scale's wins among the 15 pairs
    weights = {k: 5 - PREFER.index(k) for k in RATINGS}
    assert tlx["answer"]["weights"] == weights and tlx["answer"]["ratings"] == RATINGS
    assert tlx["raw_tlx"] == pytest.approx(290 / 6)
    assert tlx["weighted_tlx"] == pytest.approx(975 / 15)  # 4*70 + 5*85 + 40 + 3*60 + 2*25
    assert np.isclose(sum(weights.values()), 15)


@pytest.mark.parametrize("at_s, tick", [(2.8, 336), (2.79, 336), (2.801, 340),
                                        (0.1 * 3, 36), (1 / 30, 4)])
def test_a_probe_freezes_at_the_first_exchange_at_or_after_its_time(at_s: float,
                                                                    tick: int) -> None:
    from cosim.trials.live_freeze import freeze_tick

    assert freeze_tick(at_s, 120.0, 4) == tick  # 30 Hz exchanges of 120 Hz physics


def test_a_live_sessions_sagat_answer_needs_its_trial_frozen_for_the_probe(
        tmp_path: Path) -> None:
    """Before any trial has run nothing is asked (no freeze, no TLX), and an
    answer to the probe is refused: its trial was never frozen for it."""
    with live_server(live_study(tmp_path, STUDY)) as server:
        sid = _session(server, "p1")["id"]
        assert server.request("GET", f"/api/sessions/{sid}/live/freeze") == (
            200, {"freeze": None})
        assert server.request("GET", f"/api/sessions/{sid}/instrument") == (
            200, {"instrument": None})
        body = {"instrument": "sagat", "trial_index": 0, "probe": 0,
                "answers": {"where": {"north_m": 0, "east_m": 0}, "north": 1, "far": "uav1",
                            "low": "uav2", "fuel": "uav1"}}
        status, out = server.request("POST", f"/api/sessions/{sid}/instruments", body)
        assert status == 409
        assert re.fullmatch(r"probe 0: trial 0 of this session has not been frozen for it",
                            out["error"]), out
        assert server.store.instrument_answers(sid) == []


def test_a_fuel_question_is_asked_only_of_aircraft_that_record_fuel(tmp_path: Path) -> None:
    """JSBSim fixed-wings log the fuel on board (``fuel_kg``); a condition
    with an aircraft whose class records none (here a batched fixed-wing,
    whose mass is constant) cannot have a fuel question scored: refused when
    the study is read, naming the condition and the aircraft."""
    from cosim.errors import ConfigError
    from cosim.trials.study import load_study

    st = load_study(live_study(tmp_path, STUDY))
    assert [q.of for q in st.sagat[0].questions][-1] == "fuel_kg" and st.live[0].no_fuel == ()
    pair = tmp_path / "pair.yaml"
    pair.write_text(pair.read_text().replace("  - id: uav2\n    model: uav700",
                                             "  - id: uav2\n    class: fixed_wing_batched\n"
                                             "    model: uav700"))
    (tmp_path / "study.yaml").write_text(STUDY)
    with pytest.raises(ConfigError, match=r"study\.yaml:\d+: sagat\[0\]\.questions\[4\]\.of: "
                                          r"fuel_kg: aircraft of these conditions record no fuel "
                                          r".*could not be scored: two: uav2$"):
        load_study(tmp_path / "study.yaml")


def test_the_example_study_with_the_instruments_reads() -> None:
    """studies/live_instruments.yaml: live_feeds.yaml's conditions, the TLX
    with weights after the block, two probes in each minute-long trial."""
    from cosim.trials.study import load_study

    st = load_study(Path(__file__).resolve().parents[2] / "studies" / "live_instruments.yaml")
    assert [len(c.feeds) for c in st.live] == [1, 2, 4]
    assert st.tlx is not None and (st.tlx.after, st.tlx.weights) == ("block", True)
    assert [(p.at_s, [q.kind for q in p.questions]) for p in st.sagat] == [
        (20.0, ["last_target", "count"]), (45.0, ["last_target", "choice", "choice"])]
