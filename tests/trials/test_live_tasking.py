"""Tasking from the live console's map: a condition's ``tasking:`` read and
checked; the map's actions mapped to the command vocabulary; a scripted
participant in headless Debian Chromium selects an aircraft on the map and
sends it somewhere (the command is stored with the tick the run applied it
at, and the aircraft's logged track turns toward the point where the same
scenario's run without it flies on); refusals (an aircraft that cannot be
tasked, an action the condition does not allow, a point too far, too many
commands) with their messages; the export of the commands; the tasking
counts against a condition in the analysis (synthetic trials with a known
effect); ``cosim trials replay``'s refusals of bad input."""

from __future__ import annotations

import csv
import json
import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from test_live import RATE_HZ, SCENARIO, H, W, _session, browser_page, live_study
from test_server import live_server

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.trials.live import command_spec
from cosim.trials.live_analysis import ScoredSession, analyse_live, tasking_tables
from cosim.trials.live_scoring import SessionScore
from cosim.trials.store import Store
from cosim.trials.study import load_study

#: the aircraft (uav1 at north -130, east 0, heading north at 100 kt) is sent here
GOAL_NE_M = (500.0, 450.0)
TASK_STUDY = """\
name: live_tasking
protocol: live
scenarios:
  - {id: two, scenario: pair.yaml, feeds: [uav1/belly], map: {targets: true},
     conditions: {feeds: 1}}
  - {id: go_only, scenario: pair.yaml, feeds: [uav1/belly], tasking: [go],
     conditions: {feeds: 1}}
order: shuffle
"""


def tasking_study(folder: Path, duration_s: float, study: str = TASK_STUDY) -> Path:
    """The two-aircraft scenario of ``duration_s`` with a second target far to
    the north-east (the map takes it in: room to click the goal) and the
    belly cameras on gimbals (at nadir until told otherwise)."""
    text = SCENARIO.format(duration_s=duration_s, w=W, h=H, rate_hz=RATE_HZ).replace(
        "heading_deg: 20}\n", "heading_deg: 20}\n  - {id: far, kind: car, north_m: 700, "
                               "east_m: 600, heading_deg: 0}\n").replace("mount: nadir",
                                                                         "mount: gimbal")
    assert "id: far" in text and "mount: gimbal" in text
    (folder / "pair.yaml").write_text(text)
    p = folder / "study.yaml"
    p.write_text(study)
    return p


# --- the study and the mapping -------------------------------------------------

def test_a_conditions_tasking_is_read_with_its_defaults(tmp_path: Path) -> None:
    """Every action where the aircraft take commands (look where they have
    gimbal cameras) unless the condition says; the orbit's radius the 150 m
    default widened to one a uav700 at 100 kt can fly (its turn radius at a
    45 deg bank is v^2 / g = 270 m)."""
    st = load_study(tasking_study(tmp_path, 4.0))
    two, go_only = st.live
    assert two.tasking == ("go", "orbit", "look") and two.taskable == ("uav1", "uav2")
    assert two.lookers == ("uav1", "uav2") and go_only.lookers == ()
    assert go_only.tasking == ("go",)
    v_mps = 100 * 0.514444
    assert two.orbit_radius_m == 300.0 and two.orbit_radius_m - 50 < v_mps ** 2 / 9.80665
    none = load_study(live_study(tmp_path, "protocol: live\norder: shuffle\nscenarios: "
                                           "[{scenario: pair.yaml, feeds: 1, tasking: false}]\n"))
    assert none.live[0].tasking == () and none.live[0].taskable == ()
    nadir = load_study(live_study(tmp_path, "protocol: live\norder: shuffle\nscenarios: "
                                            "[{scenario: pair.yaml, feeds: 1}]\n"))
    assert nadir.live[0].tasking == ("go", "orbit")  # no gimbal: nothing to look with
    wide = load_study(live_study(tmp_path, "protocol: live\norder: shuffle\nscenarios: "
                                           "[{scenario: pair.yaml, feeds: 1, tasking: [orbit], "
                                           "orbit_radius_m: 400}]\n"))
    assert (wide.live[0].tasking, wide.live[0].orbit_radius_m) == (("orbit",), 400.0)


