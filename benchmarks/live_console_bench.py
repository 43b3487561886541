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
  server's drops (a page that did not keep up), the page's skips (received
  and never drawn: replaced while waiting for a refresh) and both over the
  frames published;
- glass-to-glass latency p50 / p95 / max and counter mismatches, as the page
  reports them (``live/timing``: from the run making a frame to the page
  drawing it, on the server's clock);
- where the CPU went, in cores (CPU seconds per wall second, sampled with
  psutil): the run's thread (physics exchange, the cameras' collection, the
  frame tap), of it the JPEG encoding (the tap's own count), the HTTP
  server's thread, the render workers, the flight-model workers, the
  browser (its processes and Playwright's driver) and the rest of the
  machine (``others``: work that is not this benchmark's); and the CPU ms
  a frame rendered, JPEG-encoded and handled by the browser.

Levers: ``--size WxH`` (every feed), ``--jpeg-quality``,
``--render-workers``, ``--map-rate-hz``, ``--cameras shown|all`` (render
only the aircraft shown, or every camera of the scenario), ``--backend``
(the flight models'; their worker count is the console's own),
``--page`` (static/live.js as it is, or its earlier ways, ``PAGE_VARIANTS``);
``--vary LEVER=V1,V2`` runs the conditions once per value, interleaved over
``--rounds`` (A/B in the same run, as the machine's load drifts).
``--decode-paths N`` instead times the page's ways of decoding a frame in
the browser alone, on N frames of a condition's first feed.

    python benchmarks/live_console_bench.py --out live.json
    python benchmarks/live_console_bench.py --condition feeds9 --vary jpeg_quality=80,60 \\
        --rounds 3
    python benchmarks/live_console_bench.py --decode-paths 60 --rounds 3
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
LEVERS = ("size", "jpeg_quality", "render_workers", "map_rate_hz", "cameras", "backend", "page")
#: the page's variants (``--page``, joined by "+"), served in place of
#: static/live.js through Playwright's routing: each a list of (text of
#: live.js, what replaces it). ``now``: live.js as it is; the others put back
#: what it did before the levers this benchmark measured were adopted:
#: ``from``: the frame's base64 turned into bytes by ``Uint8Array.from`` with
#: a function a character (not a loop); ``newest``: a frame that arrives
#: before the previous one of its feed was drawn replaces it (none wait)
PAGE_VARIANTS: dict[str, list[tuple[str, str]]] = {
    "now": [],
    "from": [
        ("""    const text = atob(msg.jpeg), bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);""",
         """    const bytes = Uint8Array.from(atob(msg.jpeg), (c) => c.charCodeAt(0));"""),
    ],
    "newest": [
        ("""    const on = drawn.get(msg.feed); // never back to a frame older than the one shown
    if (on && on.frame >= msg.frame) { bitmap.close(); return; }
    const q = due.get(msg.feed) || [];
    q.push({ frame: msg.frame, bitmap, made_ms: msg.made_ms, counter });
    q.sort((a, b) => a.frame - b.frame); // decodes may end out of order
    while (q.length > MAX_WAITING) q.shift().bitmap.close();
    due.set(msg.feed, q);""",
         """    const was = due.get(msg.feed);
    if (was && was.frame > msg.frame) { bitmap.close(); return; }
    if (was) was.bitmap.close();
    due.set(msg.feed, { frame: msg.frame, bitmap, made_ms: msg.made_ms, counter });"""),
        ("""    for (const [k, q] of due) {
      const d = q.shift();
      const f = feeds[k];""", """    for (const [k, d] of due) {
      const f = feeds[k];"""),
        ("""    for (const [k, q] of due) if (!q.length) due.delete(k);
    if (due.size) { rafPending = true; requestAnimationFrame(draw); }
    document.body.dataset.drawn""", """    due.clear();
    document.body.dataset.drawn"""),
        ("for (const q of due.values()) for (const d of q) d.bitmap.close();",
         "for (const d of due.values()) d.bitmap.close();"),
    ],
}
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
        #: each browser process's kind (``_browser_part``)
        self.kinds: dict[int, str] = {}
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
        children: list[psutil.Process] = []
        with contextlib.suppress(psutil.Error):
            children = self.me.children(recursive=True)
        for p in children:
            name = workers.get(p.pid, "")
            with contextlib.suppress(psutil.Error):
                part = ("render" if name.startswith("cosim-render") else
                        "fdm" if name.startswith("cosim-worker") else
                        self._browser_part(p) if not name else "other_workers")
                t = p.cpu_times()
                self._keep(("proc", p.pid), part, t.user + t.system)

    def _browser_part(self, p: psutil.Process) -> str:
        """``browser:`` and the kind of Chromium process (its ``--type``:
        renderer, gpu-process, utility; ``main``), or Playwright's driver."""
        kind = self.kinds.get(p.pid)
        if kind is None:
            cmd = p.cmdline()
            types = [a.split("=", 1)[1] for a in cmd if a.startswith("--type=")]
            kind = types[0] if types else ("driver" if any("playwright" in a for a in cmd)
                                           else "main")
            self.kinds[p.pid] = kind
        return f"browser:{kind}"

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
        whole machine's (``machine``; ``others``: what is not ours);
        ``browser`` is the sum of its ``browser:KIND`` processes."""
        out: dict[str, float] = {}
        for key, (part, cpu_s) in self.last.items():
            out[part] = out.get(part, 0.0) + cpu_s - self.first[key]
        out["others"] = out["machine"] - sum(v for k, v in out.items() if k != "machine")
        out["browser"] = sum(v for k, v in out.items() if k.startswith("browser:"))
        return {k: round(v / self.wall_s, 3) for k, v in sorted(out.items())}


def page_script(variant: str) -> str:
    """static/live.js as the page ``variant`` has it (``PAGE_VARIANTS``)."""
    from cosim.trials import server

    text = (Path(server.__file__).parent / "static" / "live.js").read_text()
    for old, new in (pair for v in variant.split("+") for pair in PAGE_VARIANTS[v]):
        if text.count(old) != 1:
            raise SystemExit(f"page variant {variant!r}: static/live.js no longer has "
                             f"{old.strip().splitlines()[0]!r} once: update PAGE_VARIANTS")
        text = text.replace(old, new)
    return text


def run_trial(url: str, app: Any, browser: Any, condition: str,
              variant: str = "now") -> dict[str, Any]:
    """One session's trial of ``condition``, followed by a page (``variant``
    of live.js) to its end."""
    s = _post(f"{url}/api/sessions", {"participant": f"bench-{condition}", **PROFILE})
    trial = next(t["index"] for t in s["trials"] if t["condition"] == condition)
    page = browser.new_page(viewport={"width": WIDTH_PX, "height": HEIGHT_PX})
    if variant != "now":
        script = page_script(variant)
        page.route("**/static/live.js", lambda route: route.fulfill(
            body=script, content_type="text/javascript"))
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
        # the page knows the server's clock to within half this (its quickest
        # round trip), so a latency shorter than that can come out negative
        "clock_rtt_ms": page.get("clock_rtt_ms"),
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
                                row = run_trial(url, app, browser, c.id,
                                                s.get("page") or "now")
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


#: the page's ways from a frame message's base64 JPEG to a picture on a
#: canvas, timed in the browser on the same frames (``decode_paths``); ``now``
#: is what static/live.js does
DECODE_PATHS = {
    "now: atob, Uint8Array.from, createImageBitmap": """async (m) => {
        const bytes = Uint8Array.from(atob(m.jpeg), (c) => c.charCodeAt(0));
        return createImageBitmap(new Blob([bytes], { type: "image/jpeg" })); }""",
    "atob, a loop, createImageBitmap": """async (m) => {
        const s = atob(m.jpeg), bytes = new Uint8Array(s.length);
        for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
        return createImageBitmap(new Blob([bytes], { type: "image/jpeg" })); }""",
    "fetch(data: URL), createImageBitmap": """async (m) => {
        const b = await (await fetch("data:image/jpeg;base64," + m.jpeg)).blob();
        return createImageBitmap(b); }""",
    "img element, decode()": """async (m) => {
        const img = new Image(); img.src = "data:image/jpeg;base64," + m.jpeg;
        await img.decode(); return img; }""",
    "binary (no base64, no JSON): createImageBitmap": """async (m) => {
        return createImageBitmap(new Blob([m.bytes], { type: "image/jpeg" })); }""",
}
DECODE_PAGE = """async ([texts, path, draw, binary]) => {
  const decode = eval(path);
  const canvas = document.createElement("canvas");
  const ctx = canvas.getContext("2d", { willReadFrequently: true });
  const msgs = texts.map((t) => JSON.parse(t));
  for (const m of msgs) m.bytes = Uint8Array.from(atob(m.jpeg), (c) => c.charCodeAt(0));
  let mainMs = 0;
  const t0 = performance.now();
  for (let i = 0; i < texts.length; i++) {
    const s = performance.now();
    const m = binary ? msgs[i] : JSON.parse(texts[i]);
    const p = decode(m);
    mainMs += performance.now() - s;
    const pic = await p;
    const d = performance.now();
    if (draw) {
      canvas.width = pic.width; canvas.height = pic.height;
      ctx.drawImage(pic, 0, 0);
      ctx.getImageData(0, pic.height - 32, pic.width, 32);
    }
    if (pic.close) pic.close();
    mainMs += performance.now() - d;
  }
  return [(performance.now() - t0) / texts.length, mainMs / texts.length];
}"""


def feed_messages(study: Path, condition: str, n: int, quality: int) -> list[str]:
    """``n`` frame messages of the condition's first feed as the server sends
    them (``with_counter``, JPEG at ``quality``, base64 in JSON), from a
    short unpaced run of its scenario."""
    import base64

    import cv2

    from cosim.scenario import load_scenario
    from cosim.sync.runner import Run
    from cosim.trials.live import with_counter
    from cosim.trials.study import load_study

    c = next(c for c in load_study(study).live if c.id == condition)
    f = c.feeds[0]
    with tempfile.TemporaryDirectory() as tmp:
        scn = load_scenario(c.scenario).with_duration(n / f.rate_hz + 0.5)
        Run(scn, tmp, backend="inline").run()
        cap = cv2.VideoCapture(str(Path(tmp) / "cameras" / f"{f.vehicle}_{f.camera}.mp4"))
        out: list[str] = []
        while len(out) < n:
            ok, bgr = cap.read()
            if not ok:
                break
            _, jpg = cv2.imencode(".jpg", with_counter(bgr, len(out)),
                                  [cv2.IMWRITE_JPEG_QUALITY, quality])
            out.append(json.dumps({"feed": 0, "frame": len(out), "made_ms": 0.0,
                                   "jpeg": base64.b64encode(jpg.tobytes()).decode()}))
        cap.release()
    return out


def decode_paths(study: Path, condition: str, n: int, quality: int,
                 rounds: int) -> list[dict[str, Any]]:
    """Each of ``DECODE_PATHS`` timed in headless Chromium on the same ``n``
    frames, one frame after the other (ms a frame: in all, and on the page's
    main thread), then with the drawing and the counter's read-back, over
    ``rounds`` interleaved rounds."""
    from playwright.sync_api import sync_playwright

    texts = feed_messages(study, condition, n, quality)
    rows = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM)
        page = browser.new_page()
        page.goto("about:blank")
        for r in range(rounds):
            for name, path in DECODE_PATHS.items():
                for draw in (False, True):
                    all_ms, main_ms = page.evaluate(DECODE_PAGE, [texts, path, draw,
                                                                    "binary" in name])
                    rows.append({"path": name, "drawn": draw, "round": r, "frames": len(texts),
                                 "kb_a_frame": round(sum(map(len, texts)) / len(texts) / 1024, 1),
                                 "ms_a_frame": round(all_ms, 2),
                                 "main_thread_ms_a_frame": round(main_ms, 2)})
        browser.close()
    return rows


def _cameras(text: str) -> str:
    if text not in ("shown", "all"):
        raise ValueError(f"expected shown or all, got {text!r}")
    return text


def _variant(text: str) -> str:
    if not all(v in PAGE_VARIANTS for v in text.split("+")):
        raise ValueError(f"expected a page variant of {', '.join(PAGE_VARIANTS)}, got {text!r}")
    return text


def _vary(text: str) -> tuple[str, list[Any]]:
    key, _, vals = text.partition("=")
    if key not in LEVERS or not vals:
        raise argparse.ArgumentTypeError(f"expected LEVER=V1,V2 with a lever of "
                                         f"{', '.join(LEVERS)}, got {text!r}")
    conv: Any = {"size": _size, "jpeg_quality": int, "render_workers": int,
                 "map_rate_hz": float, "cameras": _cameras, "backend": str,
                 "page": _variant}[key]
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
    ap.add_argument("--page", type=_variant, default="now",
                    help=f"the page's variant: {', '.join(PAGE_VARIANTS)} or several joined "
                         f"by + (default: now, static/live.js as it is)")
    ap.add_argument("--vary", type=_vary, help="LEVER=V1,V2: each value in turn, interleaved")
    ap.add_argument("--decode-paths", type=int, metavar="N",
                    help="instead, time the page's decode paths on N frames of the first "
                         "--condition (default feeds9) in the browser")
    ap.add_argument("--out", type=Path, help="the rows as JSON")
    a = ap.parse_args(argv)
    if not Path(CHROMIUM).exists():
        print(f"no {CHROMIUM}: install Debian's chromium", file=sys.stderr)
        return 1
    if a.decode_paths:
        got = decode_paths(a.study.resolve(), (a.condition or ["feeds9"])[0], a.decode_paths,
                           a.jpeg_quality or 80, a.rounds)
        for g in got:
            print(json.dumps(g))
        if a.out:
            a.out.write_text(json.dumps({"load_average": os.getloadavg(), "rows": got}, indent=1))
        return 0
    from cosim.errors import ConfigError
    from cosim.trials.study import load_study

    try:
        ids = [c.id for c in load_study(a.study).live]
    except ConfigError as e:
        ap.error("; ".join(e.problems)[:2000])
    unknown = sorted(set(a.condition or ()) - set(ids))
    if unknown:
        ap.error(f"no condition {', '.join(unknown)} in {a.study}; it has {', '.join(ids)}")
    settings = {"size": a.size, "jpeg_quality": a.jpeg_quality,
                "render_workers": a.render_workers, "map_rate_hz": a.map_rate_hz,
                "cameras": a.cameras, "backend": a.backend, "page": a.page}
    rows = run(a.study.resolve(), settings, a.vary, a.rounds, a.duration_s, a.condition)
    text = table(rows)
    print(text)
    if a.out:
        a.out.write_text(json.dumps({"load_average": os.getloadavg(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
