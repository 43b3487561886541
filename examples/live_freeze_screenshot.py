"""The README's picture of a SAGAT freeze on the live console: serve a live
study with ``sagat:`` probes (a copy, in a temporary folder, as
live_console_screenshot.py does), open a session's live page in headless
Chromium (Debian's /usr/bin/chromium), start the trial of the condition
asked for, wait for the run to freeze at the probe, answer the questions
before the one asked for (a click at the blank map's centre, a count of 1,
the first aircraft) and take a screenshot with that one on the page; then
the trial is stopped. With ``--until-end`` the page instead waits
``--hold-s`` seconds with the question shown, answers the rest of that
probe and every later one, follows the trial to its end and prints the
run's status with the page's timing and the run's pacing: what a freeze
does (or not) to the timing checks.

    python examples/live_freeze_screenshot.py studies/live_instruments.yaml \
        --condition four_feeds --probe 0 --question east --out freeze.png

(docs/images/trials_live_sagat.png is that picture.)

    python examples/live_freeze_screenshot.py studies/live_instruments.yaml \
        --condition four_feeds --hold-s 45 --until-end --out freeze.png
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from live_console_screenshot import live_trial


def _answer(page: Any, qid: str) -> None:
    """Answer the question on the page as a participant might."""
    form = f"[data-question='{qid}']"
    if page.locator(f"{form} input").count():
        page.fill(f"{form} input", "1")
        page.click(f"{form} button.next")
    elif page.locator(f"{form} button.choice").count():
        page.locator(f"{form} button.choice").first.click()
    else:  # a point on the blank map
        box = page.locator("#instrument canvas.blank").bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("study")
    ap.add_argument("--condition", required=True, help="the live condition's id")
    ap.add_argument("--probe", type=int, default=0, help="the probe's number (0: the first)")
    ap.add_argument("--question", help="the question's id shown (default: the first)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--hold-s", type=float, default=0.0,
                    help="seconds the question stays on the page before it is answered")
    ap.add_argument("--until-end", action="store_true",
                    help="answer every probe, follow the trial to its end, print its timing")
    a = ap.parse_args()
    with live_trial(a.study, a.condition) as lt:
        page = lt.page
        ids = [q.id for q in lt.study.sagat[a.probe].questions]
        shown = a.question or ids[0]
        page.wait_for_function(f"document.body.dataset.freeze === '{a.probe}'",
                               timeout=600_000)
        for qid in ids[:ids.index(shown)]:
            page.wait_for_selector(f"[data-question='{qid}']")
            _answer(page, qid)
        page.wait_for_selector(f"[data-question='{shown}']")
        page.screenshot(path=a.out)
        if a.until_end:
            time.sleep(a.hold_s)
            for qid in ids[ids.index(shown):]:
                page.wait_for_selector(f"[data-question='{qid}']")
                _answer(page, qid)
            for probe in lt.study.sagat[a.probe + 1:]:
                page.wait_for_function(f"document.body.dataset.freeze === "
                                       f"'{probe.index}'", timeout=600_000)
                for q in probe.questions:
                    page.wait_for_selector(f"[data-question='{q.id}']")
                    _answer(page, q.id)
            page.wait_for_function("document.body.dataset.phase === 'ended'",
                                   timeout=3_600_000)
            live = lt.status()
            summary = json.loads((Path(live["out_dir"]) / "summary.json").read_text())
            print(json.dumps({"live": live, **{k: summary.get(k) for k in (
                "sagat_freezes", "paused_s", "wall_time_s", "real_time_factor",
                "realtime")}}, indent=1))
        else:
            lt.stop()
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
