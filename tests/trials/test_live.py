"""The live console (``protocol: live``): the study's live conditions, the
hub's drops for a slow page, and a live session end to end: uvicorn on
127.0.0.1 (an ephemeral port) in a thread, a two-aircraft scenario paced at
real time, a slow raw client and a scripted participant in headless Debian
Chromium (/usr/bin/chromium through Playwright; nothing is downloaded)."""

from __future__ import annotations

import asyncio
import contextlib
import csv
import dataclasses
import json
import logging
import math
import re
import socket
import threading
import time
from collections.abc import Iterator, MutableMapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest
from test_server import live_server

from cosim.errors import ConfigError
from cosim.trials.live import MAX_WATCHERS, Hub
from cosim.trials.study import load_study

W, H, RATE_HZ, DURATION_S = 160, 120, 10.0, 4.0
SCENARIO = """\
schema_version: 1
name: live_pair
origin: {{lat_deg: 37.4150, lon_deg: -122.0480, ground_alt_m: 10}}
rates: {{physics_hz: 120, control_hz: 30, log_hz: 10}}
duration_s: {duration_s}
seed: 7
vehicles:
  - id: uav1
    model: uav700
    init: {{north_m: -130, east_m: 0, alt_agl_m: 100, heading_deg: 0, airspeed_kt: 100}}
  - id: uav2
    model: uav700
    init: {{north_m: -130, east_m: 60, alt_agl_m: 100, heading_deg: 0, airspeed_kt: 100}}
ground: {{texture: procedural}}
targets:
  - {{id: truck1, kind: truck, north_m: 0, east_m: 0, heading_deg: 20}}
cameras:
  render_workers: 0
  views:
    - {{name: belly, vehicles: [uav1, uav2], mount: nadir, vfov_deg: 40, width_px: {w},
       height_px: {h}, rate_hz: {rate_hz:g}}}
"""
STUDY = """\
name: live_test
protocol: live
scenarios:
  - {id: two, scenario: pair.yaml, feeds: [uav1/belly, uav2/belly], conditions: {feeds: 2}}
order: shuffle
"""
PROFILE = {"screen_width_px": 1000, "screen_height_px": 500, "screen_width_mm": 500.0,
           "screen_height_mm": 250.0, "viewing_distance_mm": 600.0}


def live_study(folder: Path, study: str = STUDY, size_px: tuple[int, int] = (W, H)) -> Path:
    (folder / "pair.yaml").write_text(SCENARIO.format(duration_s=DURATION_S, w=size_px[0],
                                                      h=size_px[1], rate_hz=RATE_HZ))
    p = folder / "study.yaml"
    p.write_text(study)
    return p


@pytest.mark.parametrize("scenarios, match", [
    ("[{scenario: pair.yaml, feeds: [uav1/nose]}]",
     r"study\.yaml:4: scenarios\[0\]\.feeds\[0\]: no feed 'uav1/nose' in .*pair\.yaml; it "
     r"has: uav1/belly, uav2/belly"),
    ("[{scenario: pair.yaml, feeds: 3}]",
     r"scenarios\[0\]\.feeds: 3 feeds: expected 1\.\.2 \(.*pair\.yaml has 2 camera streams"),
    ("[{scenario: pair.yaml, feeds: [uav1/belly, uav1/belly]}]",
     r"scenarios\[0\]\.feeds\[1\]: feed 'uav1/belly' given twice"),
    ("[{scenario: ../elsewhere.yaml, feeds: 1}]",
     r"scenarios\[0\]\.scenario: '\.\./elsewhere\.yaml': the scenario must be an existing "
     r"file inside the study's folder"),
    ("[{scenario: pair.yaml, feeds: 1, colour: red}]", r"scenarios\[0\]\.colour: unknown key"),
])
def test_live_conditions_are_checked(tmp_path: Path, scenarios: str, match: str) -> None:
    (tmp_path.parent / "elsewhere.yaml").write_text("{}")
    p = live_study(tmp_path, f"name: bad\nprotocol: live\norder: shuffle\n"
                             f"scenarios: {scenarios}\n")
    with pytest.raises(ConfigError, match=match):
        load_study(p)


def test_a_live_study_has_scenarios_not_clips(tmp_path: Path) -> None:
    p = live_study(tmp_path, "protocol: live\nsweep: runs\n")
    with pytest.raises(ConfigError, match=r"sweep: a live study runs scenarios"):
        load_study(p)
    p = live_study(tmp_path, "protocol: disappear\nscenarios: []\n")
    with pytest.raises(ConfigError, match=r"scenarios: `scenarios:` is for `protocol: live`"):
        load_study(p)


def test_the_example_live_study_reads() -> None:
    """studies/live_feeds.yaml: 1, 2 and 4 feeds of its line-abreast scenario."""
    st = load_study(Path(__file__).resolve().parents[2] / "studies" / "live_feeds.yaml")
    assert [(c.id, len(c.feeds), c.condition_map) for c in st.live] == [
        ("one_feed", 1, {"feeds": "1"}), ("two_feeds", 2, {"feeds": "2"}),
        ("four_feeds", 4, {"feeds": "4"})]
    assert st.live[2].feeds[3].name == "uav4/front" and st.scoring.tolerance_px == 10


