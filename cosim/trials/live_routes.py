"""The live console's routes of the trial web app (``protocol: live``).

Owns the HTTP side of live trials: the experimenter starts a session's trial
(``POST /api/sessions/{sid}/live/start``: its condition's scenario runs,
paced at real time, into the session's own run folder, one run per session
at a time) and may stop it (``.../live/stop``); the participant's page
(``/live?session=ID``, ``static/live.html``) follows the run through a
server-sent event stream (``GET .../live/stream``: the feeds, each frame
JPEG-encoded with its feed and frame number, the aircraft's positions and
each aircraft's last map command)
and posts each click on a feed (``POST .../live/reports``: the feed, the
frame the page drew there, the pixel in the frame's own coordinates, the
page's click and draw times), which the store keeps
(``Store.live_reports``). Where the condition allows tasking, the page posts
the participant's map commands (``POST .../live/command``: go to, orbit or
look at a point with one aircraft), handed to the run
(``LiveRun.command``) and kept (``Store.live_commands``, with the tick the
run applied each at). The run and its fan-out are ``live``'s.

Bounds: a report is a small flat JSON object (the app's body limits); its
feed must be one of the condition's, its frame one the server has sent on
that feed, its pixel inside the frame; a command's action must be one the
condition allows, its vehicle one that may be tasked, its point within
``MAX_COMMAND_RANGE_M`` of the scenario's origin, and a session sends at
most ``MAX_COMMANDS_PER_S`` a second and ``MAX_COMMANDS_PER_TRIAL`` a trial
(429 beyond); a session has at most one run at a
time and at most ``live.MAX_WATCHERS`` pages watching it; a page that does
not keep up loses frames (counted), never slows the run. The run is stopped
when its session is stopped or finished and when the server shuts down
(``LiveConsole.close``).
"""

from __future__ import annotations

import asyncio
import logging
import math
import re
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from cosim.errors import ConfigError
from cosim.logs import write_json_atomic
from cosim.trials.live import Hub, LiveRun
from cosim.trials.live_results import runs_folder, score_trial, trial_folder
from cosim.trials.live_scoring import SessionScore
from cosim.trials.live_study import LiveCondition, TimingLimits
from cosim.trials.study import Study

log = logging.getLogger(__name__)

REPORT_KEY = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")
#: seconds a stopped run may take to end before the server gives up waiting
STOP_WAIT_S = 30.0
#: a page's timing report: its counts (whole, at most MAX_FRAMES) and times (ms)
TIMING_COUNTS = ("frames_received", "frames_drawn", "latency_samples", "counter_mismatches")
TIMING_MS = ("latency_ms_p50", "latency_ms_p95", "latency_ms_max", "clock_rtt_ms")
MAX_FRAMES = 10_000_000
MAX_LATENCY_MS = 600_000.0
#: the page's clock readings accepted (ms since the page loaded): a day
MAX_PAGE_TIME_MS = 86_400_000.0
#: how far from the scenario's origin (m) a map command's point may be
MAX_COMMAND_RANGE_M = 20_000.0
#: a session's map commands: at most this many in any second, and in one trial
MAX_COMMANDS_PER_S = 5
MAX_COMMANDS_PER_TRIAL = 2000


def live_order(study: Study, session_number: int) -> list[dict[str, Any]]:
    """A new live session's trials: each with its condition's id and fingerprint."""
    return [{"index": t.index, "practice": False, "clip": t.clip,
             "condition_id": study.live[t.clip].id,
             "fingerprint": study.live[t.clip].fingerprint, "break_before": t.break_before}
            for t in study.trial_order(session_number)]