@pytest.mark.parametrize("item, match", [
    ("tasking: [go, fly]", r"study\.yaml:4: scenarios\[0\]\.tasking\[1\]: expected one of go, "
                           r"orbit, look, got 'fly'"),
    ("tasking: [go, go]", r"scenarios\[0\]\.tasking\[1\]: 'go' given twice"),
    ("tasking: [go, look]", r"scenarios\[0\]\.tasking\[1\]: look: none of the vehicles of "
                            r".*pair\.yaml that take commands has a camera on a gimbal"),
    ("tasking: go", r"scenarios\[0\]\.tasking: expected a list of the map's commands allowed"),
    ("orbit_radius_m: 5", r"scenarios\[0\]\.orbit_radius_m: must be >= 10, got 5"),
    ("orbit_radius_m: 150", r"scenarios\[0\]\.orbit_radius_m: 150 m: an orbit must be one the "
                            r"aircraft can fly: loiter radius 150 m is below the minimum turn "
                            r"radius of uav1 \(270 m"),
])
def test_a_conditions_tasking_is_checked(tmp_path: Path, item: str, match: str) -> None:
    p = live_study(tmp_path, f"protocol: live\norder: shuffle\nscenarios:\n"
                             f"  - {{scenario: pair.yaml, feeds: 1, {item}}}\n")
    with pytest.raises(ConfigError, match=match):
        load_study(p)


def test_the_maps_actions_are_commands_of_the_one_vocabulary() -> None:
    """go, orbit and look at a point are a goto, a loiter around it at the
    condition's radius and the gimbal's look_at, each parsed by the
    vocabulary every command path uses."""
    from cosim.sync.inbox import parse_spec

    assert command_spec("go", 120.5, -40, 300) == {"goto": {"north_m": 120.5, "east_m": -40.0}}
    assert command_spec("orbit", 1, 2, 300) == {
        "loiter": {"center": {"north_m": 1.0, "east_m": 2.0}, "radius_m": 300.0}}
    assert command_spec("look", 1, 2, 300) == {"gimbal": {"look_at": {"north_m": 1.0,
                                                                       "east_m": 2.0}}}
    go = parse_spec(command_spec("go", 120.5, -40, 300), "go")
    assert go.flies and (go.points[0].a, go.points[0].b) == (120.5, -40.0)
    orbit = parse_spec(command_spec("orbit", 1, 2, 300), "orbit")
    assert orbit.loiter_radius_m == 300.0
    with pytest.raises(ConfigError, match=r"action: expected one of go, orbit, look, got 'fly'"):
        command_spec("fly", 0, 0, 300)


def test_a_live_run_takes_only_the_commands_its_condition_allows(tmp_path: Path) -> None:
    """LiveRun.command: an action the condition does not allow, an aircraft
    it may not task, a look for an aircraft without a gimbal camera are
    refused before they reach the run; a run without tasking has no inbox."""
    import asyncio
    import dataclasses

    from cosim.trials.live import Hub, LiveRun

    two, go_only = load_study(tasking_study(tmp_path, 4.0)).live
    loop = asyncio.new_event_loop()
    try:
        run = LiveRun(dataclasses.replace(two, lookers=("uav1",)), tmp_path / "a", Hub(loop),
                      backend="inline")
        assert run.inbox is not None
        with pytest.raises(ConfigError, match=r"^vehicle: uav2 has no camera on a gimbal to "
                                              r"point \(those that do: uav1\)$"):
            run.command("uav2", "look", 0.0, 0.0)
        with pytest.raises(ConfigError, match=r"^vehicle: 'uav9' cannot be tasked in condition "
                                              r"'two' \(it may task: uav1, uav2\)$"):
            run.command("uav9", "go", 0.0, 0.0)
        with pytest.raises(ConfigError, match=r"the run has not started yet"):
            run.command("uav1", "go", 0.0, 0.0)  # reached the inbox: not running
        only = LiveRun(go_only, tmp_path / "b", Hub(loop), backend="inline")
        with pytest.raises(ConfigError, match=r"^action: 'orbit' is not allowed in condition "
                                              r"'go_only' \(allowed: go\)$"):
            only.command("uav1", "orbit", 0.0, 0.0)
        none = LiveRun(dataclasses.replace(go_only, tasking=(), taskable=()), tmp_path / "c",
                       Hub(loop), backend="inline")
        assert none.inbox is None and json.loads(none.hub.hello)["tasking"] == {
            "actions": [], "vehicles": [], "look_vehicles": [], "orbit_radius_m": 150.0}
    finally:
        loop.close()