def test_a_live_studys_scoring_settings_are_read_and_checked(tmp_path: Path) -> None:
    head = "protocol: live\nscenarios: [{scenario: pair.yaml, feeds: 2}]\n"
    st = load_study(live_study(tmp_path, head + "scoring: {tolerance_px: 4, "
                                              "duplicate_window_s: 30}\n"))
    assert (st.scoring.tolerance_px, st.scoring.duplicate_window_s) == (4.0, 30.0)
    with pytest.raises(ConfigError, match=r"study\.yaml:3: scoring\.tolerance_px: .*-1"):
        load_study(live_study(tmp_path, head + "scoring: {tolerance_px: -1}\n"))
    with pytest.raises(ConfigError, match=r"scoring: `scoring:` is for `protocol: live`"):
        load_study(live_study(tmp_path, "protocol: disappear\nscoring: {}\n"))


def test_a_live_studys_feeds_by_count_are_the_scenarios_first(tmp_path: Path) -> None:
    p = live_study(tmp_path, "protocol: live\nscenarios: [{scenario: pair.yaml, feeds: 1, "
                             "duration_s: 2}]\n")
    (c,) = load_study(p).live
    assert [f.name for f in c.feeds] == ["uav1/belly"] and c.duration_s == 2.0
    assert (c.feeds[0].width_px, c.feeds[0].height_px, c.feeds[0].rate_hz) == (W, H, RATE_HZ)


@pytest.mark.parametrize("width_px", [160, 320, 640])
def test_the_frame_number_in_the_rows_below_the_picture_survives_jpeg(width_px: int) -> None:
    """The counter the page reads back: every number written is read again
    after the JPEG encoding the feeds go through, on a busy picture."""
    from cosim.trials.live import COUNTER_ROWS, JPEG_QUALITY, read_counter, with_counter

    rng = np.random.default_rng(width_px)
    h = width_px * 3 // 4
    picture = rng.integers(0, 256, (h, width_px, 3), dtype=np.uint8)
    for k in [0, 1, 255, 256, 65535, *rng.integers(0, 65536, 40).tolist()]:
        img = with_counter(picture, int(k))
        assert img.shape == (h + COUNTER_ROWS, width_px, 3)
        assert np.array_equal(img[:h], picture)
        ok, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        back = cv2.imdecode(jpg, cv2.IMREAD_COLOR)
        assert ok and back is not None and read_counter(back) == k
    assert read_counter(with_counter(picture, 65536 + 7)) == 7  # mod 2**16


def test_a_watcher_that_does_not_keep_up_loses_its_oldest_frames_counted() -> None:
    """Frames published from another thread never wait for a page: a page
    that reads nothing keeps the newest ``max_pending`` and counts the rest
    as dropped; one that reads gets every frame."""
    async def scenario() -> tuple[int, int, list[int], int]:
        hub = Hub(asyncio.get_running_loop())
        slow, fast = hub.watch(max_pending=4), hub.watch(max_pending=1000)
        await slow.get()  # hello
        got: list[int] = []

        async def read() -> None:
            while True:
                kind, text = await fast.get()
                if kind == "end":
                    return
                if kind == "frame":
                    got.append(int(text.split('"frame":')[1].rstrip("}")))

        reader = asyncio.create_task(read())
        t0 = time.perf_counter()
        def publish() -> None:
            for k in range(50):
                hub.publish("frame", {"feed": 0, "frame": k})
            hub.end()

        th = threading.Thread(target=publish)
        th.start()
        th.join()
        took = time.perf_counter() - t0
        await reader
        left = [int(t.split('"frame":')[1].rstrip("}"))
                for _, t in list(slow.pending)]
        assert took < 1.0
        return slow.dropped_frames, hub.dropped_frames, left, len(got)

    dropped, total, left, got = asyncio.run(scenario())
    # at most MAX_WATCHERS pages watch one session
    async def crowd() -> None:
        hub = Hub(asyncio.get_running_loop())
        for _ in range(MAX_WATCHERS):
            hub.watch()
        with pytest.raises(ConfigError, match=rf"{MAX_WATCHERS} pages already watch this"):
            hub.watch()

    asyncio.run(crowd())
    assert dropped == 46  # 50 frames, the newest 4 kept
    assert total == dropped and left == [46, 47, 48, 49] and got == 50


def _same_states(a: Path, b: Path) -> None:
    """The two runs' states.parquet hold the same values, column by column."""
    ta, tb = pq.read_table(a / "states.parquet"), pq.read_table(b / "states.parquet")
    assert ta.column_names == tb.column_names and ta.num_rows == tb.num_rows > 0
    for c in ta.column_names:
        x = ta.column(c).to_numpy(zero_copy_only=False)
        y = tb.column(c).to_numpy(zero_copy_only=False)
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), c
        else:
            assert list(x) == list(y), c


def downlink_study(folder: Path, duration_s: float, latency_ms: float) -> Path:
    """The two-aircraft study with a downlink on the cameras: 5 of their 10
    frames a second, ``latency_ms`` late."""
    text = SCENARIO.format(duration_s=duration_s, w=W, h=H, rate_hz=RATE_HZ).replace(
        "rate_hz: 10}",
        f"rate_hz: 10,\n       datalink: {{rate_hz: 5, latency_ms: {latency_ms:g}}}}}")
    assert "datalink" in text
    (folder / "pair.yaml").write_text(text)
    (folder / "study.yaml").write_text(STUDY)
    return folder / "study.yaml"


