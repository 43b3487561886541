"""The live console's timing, driven headless: a live study (default
studies/live_search.yaml: 16 uav700s flying a search, 1, 4 and 9 feeds at
640 x 360 and 16 at 480 x 270, 10 frames a second) served by the trial app
(``cosim.trials.server.served_in_thread``, a copy of the study in a
temporary folder), one session per condition, its live page opened in
headless Debian Chromium (/usr/bin/chromium through Playwright), the trial
started and followed to its end (``--duration-s`` of simulated time, paced
at real time). Per trial it reports:

- real time held: the run's simulated over wall time, and its pacing
  lateness (``summary.json``'s ``realtime``: p50, p99, ticks late);
- frames published by the run, received and drawn by the page; the
  server's drops (a page that did not keep up), the page's skips (received,
  replaced by a newer frame before a refresh drew it) and both over the
  frames published;
- glass-to-glass latency p50 / p95 / max and counter mismatches, as the page
  reports them (``live/timing``: from the run making a frame to the page
  drawing it, on the server's clock);
- where the CPU went, in cores (CPU seconds per wall second, sampled with
  psutil): the run's thread (physics exchange, the cameras' collection, the
  frame tap), of it the JPEG encoding (the tap's own count), the HTTP
  server's thread, the render workers, the flight-model workers and the
  browser (its processes and Playwright's driver).

Levers: ``--size WxH`` (every feed), ``--jpeg-quality``,
``--render-workers``, ``--map-rate-hz``, ``--cameras shown|all`` (render
only the aircraft shown, or every camera of the scenario), ``--backend``;
``--vary LEVER=V1,V2`` runs the conditions once per value, interleaved over
``--rounds`` (A/B in the same run, as the machine's load drifts).

    python benchmarks/live_console_bench.py --out live.json
    python benchmarks/live_console_bench.py --condition feeds9 --vary jpeg_quality=80,50 \\
        --rounds 3
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import shutil
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import yaml

REPO = Path(__file__).resolve().parent.parent
STUDY = REPO / "studies" / "live_search.yaml"
CHROMIUM = "/usr/bin/chromium"
#: the page's window: nine 640 x 360 feeds (3 x 3) beside the map
WIDTH_PX, HEIGHT_PX = 1920, 1080
PROFILE = {"screen_width_px": WIDTH_PX, "screen_height_px": HEIGHT_PX,
           "screen_width_mm": 598.0, "screen_height_mm": 336.0, "viewing_distance_mm": 600.0}
LEVERS = ("size", "jpeg_quality", "render_workers", "map_rate_hz", "cameras", "backend")
#: how often the CPU of each thread and process is read (s)
SAMPLE_S = 0.5


def _post(url: str, body: dict[str, Any]) -> Any:
    req = urllib.request.Request(url, json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=120) as r:
        return json.loads(r.read())


def _get(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=120) as r:
        return json.loads(r.read())


def _size(text: str) -> tuple[int, int]:
    w, _, h = text.lower().partition("x")
    if not (w.isdigit() and h.isdigit() and 16 <= int(w) <= 4096 and 16 <= int(h) <= 4096):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, got {text!r}")
    return int(w), int(h)


def study_copy(study: Path, folder: Path, settings: dict[str, Any], duration_s: float,
               conditions: list[str] | None) -> Path:
    """The study and its scenarios copied into ``folder``, each condition
    ``duration_s`` long (only ``conditions``, if given), each scenario's
    cameras changed as ``settings`` asks (size, render workers, only the
    aircraft shown)."""
    from cosim.trials.study import load_study

    shown = {c.id: list(dict.fromkeys(f.vehicle for f in c.feeds)) for c in load_study(study).live}
    d = yaml.safe_load(study.read_text())
    items = [c for c in d["scenarios"] if conditions is None or c["id"] in conditions]
    if not items:
        raise SystemExit(f"no condition {conditions} in {study}")
    src = study.parent
    for c in items:
        scn = yaml.safe_load((src / c["scenario"]).read_text())
        cams = scn["cameras"]
        for view in cams["views"]:
            if settings.get("size"):
                view["width_px"], view["height_px"] = settings["size"]
            if settings.get("cameras") == "shown":
                view["vehicles"] = shown[c["id"]]
        if settings.get("render_workers") is not None:
            cams["render_workers"] = settings["render_workers"]
        name = f"{c['id']}.yaml"
        (folder / name).write_text(yaml.safe_dump(scn, sort_keys=False))
        c["scenario"] = name
        c["duration_s"] = duration_s
    d["scenarios"] = items
    out = folder / "study.yaml"
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    return out


class CpuSampler:
    """CPU seconds of this process's threads and of its child processes,
    read every ``SAMPLE_S`` in a thread of its own, summed by part (a
    process that ends keeps its last reading)."""

    def __init__(self) -> None:
        self.me = psutil.Process()
        self.last: dict[tuple[str, int], tuple[str, float]] = {}
        self.first: dict[tuple[str, int], float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._main, name="cpu-sampler", daemon=True)

    def _part_of_thread(self, names: dict[int, str], tid: int) -> str:
        name = names.get(tid, "")
        if name.startswith("live-"):
            return "run"
        if name.startswith("Thread-") or name.startswith("uvicorn"):
            return "http"
        return "server_other"

    def sample(self) -> None:
        t = psutil.cpu_times()
        self._keep(("machine", 0), "machine", t.user + t.system + t.nice + t.irq + t.softirq)
        names = {t.native_id: t.name for t in threading.enumerate() if t.native_id}
        with contextlib.suppress(psutil.Error):
            for th in self.me.threads():
                key = ("thread", th.id)
                part = self._part_of_thread(names, th.id)
                self._keep(key, part, th.user_time + th.system_time)
        workers = {p.pid: p.name for p in multiprocessing.active_children()}
        with contextlib.suppress(psutil.Error):
            children = self.me.children(recursive=True)
        for p in children:
            name = workers.get(p.pid, "")
            part = ("render" if name.startswith("cosim-render") else
                    "fdm" if name.startswith("cosim-worker") else
                    "browser" if not name else "other_workers")
            with contextlib.suppress(psutil.Error):
                t = p.cpu_times()
                self._keep(("proc", p.pid), part, t.user + t.system)

    def _keep(self, key: tuple[str, int], part: str, cpu_s: float) -> None:
        self.first.setdefault(key, cpu_s)
        was = self.last.get(key)
        # a thread once named live-... stays the run's (its name goes with it)
        if was is not None and was[0] == "run":
            part = "run"
        self.last[key] = (part, cpu_s)

    def _main(self) -> None:
        while not self._stop.wait(SAMPLE_S):
            self.sample()

    @contextlib.contextmanager
    def running(self) -> Iterator[CpuSampler]:
        self.sample()
        t0 = time.monotonic()
        self._thread.start()
        try:
            yield self
        finally:
            self._stop.set()
            self._thread.join()
            self.sample()
            self.wall_s = time.monotonic() - t0

    def cores(self) -> dict[str, float]:
        """Each part's CPU seconds per wall second while running, and the
        whole machine's (``machine``; ``others``: what is not ours)."""
        out: dict[str, float] = {}
        for key, (part, cpu_s) in self.last.items():
            out[part] = out.get(part, 0.0) + cpu_s - self.first[key]
        out["others"] = out["machine"] - sum(v for k, v in out.items() if k != "machine")
        return {k: round(v / self.wall_s, 3) for k, v in sorted(out.items())}


