"""The web app of a conspicuity trial (``cosim trials serve STUDY.yaml``).

Owns HTTP: the experimenter page (``/``: create a session with a
pseudonymous participant id and a display profile, start and pause it, watch
its progress), the participant page (``/participant?session=ID``: the
session's clips full screen in order; ``static/participant.js``), the JSON
API both use, the clips' videos (``/video/N``: only the files the study
resolved inside its folders, by number; nothing a request names is ever
opened) and a picture of each target (``/target/N``, cut from a clip by
``target_picture``) that the participant's page shows. It does not parse
the study (``study``), store (``store``) or compute measures
(``measures``): the browser posts which key it saw and the ``mediaTime`` of
the frame on screen at that moment; the server turns that
into the frame number (``round(mediaTime * rate_hz)``) and computes every
measure from the stored ground truth and the session's display profile.

A study with ``protocol: live`` is served by the same app: its sessions'
trials are runs of scenarios, started by the experimenter and watched on
``/live`` (routes, runs and reports: ``live_routes``).

The participant's page reports its size (device px) when it loads, when it
is resized and with every response; the server keeps the last one per
session (in the database: it survives a restart of the server) and the
experimenter's page warns next to a session whose page is not the size of
its display profile. The participant sees no such warning.

A session records each trial's clip id and fingerprint (``study``); a
session whose clip is gone from the study, or whose ground truth or video
changed since, is refused (409, naming the clip and what changed) rather
than measured against another clip. A session made before clip ids were
recorded is read by clip number; one with ids but no fingerprints, by id.

A local app: it binds 127.0.0.1 (or another loopback address it is given)
unless told ``public=True``, and refuses requests whose ``Host`` is not this
machine's or the address bound (a web page elsewhere cannot drive it through
the browser: DNS rebinding). Request bodies are bounded in size and nesting,
requests in the time they take to arrive, connections in number (``limits``).
The frequent database calls (a participant's page fetching its session, a
response stored) run in the thread pool, off the event loop.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import re
import socket
import stat
import threading
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any, Literal

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import ClientDisconnect, Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from cosim.core.display import DisplayProfile
from cosim.core.netaddr import is_loopback
from cosim.errors import ConfigError
from cosim.trials.files import file_kind
from cosim.trials.instrument_routes import Instruments
from cosim.trials.limits import (
    MAX_BODY_BYTES,
    MAX_JSON_DEPTH,
    HeadLimit,
    json_depth,
    uvicorn_settings,
)
from cosim.trials.live_routes import LiveConsole, live_order
from cosim.trials.live_routes import routes as live_routes
from cosim.trials.measures import measures_at, participant_display, track_measures
from cosim.trials.store import Store, shown_url, write_csv
from cosim.trials.study import TRACK_DIRECTIONS, Clip, Study, load_study
from cosim.trials.target_picture import choose_still, target_png

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
PARTICIPANT_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
KEY_NAME = re.compile(r"^[A-Za-z0-9_ ]{1,32}$")
LOCAL_HOSTS = ["127.0.0.1", "localhost", "[::1]", "::1"]
#: a reaction time beyond this (10 minutes) is not one
MAX_REACTION_MS = 600_000.0
#: the page's size the browser may report (device px, each side)
WINDOW_PX = (16, 16384)
#: the condition names the export has columns of (the rest stay in ``conditions``)
CONDITION_COLUMNS = ("speed_kt", "alt_agl_m", "target")
DISPLAY_FIELDS = ("screen_width_px", "screen_height_px", "screen_width_mm", "screen_height_mm",
                  "viewing_distance_mm")
#: the measures (``cosim.trials.measures.Measures``) stored with a response
MEASURE_FIELDS = ("frame", "target_in_view", "eccentricity_deg", "onscreen_distance_mm",
                  "target_angular_size_deg", "camera_gap_deg", "target_depth_m")


class BadRequest(Exception):
    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message, status)
        self.message, self.status = message, status


def _same_origin(request: Request) -> None:
    """A state-changing request must be JSON (which a page elsewhere cannot
    send without asking first) and, when the browser says where it comes
    from, come from this server's own pages."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype != "application/json":
        raise BadRequest("expected Content-Type: application/json", 415)
    origin = request.headers.get("origin")
    if origin is not None and origin.split("://", 1)[-1] != request.headers.get("host", ""):
        raise BadRequest("refused: a request from another site's page", 403)