def _session(server: Any, participant: str) -> dict[str, Any]:
    status, s = server.request("POST", "/api/sessions", {"participant": participant, **PROFILE})
    assert status == 201 and s["protocol"] == "live", s
    return dict(s)


@contextlib.contextmanager
def browser_page(chromium: str, *scripts: str,
                 viewport: tuple[int, int] | None = None) -> Iterator[Any]:
    """A page of headless Chromium (the ``chromium`` fixture's), ``scripts``
    run in it before the page's own."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium)
        try:
            page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]},
                                    device_scale_factor=1) if viewport else browser.new_page()
            for script in scripts:
                page.add_init_script(script)
            page.set_default_timeout(30_000)
            yield page
        finally:
            browser.close()


def _start(server: Any, sid: str) -> dict[str, Any]:
    status, out = server.request("POST", f"/api/sessions/{sid}/live/start", {"trial_index": 0})
    assert status == 201, out
    return dict(out)


def _wait_over(server: Any, sid: str, timeout_s: float = 60.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        status, v = server.request("GET", f"/api/sessions/{sid}/live")
        assert status == 200, v
        if not v["live"]["running"]:
            return dict(v)
        assert time.monotonic() < deadline, "the live run did not end"
        time.sleep(0.2)


def test_timing_over_the_studys_limits_is_flagged(tmp_path: Path) -> None:
    from cosim.trials.live_routes import timing_flags
    from cosim.trials.live_study import TimingLimits

    status = {"frames_published": 200, "frames_dropped": 3,
              "page_timing": {"frames_received": 197, "frames_drawn": 190,
                              "latency_ms_p50": 250.0}}
    assert timing_flags(TimingLimits(200, 1.0), status) == [
        "median glass-to-glass latency 250 ms, over the study's 200 ms",
        "5.0 % of frames lost (3 dropped for the page, 7 skipped by it, of 200), over the "
        "study's 1 %"]  # (3 + 7) / 200
    assert timing_flags(TimingLimits(250, 5.0), status) == []
    assert timing_flags(TimingLimits(), status) == []
    head = "protocol: live\nscenarios: [{scenario: pair.yaml, feeds: 2}]\n"
    st = load_study(live_study(tmp_path, head + "timing_limits: {latency_ms_p50: 200, "
                                              "dropped_percent: 1}\n"))
    assert st.timing_limits == TimingLimits(200.0, 1.0)
    with pytest.raises(ConfigError, match=r"study\.yaml:3: timing_limits\.dropped_percent: "
                                          r".*101"):
        load_study(live_study(tmp_path, head + "timing_limits: {dropped_percent: 101}\n"))


def test_the_page_s_timing_before_the_run_has_a_folder_is_kept(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The page may report its timing while the run is still being built,
    before the run's folder exists: the timing is kept with the run (its
    status) and written to the folder by a later report, not a server error."""
    from cosim.trials.live import LiveRun

    monkeypatch.setattr(LiveRun, "start", lambda self: None)  # built, never started
    with live_server(live_study(tmp_path)) as server:
        status, s = server.request("POST", "/api/sessions", {"participant": "early", **PROFILE})
        assert status == 201, s
        _start(server, s["id"])
        status, out = server.request("POST", f"/api/sessions/{s['id']}/live/timing",
                                     {"trial_index": 0, "frames_received": 0,
                                      "frames_drawn": 0, "latency_samples": 0,
                                      "counter_mismatches": 0})
        assert status == 200, out
        status, v = server.request("GET", f"/api/sessions/{s['id']}/live")
        assert v["live"]["page_timing"]["frames_received"] == 0, v
        assert not Path(v["live"]["out_dir"]).exists()