class LiveConsole:
    """The live runs of one app (one per session at most) and their routes.
    ``bad``: the app's exception for a refused request (message, status);
    ``number(body, key, optional=False)``: the app's reader of a JSON number."""

    def __init__(self, study: Study, store: Any, bad: type[Exception], number: Any,
                 runs_dir: Path | None = None, backend: str = "process",
                 realtime: float = 1.0) -> None:
        self.study, self.store, self.bad, self.number = study, store, bad, number
        self.runs_dir = runs_dir or runs_folder(study)
        self.backend, self.realtime = backend, realtime
        #: called with (session, trial index, LiveRun) as a trial's run is about
        #: to start (its thread not yet started): ``instrument_routes`` adds its
        #: SAGAT freezes to the run this way
        self.on_start: list[Callable[[dict[str, Any], int, LiveRun], None]] = []
        self.runs: dict[str, tuple[int, LiveRun]] = {}
        self._by_id = {c.id: c for c in study.live}
        #: per session: when (monotonic s) its last commands were taken, and
        #: how many its live trial has taken
        self._sent: dict[str, deque[float]] = {}
        self._commands: dict[tuple[str, int], int] = {}
        #: the (session, trial, seq) of commands stored, and the log entries of
        #: those applied before they were stored (both only touched in the event loop)
        self._stored: set[tuple[str, int, int]] = set()
        self._applied_early: dict[tuple[str, int, int], dict[str, Any]] = {}

    # --- helpers ---
    def condition(self, t: dict[str, Any]) -> LiveCondition:
        """A session trial's condition, refused (409) if gone or changed."""
        c = self._by_id.get(t.get("condition_id", ""))
        if c is None:
            raise self.bad(f"condition {str(t.get('condition_id'))[:200]!r} of this session is "
                           f"no longer in the study {self.study.path}", 409)
        if t.get("fingerprint") != c.fingerprint:
            raise self.bad(f"condition {c.id!r}: its scenario {c.scenario} changed since the "
                           f"session was created: restore it, or start a new session", 409)
        return c

    def view(self, s: dict[str, Any]) -> dict[str, Any]:
        """What the pages see of a live session."""
        trials = []
        for t in s["trial_order"]:
            c = self.condition(t)
            folder = self._folder(s["id"], t["index"])
            trials.append({**t, "condition": c.id, "conditions": c.condition_map,
                           "feeds": [f.name for f in c.feeds], "run": str(folder),
                           "ran": folder.exists()})
        live = self.runs.get(s["id"])
        if s["state"] != "finished" and all(t["ran"] for t in trials) and not (
                live is not None and live[1].running):  # every trial has run
            self.store.set_state(s["id"], "finished")
            s["state"] = "finished"
        status = None
        if live is not None:
            status = {"trial_index": live[0], **live[1].status()}
            status["flags"] = timing_flags(self.study.timing_limits, status)
        return {"id": s["id"], "participant": s["participant"], "protocol": "live",
                "state": s["state"], "trials": trials, "live": status,
                "order_method": s["order_method"], "seed": s["seed"],
                "session_number": s["session_number"]}

    def _folder(self, sid: str, index: int) -> Path:
        return trial_folder(self.runs_dir, sid, index)

    def _session(self, request: Request) -> dict[str, Any]:
        sid = request.path_params["sid"]
        s = self.store.session(sid) if len(sid) <= 32 else None
        if s is None or s["protocol"] != "live":
            raise self.bad(f"no live session {sid[:40]!r}", 404)
        return dict(s)

    def _live(self, sid: str) -> tuple[int, LiveRun]:
        live = self.runs.get(sid)
        if live is None:
            raise self.bad("no trial of this session has been started", 409)
        return live

    # --- routes ---
    async def start(self, request: Request, body: dict[str, Any]) -> Response:
        s = await run_in_threadpool(self._session, request)
        ti = body.get("trial_index")
        if isinstance(ti, bool) or not isinstance(ti, int) or not 0 <= ti < len(s["trial_order"]):
            raise self.bad(f"trial_index: expected 0..{len(s['trial_order']) - 1}, "
                           f"got {ti!r}"[:200])
        if s["state"] == "finished":
            raise self.bad("this session is finished", 409)
        was = self.runs.get(s["id"])
        if was is not None and was[1].running:
            raise self.bad(f"trial {was[0]} of this session is still running: stop it first "
                           f"(one run per session)", 409)
        folder = self._folder(s["id"], ti)
        if folder.exists():
            raise self.bad(f"trial {ti} of this session has run already (its run is in "
                           f"{folder})", 409)
        c = self.condition(s["trial_order"][ti])
        loop = asyncio.get_running_loop()
        hub = Hub(loop)

        def on_applied(entry: dict[str, Any], sid: str = s["id"]) -> None:  # the run's thread
            try:
                loop.call_soon_threadsafe(self._applied, sid, ti, entry)
            except RuntimeError:  # the loop is closed: the server is going
                log.warning("session %s trial %d: command %s applied at tick %s not stored",
                            sid, ti, entry.get("seq"), entry.get("tick"))

        try:
            run = await run_in_threadpool(LiveRun, c, folder, hub, realtime=self.realtime,
                                          backend=self.backend, on_applied=on_applied)
        except ConfigError as e:
            raise self.bad("; ".join(e.problems)[:2000], 409) from None
        self.runs[s["id"]] = (ti, run)
        for hook in self.on_start:  # participants of others join the run (SAGAT freezes)
            hook(s, ti, run)
        run.start()
        await run_in_threadpool(self.store.set_state, s["id"], "running")
        log.info("session %s: trial %d (%s) live in %s", s["id"], ti, c.id, folder)
        return JSONResponse({"trial_index": ti, **run.status()}, status_code=201)

    async def stop(self, request: Request, body: dict[str, Any]) -> Response:
        s = await run_in_threadpool(self._session, request)
        ti, run = self._live(s["id"])
        run.stop("stopped by the experimenter")
        await run_in_threadpool(run.wait, STOP_WAIT_S)
        return JSONResponse({"trial_index": ti, **run.status()})

    async def status(self, request: Request) -> Response:
        s = await run_in_threadpool(self._session, request)
        return JSONResponse(await run_in_threadpool(self.view, s))

    async def stream(self, request: Request) -> Response:
        """The session's live run as server-sent events: ``hello`` (its feeds),
        ``frame`` and ``states`` messages, then ``end``."""
        s = await run_in_threadpool(self._session, request)
        ti, run = self._live(s["id"])
        try:
            watcher = run.hub.watch()
        except ConfigError as e:
            raise self.bad("; ".join(e.problems), 429) from None

        async def events() -> AsyncIterator[str]:
            try:
                while True:
                    kind, text = await watcher.get()
                    yield f"event: {kind}\ndata: {text}\n\n"
                    if kind == "end":
                        return
            finally:
                run.hub.leave(watcher)

        return StreamingResponse(events(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store",
                                          "X-Accel-Buffering": "no"})

    async def report(self, request: Request, body: dict[str, Any]) -> Response:
        s = await run_in_threadpool(self._session, request)
        ti, run = self._live(s["id"])
        if body.get("trial_index") != ti:
            raise self.bad(f"trial_index: the live trial of this session is {ti}, got "
                           f"{body.get('trial_index')!r}"[:200], 409)
        key = body.get("report_key")
        if not isinstance(key, str) or not REPORT_KEY.match(key):
            raise self.bad("report_key: expected the page's id of the click (1-64 letters, "
                           "digits, '_', '-')")
        feeds = run.condition.feeds
        k = body.get("feed")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(feeds):
            raise self.bad(f"feed: expected 0..{len(feeds) - 1} (this trial's feeds), "
                           f"got {k!r}"[:200])
        feed = feeds[k]
        frame = body.get("frame")
        last = run.hub.last_frame.get(k)
        if isinstance(frame, bool) or not isinstance(frame, int) or last is None \
                or not 0 <= frame <= last:
            sent = "none yet" if last is None else f"0..{last}"
            raise self.bad(f"frame: expected a frame of feed {feed.name} sent to the page "
                           f"({sent}), got {frame!r}"[:200])
        x, y = self.number(body, "x_px"), self.number(body, "y_px")
        if not (0 <= x <= feed.width_px and 0 <= y <= feed.height_px):
            raise self.bad(f"x_px, y_px: expected a point of the {feed.width_px} x "
                           f"{feed.height_px} frame (0 at its left and top edges), got "
                           f"({x:g}, {y:g})")
        click = self.number(body, "click_time_ms")
        drawn = self.number(body, "drawn_time_ms", optional=True)
        for name, v in (("click_time_ms", click), ("drawn_time_ms", drawn)):
            if v is not None and not 0 <= v <= MAX_PAGE_TIME_MS:
                raise self.bad(f"{name}: expected 0..{MAX_PAGE_TIME_MS:.0f} ms (the page's "
                               f"clock), got {v:g}")
        row = {"session": s["id"], "participant": s["participant"], "trial_index": ti,
               "condition": run.condition.id, "report_key": key, "feed": k,
               "feed_name": feed.name, "frame": frame, "x_px": x, "y_px": y,
               "click_time_ms": click, "drawn_time_ms": drawn, "run": str(run.out_dir)}
        stored, created = await run_in_threadpool(self.store.record_live_report, row)
        return JSONResponse({"report": stored, "created": created},
                            status_code=201 if created else 200)

    async def command(self, request: Request, body: dict[str, Any]) -> Response:
        """A map command of the participant (``live.command_spec``): checked,
        handed to the run and stored; its sequence number in the run."""
        s = await run_in_threadpool(self._session, request)
        ti, run = self._live(s["id"])
        if body.get("trial_index") != ti:
            raise self.bad(f"trial_index: the live trial of this session is {ti}, got "
                           f"{body.get('trial_index')!r}"[:200], 409)
        c = run.condition
        action, vehicle = body.get("action"), body.get("vehicle")
        if not c.tasking:
            raise self.bad(f"action: condition {c.id!r} allows no commands from the map")
        if not isinstance(action, str) or action not in c.tasking:
            raise self.bad(f"action: expected one of {', '.join(c.tasking)} (condition "
                           f"{c.id!r}), got {action!r}"[:300])
        if not isinstance(vehicle, str) or vehicle not in c.taskable:
            raise self.bad(f"vehicle: expected one of {', '.join(c.taskable)[:400]} (the "
                           f"aircraft of condition {c.id!r} that take commands), got "
                           f"{vehicle!r}"[:600])
        if action == "look" and vehicle not in c.lookers:
            raise self.bad(f"vehicle: {vehicle} has no camera on a gimbal to point: look is for "
                           f"{', '.join(c.lookers)[:400]}")
        north_m, east_m = self.number(body, "north_m"), self.number(body, "east_m")
        if not (math.isfinite(north_m) and math.isfinite(east_m)
                and math.hypot(north_m, east_m) <= MAX_COMMAND_RANGE_M):
            raise self.bad(f"north_m, east_m: expected a point within "
                           f"{MAX_COMMAND_RANGE_M:.0f} m of the scenario's origin, got "
                           f"({north_m:g}, {east_m:g})")
        client = self.number(body, "client_time_ms", optional=True)
        if client is not None and not 0 <= client <= MAX_PAGE_TIME_MS:
            raise self.bad(f"client_time_ms: expected 0..{MAX_PAGE_TIME_MS:.0f} ms (the "
                           f"page's clock), got {client:g}")
        self._room_for_command(s["id"], ti)
        try:
            seq = run.command(vehicle, action, north_m, east_m)
        except ConfigError as e:  # a full queue, a run that is over
            raise self.bad("; ".join(e.problems)[:1000], 409) from None
        self._took_command(s["id"], ti)  # (no await since the check: none slipped in)
        row = {"session": s["id"], "participant": s["participant"], "trial_index": ti,
               "condition": c.id, "seq": seq, "vehicle": vehicle, "action": action,
               "north_m": north_m, "east_m": east_m, "client_time_ms": client,
               "run": str(run.out_dir)}
        run.hub.command({"seq": seq, "vehicle": vehicle, "action": action,
                         "north_m": north_m, "east_m": east_m})
        stored = await run_in_threadpool(self.store.record_live_command, row)
        key = (s["id"], ti, seq)
        self._stored.add(key)
        early = self._applied_early.pop(key, None)
        if early is not None:  # applied while it was being stored
            await run_in_threadpool(self._store_applied, key, early)
        return JSONResponse({"seq": seq, "action": action, "vehicle": vehicle,
                             "server_time": stored["server_time"]}, status_code=201)

    def _room_for_command(self, sid: str, ti: int) -> None:
        """429 if session ``sid`` has had its commands of the last second, or
        its trial ``ti`` its commands of a trial (refused ones do not count)."""
        now = time.monotonic()
        sent = self._sent.setdefault(sid, deque())
        while sent and now - sent[0] >= 1.0:
            sent.popleft()
        if len(sent) >= MAX_COMMANDS_PER_S:
            raise self.bad(f"too many commands: at most {MAX_COMMANDS_PER_S} a second; wait "
                           f"a moment and send it again", 429)
        if self._commands.get((sid, ti), 0) >= MAX_COMMANDS_PER_TRIAL:
            raise self.bad(f"too many commands: at most {MAX_COMMANDS_PER_TRIAL} in a trial, "
                           f"and this trial has had them", 429)

    def _took_command(self, sid: str, ti: int) -> None:
        """Count a command the run took."""
        self._sent.setdefault(sid, deque()).append(time.monotonic())
        self._commands[(sid, ti)] = self._commands.get((sid, ti), 0) + 1

    def _applied(self, sid: str, ti: int, entry: dict[str, Any]) -> None:
        """A command's log entry once the run applied it (in the event loop):
        its tick stored, or kept until its row is."""
        key = (sid, ti, int(entry["seq"]))
        if key not in self._stored:
            self._applied_early[key] = entry
            return
        asyncio.get_running_loop().run_in_executor(None, self._store_applied, key, entry)

    def _store_applied(self, key: tuple[str, int, int], entry: dict[str, Any]) -> None:
        try:
            self.store.live_command_applied(*key, int(entry["tick"]), float(entry["time_s"]))
        except Exception:  # noqa: BLE001 - the run goes on; its commands.jsonl has it
            log.exception("session %s trial %d: command %d's tick not stored", *key)

    async def score(self, request: Request) -> Response:
        """A trial's stored reports scored against its run's ground truth
        (``?trial_index=N``; once its run is over)."""
        s = await run_in_threadpool(self._session, request)
        raw = request.query_params.get("trial_index", "")
        if not raw.isdigit() or not int(raw) < len(s["trial_order"]):
            raise self.bad(f"trial_index: expected 0..{len(s['trial_order']) - 1}, "
                           f"got {raw[:40]!r}")
        score = await run_in_threadpool(self.score_trial, s, int(raw))
        return JSONResponse(score_json(score))

    def score_trial(self, s: dict[str, Any], ti: int) -> SessionScore:
        """Trial ``ti`` of session ``s``: its reports scored (``live_scoring``)
        against the ground truth of its run's feeds, with the study's
        ``scoring:`` settings."""
        live = self.runs.get(s["id"])
        if live is not None and live[0] == ti and live[1].running:
            raise self.bad(f"trial {ti} is still running: it is scored once its run is over",
                           409)
        folder = self._folder(s["id"], ti)
        if not (folder / "summary.json").is_file():
            raise self.bad(f"trial {ti} of this session has not run (no {folder})", 409)
        self.condition(s["trial_order"][ti])  # refused (409) if gone or changed
        try:
            return score_trial(self.study, s, ti, self.store.live_reports(s["id"]),
                               self.runs_dir)
        except ConfigError as e:  # ReportError too
            raise self.bad(f"trial {ti}: " + "; ".join(e.problems)[:2000], 409) from None

    async def clock(self, request: Request) -> Response:
        """This server's clock (ms since 1970), for the page's estimate of the
        offset between its clock and the server's."""
        return JSONResponse({"server_ms": time.time() * 1000.0})

    async def timing(self, request: Request, body: dict[str, Any]) -> Response:
        """The page's timing of the running trial: frames received and drawn,
        and the glass-to-glass latency (from the run making a frame to the page
        drawing it) of the frames drawn; kept with the run (its status and
        ``page_timing.json`` in its folder)."""
        s = await run_in_threadpool(self._session, request)
        ti, run = self._live(s["id"])
        if body.get("trial_index") != ti:
            raise self.bad(f"trial_index: the live trial of this session is {ti}, got "
                           f"{body.get('trial_index')!r}"[:200], 409)
        out: dict[str, Any] = {"trial_index": ti}
        for key in TIMING_COUNTS:
            v = self.number(body, key)
            if not (v == int(v) and 0 <= v <= MAX_FRAMES):
                raise self.bad(f"{key}: expected a whole number 0..{MAX_FRAMES}, got {v:g}")
            out[key] = int(v)
        for key in TIMING_MS:
            v = self.number(body, key, optional=True)
            if v is not None and not -MAX_LATENCY_MS <= v <= MAX_LATENCY_MS:
                raise self.bad(f"{key}: expected -{MAX_LATENCY_MS:.0f}..{MAX_LATENCY_MS:.0f} ms, "
                               f"got {v:g}")
            out[key] = v
        run.page_timing = out
        if run.out_dir.is_dir():  # not yet while the run is being built: the page's
            # next report (every 2 s, and one at the end) writes it
            await run_in_threadpool(write_json_atomic, run.out_dir / "page_timing.json", out)
        return JSONResponse(out)

    def close(self) -> None:
        """Stop every run and wait for each to end (the server is going)."""
        for _, run in self.runs.values():
            run.stop("server shut down")
        for _, run in self.runs.values():
            if not run.wait(STOP_WAIT_S):
                log.error("live run %s did not stop within %g s", run.out_dir, STOP_WAIT_S)

    def stop_session(self, sid: str) -> None:
        """The session ends (paused, finished): its run stops."""
        live = self.runs.get(sid)
        if live is not None and live[1].running:
            live[1].stop("session ended")