def _experimenter(fn: Any) -> Any:
    """The experimenter's routes (sessions, their states, the export) answer
    this machine only, also when the server is ``--public`` for the
    participants' screens."""
    async def guarded(request: Request) -> Response:
        client = request.client.host if request.client is not None else ""
        if not is_loopback(client):
            raise BadRequest("the experimenter's pages answer this machine only", 403)
        out: Response = await fn(request)
        return out
    return guarded


async def _json_body(request: Request) -> dict[str, Any]:
    _same_origin(request)
    body = b""
    try:
        async for chunk in request.stream():
            body += chunk
            if len(body) > MAX_BODY_BYTES:
                raise BadRequest(f"request body over {MAX_BODY_BYTES} bytes", 413)
    except ClientDisconnect:  # gone (or cut off for sending too slowly): no one to answer
        raise BadRequest("the client disconnected before its request body arrived") from None
    if json_depth(body) > MAX_JSON_DEPTH:
        raise BadRequest(f"request body: JSON nested deeper than {MAX_JSON_DEPTH} levels; "
                         f"expected a flat JSON object")
    try:
        data = json.loads(body or b"{}")
    except ValueError as e:
        raise BadRequest(f"not JSON: {e}") from None
    if not isinstance(data, dict):
        raise BadRequest("expected a JSON object")
    return data


def _number(d: dict[str, Any], key: str, *, optional: bool = False) -> float | None:
    v = d.get(key)
    if v is None and optional:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise BadRequest(f"{key}: expected a number, got {v!r}"[:200])
    return float(v)


def _flag(d: dict[str, Any], key: str) -> bool | None:
    """A JSON boolean, or None if absent (or null)."""
    v = d.get(key)
    if v is not None and not isinstance(v, bool):
        raise BadRequest(f"{key}: expected true, false or null, got {v!r}"[:200])
    return v


def _window_px(d: dict[str, Any]) -> tuple[int, int] | None:
    """The page's size (device px) a request reports, None if it does not say."""
    w = _number(d, "window_width_px", optional=True)
    h = _number(d, "window_height_px", optional=True)
    if w is None or h is None:
        return None
    lo, hi = WINDOW_PX
    if not (w == int(w) and h == int(h) and lo <= w <= hi and lo <= h <= hi):
        raise BadRequest(f"window_width_px/window_height_px: whole numbers {lo}..{hi}, got "
                         f"{w:g} x {h:g}"[:200])
    return int(w), int(h)


