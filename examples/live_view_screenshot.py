"""The README's picture of the live view: record a run's 3-D view, serve it
with Rerun's web viewer on loopback, and screenshot it in headless Chromium.

    pip install -e .[view] playwright     # playwright drives the browser only:
    apt-get install chromium              # no browser build is downloaded
    python examples/live_view_screenshot.py [--scenario S] [--out docs/images/live_view.png]

Rerun's native viewer needs a display; its web viewer renders in the
browser (with Chromium's software rasteriser here), from the same recording
`cosim run --record-view` writes.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

REPO = Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=str(REPO / "scenarios" / "hetero" /
                                             "quad_guides_car.yaml"))
    p.add_argument("--out", default=str(REPO / "docs" / "images" / "live_view.png"))
    p.add_argument("--chromium", default="/usr/bin/chromium")
    p.add_argument("--wait-s", type=float, default=25.0, help="time the viewer gets to load")
    a = p.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as d:
        rrd = Path(d) / "view.rrd"
        subprocess.run([sys.executable, "-m", "cosim", "-q", "run", a.scenario, "--out",
                        str(Path(d) / "run"), "--record-view", str(rrd), "--no-progress"],
                       check=True)
        web, grpc = _free_port(), _free_port()
        env = dict(os.environ, RERUN_ANALYTICS="0")
        rerun = Path(sys.executable).parent / "rerun"
        server = subprocess.Popen([str(rerun), "--web-viewer", "--bind", "127.0.0.1",
                                   "--web-viewer-port", str(web), "--port", str(grpc),
                                   str(rrd)], env=env, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
        try:
            time.sleep(3.0)
            url = (f"http://127.0.0.1:{web}/?url="
                   + quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe=""))
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=a.chromium, headless=True,
                    args=["--no-sandbox", "--use-angle=swiftshader",
                          "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"])
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(url)
                time.sleep(a.wait_s)
                page.screenshot(path=a.out)
                browser.close()
        finally:
            server.terminate()
            server.wait(10)
    print(a.out)


if __name__ == "__main__":
    main()