# --- the page ------------------------------------------------------------------

#: the client pixel of a point (north, east m) on the map, from the map's last
#: transform (the page's own, ``window.live.view``)
MAP_PX = """([n, e]) => {
  const m = document.getElementById("map"), r = m.getBoundingClientRect();
  const v = window.live.view;
  return [r.left + (v.w / 2 + (e - v.ce) * v.s) * r.width / v.w,
          r.top + (v.h / 2 - (n - v.cn) * v.s) * r.height / v.h];
}"""
#: select an aircraft: a pointerdown where the map drew it (in the page's own
#: task, so that the map does not move between reading it and clicking)
SELECT = "(id) => {\n  const at = " + MAP_PX + """;
  const u = window.live.vehicles.find((x) => x.id === id);
  const [x, y] = at([u.north_m, u.east_m]);
  document.getElementById("map").dispatchEvent(
    new PointerEvent("pointerdown", {clientX: x, clientY: y, bubbles: true}));
  return [x, y];
}"""


def _track(run_dir: Path, vehicle: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tick, north_m, east_m) of one vehicle's logged states."""
    t = pq.read_table(run_dir / "states.parquet", columns=["tick", "vehicle", "north_m",
                                                           "east_m"])
    mine = np.array(t.column("vehicle").to_pylist()) == vehicle
    return tuple(np.asarray(t.column(c).to_numpy())[mine] for c in ("tick", "north_m", "east_m"))


def _bearing_error_deg(n: np.ndarray, e: np.ndarray, i: int, goal: tuple[float, float]) -> float:
    """The angle between the track at sample ``i`` (from the sample before)
    and the line to the goal."""
    course = math.atan2(e[i] - e[i - 1], n[i] - n[i - 1])
    to_goal = math.atan2(goal[1] - e[i], goal[0] - n[i])
    return abs(math.degrees((to_goal - course + math.pi) % (2 * math.pi) - math.pi))