class TrialApp:
    """The study and the store behind the routes (one per app)."""

    def __init__(self, study: Study, store: Store) -> None:
        self.study, self.store = study, store
        self._by_id = {c.id: n for n, c in enumerate(study.all_clips)}
        #: the study's targets, numbered for ``/target/N`` (their pictures)
        self.targets = sorted({c.target for c in study.all_clips})
        self._pictures: dict[int, bytes] = {}
        #: ``protocol: live``: the sessions' runs (``live_routes``)
        self.live = LiveConsole(study, store, BadRequest, _number)

    # --- helpers ---
    def _session(self, sid: str) -> dict[str, Any]:
        s = self.store.session(sid) if len(sid) <= 32 else None
        if s is None:
            raise BadRequest(f"no session {sid[:40]!r}", 404)
        return s

    def _clip(self, t: dict[str, Any]) -> tuple[int, Clip]:
        """A session trial's clip (its number in ``Study.all_clips``, the clip):
        by the clip id and fingerprint the session recorded; refused (409) if
        the clip is gone or changed. A session from before clip ids: by number."""
        clips, where = self.study.all_clips, f"the study {self.study.path}"
        cid = t.get("clip_id")
        if cid is None:
            n = t.get("clip")
            if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n < len(clips):
                raise BadRequest(f"trial {t.get('index')} of this session shows clip number "
                                 f"{n!r}, which {where} no longer has", 409)
            return n, clips[n]
        n = self._by_id.get(cid, -1) if isinstance(cid, str) else -1
        if n < 0:
            raise BadRequest(f"clip {str(cid)[:200]!r} of this session is no longer in {where}: "
                             f"restore it, or start a new session", 409)
        c, was = clips[n], t.get("fingerprint")
        if was is not None and was != c.fingerprint:
            old = was if isinstance(was, dict) else {}
            changed = []
            if old.get("ground_truth_sha256") != c.gt_sha256:
                changed.append(f"its ground truth {c.ground_truth} is not the file it was")
            if old.get("video_bytes") != c.video_bytes:
                changed.append(f"its video {c.video} is {c.video_bytes} bytes, not "
                               f"{old.get('video_bytes')!r}")
            raise BadRequest(f"clip {c.id!r} of this session changed since the session was "
                             f"created ({'; '.join(changed) or 'its fingerprint differs'}): "
                             f"restore the files, or start a new session", 409)
        return n, c

    def _view(self, s: dict[str, Any]) -> dict[str, Any]:
        if s["protocol"] == "live":
            return self.live.view(s)
        done: dict[int, list[str]] = {}
        for r in self.store.responses(s["id"]):
            done.setdefault(r["trial_index"], []).append(r["kind"])
        need = len(TRACK_DIRECTIONS) if s["protocol"] == "track" else 1
        answered = {i for i, ks in done.items() if len(ks) >= need}
        trials = []
        for t in s["trial_order"]:
            n, c = self._clip(t)
            view = {**t, "clip": n, "video": f"/video/{n}", "rate_hz": c.rate_hz,
                    "frames": len(c.frames), "answered": t["index"] in answered,
                    "done": sorted(done.get(t["index"], [])), "target": c.target,
                    "target_picture": f"/target/{self.targets.index(c.target)}"}
            if s["protocol"] == "track":  # the still frame and the target on it
                g = c.frames[c.still_frame]
                view.update(still_time_s=c.still_frame / c.rate_hz,
                            still_center_px=list(g.center_px) if g.center_px else None,
                            width_px=c.width_px, height_px=c.height_px,
                            arrow_speed_deg_s=self.study.arrow_speed_deg_s,
                            directions=_directions(self.study.seed, s["session_number"],
                                                   t["index"]))
            trials.append(view)
        nxt = next((t["index"] for t in trials if not t["answered"]), None)
        if nxt is None and s["state"] != "finished":
            self.store.set_state(s["id"], "finished")
            s["state"] = "finished"
        display = {k: s[k] for k in DISPLAY_FIELDS}
        return {"id": s["id"], "participant": s["participant"], "protocol": s["protocol"],
                "state": s["state"], "display": display, "trials": trials, "next_trial": nxt,
                "answered": len(answered), "order_method": s["order_method"],
                "seed": s["seed"], "session_number": s["session_number"]}

    # --- routes ---
    async def study_info(self, request: Request) -> Response:
        st = self.study
        return JSONResponse({"name": st.name, "protocol": st.protocol, "clips": len(st.clips),
                             "practice": st.practice, "practice_clips": len(st.practice_clips),
                             "break_every": st.break_every, "conditions": len(st.live),
                             "repeats": st.repeats, "order": st.order, "seed": st.seed})

    async def list_sessions(self, request: Request) -> Response:
        """Every session, with the size its participant's page last reported
        and a warning if that is not its display profile's."""
        out = self.store.sessions()
        for s in out:
            w, h = s.pop("window_width_px", None), s.pop("window_height_px", None)
            px = (w, h) if w is not None and h is not None else None
            s["window_px"] = list(px) if px else None
            s["window_warning"] = None
            if px and px != (s["screen_width_px"], s["screen_height_px"]):
                s["window_warning"] = (f"the participant's page is {px[0]} x {px[1]} px, not "
                                       f"the profile's {s['screen_width_px']} x "
                                       f"{s['screen_height_px']} (not full screen? another "
                                       f"screen?): measured as drawn")
        return JSONResponse(out)

    async def report_window(self, request: Request) -> Response:
        """The participant's page says its size (device px): kept for the
        experimenter's page."""
        d = await _json_body(request)
        s = await run_in_threadpool(self._session, request.path_params["sid"])
        px = _window_px(d)
        if px is None:
            raise BadRequest("window_width_px, window_height_px: expected the page's size")
        await self._keep_window(s, px)
        return JSONResponse({"window_px": list(px)})

    async def _keep_window(self, s: dict[str, Any], px: tuple[int, int]) -> None:
        """Store the session ``s``'s page size when it differs from the one its
        row holds (the experimenter's warning survives a restart of the server)."""
        if (s["window_width_px"], s["window_height_px"]) != px:
            await run_in_threadpool(self.store.set_window, s["id"], *px)

    async def create_session(self, request: Request) -> Response:
        d = await _json_body(request)
        participant = d.get("participant")
        if not isinstance(participant, str) or not PARTICIPANT_ID.match(participant):
            raise BadRequest("participant: a pseudonym of 1-64 letters, digits, '_', '.', '-' "
                             "(never a name)")
        try:
            fields: dict[str, Any] = {k: _whole(d.get(k)) if k.endswith("_px") else d.get(k)
                                      for k in DISPLAY_FIELDS}
            participant_display(**fields)  # checked; stored as given
        except ConfigError as e:
            raise BadRequest("; ".join(e.problems)) from None
        st = self.study
        number = self.store.session_count(st.name)
        clips = st.all_clips
        order = live_order(st, number) if st.protocol == "live" else [
            {"index": t.index, "practice": t.practice, "clip": t.clip,
             "clip_id": clips[t.clip].id, "fingerprint": clips[t.clip].fingerprint,
             "break_before": t.break_before}
            for t in st.trial_order(number)]
        s = self.store.create_session(
            participant=participant, study=st.name, protocol=st.protocol,
            display={k: float(fields[k]) if k.endswith("_mm") else int(fields[k])
                     for k in DISPLAY_FIELDS},
            order_method=st.order, seed=st.seed, session_number=number, trial_order=order)
        log.info("session %s for participant %s: %d trials", s["id"], participant, len(order))
        return JSONResponse(self._view(s), status_code=201)

    async def get_session(self, request: Request) -> Response:
        sid = request.path_params["sid"]
        return JSONResponse(await run_in_threadpool(lambda: self._view(self._session(sid))))

    async def set_state(self, request: Request) -> Response:
        s = self._session(request.path_params["sid"])
        state = (await _json_body(request)).get("state")
        if state not in ("running", "paused"):
            raise BadRequest("state: expected 'running' or 'paused'")
        if s["state"] != "finished":
            self.store.set_state(s["id"], state)
        if state == "paused":  # a live trial's run ends with it
            self.live.stop_session(s["id"])
        return JSONResponse(self._view(self._session(s["id"])))

    async def post_response(self, request: Request) -> Response:
        s = self._session(request.path_params["sid"])
        d = await _json_body(request)
        if s["protocol"] == "live":
            raise BadRequest(f"session {s['id']} is a live session: its clicks go to "
                             f"/api/sessions/{s['id']}/live/reports", 409)
        ti = d.get("trial_index")
        if isinstance(ti, bool) or not isinstance(ti, int) or not 0 <= ti < len(s["trial_order"]):
            raise BadRequest(f"trial_index: expected 0..{len(s['trial_order']) - 1}, "
                             f"got {ti!r}"[:200])
        kind = d.get("kind", s["protocol"])
        kinds = [f"track-{k}" for k in TRACK_DIRECTIONS] if s["protocol"] == "track" \
            else [s["protocol"]]
        if kind not in kinds:
            raise BadRequest(f"kind: this session's protocol is {s['protocol']}: expected "
                             f"{' or '.join(kinds)}, got {kind!r}"[:200])
        key = d.get("key")
        if not isinstance(key, str) or not KEY_NAME.match(key):
            raise BadRequest("key: expected a key name (letters, digits, '_', ' ')")
        t = s["trial_order"][ti]
        _, clip = self._clip(t)
        media = _number(d, "media_time_s", optional=True)
        rt = _number(d, "reaction_time_ms", optional=True)
        if rt is not None and not 0.0 <= rt <= MAX_REACTION_MS:
            raise BadRequest(f"reaction_time_ms: expected 0..{MAX_REACTION_MS:.0f} ms (from the "
                             f"clip's start to the press), got {rt:g}")
        recognised = _flag(d, "recognised")
        reshown = _flag(d, "reshown")  # shown again after a reload of the page
        if s["protocol"] == "recognise" and recognised is None:
            raise BadRequest("recognised: a recognise trial's answer must say true or false")
        if media is not None and not -1.0 <= media <= len(clip.frames) / clip.rate_hz + 1.0:
            raise BadRequest(f"media_time_s {media} is outside clip {clip.id}")
        profile = {k: s[k] for k in DISPLAY_FIELDS}
        display = participant_display(**profile)
        px = _window_px(d)
        drawn = _drawn_on(display, px)
        if px is not None:
            await self._keep_window(s, px)
        row: dict[str, Any] = {
            "session": s["id"], "participant": s["participant"], "trial_index": ti,
            "kind": kind, "practice": bool(t["practice"]), "protocol": s["protocol"],
            "clip": clip.id, "run": clip.run, "conditions": json.dumps(clip.condition_map),
            "key": key, "reaction_time_ms": rt, "recognised": recognised, "reshown": reshown,
            **{f"condition_{c}": clip.condition_map.get(c) for c in CONDITION_COLUMNS},
            **profile}
        if not row.get("condition_target"):  # a study that does not vary the target
            row["condition_target"] = clip.target
        if s["protocol"] == "track":  # the arrow's way from the target, at the press
            if rt is None:
                raise BadRequest(f"reaction_time_ms: a track sub-trial needs the time from its "
                                 f"start to the press (0..{MAX_REACTION_MS:.0f} ms)")
            m = track_measures(clip, drawn, TRACK_DIRECTIONS[kind.split("-", 1)[1]],
                               self.study.arrow_speed_deg_s, rt)
            row.update({k: getattr(m, k) for k in MEASURE_FIELDS},
                       video_time_s=m.frame / clip.rate_hz)
        elif media is not None:
            m = measures_at(clip, clip.frame_at(media), drawn)
            row.update({k: getattr(m, k) for k in MEASURE_FIELDS}, video_time_s=media)
        stored, created = await run_in_threadpool(self.store.record_response, row)
        if not created:
            log.info("session %s trial %d: response posted again; kept the first",
                     s["id"], ti)
        out = {k: None if isinstance(v, float) and not math.isfinite(v) else v
               for k, v in stored.items()}
        return JSONResponse({"response": out, "created": created},
                            status_code=201 if created else 200)

    async def export(self, request: Request) -> Response:
        buf = io.StringIO()
        write_csv(self.store.responses(), buf)
        return Response(buf.getvalue(), media_type="text/csv",
                        headers={"Content-Disposition": "attachment; filename=responses.csv"})

    async def target_picture(self, request: Request) -> Response:
        """A picture of the study's N-th target, cut from a clip's frame
        (``cosim.trials.target_picture``); made once, on the first request."""
        k = request.path_params["n"]
        if not 0 <= k < len(self.targets):
            raise BadRequest(f"no target {k}", 404)
        if k not in self._pictures:
            self._pictures[k] = await run_in_threadpool(self._picture, self.targets[k])
        return Response(self._pictures[k], media_type="image/png")

    def _picture(self, target: str) -> bytes:
        st = self.study
        still = choose_still(st.clips, st.practice_clips, target)
        if still is None:
            raise BadRequest(f"no picture of target {target[:100]!r}: no frame of its clips "
                             f"has it in view", 404)
        try:
            return target_png(still)
        except ConfigError as e:
            raise BadRequest("; ".join(e.problems), 409) from None

    async def video(self, request: Request) -> Response:
        n, clips = request.path_params["n"], self.study.all_clips
        if not 0 <= n < len(clips):
            raise BadRequest(f"no clip {n}", 404)
        p = clips[n].video
        if not any(p.is_relative_to(r) for r in self.study.roots):  # checked at load; again
            raise BadRequest("not a study file", 403)
        try:  # still the regular file it was at load (a FIFO would hang the reader)
            st = p.stat()
        except OSError:
            raise BadRequest(f"clip {clips[n].id!r}: its video {p} is gone: restore it",
                             409) from None
        if not stat.S_ISREG(st.st_mode):
            raise BadRequest(f"clip {clips[n].id!r}: its video {p} is {file_kind(st.st_mode)}, "
                             f"not a regular file", 409)
        return FileResponse(p, media_type=_video_type(p), stat_result=st)