def run_trial(url: str, app: Any, browser: Any, condition: str) -> dict[str, Any]:
    """One session's trial of ``condition``, followed by a page to its end."""
    s = _post(f"{url}/api/sessions", {"participant": f"bench-{condition}", **PROFILE})
    trial = next(t["index"] for t in s["trials"] if t["condition"] == condition)
    page = browser.new_page(viewport={"width": WIDTH_PX, "height": HEIGHT_PX})
    try:
        page.goto(f"{url}/live?session={s['id']}")
        page.wait_for_function("document.body.dataset.phase === 'waiting'")
        with CpuSampler().running() as cpu:
            _post(f"{url}/api/sessions/{s['id']}/live/start", {"trial_index": trial})
            page.wait_for_function("document.body.dataset.phase === 'ended'",
                                   timeout=3_600_000, polling=500)
        status = _get(f"{url}/api/sessions/{s['id']}/live")["live"]
    finally:
        page.close()
    live = app.state.trials.live.runs[s["id"]][1]
    live.wait(60)
    summary = json.loads((Path(status["out_dir"]) / "summary.json").read_text())
    return measures(condition, live.condition, status, summary, cpu.cores(), cpu.wall_s)


def measures(condition: str, cond: Any, status: dict[str, Any], summary: dict[str, Any],
             cores: dict[str, float], wall_s: float) -> dict[str, Any]:
    """The report's row of one trial (``cores``: ``CpuSampler.cores`` over
    ``wall_s``)."""
    page = status.get("page_timing") or {}
    published = int(status["frames_published"])
    dropped = int(status["frames_dropped"])
    received, drawn = int(page.get("frames_received", 0)), int(page.get("frames_drawn", 0))
    pace = summary.get("realtime", {})
    tap = summary.get("live_console", {})
    split = summary.get("time_split_s", {})
    f = cond.feeds[0]
    rendered = sum(int(c.get("frames", 0)) for c in summary.get("cameras", {}).get("streams", []))
    return {
        "condition": condition, "feeds": len(cond.feeds), "size": f"{f.width_px}x{f.height_px}",
        "rate_hz": f.rate_hz, "sim_time_s": summary["sim_time_s"],
        "stop_reason": summary["stop_reason"],
        "real_time_factor": summary["real_time_factor"],
        "lateness_ms_p50": pace.get("lateness_ms_p50"),
        "lateness_ms_p99": pace.get("lateness_ms_p99"),
        "ticks_late_percent": round(100.0 * pace["overruns"] / pace["ticks"], 1)
        if pace.get("ticks") else None,
        "frames_published": published, "frames_received": received, "frames_drawn": drawn,
        "server_dropped": dropped, "page_skipped": received - drawn,
        "dropped_percent": _ratio(100.0 * dropped, published),
        "skipped_percent": _ratio(100.0 * (received - drawn), published),
        "lost_percent": _ratio(100.0 * (dropped + received - drawn), published),
        "latency_ms_p50": page.get("latency_ms_p50"), "latency_ms_p95": page.get("latency_ms_p95"),
        "latency_ms_max": page.get("latency_ms_max"),
        "counter_mismatches": page.get("counter_mismatches"),
        "jpeg_ms_per_frame": _ratio(1000.0 * tap.get("jpeg_encode_s", 0.0), published),
        "jpeg_cores": _ratio(tap.get("jpeg_encode_s", 0.0), summary.get("wall_time_s"), 3),
        "camera_wait_s": round(split.get("CameraParticipant.on_exchange", 0.0), 2),
        "frames_rendered": rendered,
        "render_ms_per_frame": _ratio(1000.0 * cores.get("render", 0.0) * wall_s, rendered),
        "browser_ms_per_frame": _ratio(1000.0 * cores.get("browser", 0.0) * wall_s, received),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cores": cores,
    }


