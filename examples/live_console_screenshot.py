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
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import urllib.request
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


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("study")
    ap.add_argument("--condition", required=True, help="the live condition's id")
    ap.add_argument("--at-s", type=float, default=10.0, help="seconds into the trial")
    ap.add_argument("--out", required=True)
    ap.add_argument("--until-end", action="store_true",
                    help="then wait for the trial's end and print its timing")
    a = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(a.study).resolve().parent
        shutil.copytree(src, Path(tmp) / "study", ignore=shutil.ignore_patterns(
            "*.sqlite*", "*-live"))
        study = load_study(Path(tmp) / "study" / Path(a.study).name)
        store = Store(Path(tmp) / "demo.sqlite")
        try:
            with served_in_thread(make_app(study, store), lifespan="auto",
                                  stop_timeout_s=30) as url:
                s = _post(f"{url}/api/sessions", {"participant": "demo", **PROFILE})
                trial = next(t["index"] for t in s["trials"] if t["condition"] == a.condition)
                with sync_playwright() as pw:
                    browser = pw.chromium.launch(executable_path=CHROMIUM)
                    page = browser.new_page(viewport={"width": WIDTH_PX, "height": HEIGHT_PX})
                    page.goto(f"{url}/live?session={s['id']}")
                    page.wait_for_function("document.body.dataset.phase === 'waiting'")
                    _post(f"{url}/api/sessions/{s['id']}/live/start", {"trial_index": trial})
                    page.wait_for_function("document.body.dataset.phase === 'live'",
                                           timeout=60_000)
                    page.wait_for_function(f"Number((document.getElementById('clock')"
                                           f".textContent.match(/[0-9.]+/) || [0])[0]) >= "
                                           f"{a.at_s}", timeout=120_000)
                    page.screenshot(path=a.out)
                    if a.until_end:
                        page.wait_for_function("document.body.dataset.phase === 'ended'",
                                               timeout=3_600_000)
                    browser.close()
                if a.until_end:
                    with urllib.request.urlopen(f"{url}/api/sessions/{s['id']}/live") as r:
                        print(json.dumps(json.loads(r.read())["live"], indent=1))
                else:
                    _post(f"{url}/api/sessions/{s['id']}/live/stop", {})
        finally:
            store.close()
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