def _directions(seed: int, session_number: int, trial: int) -> list[str]:
    """A ``track`` trial's sub-trial directions, in an order drawn from the
    study's seed (recorded by being derived: the same session, the same order)."""
    import numpy as np

    names = list(TRACK_DIRECTIONS)
    order = np.random.default_rng([seed, session_number, trial, 0x7AC]).permutation(len(names))
    return [names[i] for i in order]


def _drawn_on(display: DisplayProfile, px: tuple[int, int] | None) -> DisplayProfile:
    """Where the clip was drawn: the page's size (device px) as the browser
    reported it, at the profile's millimetres per pixel, with the fixation
    mark at its centre; the profile's screen if the page did not say (or said
    the same)."""
    if px is None:
        return display
    wi, hi = px
    if (wi, hi) == (display.width_px, display.height_px):
        return display
    mx, my = display.mm_per_px
    log.warning("the participant's page is %d x %d px, not the profile's %d x %d: measured "
                "as drawn", wi, hi, display.width_px, display.height_px)
    try:
        return participant_display(wi, hi, wi * mx, hi * my, display.viewing_distance_mm)
    except ConfigError as e:
        raise BadRequest(f"the page's size {wi} x {hi} px: {e}") from None


def _whole(v: Any) -> Any:
    """A JSON number that is whole (``1920.0``) as an int; anything else unchanged."""
    if isinstance(v, float) and v.is_integer():
        return int(v)
    return v