def _ratio(x: float, of: float | None, digits: int = 2) -> float | None:
    return round(x / of, digits) if of else None


def run(study: Path, settings: dict[str, Any], vary: tuple[str, list[Any]] | None,
        rounds: int, duration_s: float, conditions: list[str] | None) -> list[dict[str, Any]]:
    """Every condition with every value of the lever varied, ``rounds`` times,
    interleaved; one row per trial."""
    from playwright.sync_api import sync_playwright

    from cosim.trials import live
    from cosim.trials.server import make_app, served_in_thread
    from cosim.trials.store import Store
    from cosim.trials.study import load_study

    values = vary[1] if vary else [None]
    rows: list[dict[str, Any]] = []
    defaults = {"jpeg_quality": live.JPEG_QUALITY, "map_rate_hz": live.MAP_RATE_HZ}
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM)
        try:
            for r in range(rounds):
                for value in values:
                    s = dict(settings)
                    if vary:
                        s[vary[0]] = value
                    folder = Path(tmp) / f"r{r}_{values.index(value)}"
                    folder.mkdir()
                    st = load_study(study_copy(study, folder, s, duration_s, conditions))
                    live.JPEG_QUALITY = int(s.get("jpeg_quality") or defaults["jpeg_quality"])
                    live.MAP_RATE_HZ = float(s.get("map_rate_hz") or defaults["map_rate_hz"])
                    store = Store(folder / "bench.sqlite")
                    app = make_app(st, store)
                    app.state.trials.live.backend = s.get("backend") or "process"
                    try:
                        with served_in_thread(app, lifespan="auto", stop_timeout_s=60) as url:
                            for c in st.live:
                                row = run_trial(url, app, browser, c.id)
                                row.update(round=r, lever=vary[0] if vary else None,
                                           value=value, settings=_shown(s))
                                rows.append(row)
                                print(_line(row), file=sys.stderr, flush=True)
                    finally:
                        store.close()
                        shutil.rmtree(folder, ignore_errors=True)
        finally:
            browser.close()
            live.JPEG_QUALITY = int(defaults["jpeg_quality"])
            live.MAP_RATE_HZ = float(defaults["map_rate_hz"])
    return rows


def _shown(s: dict[str, Any]) -> dict[str, Any]:
    return {k: (f"{v[0]}x{v[1]}" if k == "size" and v else v) for k, v in s.items()
            if v is not None}


