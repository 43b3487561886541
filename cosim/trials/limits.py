"""The bounds of the trial server's HTTP (``cosim trials serve``).

Owns what one client may ask of the server: the size and nesting of a
request body, how long a request may take to arrive, how long an idle
connection stays open and how many connections are served at once; and the
uvicorn settings that apply them (``uvicorn_settings``). It does not
route, parse or answer requests (``server``).

Every request must arrive whole (its head and its body) within
``REQUEST_TIMEOUT_S`` of the connection opening or of the previous response
on it: a client still sending then (a slow or stalled one, one byte at a
time or nothing at all) is disconnected. A kept-alive connection that sends
nothing for ``KEEP_ALIVE_S`` is closed. A connection from an address that
already has ``MAX_CONNECTIONS_PER_CLIENT`` open is closed as it opens (one
machine's flood of stalled connections leaves the others served); beyond
``MAX_CONNECTIONS`` open connections in all, a request is answered 503
(Service Unavailable). A request head over ``MAX_HEAD_BYTES`` is refused
(``HeadLimit``) and the connection closed. The clock stops once a request has
arrived: a slow answer, or a long video sent to a browser that reads it as
it plays, is never cut off.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
from collections import Counter
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

log = logging.getLogger(__name__)

#: bytes of a request body (the API's bodies are flat JSON objects of a few hundred)
MAX_BODY_BYTES = 16 * 1024
#: nesting of a request body's JSON arrays and objects (the API's are 1 deep)
MAX_JSON_DEPTH = 8
#: bytes of a request's head: its request line and headers
MAX_HEAD_BYTES = 16 * 1024
#: seconds for a whole request (head and body) to arrive
REQUEST_TIMEOUT_S = 10.0
#: seconds an idle kept-alive connection stays open (whole seconds: uvicorn's)
KEEP_ALIVE_S = 5
#: open connections served at once (a lab's participant pages and videos need tens)
MAX_CONNECTIONS = 200
#: open connections from one address (a browser opens at most 6 to one server)
MAX_CONNECTIONS_PER_CLIENT = 32

_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)
_JSON_BRACKET = re.compile(rb"[\[\]{}]")


def json_depth(body: bytes, limit: int = MAX_JSON_DEPTH) -> int:
    """How deep the arrays and objects of the JSON text ``body`` nest
    (brackets inside strings not counted), counted up to ``limit + 1``: found
    without parsing, so that a deep text is refused before ``json.loads``
    recurses into it."""
    depth = deepest = 0
    for m in _JSON_BRACKET.finditer(_JSON_STRING.sub(b'""', body)):
        depth += 1 if m.group() in (b"[", b"{") else -1
        if depth > deepest:
            deepest = depth
            if deepest > limit:
                break
    return deepest


class BoundedProtocol(H11Protocol):
    """uvicorn's HTTP/1.1 protocol (h11) with a deadline for each request to
    arrive (``request_timeout_s``, from the connection's opening or the
    previous response's end; a client still sending its request then is
    disconnected) and at most ``max_per_client`` connections from one address
    (one more is closed as it opens). See the module docstring."""

    request_timeout_s: float = REQUEST_TIMEOUT_S
    max_per_client: int = MAX_CONNECTIONS_PER_CLIENT
    #: open connections by client address, of one server (``uvicorn_settings``)
    per_client: Counter[str] = Counter()
    _deadline: asyncio.TimerHandle | None = None
    _counted: str | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        host = self.client[0] if self.client else None
        if host is not None:
            self._counted = host
            self.per_client[host] += 1
            if self.per_client[host] > self.max_per_client:
                log.debug("%s: over %d connections from one address: closed", host,
                          self.max_per_client)
                transport.close()
                return
        self._arm()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        if self._counted is not None:
            self.per_client[self._counted] -= 1
            if self.per_client[self._counted] <= 0:
                del self.per_client[self._counted]
            self._counted = None
        super().connection_lost(exc)

    def _arm(self) -> None:
        self._disarm()
        if not self.transport.is_closing():
            self._deadline = self.loop.call_later(self.request_timeout_s, self._expired)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _expired(self) -> None:
        self._deadline = None
        # IDLE: no whole request head yet; SEND_BODY: its body still coming
        if self.conn.their_state in (h11.IDLE, h11.SEND_BODY) and \
                not self.transport.is_closing():
            log.debug("%s: no whole request within %g s: disconnected",
                      self.client, self.request_timeout_s)
            self.transport.close()


class HeadLimit:
    """ASGI middleware: a request whose head (target and headers) is over
    ``MAX_HEAD_BYTES`` is answered 431 and its connection closed. (uvicorn's
    h11 refuses a head that grows past it while it arrives; one that arrives
    whole in one read is counted here.)"""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http":
            size = len(scope.get("raw_path", b"")) + len(scope.get("query_string", b"")) + sum(
                len(k) + len(v) + 4 for k, v in scope.get("headers", ()))
            if size > MAX_HEAD_BYTES:
                body = json.dumps({"error": f"request head of {size} bytes; at most "
                                            f"{MAX_HEAD_BYTES}"}).encode()
                await send({"type": "http.response.start", "status": 431,
                            "headers": [(b"content-type", b"application/json"),
                                        (b"content-length", str(len(body)).encode()),
                                        (b"connection", b"close")]})
                await send({"type": "http.response.body", "body": body})
                return
        await self.app(scope, receive, send)


def uvicorn_settings(*, request_timeout_s: float = REQUEST_TIMEOUT_S,
                     keep_alive_s: int = KEEP_ALIVE_S, max_connections: int = MAX_CONNECTIONS,
                     max_per_client: int = MAX_CONNECTIONS_PER_CLIENT) -> dict[str, Any]:
    """The keyword arguments of ``uvicorn.run`` or ``uvicorn.Config`` that apply
    the bounds above (the others, e.g. ``host`` and ``port``, are the caller's).
    Each call makes a protocol class of its own: one server's count of
    connections per address."""
    protocol = type("BoundedProtocol", (BoundedProtocol,),
                    {"request_timeout_s": float(request_timeout_s),
                     "max_per_client": int(max_per_client), "per_client": Counter()})
    return {"http": protocol, "ws": "none", "timeout_keep_alive": keep_alive_s,
            "limit_concurrency": max_connections,
            "h11_max_incomplete_event_size": MAX_HEAD_BYTES}