def timing_flags(limits: TimingLimits, status: dict[str, Any]) -> list[str]:
    """What is wrong with a live run's timing (``LiveRun.status``) by the
    study's limits: its page's median glass-to-glass latency, and its frames
    lost (dropped for a page that did not keep up, or received and skipped
    by it) as a share of the frames sent."""
    out = []
    page = status.get("page_timing") or {}
    p50 = page.get("latency_ms_p50")
    if limits.latency_ms_p50 is not None and p50 is not None and p50 > limits.latency_ms_p50:
        out.append(f"median glass-to-glass latency {p50:.0f} ms, over the study's "
                   f"{limits.latency_ms_p50:g} ms")
    sent = status.get("frames_published") or 0
    if limits.dropped_percent is not None and sent:
        dropped = status.get("frames_dropped") or 0
        skipped = max(0, page.get("frames_received", 0) - page.get("frames_drawn", 0))
        lost = 100.0 * (dropped + skipped) / sent
        if lost > limits.dropped_percent:
            out.append(f"{lost:.1f} % of frames lost ({dropped} dropped for the page, "
                       f"{skipped} skipped by it, of {sent}), over the study's "
                       f"{limits.dropped_percent:g} %")
    return out


def score_json(score: SessionScore) -> dict[str, Any]:
    """A trial's score as the experimenter's API gives it."""
    return {
        "hits": score.count("hit"), "duplicates": score.count("duplicate"),
        "false_alarms": score.count("false_alarm"), "misses": len(score.misses),
        "reports": [{"feed": r.report.feed, "frame": r.report.frame, "x_px": r.report.x_px,
                     "y_px": r.report.y_px, "time_s": r.report.time_s, "outcome": r.outcome,
                     "target": r.target, "error_px": r.error_px,
                     "latency_feed_s": r.latency_feed_s, "latency_any_s": r.latency_any_s}
                    for r in score.reports],
        "targets": [{"target": t.target, "detected": t.detected, "eligible": t.eligible,
                     "visible_s": t.visible_s, "first_visible_s": t.first_visible_s,
                     "latency_feed_s": t.latency_feed_s, "latency_any_s": t.latency_any_s,
                     "error_px": t.error_px} for t in score.targets]}


def routes(console: LiveConsole, json_body: Any, experimenter: Any, page: Any) -> list[Route]:
    """The live console's routes; ``json_body``, ``experimenter`` and ``page``
    are the app's (a checked JSON body, the loopback-only guard, a static page)."""
    def with_body(fn: Any) -> Any:
        async def handler(request: Request) -> Response:
            out: Response = await fn(request, await json_body(request))
            return out
        return handler

    base = "/api/sessions/{sid}/live"
    return [
        Route("/live", page("live.html")),
        Route(base, console.status, methods=["GET"]),
        Route(f"{base}/start", experimenter(with_body(console.start)), methods=["POST"]),
        Route(f"{base}/stop", experimenter(with_body(console.stop)), methods=["POST"]),
        Route(f"{base}/stream", console.stream, methods=["GET"]),
        Route(f"{base}/reports", with_body(console.report), methods=["POST"]),
        Route(f"{base}/command", with_body(console.command), methods=["POST"]),
        Route(f"{base}/score", experimenter(console.score), methods=["GET"]),
        Route(f"{base}/clock", console.clock, methods=["GET"]),
        Route(f"{base}/timing", with_body(console.timing), methods=["POST"]),
    ]