def _line(r: dict[str, Any]) -> str:
    return (f"{r['condition']} {r['size']} {r['lever'] or ''}={r['value']} round {r['round']}: "
            f"rtf {r['real_time_factor']}, {r['frames_drawn']}/{r['frames_received']}/"
            f"{r['frames_published']} drawn/received/published, lost {r['lost_percent']} %, "
            f"g2g p50 {r['latency_ms_p50']} ms")


def _fmt(v: Any, digits: int = 0) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table (one line a trial)."""
    head = ("| condition | size | lever | round | real time | late p50 / p99 (ms) | published "
            "| received | drawn | dropped % | skipped % | g2g p50 / p95 (ms) | JPEG ms/frame "
            "| render / browser ms a frame | cores: run / JPEG / http / render / fdm / browser "
            "| others' cores |")
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        c = r["cores"]
        lever = f"{r['lever']}={r['value']}" if r["lever"] else ""
        out.append(
            f"| {r['condition']} | {r['size']} | {lever} | {r['round']} "
            f"| {_fmt(r['real_time_factor'], 3)} "
            f"| {_fmt(r['lateness_ms_p50'], 1)} / {_fmt(r['lateness_ms_p99'], 0)} "
            f"| {r['frames_published']} | {r['frames_received']} | {r['frames_drawn']} "
            f"| {_fmt(r['dropped_percent'], 2)} | {_fmt(r['skipped_percent'], 2)} "
            f"| {_fmt(r['latency_ms_p50'])} / {_fmt(r['latency_ms_p95'])} "
            f"| {_fmt(r['jpeg_ms_per_frame'], 2)} "
            f"| {_fmt(r['render_ms_per_frame'], 1)} / {_fmt(r['browser_ms_per_frame'], 1)} "
            f"| {_fmt(c.get('run', 0.0), 2)} / {_fmt(r['jpeg_cores'], 2)} "
            f"/ {_fmt(c.get('http', 0.0), 2)} / {_fmt(c.get('render', 0.0), 2)} "
            f"/ {_fmt(c.get('fdm', 0.0), 2)} / {_fmt(c.get('browser', 0.0), 2)} "
            f"| {_fmt(c.get('others', 0.0), 2)} |")
    return "\n".join(out)


def _vary(text: str) -> tuple[str, list[Any]]:
    key, _, vals = text.partition("=")
    if key not in LEVERS or not vals:
        raise argparse.ArgumentTypeError(f"expected LEVER=V1,V2 with a lever of "
                                         f"{', '.join(LEVERS)}, got {text!r}")
    conv: Any = {"size": _size, "jpeg_quality": int, "render_workers": int,
                 "map_rate_hz": float, "cameras": str, "backend": str}[key]
    try:
        return key, [conv(v) for v in vals.split(",")]
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: {e}") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--study", type=Path, default=STUDY, help="a live study (default: %(default)s)")
    ap.add_argument("--condition", action="append", help="a condition's id (repeat; default: all)")
    ap.add_argument("--duration-s", type=float, default=30.0,
                    help="simulated seconds per trial (default: %(default)s)")
    ap.add_argument("--rounds", type=int, default=1, help="interleaved rounds (default: 1)")
    ap.add_argument("--size", type=_size, help="every feed's size, WxH (default: the study's)")
    ap.add_argument("--jpeg-quality", type=int, help="the feeds' JPEG quality (default: 80)")
    ap.add_argument("--render-workers", type=int, help="the cameras' render workers "
                                                       "(default: the scenario's)")
    ap.add_argument("--map-rate-hz", type=float, help="the map's updates a second (default: 4)")
    ap.add_argument("--cameras", choices=("shown", "all"), default="shown",
                    help="render the aircraft shown only, or every camera (default: shown)")
    ap.add_argument("--backend", default="process", help="the flight models' backend")
    ap.add_argument("--vary", type=_vary, help="LEVER=V1,V2: each value in turn, interleaved")
    ap.add_argument("--out", type=Path, help="the rows as JSON")
    a = ap.parse_args(argv)
    if not Path(CHROMIUM).exists():
        print(f"no {CHROMIUM}: install Debian's chromium", file=sys.stderr)
        return 1
    settings = {"size": a.size, "jpeg_quality": a.jpeg_quality,
                "render_workers": a.render_workers, "map_rate_hz": a.map_rate_hz,
                "cameras": a.cameras, "backend": a.backend}
    rows = run(a.study.resolve(), settings, a.vary, a.rounds, a.duration_s, a.condition)
    text = table(rows)
    print(text)
    if a.out:
        a.out.write_text(json.dumps({"load_average": os.getloadavg(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
