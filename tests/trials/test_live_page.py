"""The live page's drawing of frames that arrive together, alone: static/live.js
in headless Debian Chromium (/usr/bin/chromium through Playwright) with the
server's answers made up by the test (Playwright's routing: no server, no
socket), so that when each frame arrives is the test's to choose."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from cosim.trials.live import with_counter

pytestmark = pytest.mark.integration  # a browser

CHROMIUM = "/usr/bin/chromium"
STATIC = Path(__file__).resolve().parents[2] / "cosim" / "trials" / "static"
ORIGIN = "http://cosim.test"
W, H = 160, 120


def _frame(feed: int, n: int) -> dict[str, Any]:
    rng = np.random.default_rng(n)
    bgr = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    ok, jpg = cv2.imencode(".jpg", with_counter(bgr, n), [cv2.IMWRITE_JPEG_QUALITY, 80])
    assert ok
    return {"feed": feed, "frame": n, "time_s": n / 10, "made_ms": 0.0,
            "jpeg": base64.b64encode(jpg.tobytes()).decode()}


def _events(frames: list[dict[str, Any]]) -> str:
    hello = {"condition": "c", "duration_s": 1.0, "map": [], "targets": [], "vehicles": [],
             "feeds": [{"feed": k, "name": f"uav{k + 1}/belly", "width_px": W, "height_px": H,
                        "rate_hz": 10.0} for k in range(2)]}
    out = [f"event: hello\ndata: {json.dumps(hello)}\n\n"]
    out += [f"event: frame\ndata: {json.dumps(f)}\n\n" for f in frames]
    return "".join(out) + "event: end\ndata: {}\n\n"


#: the display's refreshes held back until the test runs them
HOLD_REFRESHES = """
window.__refreshes = [];
window.requestAnimationFrame = (cb) => { window.__refreshes.push(cb); return 0; };
"""
REFRESH = "() => { const cbs = window.__refreshes.splice(0); " \
          "cbs.forEach((cb) => cb(performance.now())); return cbs.length; }"


def _drawn(frames: list[dict[str, Any]]) -> list[list[int]]:
    """The page's (feed, frame, counter read) drawn, in order, when the
    stream brings ``frames`` at once and every one has been decoded before
    the display's next refresh (refreshes are held until then)."""
    from playwright.sync_api import Route, sync_playwright

    def answer(route: Route) -> None:
        path = route.request.url[len(ORIGIN):].split("?")[0]
        if path == "/live":
            route.fulfill(body=(STATIC / "live.html").read_text(), content_type="text/html")
        elif path.startswith("/static/"):
            name = path[len("/static/"):]
            kind = "text/css" if name.endswith(".css") else "text/javascript"
            route.fulfill(body=(STATIC / name).read_text(), content_type=kind)
        elif path == "/api/sessions/s1/live":
            route.fulfill(json={"live": {"running": True, "trial_index": 0},
                                "trials": [{"ran": True}]})
        elif path == "/api/sessions/s1/live/stream":
            route.fulfill(body=_events(frames), content_type="text/event-stream")
        elif path == "/api/sessions/s1/live/clock":
            route.fulfill(json={"server_ms": 0.0})
        else:  # timing, the instruments' questions: nothing to say
            route.fulfill(status=404, json={"error": "none"})

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM)
        try:
            page = browser.new_page()
            page.add_init_script(HOLD_REFRESHES)
            page.route(f"{ORIGIN}/**", answer)
            page.goto(f"{ORIGIN}/live?session=s1")
            page.wait_for_function("document.body.dataset.phase === 'ended'", timeout=20_000,
                                   polling=100)  # not by refreshes: they are held
            page.wait_for_timeout(1000)  # every decode done
            for _ in range(20):  # a refresh at a time, until none is asked for
                if not page.evaluate(REFRESH):
                    break
            drawn: list[list[int]] = page.evaluate(
                "window.live.drawn.map((d) => [d[0], d[1], d[3]])")
        finally:
            browser.close()
    return drawn


def test_frames_that_arrive_together_are_each_drawn_in_order() -> None:
    """Three frames of a feed and two of another arrive before a refresh, one
    of them out of order: each is drawn, one a refresh, in frame order, with
    its own counter (the page drew only the newest of each feed: 2 and 7)."""
    frames = [_frame(0, 0), _frame(1, 5), _frame(0, 2), _frame(0, 1), _frame(1, 7)]
    drawn = _drawn(frames)
    assert [(k, n) for k, n, _ in drawn if k == 0] == [(0, 0), (0, 1), (0, 2)]
    assert [(k, n) for k, n, _ in drawn if k == 1] == [(1, 5), (1, 7)]
    assert all(counter == n for _, n, counter in drawn)


def test_a_feed_keeps_at_most_three_frames_waiting() -> None:
    """Eight frames of a feed before a refresh: the newest three are drawn,
    one a refresh; the five older are skipped."""
    assert [n for _, n, _ in _drawn([_frame(0, n) for n in range(8)])] == [5, 6, 7]
