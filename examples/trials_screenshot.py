"""The README's pictures of the participant page: serve a study, open a
session in headless Chromium (Debian's /usr/bin/chromium), take a
screenshot of the instructions with the target's picture (``--instructions-out``),
start the first clip and take one when its target is in view (from the
clip's ground truth).

    python examples/trials_screenshot.py STUDY.yaml --out participant.jpg \
        --instructions-out instructions.png

A fresh database beside the output is used (the study's own is left alone).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import urllib.request
from pathlib import Path

from cosim.trials.server import make_app, served_in_thread
from cosim.trials.store import Store
from cosim.trials.study import load_study

CHROMIUM = "/usr/bin/chromium"
PROFILE = {"screen_width_px": 1280, "screen_height_px": 720, "screen_width_mm": 531.0,
           "screen_height_mm": 299.0, "viewing_distance_mm": 600.0}


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def _inside(clip: object, k: int) -> bool:
    box = clip.frames[k].bbox_px  # type: ignore[attr-defined]
    w, h = clip.width_px, clip.height_px  # type: ignore[attr-defined]
    return box is not None and box[0] > 0.3 * w and box[2] < 0.7 * w and \
        box[1] > 0.2 * h and box[3] < 0.8 * h


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study")
    ap.add_argument("--out", required=True)
    ap.add_argument("--instructions-out", help="also the instructions page, here")
    a = ap.parse_args()
    from playwright.sync_api import sync_playwright

    study = load_study(a.study)
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(Path(tmp) / "demo.sqlite")
        try:
            with served_in_thread(make_app(a.study, store)) as url:
                s = _post(f"{url}/api/sessions", {"participant": "demo", **PROFILE})
                _post(f"{url}/api/sessions/{s['id']}/state", {"state": "running"})
                with sync_playwright() as pw:
                    browser = pw.chromium.launch(executable_path=CHROMIUM,
                                                 args=["--autoplay-policy=no-user-gesture-required"])
                    page = browser.new_page(viewport={"width": PROFILE["screen_width_px"],
                                                      "height": PROFILE["screen_height_px"]})
                    page.goto(f"{url}/participant?session={s['id']}")
                    page.wait_for_function("document.body.dataset.phase === 'begin'")
                    if a.instructions_out:
                        page.wait_for_function("[...document.querySelectorAll('img.target')]"
                                               ".every((i) => i.complete && i.naturalWidth > 0)")
                        page.screenshot(path=a.instructions_out)
                    page.keyboard.press("Space")
                    page.wait_for_function("['practice', 'fixation']"
                                           ".includes(document.body.dataset.phase)")
                    if page.evaluate("document.body.dataset.phase") == "practice":
                        page.keyboard.press("Space")  # (the practice clips' screen)
                    page.wait_for_function("document.body.dataset.phase === 'playing'")
                    clip = study.all_clips[s["trials"][0]["clip"]]
                    deadline = time.monotonic() + 60
                    while time.monotonic() < deadline:  # the target fully in the picture
                        k = int(page.evaluate("Number(document.body.dataset.frame || -1)"))
                        if 0 <= k < len(clip.frames) and clip.frames[k].in_view and \
                                _inside(clip, k):
                            page.screenshot(path=a.out)
                            break
                        page.wait_for_timeout(20)
                    else:
                        raise SystemExit("the first clip's target never came into view")
                    browser.close()
        finally:
            store.close()
    print(a.out)


if __name__ == "__main__":
    main()