def _video_type(p: Path) -> str:
    return {".mp4": "video/mp4", ".webm": "video/webm", ".ogv": "video/ogg",
            ".mkv": "video/x-matroska"}.get(p.suffix.lower(), "application/octet-stream")


def _page(name: str) -> Any:
    async def page(request: Request) -> Response:
        return FileResponse(STATIC / name, media_type="text/html",
                            headers={"Cache-Control": "no-store"})
    return page


async def _bad_request(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, BadRequest)
    return JSONResponse({"error": exc.message}, status_code=exc.status)


def make_app(study: Study | str | Path, db: Store | str | Path,
             allowed_hosts: list[str] | None = None) -> Starlette:
    """The app for ``study`` with responses in ``db`` (a Store, a SQLite
    path or a database URL). ``allowed_hosts``: the Host names accepted
    (default: this machine's loopback names)."""
    st = study if isinstance(study, Study) else load_study(study)
    store = db if isinstance(db, Store) else Store(db)
    a = TrialApp(st, store)
    instruments = Instruments(st, store, a._session, a._view, _json_body, BadRequest)
    routes = [
        Route("/", _experimenter(_page("experimenter.html"))),
        Route("/participant", _page("participant.html")),
        Route("/api/study", _experimenter(a.study_info)),
        Route("/api/sessions", _experimenter(a.list_sessions), methods=["GET"]),
        Route("/api/sessions", _experimenter(a.create_session), methods=["POST"]),
        Route("/api/sessions/{sid}", a.get_session),
        *instruments.routes(),
        Route("/api/sessions/{sid}/state", _experimenter(a.set_state), methods=["POST"]),
        Route("/api/sessions/{sid}/responses", a.post_response, methods=["POST"]),
        Route("/api/sessions/{sid}/window", a.report_window, methods=["POST"]),
        Route("/api/export.csv", _experimenter(a.export)),
        *live_routes(a.live, _json_body, _experimenter, _page),
        Route("/video/{n:int}", a.video),
        Route("/target/{n:int}", a.target_picture),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        yield
        await run_in_threadpool(a.live.close)  # the live runs stop with the server

    app = Starlette(routes=routes, exception_handlers={BadRequest: _bad_request},
                    lifespan=lifespan,
                    middleware=[Middleware(HeadLimit),
                                Middleware(TrustedHostMiddleware,
                                           allowed_hosts=allowed_hosts or LOCAL_HOSTS)])
    app.state.trials = a
    instruments.follow_live(a.live)  # a live study's SAGAT probes freeze its runs
    app.state.instruments = instruments
    return app


def local_hosts(host: str) -> list[str]:
    """The ``Host`` names a server bound to loopback address ``host`` answers:
    this machine's usual names and ``host`` itself (IPv6 in brackets, as a
    ``Host`` header writes it)."""
    h = host.strip().lower()
    if ":" in h and not h.startswith("["):
        h = f"[{h}]"
    return LOCAL_HOSTS + ([h] if h not in LOCAL_HOSTS else [])


def default_db(study_path: str | Path) -> Path:
    """Where a study's responses go unless ``--db`` says: ``STUDY.sqlite`` beside
    the study file (``studies/exp2.yaml``: ``studies/exp2.sqlite``; git ignores
    ``*.sqlite``: participants' data stay out of the repository)."""
    return Path(study_path).with_suffix(".sqlite")


@contextlib.contextmanager
def served_in_thread(app: Any, *, lifespan: Literal["auto", "on", "off"] = "off",
                     start_timeout_s: float = 10.0, stop_timeout_s: float = 10.0,
                     **limits: Any) -> Iterator[str]:
    """``app`` served by uvicorn in a thread on 127.0.0.1 at an ephemeral port,
    with ``cosim trials serve``'s bounds (``limits``: other values of
    ``uvicorn_settings``'s); yields its URL. For scripts and tests that drive
    the pages; a ``RuntimeError`` if uvicorn does not start or stop in time."""
    import uvicorn

    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    srv = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan=lifespan,
                                        **uvicorn_settings(**limits)))
    th = threading.Thread(target=srv.run, kwargs={"sockets": [sock]}, daemon=True)
    th.start()
    deadline = time.monotonic() + start_timeout_s
    try:
        while not srv.started:
            if time.monotonic() >= deadline or not th.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        yield f"http://127.0.0.1:{port}"
    finally:
        srv.should_exit = True
        th.join(stop_timeout_s)
        sock.close()
    if th.is_alive():
        raise RuntimeError("uvicorn did not stop")


def serve(study_path: str | Path, host: str = "127.0.0.1", port: int = 8000,
          db_url: str | None = None, public: bool = False) -> None:
    """Run the app until Ctrl-C. ``db_url`` default: ``<study>.sqlite`` beside
    the study file. A host other than a loopback address needs ``public``."""
    import uvicorn

    if not is_loopback(host) and not public:
        raise ConfigError(f"refusing to listen on {host}: participants' responses would be "
                          f"reachable from other machines; pass --public to mean it")
    st = load_study(study_path)
    db = db_url or str(default_db(study_path))
    hosts = ["*"] if public else local_hosts(host)
    app = make_app(st, db, allowed_hosts=hosts)
    what = f"{len(st.live)} live conditions" if st.protocol == "live" else \
        f"{len(st.clips)} clips"
    log.info("study %s: %s; responses in %s; experimenter page http://%s:%d/",
             st.name, what, shown_url(db), host, port)
    uvicorn.run(app, host=host, port=port, log_level="info", **uvicorn_settings())
