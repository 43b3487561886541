"""The trial server's HTTP bounds (cosim/trials/limits.py), live: the body's
nesting, the request head's size, slow and idle clients and the connections
from one address, with raw sockets on an ephemeral loopback port."""

from __future__ import annotations

import re
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_server import PROFILE, LiveServer, _session, live_server, small_study


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study of one clip."""
    return small_study(tmp_path_factory.mktemp("limits"), "protocol: disappear\n", {"a": 150.0})


@pytest.fixture(scope="module")
def server(study_file: Path) -> Iterator[LiveServer]:
    """The study served with ``cosim trials serve``'s bounds."""
    with live_server(study_file) as s:
        yield s


def test_a_request_head_over_16_kib_is_refused(server: LiveServer) -> None:
    status, body = server.request("GET", "/api/study", headers={"X-Big": "a" * 20000})
    assert status == 431 and re.fullmatch(r"request head of 20\d\d\d bytes; at most 16384",
                                          body["error"]), body
    assert server.request("GET", "/api/study", headers={"X-Small": "a" * 1000})[0] == 200


def test_deeply_nested_json_is_refused(server: LiveServer) -> None:
    """A body of 8000 '[' (16 KB) is a clear 400, not a RecursionError (500);
    brackets inside strings are not nesting, and the API's flat objects pass."""
    status, body = server.request("POST", "/api/sessions", b"[" * 8000)
    assert status == 400, body
    assert body["error"] == ("request body: JSON nested deeper than 8 levels; expected a flat "
                             "JSON object")
    for nested, error in ((8, "participant: a pseudonym"), (9, "nested deeper than 8 levels")):
        deep = b'{"participant": ' + b"[" * (nested - 1) + b"]" * (nested - 1) + b"}"
        status, body = server.request("POST", "/api/sessions", deep)
        assert status == 400 and error in body["error"], (nested, body)
    status, body = server.request("POST", "/api/sessions", {"participant": "[" * 5000, **PROFILE})
    assert status == 400 and body["error"].startswith("participant: a pseudonym")
    assert _session(server, "p-flat")["participant"] == "p-flat"


def _read_response(s: socket.socket) -> bytes:
    """One whole HTTP response (with a Content-Length) from ``s``."""
    data = b""
    while b"\r\n\r\n" not in data:
        data += s.recv(65536)
    head, _, body = data.partition(b"\r\n\r\n")
    length = int(next(h.split(b":")[1] for h in head.split(b"\r\n")
                      if h.lower().startswith(b"content-length:")))
    while len(body) < length:
        body += s.recv(65536)
    return head


def test_slow_clients_are_disconnected_and_others_served_meanwhile(study_file: Path) -> None:
    """Clients that send half a request head, one byte of a 100-byte body or
    nothing at all are disconnected when the request deadline passes (2 s
    here, from each one's connection), an idle kept-alive connection when its
    time is up (2 s); one address's connections beyond 32 are closed as they
    open; a normal client is served while the others hang on. Every time is
    measured from the socket's own opening, so a slow machine setting up the
    80 connections does not move the bounds."""
    import selectors

    timeout_s, margin_s = 2.0, 1.5
    sends = {"half a head": b"GET /api/study HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: a",
             "a byte of the body": b"POST /api/sessions HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                   b"Content-Type: application/json\r\n"
                                   b"Content-Length: 100\r\n\r\n{",
             "nothing": b""}
    with live_server(study_file, request_timeout_s=timeout_s, keep_alive_s=2) as server:
        addr = (server.host, int(server.port))
        slow: dict[socket.socket, tuple[str, float]] = {}  # name, opened at
        for _ in range(10):  # 30 from 127.0.0.3
            for name, data in sends.items():
                opened = time.monotonic()
                s = socket.create_connection(addr, source_address=("127.0.0.3", 0))
                s.sendall(data)
                slow[s] = (name, opened)
        for k in range(40):  # 40 from 127.0.0.4: 32 are let in
            opened = time.monotonic()
            s = socket.create_connection(addr, source_address=("127.0.0.4", 0))
            s.sendall(sends["half a head"])
            slow[s] = ("from one address, in" if k < 32 else "from one address, over 32",
                       opened)
        idle = socket.create_connection(addr)
        idle.sendall(b"GET /api/study HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert _read_response(idle).startswith(b"HTTP/1.1 200")
        slow[idle] = ("kept alive, idle", time.monotonic())
        status, _ = server.request("GET", "/api/study")
        served = time.monotonic()
        assert status == 200
        # served while every slow client let in was still within its deadline
        # (a server blocked by them would answer only after dropping them)
        first_deadline = min(opened for name, opened in slow.values()
                             if name != "from one address, over 32") + timeout_s
        assert served < first_deadline, (served, first_deadline)
        closed: dict[str, list[float]] = {}
        sel = selectors.DefaultSelector()
        for s in slow:
            sel.register(s, selectors.EVENT_READ)
        try:
            while len(sel.get_map()) and time.monotonic() - served < timeout_s + 5:
                for key, _ in sel.select(timeout=0.1):
                    s = key.fileobj
                    assert isinstance(s, socket.socket)
                    try:
                        got = s.recv(65536)
                    except ConnectionResetError:
                        got = b""
                    if got == b"":  # disconnected by the server
                        name, opened = slow[s]
                        closed.setdefault(name, []).append(time.monotonic() - opened)
                        sel.unregister(s)
        finally:
            sel.close()
            for s in slow:
                s.close()
    counts = {k: len(v) for k, v in closed.items()}
    assert counts == {**{k: 10 for k in sends}, "from one address, in": 32,
                      "from one address, over 32": 8, "kept alive, idle": 1}, closed
    assert max(closed.pop("from one address, over 32")) < timeout_s / 2
    for name, after_s in closed.items():
        assert 0.8 * timeout_s < min(after_s) and max(after_s) < timeout_s + margin_s, (
            name, after_s)