@pytest.mark.integration  # a live run of 10 s in headless Chromium
def test_a_map_click_sends_the_aircraft_there_and_the_command_is_stored(
        tmp_path: Path, chromium: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Select uav1 on the map, click the ground, choose Go here: the command
    is stored with the tick the run applied it at (as its commands.jsonl
    logged it), and uav1's logged track turns toward the point: its bearing
    error and distance to it shrink, against the same scenario's run without
    the command, which flies on north. An orbit and a look for uav2 sent
    with the same route are stored and logged as their commands; the page
    marks each aircraft's last command, again after a reload. ``cosim
    trials replay`` of the session says its run comes out identical (exit
    0), and with its log altered that it differs (exit 1)."""
    from cosim.scenario import load_scenario
    from cosim.sync.runner import run_scenario

    study = tasking_study(tmp_path, 10.0)
    alone = run_scenario(load_scenario(tmp_path / "pair.yaml"), tmp_path / "alone")
    assert alone.ok
    with live_server(study) as server:
        s = _session(server, "p1")
        ti = next(t["index"] for t in s["trials"] if t["condition"] == "two")
        with browser_page(chromium, viewport=(1000, 500)) as page:
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{server.url}/live?session={s['id']}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            status, out = server.request("POST", f"/api/sessions/{s['id']}/live/start",
                                         {"trial_index": ti})
            assert status == 201, out
            page.wait_for_function("window.live.view && window.live.vehicles && "
                                   "window.live.vehicles.length === 2")
            page.evaluate(SELECT, "uav1")
            assert page.text_content("#tasking") == ("uav1 selected: click the map where it "
                                                     "should go")
            x, y = page.evaluate(MAP_PX, list(GOAL_NE_M))
            page.mouse.click(x, y)
            assert page.is_visible("#taskmenu")
            assert page.locator("#taskmenu button").all_text_contents() == [
                "Go here (G)", "Orbit here (O)", "Look here (L)"]
            page.screenshot(path=str(tmp_path / "menu.png"))
            page.click("#taskmenu button[data-action='go']")
            page.wait_for_function("window.live.commands.length === 1 && "
                                   "window.live.commands[0].status === 201")
            assert not page.is_visible("#taskmenu")
            sent = page.evaluate("window.live.commands[0]")
            for action in ("orbit", "look"):
                status, out = server.request(
                    "POST", f"/api/sessions/{s['id']}/live/command",
                    {"trial_index": ti, "vehicle": "uav2", "action": action, "north_m": 200,
                     "east_m": 100, "client_time_ms": 5.0})
                assert status == 201, out
            # every page hears of every command: those sent without it too
            page.wait_for_function("window.live.marked && window.live.marked.length === 2")
            page.screenshot(path=str(tmp_path / "sent.png"))
            page.reload()  # and a reloaded page has them again
            page.wait_for_function("document.body.dataset.phase === 'live' && "
                                   "window.live.marked && window.live.marked.length === 2")
            assert sorted(page.evaluate("window.live.marked")) == ["uav1", "uav2"]
            page.wait_for_function("document.body.dataset.phase === 'ended'", timeout=60_000)
            assert not errors, errors
        rows = server.store.live_commands(s["id"])
        status, v = server.request("GET", f"/api/sessions/{s['id']}/live")
    run_dir = Path(v["trials"][ti]["run"])
    logged = [json.loads(line) for line in (run_dir / "commands.jsonl").read_text().splitlines()]
    assert [(r["seq"], r["vehicle"], r["action"]) for r in rows] == [
        (0, "uav1", "go"), (1, "uav2", "orbit"), (2, "uav2", "look")]
    go = rows[0]
    # the point the page computed from its click, as the page sent it
    assert (go["north_m"], go["east_m"]) == (sent["north_m"], sent["east_m"])
    assert math.hypot(go["north_m"] - GOAL_NE_M[0], go["east_m"] - GOAL_NE_M[1]) < 10
    assert [e["command"] for e in logged] == [
        {"goto": {"north_m": go["north_m"], "east_m": go["east_m"]}},
        {"loiter": {"center": {"north_m": 200.0, "east_m": 100.0}, "radius_m": 300.0}},
        {"gimbal": {"look_at": {"north_m": 200.0, "east_m": 100.0}}}]
    for r, e in zip(rows, logged):
        assert (r["tick"], r["sim_time_s"]) == (e["tick"], e["tick"] / 120), (r, e)
        assert r["run"] == str(run_dir) and r["client_time_ms"] is not None
    # uav1's track against the run without the command
    goal = (go["north_m"], go["east_m"])
    tick, n, e = _track(run_dir, "uav1")
    tick0, n0, e0 = _track(tmp_path / "alone", "uav1")
    assert np.array_equal(tick, tick0)
    k = int(np.searchsorted(tick, go["tick"]))  # the first sample after the command
    assert 2 <= k < len(tick) - 20, (k, len(tick))
    assert np.array_equal(n[:k], n0[:k]) and np.array_equal(e[:k], e0[:k])
    end = len(tick) - 1
    err_at, err_end = _bearing_error_deg(n, e, k, goal), _bearing_error_deg(n, e, end, goal)
    err_alone = _bearing_error_deg(n0, e0, end, goal)
    assert err_at > 20 and err_end < 0.5 * err_at and err_end < err_alone - 15, (
        err_at, err_end, err_alone)
    d_with = math.hypot(goal[0] - n[end], goal[1] - e[end])
    d_alone = math.hypot(goal[0] - n0[end], goal[1] - e0[end])
    assert d_with < d_alone - 20, (d_with, d_alone)
    # the session replayed from its logged commands: the same states and video
    assert main(["trials", "replay", str(study.with_suffix(".sqlite")), s["id"], "--out",
                 str(tmp_path / "replay")]) == 0
    said = capsys.readouterr().out
    assert re.search(rf"^trial {ti}: identical \(.*trial{ti:03d} replayed into "
                     rf".*replay/trial{ti:03d}\)$", said, re.M), said
    tick_r, n_r, e_r = _track(tmp_path / "replay" / f"trial{ti:03d}", "uav1")
    assert np.array_equal(n_r, n) and np.array_equal(e_r, e)
    # its log altered (the goal 50 m further east): the replay differs, exit 1
    log = run_dir / "commands.jsonl"
    log.write_text(log.read_text().replace(f'"east_m": {go["east_m"]}',
                                           f'"east_m": {go["east_m"] + 50}', 1))
    assert main(["trials", "replay", str(study.with_suffix(".sqlite")), s["id"], "--trial",
                 str(ti), "--out", str(tmp_path / "replay2")]) == 1
    said = capsys.readouterr().out
    assert re.search(rf"^trial {ti}: differs \(.*\):$", said, re.M), said
    assert re.search(r"^  .*states", said, re.M), said


@pytest.mark.integration  # a live run of a few seconds
def test_commands_the_condition_does_not_allow_are_refused(tmp_path: Path) -> None:
    """In the go-only condition: a look, an aircraft not in the scenario, a
    point past 20 km and a wrong trial are refused (400, 409) saying what
    was expected; the sixth command within a second is refused (429), and
    nothing refused is stored or reaches the run."""
    study = tasking_study(tmp_path, 6.0)
    with live_server(study) as server:
        s = _session(server, "p2")
        ti = next(t["index"] for t in s["trials"] if t["condition"] == "go_only")
        status, out = server.request("POST", f"/api/sessions/{s['id']}/live/start",
                                     {"trial_index": ti})
        assert status == 201, out
        url = f"/api/sessions/{s['id']}/live/command"

        def post(**over: Any) -> tuple[int, Any]:
            body = {"trial_index": ti, "vehicle": "uav1", "action": "go", "north_m": 100.0,
                    "east_m": 0.0, "client_time_ms": 1.0, **over}
            return server.request("POST", url, body)

        cases: list[tuple[dict[str, Any], int, str]] = [
            ({"action": "look"}, 400,
             r"^action: expected one of go \(condition 'go_only'\), got 'look'$"),
            ({"vehicle": "uav9"}, 400,
             r"^vehicle: expected one of uav1, uav2 \(the aircraft of condition 'go_only' "
             r"that take commands\), got 'uav9'$"),
            ({"north_m": 20_000.0, "east_m": 500.0}, 400,
             r"^north_m, east_m: expected a point within 20000 m of the scenario's origin, "
             r"got \(20000, 500\)$"),
            ({"north_m": "far"}, 400, r"^north_m: expected a number, got 'far'$"),
            ({"trial_index": 1 - ti}, 409, rf"^trial_index: the live trial of this session is "
                                           rf"{ti}, got {1 - ti}$"),
        ]
        for over, code, match in cases:
            status, out = post(**over)
            assert status == code and re.search(match, out["error"]), (over, status, out)
        # the run takes commands once its vehicles are built: retried at 20 a
        # second until then, each refused (409), none counted against the limit
        deadline = time.monotonic() + 30
        refused = 0
        while (got := post())[0] != 201:
            assert got[0] == 409 and "has not started yet" in got[1]["error"], (refused, got)
            assert time.monotonic() < deadline, got
            refused += 1
            time.sleep(0.05)
        time.sleep(1.05)
        t0 = time.monotonic()
        statuses = [post(north_m=100.0 + i)[0] for i in range(6)]
        assert time.monotonic() - t0 < 1.0, "too slow to test the rate limit"
        status, out = post()
        assert statuses == [201] * 5 + [429] and status == 429, statuses
        assert re.search(r"^too many commands: at most 5 a second; wait a moment and send it "
                         r"again$", out["error"]), out
        status, out = server.request("POST", f"/api/sessions/{s['id']}/live/stop", {})
        assert status == 200, out
        rows = server.store.live_commands(s["id"])
        run_dir = Path(out["out_dir"])
    assert [r["seq"] for r in rows] == list(range(6)) and {r["action"] for r in rows} == {"go"}
    logged = [json.loads(line) for line in (run_dir / "commands.jsonl").read_text().splitlines()]
    assert [e["seq"] for e in logged] == [r["seq"] for r in rows if r["tick"] is not None]


def test_the_per_trial_limit_is_refused_with_429(tmp_path: Path) -> None:
    """Past MAX_COMMANDS_PER_TRIAL in a trial (the count kept per session and
    trial, the second's window aside), a command is refused (429)."""
    from cosim.trials import live_routes
    from cosim.trials.server import BadRequest

    console = live_routes.LiveConsole.__new__(live_routes.LiveConsole)
    console.bad = BadRequest
    console._sent, console._commands = {}, {("s", 0): live_routes.MAX_COMMANDS_PER_TRIAL - 1}
    console._room_for_command("s", 0)
    console._took_command("s", 0)
    with pytest.raises(BadRequest, match=r"too many commands: at most 2000 in a trial"):
        console._room_for_command("s", 0)
    console._room_for_command("s", 1)  # another trial: its own count


# --- the store, the export and the analysis --------------------------------------

def test_the_commands_export_as_stored_spreadsheet_safe(tmp_path: Path) -> None:
    from test_live import PROFILE

    db = tmp_path / "t.sqlite"
    with Store(db) as store:
        s = store.create_session(participant="=HYPERLINK(1)", study="x", protocol="live",
                                 display=PROFILE, order_method="shuffle", seed=1,
                                 session_number=0, trial_order=[{"index": 0}])
        for seq, action in enumerate(("go", "look")):
            store.record_live_command({
                "session": s["id"], "participant": s["participant"], "trial_index": 0,
                "condition": "c", "seq": seq, "vehicle": "uav1", "action": action,
                "north_m": 10.5 * seq, "east_m": -3.0, "client_time_ms": 100.0 + seq,
                "run": "runs/x"})
        store.live_command_applied(s["id"], 0, 0, 360, 3.0)
    out = tmp_path / "commands.csv"
    assert main(["trials", "export", str(db), "--out", str(tmp_path / "r.csv"),
                 "--live-commands", str(out)]) == 0
    with out.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["seq"], r["action"], r["north_m"], r["tick"], r["sim_time_s"]) for r in rows] == [
        ("0", "go", "0.0", "360", "3.0"), ("1", "look", "10.5", "", "")]
    assert rows[0]["participant"] == "'=HYPERLINK(1)" and rows[0]["server_time"]