@pytest.mark.integration  # a live run of a few seconds
def test_a_slow_page_loses_frames_and_the_run_keeps_real_time(tmp_path: Path,
                                                              chromium: str) -> None:
    """A client that opens the stream and never reads: its frames are dropped
    and counted, and the run still keeps to real time; the trial is flagged
    on the experimenter's page for the study's limit on lost frames. (640 x
    480 frames: more than the sockets' buffers hold.)"""
    study = STUDY + "timing_limits: {dropped_percent: 0.5}\n"
    with live_server(live_study(tmp_path, study, size_px=(640, 480))) as server:
        status, s = server.request("POST", "/api/sessions", {"participant": "slow", **PROFILE})
        assert status == 201, s
        status, out = server.request("GET", f"/api/sessions/{s['id']}/live/stream")
        assert status == 409 and "no trial of this session has been started" in out["error"]
        _start(server, s["id"])
        status, out = server.request("POST", f"/api/sessions/{s['id']}/live/start",
                                     {"trial_index": 0})
        assert status == 409 and "still running" in out["error"], out
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
        sock.connect((server.host, int(server.port)))
        sock.sendall(f"GET /api/sessions/{s['id']}/live/stream HTTP/1.1\r\n"
                     f"Host: 127.0.0.1\r\n\r\n".encode())
        try:
            v = _wait_over(server, s["id"])
        finally:
            sock.close()
        folder = Path(v["trials"][0]["run"])
        summary = json.loads((folder / "summary.json").read_text())
        assert summary["stop_reason"] == "completed"
        live = v["live"]
        assert live["frames_published"] == 2 * DURATION_S * RATE_HZ, live
        assert live["frames_dropped"] > 0, live
        lost = 100 * live["frames_dropped"] / live["frames_published"]
        assert live["flags"] == [f"{lost:.1f} % of frames lost ({live['frames_dropped']} "
                                 f"dropped for the page, 0 skipped by it, of "
                                 f"{live['frames_published']}), over the study's 0.5 %"]
        # reports and timings are checked against the trial's feeds and frames sent
        good = {"trial_index": 0, "report_key": "k1", "feed": 1, "frame": 3, "x_px": 10.5,
                "y_px": 20.0, "click_time_ms": 1000.0, "drawn_time_ms": 990.0}
        last = 2 * DURATION_S * RATE_HZ // 2 - 1
        cases: list[tuple[dict[str, Any], int, str]] = [
            ({"feed": 2}, 400, r"feed: expected 0\.\.1 \(this trial's feeds\), got 2"),
            ({"frame": 10_000}, 400, rf"frame: expected a frame of feed uav2/belly sent to "
                                     rf"the page \(0\.\.{last:.0f}\), got 10000"),
            ({"x_px": 641.0}, 400, r"x_px, y_px: expected a point of the 640 x 480 frame"),
            ({"y_px": float("nan")}, 400, r"not JSON|y_px: expected a number"),
            ({"report_key": "a b"}, 400, r"report_key: expected the page's id of the click"),
            ({"trial_index": 1}, 409, r"trial_index: the live trial of this session is 0"),
            ({"click_time_ms": -1}, 400, r"click_time_ms: expected 0\.\.86400000 ms"),
        ]
        for change, status_want, match in cases:
            status, out = server.request("POST", f"/api/sessions/{s['id']}/live/reports",
                                         {**good, **change})
            assert status == status_want and re.search(match, out["error"]), (change, out)
        for again, status_want in ((False, 201), (True, 200)):  # a retry is kept once
            status, out = server.request("POST", f"/api/sessions/{s['id']}/live/reports", good)
            assert status == status_want and out["created"] is not again, out
        assert len(server.store.live_reports(s["id"])) == 1
        (stored,) = server.store.live_reports(s["id"])
        status, out = server.request("POST", f"/api/sessions/{s['id']}/live/timing",
                                     {"trial_index": 0, "frames_received": 1.5,
                                      "frames_drawn": 1, "latency_samples": 1})
        assert status == 400 and re.search(r"frames_received: expected a whole number "
                                           r"0\.\.10000000, got 1\.5", out["error"]), out
        with browser_page(chromium) as page:
            page.goto(f"{server.url}/")
            page.wait_for_selector(".live-flags")
            assert page.locator(".live-flags").inner_text() == \
                f" \u26a0 trial 1: {live['flags'][0]}"
        pacing = summary["realtime"]
        # the tick loop was not held by the client: a run waiting on the page's
        # socket would fall seconds behind (the bound leaves room for a loaded
        # machine: the median was 185 ms with two test runs at once)
        assert pacing["lateness_ms_p50"] < 1000.0, pacing
    # cosim trials export --live: the click as stored
    from cosim.cli import main

    out = tmp_path / "live.csv"
    assert main(["-q", "trials", "export", str(tmp_path / "study.sqlite"), "--out",
                 str(tmp_path / "responses.csv"), "--live", str(out)]) == 0
    with open(out, newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert {k: row[k] for k in ("session", "participant", "feed_name", "frame", "x_px",
                                "click_time_ms", "report_key")} == {
        "session": s["id"], "participant": "slow", "feed_name": "uav2/belly", "frame": "3",
        "x_px": "10.5", "click_time_ms": "1000.0", "report_key": "k1"}
    assert row["run"] == stored["run"] and row["created"] == stored["created"]


PIXELS_AT_CLICK = """
(() => {
  window.witness = [];
  window.addEventListener("pointerdown", (e) => {  // before the page's own listener
    const c = e.target;
    if (!(c instanceof HTMLCanvasElement) || c.dataset.feed === undefined) return;
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    window.witness.push({feed: Number(c.dataset.feed), pixels: Array.from(d)});
  }, true);
})();
"""


#: a script clicking feed 0 where the truck's centre is on the frame drawn there
#: last (its argument: [{frame: [x, y]}, width, height]); [frame, x, y]
CLICK_ON_TRUCK = """([centres, w, h]) => {
  const d = window.live.drawn.filter((d) => d[0] === 0).pop();
  const p = centres[d[1]];
  if (!p) return [d[1], null, null];
  const canvas = document.querySelector("canvas[data-feed='0']");
  const r = canvas.getBoundingClientRect();
  const x = r.left + (p[0] + 0.5) * r.width / w, y = r.top + (p[1] + 0.5) * r.height / h;
  canvas.dispatchEvent(new PointerEvent("pointerdown", {clientX: x, clientY: y,
                                                        bubbles: true}));
  return [d[1], x, y];
}"""


def _video_frames(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    out: list[np.ndarray] = []
    while True:
        ok, img = cap.read()
        if not ok:
            return out
        out.append(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(float))


def _truck(gt: Path) -> dict[int, dict[str, float]]:
    """The truck's rows of a feed's ground truth, by frame, where it is in
    view with at least 4 pixels (the scoring's default visibility)."""
    with open(gt, newline="") as f:
        return {int(r["frame"]): {k: float(r[k]) for k in (
                    "time_s", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px",
                    "center_x_px", "center_y_px")}
                for r in csv.DictReader(f)
                if r["target"] == "truck1" and r["in_view"] == "1"
                and float(r["pixels_on_target"]) >= 4}


def _expected(truck: dict[int, dict[str, float]], frame: int, x: float, y: float
              ) -> tuple[str, float | None]:
    """(outcome, pixel error) of a first click at (x, y) on ``frame``: a hit
    inside the truck's box grown by 10 px (the default tolerance)."""
    r = truck.get(frame)
    if r is None or not (r["bbox_x0_px"] - 10 <= x <= r["bbox_x1_px"] + 10
                         and r["bbox_y0_px"] - 10 <= y <= r["bbox_y1_px"] + 10):
        return "false_alarm", None
    return "hit", math.hypot(x - r["center_x_px"], y - r["center_y_px"])


def test_a_click_on_a_feed_is_stored_with_its_frame_and_pixel(tmp_path: Path,
                                                              chromium: str) -> None:
    """The page draws both feeds of a live run; a scripted click on the
    second is stored with that feed, a frame the page drew (its pixels are
    the run's video frame of that number, not its neighbours') and the pixel
    in the frame's coordinates from the canvas's box as Playwright measures
    it; a click on the truck in the first feed (where the same scenario's
    run without the console has it) is scored a hit with the pixel error
    from the ground truth, the other a false alarm. The run's states and
    ground truth equal those of the run without the console."""
    from cosim.scenario import load_scenario
    from cosim.sync.runner import run_scenario

    study = live_study(tmp_path)
    alone = run_scenario(load_scenario(tmp_path / "pair.yaml"), tmp_path / "alone")
    assert alone.ok
    truck = _truck(tmp_path / "alone" / "cameras" / "uav1_belly.gt.csv")
    seen = sorted(truck)
    assert len(seen) >= 8, seen  # the truck passes under uav1 within the run
    with live_server(study) as server:
        sid = _session(server, "p1")["id"]
        with browser_page(chromium, PIXELS_AT_CLICK,
                          viewport=(1000, 500)) as page:
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{server.url}/live?session={sid}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            _start(server, sid)
            page.wait_for_function("document.body.dataset.drawn === '2' && "
                                   "window.live.drawn.length >= 6")
            box = page.locator("canvas[data-feed='1']").bounding_box()
            assert box is not None
            cx, cy = round(box["x"] + 0.3 * box["width"]), round(box["y"] + 0.6 * box["height"])
            page.mouse.click(cx, cy)
            page.screenshot(path=str(tmp_path / "live.png"))
            # the truck in feed 0: a click (in the page's own task, so that no
            # other frame is drawn first) where the ground truth has it on the
            # frame drawn last
            page.wait_for_function(f"window.live.drawn.some((d) => d[0] === 0 && "
                                   f"d[1] >= {seen[1]})", timeout=60_000)
            centres = {k: [r["center_x_px"], r["center_y_px"]] for k, r in truck.items()}
            last, _, _ = page.evaluate(CLICK_ON_TRUCK, [centres, W, H])
            assert last in truck, (last, seen)
            page.wait_for_function("window.live.reports.length === 2 && "
                                   "window.live.reports.every((r) => r.status === 201)")
            sent = page.evaluate("window.live.reports")
            drawn = page.evaluate("window.live.drawn")
            witness = page.evaluate("window.witness")
            page.wait_for_function("document.body.dataset.phase === 'ended'",
                                   timeout=60_000)
            assert not errors, errors
        v = _wait_over(server, sid)
        timing = v["live"]["page_timing"]
        first, second = server.store.live_reports(sid)
        status, score = server.request("GET", f"/api/sessions/{sid}/live/score?trial_index=0")
        assert status == 200, score
    folder = Path(v["trials"][0]["run"])
    assert first["feed"] == 1 and first["feed_name"] == "uav2/belly"
    assert first["frame"] == sent[0]["frame"]
    # a frame the page drew on that feed before the click
    assert [1, first["frame"]] in [d[:2] for d in drawn if d[2] <= sent[0]["click_time_ms"]]
    # the pixel, from the canvas's box as the browser lays it out (0 at the
    # frame's edge)
    assert first["x_px"] == pytest.approx((cx - box["x"]) * W / box["width"], abs=1e-6)
    assert first["y_px"] == pytest.approx((cy - box["y"]) * H / box["height"], abs=1e-6)
    assert 0 < first["x_px"] < W and 0 < first["y_px"] < H
    assert first["drawn_time_ms"] <= first["click_time_ms"]
    # what was on the canvas at the click is the run's frame of that number
    (w, _) = witness
    assert w["feed"] == 1
    shown = np.asarray(w["pixels"], float).reshape(H, W, 4)[:, :, :3]
    grey = shown @ np.array([0.299, 0.587, 0.114])
    frames = _video_frames(folder / "cameras" / "uav2_belly.mp4")
    k = first["frame"]
    near = {j: float(np.abs(frames[j] - grey).mean()) for j in (k - 1, k, k + 1)
            if 0 <= j < len(frames)}
    assert min(near, key=near.__getitem__) == k, near
    # the scores, against the ground truth of the run without the console
    assert second["feed_name"] == "uav1/belly" and second["frame"] == last
    assert (second["x_px"], second["y_px"]) == pytest.approx(
        (truck[last]["center_x_px"] + 0.5, truck[last]["center_y_px"] + 0.5), abs=1e-6)
    outcomes = [(r["feed"], r["frame"], r["outcome"], r["error_px"]) for r in score["reports"]]
    truck2 = _truck(tmp_path / "alone" / "cameras" / "uav2_belly.gt.csv")
    # (the ground truth's pixel centres are at whole numbers: half a pixel off the edge)
    want = [("uav2/belly", first["frame"], *_expected(truck2, first["frame"],
                                                     first["x_px"] - 0.5, first["y_px"] - 0.5)),
            ("uav1/belly", second["frame"], *_expected(truck, second["frame"],
                                                      second["x_px"] - 0.5,
                                                      second["y_px"] - 0.5))]
    assert [o[:3] for o in outcomes] == [o[:3] for o in want]
    assert want[1][2] == "hit" and outcomes[1][3] == pytest.approx(want[1][3], abs=1e-3)
    # the report's time: its frame's time plus the page's time from drawing it to the click
    assert score["reports"][1]["time_s"] == pytest.approx(
        truck[second["frame"]]["time_s"]
        + (second["click_time_ms"] - second["drawn_time_ms"]) / 1000, abs=1e-6)
    # the page's timing: every frame drawn has its glass-to-glass latency, under a
    # second here (no downlink; the test's downlink one adds its delay)
    assert timing["frames_drawn"] == timing["latency_samples"] >= 6, timing
    assert timing["frames_received"] >= timing["frames_drawn"]
    assert 0 <= timing["latency_ms_p50"] <= timing["latency_ms_p95"] < 1000, timing
    # every frame drawn carried its number in its pixels, as the page read them back
    assert timing["counter_mismatches"] == 0
    assert all(d[3] == d[1] for d in drawn), [d for d in drawn if d[3] != d[1]][:5]
    assert json.loads((folder / "page_timing.json").read_text()) == timing
    # the console never changes the simulation
    _same_states(folder, tmp_path / "alone")
    for f in ("uav1_belly.gt.csv", "uav2_belly.gt.csv"):
        assert (folder / "cameras" / f).read_bytes() == \
            (tmp_path / "alone" / "cameras" / f).read_bytes(), f


@pytest.mark.integration  # a live run of a second and a half
def test_a_downlinked_feed_is_its_delivered_frames_handed_on_after_the_latency(
        tmp_path: Path) -> None:
    """With a ``datalink:`` (5 of the camera's 10 frames a second, 300 ms
    late) the page gets the frames the ground truth says were delivered,
    each handed on 300 ms after the run made it."""
    from cosim.trials.live import LiveRun

    (c,) = load_study(downlink_study(tmp_path, 1.5, 300)).live
    published: dict[int, float] = {}
    arrived: dict[int, float] = {}

    class Timed(Hub):
        def publish(self, kind: str, payload: dict[str, Any], delay_s: float = 0.0) -> None:
            if kind == "frame" and payload["feed"] == 0:
                published[payload["frame"]] = time.monotonic()
            super().publish(kind, payload, delay_s)

    async def watch() -> None:
        hub = Timed(asyncio.get_running_loop())
        w = hub.watch(max_pending=1000)
        run = LiveRun(c, tmp_path / "run", hub, backend="inline")
        run.start()
        while True:
            kind, msg = await w.get()
            if kind == "end":
                break
            if kind == "frame" and json.loads(msg)["feed"] == 0:
                arrived[json.loads(msg)["frame"]] = time.monotonic()
        assert run.wait(10) and run.error is None, run.error

    asyncio.run(watch())
    with open(tmp_path / "run" / "cameras" / "uav1_belly.gt.csv", newline="") as f:
        delivered = sorted({int(r["frame"]) for r in csv.DictReader(f)
                            if r["delivered_time_s"]})
    assert delivered == list(range(0, 15, 2))
    assert sorted(arrived) == sorted(published) == delivered
    late = [arrived[k] - published[k] for k in delivered]
    assert min(late) >= 0.3 - 0.005, late


def test_the_experimenter_starts_and_stops_a_live_trial_from_the_page(
        tmp_path: Path, chromium: str) -> None:
    """The experimenter's page links a live session's participant page to
    /live and has its trial's button: Start runs it, Stop ends its run
    early (the run's summary says so), then no trial is left to start."""
    with live_server(live_study(tmp_path)) as server:
        s = _session(server, "p2")
        with browser_page(chromium) as page:
            page.goto(f"{server.url}/")
            button = page.locator("button.live-control")
            page.wait_for_function("document.querySelector('button.live-control')"
                                   "?.textContent === 'Start trial 1 of 1'")
            assert page.locator("#sessions a").get_attribute("href") == \
                f"/live?session={s['id']}"
            assert "protocol live, 1 conditions" in page.locator("#study").inner_text()
            button.click()
            page.wait_for_function("document.querySelector('button.live-control')"
                                   "?.textContent === 'Stop trial 1'")
            page.locator("button.live-control").click()
            page.wait_for_function("document.querySelector('button.live-control')"
                                   "?.textContent === 'All trials run'")
            assert page.locator("button.live-control").is_disabled()
            # every trial has run: the session is finished, its progress in runs
            page.wait_for_function("document.querySelector('#sessions td:nth-child(4)')"
                                   "?.textContent === 'finished'")
            assert page.locator("#sessions td:nth-child(3)").inner_text() == "1 / 1 run"
        v = _wait_over(server, s["id"])
    summary = json.loads((Path(v["trials"][0]["run"]) / "summary.json").read_text())
    assert summary["stop_reason"] == "stopped by the experimenter"
    assert summary["ticks"] < DURATION_S * 120, summary["ticks"]


@pytest.mark.integration  # a live run started, then stopped
def test_the_live_runs_stop_when_the_server_shuts_down(tmp_path: Path) -> None:
    """The app's lifespan ends with every live run stopped and waited for."""
    from test_server import asgi

    from cosim.trials.server import make_app
    from cosim.trials.store import Store

    with Store(tmp_path / "db.sqlite") as store:
        app = make_app(live_study(tmp_path), store)
        status, s = asgi(app, "POST", "/api/sessions", {"participant": "p3", **PROFILE})
        assert status == 201, s
        status, out = asgi(app, "POST", f"/api/sessions/{s['id']}/live/start",
                           {"trial_index": 0})
        assert status == 201 and out["running"], out
        events = [{"type": "lifespan.startup"}, {"type": "lifespan.shutdown"}]
        sent: list[dict[str, Any]] = []

        async def receive() -> dict[str, Any]:
            return events.pop(0)

        async def send(message: MutableMapping[str, Any]) -> None:
            sent.append(dict(message))

        asyncio.run(app({"type": "lifespan", "asgi": {"version": "3.0"}, "state": {}},
                        receive, send))
        assert [m["type"] for m in sent] == ["lifespan.startup.complete",
                                             "lifespan.shutdown.complete"]
        _, run = app.state.trials.live.runs[s["id"]]
        assert not run.running
    summary = json.loads((Path(out["out_dir"]) / "summary.json").read_text())
    assert summary["stop_reason"] == "server shut down"


def test_the_page_measures_a_downlinks_delay_in_its_glass_to_glass_latency(
        tmp_path: Path, chromium: str) -> None:
    """With a downlink 500 ms late, the page's glass-to-glass latency (from
    the run making a frame, on the server's clock, to the page drawing it)
    is at least 500 ms and the page draws the delivered frames."""
    with live_server(downlink_study(tmp_path, 2.0, 500)) as server:
        s = _session(server, "p4")
        with browser_page(chromium) as page:
            page.goto(f"{server.url}/live?session={s['id']}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            _start(server, s["id"])
            page.wait_for_function("document.body.dataset.phase === 'ended'",
                                   timeout=60_000)
            drawn = page.evaluate("window.live.drawn")
        timing = _wait_over(server, s["id"])["live"]["page_timing"]
    assert {d[1] % 2 for d in drawn} == {0}  # the delivered frames only
    assert timing["frames_drawn"] >= 10, timing  # 2 feeds x 10 delivered, some skipped
    assert 500 <= timing["latency_ms_p50"] < 1500, timing


def test_a_reloaded_page_follows_the_running_trial_again(tmp_path: Path, chromium: str) -> None:
    """Reloaded mid-trial, the page finds the running trial again and draws
    its next frames; the stream of the page before is let go (one watcher)."""
    with live_server(live_study(tmp_path)) as server:
        sid = _session(server, "p5")["id"]
        with browser_page(chromium) as page:
            page.goto(f"{server.url}/live?session={sid}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            _start(server, sid)
            page.wait_for_function("window.live.drawn.length >= 4")
            before = page.evaluate("Math.max(...window.live.drawn.map((d) => d[1]))")
            page.reload()
            page.wait_for_function("document.body.dataset.phase === 'live' && "
                                   "window.live.drawn.length >= 2")
            after = page.evaluate("Math.min(...window.live.drawn.map((d) => d[1]))")
            status, v = server.request("GET", f"/api/sessions/{sid}/live")
            assert status == 200 and v["live"]["running"], v
            assert v["live"]["watchers"] == 1, v["live"]
            page.wait_for_function("document.body.dataset.phase === 'ended'", timeout=60_000)
        _wait_over(server, sid)
    assert after >= before, (before, after)


@pytest.mark.integration  # a live run of a second
def test_the_map_gets_the_feeds_footprints_and_the_targets_its_condition_asks_for(
        tmp_path: Path) -> None:
    """A condition with ``map: {targets: true}``: the page is told the
    targets; every states message has each feed's footprint, a nadir
    camera's about the aircraft (within its attitude's tilt) with sides
    2 h tan(fov / 2)."""
    from cosim.trials.live import LiveRun

    study = STUDY.replace("conditions: {feeds: 2}}", "conditions: {feeds: 2},\n"
                          "     map: {targets: true, tracks: false}}")
    (c,) = load_study(live_study(tmp_path, study)).live
    assert c.map_layers == ("footprints", "targets")
    got: list[tuple[str, dict[str, Any]]] = []

    async def watch() -> None:
        hub = Hub(asyncio.get_running_loop())
        run = LiveRun(dataclasses.replace(c, duration_s=1.0), tmp_path / "run", hub,
                      backend="inline")
        w = hub.watch(max_pending=10_000)  # as a page does: once the run is made
        run.start()
        while True:
            kind, msg = await w.get()
            if kind == "end":
                break
            if kind in ("hello", "states"):
                got.append((kind, json.loads(msg)))
        assert run.wait(10) and run.error is None, run.error

    asyncio.run(watch())
    hello = got[0][1]
    assert hello["map"] == ["footprints", "targets"]
    assert hello["targets"] == [{"id": "truck1", "north_m": 0.0, "east_m": 0.0}]
    states = [m for k, m in got if k == "states"]
    assert len(states) >= 4
    half_v = math.tan(math.radians(20))
    half_h = half_v * W / H  # square pixels: the horizontal field from the vertical
    for m in states:
        assert [f["feed"] for f in m["footprints"]] == [0, 1]
        for f, v in zip(m["footprints"], m["vehicles"]):
            ne = np.asarray(f["corners_ne_m"])
            h = v["alt_agl_m"]
            sides = sorted(float(np.hypot(*(ne[i] - ne[(i + 1) % 4]))) for i in range(4))
            assert sides == pytest.approx([2 * h * half_v] * 2 + [2 * h * half_h] * 2,
                                          rel=0.05), (sides, h)
            tilt_m = h * math.tan(math.radians(6))
            assert math.hypot(*(ne.mean(axis=0) - [v["north_m"], v["east_m"]])) < tilt_m


@pytest.mark.integration  # a live run of a second
def test_a_gimbal_camera_s_footprint_follows_its_look_at(tmp_path: Path) -> None:
    """A gimbal camera told to look at a point 150 m east of the aircraft's
    track: its footprint on the map is where the cameras point it, not the
    mount's. The image centre is where the footprint's diagonals cross
    (a perspective view maps the image's diagonals to the ground's), and it
    is the point looked at."""
    from cosim.trials.live import LiveRun

    (tmp_path / "pair.yaml").write_text(SCENARIO.format(
        duration_s=1.0, w=W, h=H, rate_hz=RATE_HZ).replace(
        "mount: nadir", "mount: gimbal").replace(
        "cameras:", "schedule:\n  - {at_s: 0, vehicles: [uav1], command: {gimbal: "
        "{look_at: {north_m: -60, east_m: 150}}}}\ncameras:"))
    (tmp_path / "study.yaml").write_text(STUDY)
    (c,) = load_study(tmp_path / "study.yaml").live
    got: list[dict[str, Any]] = []

    async def watch() -> None:
        hub = Hub(asyncio.get_running_loop())
        run = LiveRun(c, tmp_path / "run", hub, backend="inline")
        w = hub.watch(max_pending=10_000)
        run.start()
        while True:
            kind, msg = await w.get()
            if kind == "end":
                break
            if kind == "states":
                got.append(json.loads(msg))
        assert run.wait(10) and run.error is None, run.error

    asyncio.run(watch())
    assert len(got) >= 3
    for m in got:
        looking, nadir = (np.asarray(f["corners_ne_m"]) for f in m["footprints"])
        (p0, p1, p2, p3) = looking
        # the diagonals p0-p2 and p1-p3 cross at p0 + s (p2 - p0)
        s = np.linalg.solve(np.column_stack([p2 - p0, p1 - p3]), p1 - p0)[0]
        centre = p0 + s * (p2 - p0)
        assert np.hypot(*(centre - [-60.0, 150.0])) < 1.0, (m["time_s"], centre)
        uav2 = m["vehicles"][1]  # its camera still looks straight down
        assert np.hypot(*(nadir.mean(axis=0) - [uav2["north_m"], uav2["east_m"]])) < 15.0


def test_the_page_follows_each_trial_the_experimenter_starts(tmp_path: Path,
                                                             chromium: str) -> None:
    """A session of two trials: after the first the page says so and waits;
    the second, started later, is followed with its own feeds; after it the
    page says the session is over."""
    study = ("name: two\nprotocol: live\norder: shuffle\nscenarios:\n"
             "  - {id: one, scenario: pair.yaml, feeds: [uav2/belly], duration_s: 1}\n"
             "  - {id: two, scenario: pair.yaml, feeds: 2, duration_s: 1}\n")
    with live_server(live_study(tmp_path, study)) as server:
        s = _session(server, "p6")
        feeds = {t["index"]: len(t["feeds"]) for t in s["trials"]}
        with browser_page(chromium) as page:
            page.goto(f"{server.url}/live?session={s['id']}")
            page.wait_for_function("document.body.dataset.phase === 'waiting'")
            for ti in (0, 1):
                status, out = server.request("POST", f"/api/sessions/{s['id']}/live/start",
                                             {"trial_index": ti})
                assert status == 201, out
                page.wait_for_function("document.body.dataset.phase === 'live'")
                assert page.locator("canvas[data-feed]").count() == feeds[ti]
                page.wait_for_function("document.body.dataset.phase === 'ended'",
                                       timeout=60_000)
                _wait_over(server, s["id"])
                text = "Please wait for the next one" if ti == 0 else "and the session with it"
                page.wait_for_function(f"document.getElementById('message').innerText"
                                       f".includes({text!r})")
                assert page.evaluate("window.live.drawn.every((d) => d[0] < "
                                     f"{feeds[ti]})")


def test_serve_says_how_many_live_conditions_the_study_has(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    import uvicorn

    from cosim.trials.server import serve

    monkeypatch.setattr(uvicorn, "run", lambda *a, **k: None)  # not served: only its start
    with caplog.at_level(logging.INFO, logger="cosim.trials.server"):
        serve(live_study(tmp_path), port=8123)
    assert re.search(r"study live_test: 1 live conditions; responses in .*study\.sqlite",
                     caplog.text), caplog.text
