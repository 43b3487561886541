"""The instruments' routes of the trial web app: NASA-TLX and SAGAT answers.

Owns the HTTP side of ``instruments`` and ``sagat``:

- ``GET /api/sessions/{sid}/instrument``: the instrument the participant's
  page asks now: ``{"instrument": "tlx", "block", "scales", "pairs", ...}``
  when a block's trials all have their response and its TLX is not stored,
  else ``{"instrument": null}``.
- ``GET /api/sessions/{sid}/sagat/{probe}``: a probe's questions (for the
  live console's page to ask at the probe's time; never the answers).
- ``GET /api/sessions/{sid}/live/freeze``: ``{"freeze": ...}``, what the
  live console's page asks now: the probe its trial's run is frozen at
  (``live_freeze.Freezes.current``: its questions, the aircraft, the blank
  map's extent), or null.
- ``POST /api/sessions/{sid}/instruments``: an answer, ``{"instrument":
  "tlx", "block", "ratings", "pairs"}`` or ``{"instrument": "sagat",
  "trial_index", "probe", "answers"}``, checked (``instruments``) and stored
  once (posting it again returns the stored row: 200, not 201). A SAGAT
  answer is scored at once when ``Instruments.freeze_state`` (set by the
  live console, which knows the run) gives the true state at that freeze;
  otherwise it is stored unscored (``Store.score_instrument`` keeps scores
  made later, e.g. from the run's state log through
  ``sagat.from_state_log``). With the live console's ``freezes``, a live
  session's SAGAT answer must be to a probe its trial was frozen for (409
  otherwise), and posting it lets the frozen run go on.

A block's trials count as done when the session's view (``server``'s
``_view``) marks them ``answered``: a clip trial with its response; a live
trial once it has run (its run folder made) and is not running.

Requests go through the app's own bounds (same origin, JSON, size and
nesting: ``server``'s ``_json_body``, handed in, as are its session lookup
and its error class, so this module does not import the server).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from cosim.trials.instruments import (
    AnswerError,
    pending_tlx,
    sagat_page,
    sagat_row,
    score_probe,
    tlx_row,
)
from cosim.trials.live_freeze import Freezes
from cosim.trials.sagat import FreezeState, Probe, ScoringError
from cosim.trials.store import Store

log = logging.getLogger(__name__)

#: (session, trial index, probe) -> the true state at that freeze, or None if not known
FreezeSource = Callable[[dict[str, Any], int, Probe], FreezeState | None]


class Instruments:
    """The routes above for one app: the study, the store and the server's
    helpers they need (``session_of(sid)``, ``view_of(session)``,
    ``json_body(request)``, ``bad_request(message, status)``)."""

    def __init__(self, study: Any, store: Store, session_of: Callable[[str], dict[str, Any]],
                 view_of: Callable[[dict[str, Any]], dict[str, Any]],
                 json_body: Callable[[Request], Any], bad_request: type[Exception]) -> None:
        self.study, self.store = study, store
        self._session_of, self._view_of = session_of, view_of
        self._json_body, self._bad = json_body, bad_request
        #: the live console's source of the true state at a freeze (None: scored later)
        self.freeze_state: FreezeSource | None = None
        #: the live console's freeze probes (None: no live console)
        self.freezes: Freezes | None = None

    def follow_live(self, console: Any) -> None:
        """Freeze the live console's trials at the study's SAGAT probes
        (``live_freeze``): each run gets its probes as it starts
        (``console.on_start``) and the answers are scored from its freezes."""
        if getattr(self.study, "protocol", None) != "live" or not self.study.sagat:
            return
        self.freezes = Freezes(self.study, self.store)
        self.freeze_state = self.freezes.freeze_state
        console.on_start.append(self.freezes.attach)

    def routes(self) -> list[Route]:
        return [Route("/api/sessions/{sid}/instrument", self.pending, methods=["GET"]),
                Route("/api/sessions/{sid}/sagat/{probe:int}", self.probe, methods=["GET"]),
                Route("/api/sessions/{sid}/instruments", self.post, methods=["POST"]),
                Route("/api/sessions/{sid}/live/freeze", self.freeze, methods=["GET"])]

    def _answered(self, s: dict[str, Any]) -> set[int]:
        """The session's trials with their response (as its page's view says);
        a live trial once it has run and is not running."""
        view = self._view_of(s)
        live = view.get("live") or {}
        running = live.get("trial_index") if live.get("running") else None
        return {int(t["index"]) for t in view["trials"]
                if t.get("answered") or (t.get("ran") and t["index"] != running)}

    def _pending(self, sid: str) -> dict[str, Any]:
        s = self._session_of(sid)
        stored = {r["item"] for r in self.store.instrument_answers(s["id"], "tlx")}
        return pending_tlx(self.study, s, self._answered(s), stored) or {"instrument": None}

    async def pending(self, request: Request) -> Response:
        sid = request.path_params["sid"]
        return JSONResponse(await run_in_threadpool(self._pending, sid))

    async def probe(self, request: Request) -> Response:
        await run_in_threadpool(self._session_of, request.path_params["sid"])
        try:
            return JSONResponse(sagat_page(self.study, request.path_params["probe"]))
        except AnswerError as e:
            raise self._bad(str(e), 404) from None

    async def freeze(self, request: Request) -> Response:
        s = await run_in_threadpool(self._session_of, request.path_params["sid"])
        now = self.freezes.current(s["id"]) if self.freezes is not None else None
        return JSONResponse({"freeze": now}, headers={"Cache-Control": "no-store"})

    def _store(self, sid: str, body: dict[str, Any]) -> tuple[dict[str, Any], bool]:
        s = self._session_of(sid)
        kind = body.get("instrument")
        try:
            if kind == "tlx":
                row = tlx_row(self.study, s, body, self._answered(s))
            elif kind == "sagat":
                row = sagat_row(self.study, s, body)
            else:
                raise AnswerError(f"instrument: expected 'tlx' or 'sagat', got {kind!r}"[:200])
        except AnswerError as e:
            raise self._bad(str(e), 400) from None
        freezes = self.freezes if kind == "sagat" and s.get("protocol") == "live" else None
        if freezes is not None and not freezes.asked(s["id"], row["trial_index"], row["item"]):
            raise self._bad(f"probe {row['item']}: trial {row['trial_index']} of this session "
                            f"has not been frozen for it", 409)
        stored, created = self.store.record_instrument(row)
        if freezes is not None:  # the frozen run goes on
            freezes.answered(s["id"], row["trial_index"], row["item"])
        if kind == "sagat" and created and self.freeze_state is not None:
            probe = self.study.sagat[row["item"]]
            state = self.freeze_state(s, row["trial_index"], probe)
            if state is not None:
                try:
                    self.store.score_instrument(stored["id"],
                                                score_probe(probe, state, row["answer"]))
                except ScoringError as e:
                    log.warning("session %s trial %d probe %d: not scored: %s", s["id"],
                                row["trial_index"], row["item"], e)
                (stored,) = [r for r in self.store.instrument_answers(s["id"], "sagat")
                             if r["id"] == stored["id"]]
        if not created:
            log.info("session %s: %s answer %d posted again; kept the first", s["id"], kind,
                     row["item"])
        return stored, created

    async def post(self, request: Request) -> Response:
        body = await self._json_body(request)
        stored, created = await run_in_threadpool(self._store, request.path_params["sid"],
                                                  body)
        return JSONResponse({"answer": stored, "created": created},
                            status_code=201 if created else 200)