def test_tasking_counts_against_a_condition_recover_a_known_effect(tmp_path: Path) -> None:
    """Twelve synthetic participants' commands a minute fall by 0.6 a feed
    (12 - 0.6 * feeds, each participant's own offset, noise): the slope's
    interval holds -0.6 and not 0; each level's mean its model value within
    its interval; analyse_live writes the tables and live_tasking.png."""
    rng = np.random.default_rng(30)
    sessions = []
    truth: dict[int, list[float]] = {}
    for p in range(12):
        offset = rng.normal(0, 1.0)
        for k in (1, 2, 4, 9):
            rate = 12 - 0.6 * k + offset + rng.normal(0, 0.4)
            n = max(0, round(rate * 2))  # two minutes
            actions = tuple(rng.choice(["go", "orbit", "look"], n).tolist())
            sessions.append(ScoredSession(f"s{p}/{k}", f"p{p}", (("feeds", str(k)),),
                                          SessionScore((), ()), actions, 120.0))
            truth.setdefault(k, []).append(n / 2)
    levels, effects = tasking_tables(sessions)
    (slope,) = [r for r in effects if r["measure"] == "commands_per_min"]
    assert slope["ci_lo"] < -0.6 < slope["ci_hi"] < 0, slope
    assert slope["unit"] == "commands per minute per unit of feeds"
    got = {r["level"]: r for r in levels if r["measure"] == "commands_per_min"}
    assert sorted(got) == [1.0, 2.0, 4.0, 9.0]
    for k, r in got.items():
        assert r["estimate"] == pytest.approx(np.mean(truth[int(k)]))
        assert r["ci_lo"] < 12 - 0.6 * k < r["ci_hi"], (k, r)
        assert (r["participants"], r["targets"]) == (12, 12)
    summary = analyse_live(sessions, tmp_path)
    assert {"live_tasking_levels.csv", "live_tasking_effects.csv",
            "live_tasking.png"} <= set(summary["files"])
    assert sum(summary["commands"].values()) == sum(len(s.commands) for s in sessions)
    with open(tmp_path / "live_tasking_effects.csv", newline="") as f:
        (row,) = [r for r in csv.DictReader(f) if r["measure"] == "commands_per_min"]
    assert float(row["slope"]) == pytest.approx(slope["slope"])
    assert (tmp_path / "live_tasking.png").stat().st_size > 10_000


