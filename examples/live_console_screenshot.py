"""The README's picture of the live console: serve a live study (a copy, in a
temporary folder, so its runs and database stay out of the repository),
open a session's live page in headless Chromium (Debian's
/usr/bin/chromium), start the trial of the condition asked for and take a
screenshot some seconds into it; with ``--until-end``, also wait for the
trial's end and print the run's status with the page's timing (frames sent,
dropped, drawn, glass-to-glass latency).

    python examples/live_console_screenshot.py studies/live_feeds.yaml \
        --condition four_feeds --at-s 11 --out console.png

(docs/images/trials_live_console.jpg is that picture as JPEG, quality 85.)
With ``--task VEHICLE:ACTION:NORTH_M:EAST_M`` (repeatable) the page's
participant tasks aircraft from the map first, as a person does (click the
aircraft, click the ground, choose the action in the menu), a second apart
from 2 s into the trial; with ``--menu VEHICLE:NORTH_M:EAST_M`` the picture
is taken with that aircraft selected and the menu open at that point:

    python examples/live_console_screenshot.py studies/live_feeds.yaml \
        --condition four_feeds --at-s 12 --task uav1:go:400:-500 \
        --task uav4:orbit:500:400 --menu uav3:300:150 --out tasking.png

(docs/images/trials_live_tasking.jpg is that picture as JPEG, quality 85.)
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import tempfile
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.trials.server import make_app, served_in_thread
from cosim.trials.store import Store
from cosim.trials.study import load_study

CHROMIUM = "/usr/bin/chromium"
WIDTH_PX, HEIGHT_PX = 1280, 600
PROFILE = {"screen_width_px": WIDTH_PX, "screen_height_px": HEIGHT_PX, "screen_width_mm": 531.0,
           "screen_height_mm": 249.0, "viewing_distance_mm": 600.0}


def _post(url: str, body: dict[str, Any]) -> Any:
    req = urllib.request.Request(url, json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=60) as r:
        return json.loads(r.read())


#: the client pixel of a point (north, east m) on the map, from the page's map
#: transform; then a pointerdown there (selecting an aircraft) or a click
_MAP_PX = """([n, e]) => {
  const m = document.getElementById("map"), r = m.getBoundingClientRect();
  const v = window.live.view;
  return [r.left + (v.w / 2 + (e - v.ce) * v.s) * r.width / v.w,
          r.top + (v.h / 2 - (n - v.cn) * v.s) * r.height / v.h];
}"""
_SELECT = "(id) => {\n  const at = " + _MAP_PX + """;
  const u = window.live.vehicles.find((x) => x.id === id);
  const [x, y] = at([u.north_m, u.east_m]);
  document.getElementById("map").dispatchEvent(
    new PointerEvent("pointerdown", {clientX: x, clientY: y, bubbles: true}));
}"""


def _clock_at(page: Any, at_s: float) -> None:
    page.wait_for_function(f"Number((document.getElementById('clock')"
                           f".textContent.match(/[0-9.]+/) || [0])[0]) >= {at_s}",
                           timeout=120_000)


def _menu(page: Any, vehicle: str, north_m: float, east_m: float) -> None:
    """Select ``vehicle`` on the map and click the ground at the point: the menu opens."""
    page.evaluate(_SELECT, vehicle)
    x, y = page.evaluate(_MAP_PX, [north_m, east_m])
    page.mouse.click(x, y)
    page.wait_for_selector("#taskmenu button")


@dataclass
class LiveTrial:
    """A live trial being followed: the study (a copy), the app's address,
    the session and the participant's page."""

    study: Any
    url: str
    session: dict[str, Any]
    page: Any

    def status(self) -> dict[str, Any]:
        """The session's live run as the experimenter's page sees it."""
        with urllib.request.urlopen(f"{self.url}/api/sessions/{self.session['id']}/live") as r:
            return dict(json.loads(r.read())["live"])

    def stop(self) -> None:
        _post(f"{self.url}/api/sessions/{self.session['id']}/live/stop", {})


@contextlib.contextmanager
def live_trial(study_file: str, condition: str) -> Iterator[LiveTrial]:
    """Serve a copy of the study (in a temporary folder, its databases and run
    folders left behind), open a session's live page in headless Chromium and
    start the trial of ``condition``; the page, browser, server and store are
    closed after."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(study_file).resolve().parent
        shutil.copytree(src, Path(tmp) / "study", ignore=shutil.ignore_patterns(
            "*.sqlite*", "*-live"))
        study = load_study(Path(tmp) / "study" / Path(study_file).name)
        store = Store(Path(tmp) / "demo.sqlite")
        try:
            with served_in_thread(make_app(study, store), lifespan="auto",
                                  stop_timeout_s=30) as url:
                s = _post(f"{url}/api/sessions", {"participant": "demo", **PROFILE})
                trial = next(t["index"] for t in s["trials"] if t["condition"] == condition)
                with sync_playwright() as pw:
                    browser = pw.chromium.launch(executable_path=CHROMIUM)
                    try:
                        page = browser.new_page(viewport={"width": WIDTH_PX,
                                                          "height": HEIGHT_PX})
                        page.goto(f"{url}/live?session={s['id']}")
                        page.wait_for_function("document.body.dataset.phase === 'waiting'")
                        _post(f"{url}/api/sessions/{s['id']}/live/start",
                              {"trial_index": trial})
                        yield LiveTrial(study, url, s, page)
                    finally:
                        browser.close()
        finally:
            store.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("study")
    ap.add_argument("--condition", required=True, help="the live condition's id")
    ap.add_argument("--at-s", type=float, default=10.0, help="seconds into the trial")
    ap.add_argument("--out", required=True)
    ap.add_argument("--until-end", action="store_true",
                    help="then wait for the trial's end and print its timing")
    ap.add_argument("--task", action="append", default=[],
                    metavar="VEHICLE:ACTION:NORTH_M:EAST_M",
                    help="task an aircraft from the map first (go, orbit or look)")
    ap.add_argument("--menu", metavar="VEHICLE:NORTH_M:EAST_M",
                    help="take the picture with the map's menu open here")
    a = ap.parse_args()
    with live_trial(a.study, a.condition) as lt:
        page = lt.page
        page.wait_for_function("document.body.dataset.phase === 'live'", timeout=60_000)
        for k, task in enumerate(a.task):
            vehicle, action, north_m, east_m = task.split(":")
            _clock_at(page, 2.0 + k)
            _menu(page, vehicle, float(north_m), float(east_m))
            page.click(f"#taskmenu button[data-action='{action}']")
        _clock_at(page, a.at_s)
        if a.menu:
            vehicle, north_m, east_m = a.menu.split(":")
            _menu(page, vehicle, float(north_m), float(east_m))
        page.screenshot(path=a.out)
        if a.until_end:
            page.wait_for_function("document.body.dataset.phase === 'ended'",
                                   timeout=3_600_000)
            print(json.dumps(lt.status(), indent=1))
        else:
            lt.stop()
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