# --- cosim trials replay ------------------------------------------------------------

def test_replay_refuses_what_it_cannot_replay(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown session, a clip session, a trial not run, a trial out of
    range: exit 2, saying which."""
    from test_live import PROFILE

    db = tmp_path / "study.sqlite"
    with Store(db) as store:
        live = store.create_session(participant="p", study="x", protocol="live",
                                    display=PROFILE, order_method="shuffle", seed=1,
                                    session_number=0, trial_order=[{"index": 0}])
        clip = store.create_session(participant="q", study="x", protocol="yes_no",
                                    display=PROFILE, order_method="shuffle", seed=1,
                                    session_number=0, trial_order=[{"index": 0}])
    for args, match in [
        (["nosuch"], r"no session 'nosuch' in the database"),
        ([clip["id"]], rf"session {clip['id']}: a yes_no session; only a live session's"),
        ([live["id"]], rf"session {live['id']}: none of its 1 trials has a run folder in "
                       rf".*study-live/{live['id']}"),
        ([live["id"], "--trial", "3"], rf"--trial: session {live['id']} has trials 0\.\.0, "
                                       rf"not 3"),
    ]:
        assert main(["trials", "replay", str(db), *args]) == 2
        assert re.search(match, capsys.readouterr().err), (args, match)
    assert main(["trials", "replay", str(tmp_path / "none.sqlite"), "x"]) == 2
    assert "no such trial database" in capsys.readouterr().err


def test_analyse_counts_each_stored_trials_commands(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """cosim trials analyse --study on stored sessions: each trial's stored
    commands counted by action, a minute of its run's simulated time (its
    summary.json), and the print-out says so; a trial whose summary gives no
    time has its counts and no rate."""
    from test_live_results import live_db as make_db

    study, db, s = make_db.__wrapped__(tmp_path)  # type: ignore[attr-defined]
    p1 = s["p1"]
    folder = tmp_path / "study-live" / p1["id"]
    for ti, sim_s in ((0, 30.0), (1, None)):
        summary = json.loads((folder / f"trial{ti:03d}" / "summary.json").read_text())
        if sim_s is not None:
            summary["sim_time_s"] = sim_s
        (folder / f"trial{ti:03d}" / "summary.json").write_text(json.dumps(summary))
    with Store(db) as store:
        for seq, (ti, action) in enumerate([(0, "go"), (0, "look"), (0, "go"), (1, "orbit")]):
            store.record_live_command({
                "session": p1["id"], "participant": "p1", "trial_index": ti, "condition": "c",
                "seq": seq, "vehicle": "uav1", "action": action, "north_m": 0.0,
                "east_m": 0.0, "client_time_ms": None, "run": "r"})
    out = tmp_path / "a"
    assert main(["-q", "trials", "analyse", str(db), "--study", str(study), "--out",
                 str(out)]) == 0
    assert ("live: 4 commands from the map (2 go, 1 orbit, 1 look): live_tasking_levels.csv"
            in capsys.readouterr().out)
    with (out / "live_sessions.csv").open(newline="") as f:
        got = {r["session"]: (r["go"], r["orbit"], r["look"], r["commands"], r["duration_s"],
                              r["commands_per_min"]) for r in csv.DictReader(f)}
    assert got[f"{p1['id']}/0"] == ("2", "0", "1", "3", "30", "6")  # 3 in 30 s
    assert got[f"{p1['id']}/1"] == ("0", "1", "0", "1", "", "")
    assert got[f"{s['p2']['id']}/0"] == ("0", "0", "0", "0", "", "")
