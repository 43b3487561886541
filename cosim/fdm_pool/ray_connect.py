"""Joining the Ray cluster the ``ray`` backend runs on, and its live machines.

``address`` (``HOST:PORT`` of a cluster started with ``ray start --head``;
else ``RAY_ADDRESS``; else a local Ray is started for this process and
stopped with it). Joining an address takes at most ``connect_timeout_s``
(default ``CONNECT_TIMEOUT_S``): first a plain TCP connection to it
(nothing listening there is said at once), then ``ray.init``, which Ray
would retry for many minutes in native code, deaf to signals. That runs in
a thread of its own while this one waits, so Ctrl-C and SIGTERM act at once
(and Ray does not replace the process's SIGTERM handler); an attempt given
up on is left to end with the process (or, should it still succeed, is shut
down). A local Ray is started from the calling thread (its processes die
with the thread that starts them), with no timeout. A failure is a
``ClusterUnreachable`` naming the address and what to check. A cluster with
token authentication (``RAY_AUTH_MODE=token``) needs the same token in this
process's environment (``RAY_AUTH_TOKEN`` or ``RAY_AUTH_TOKEN_PATH``), as
every Ray client does.

It owns the joining and Ray's import; it starts no actor and holds no
vehicle (``ray_agent``, ``ray_cluster``).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import signal
import socket
import sys
import threading
import time
from typing import Any

from cosim.errors import ClusterUnreachable, ConfigError, install_extra
from cosim.fdm_pool.process import default_workers

log = logging.getLogger(__name__)

#: a local Ray started by this backend keeps its object store this small (the
#: states and setpoints of an exchange are a few megabytes at most)
_LOCAL_OBJECT_STORE_BYTES = 128 * 1024 * 1024
#: how long joining a cluster may take unless told (``connect``, ``--connect-timeout-s``)
CONNECT_TIMEOUT_S = 30.0
#: a private local Ray's address: on the loopback net (on Linux Ray replaces
#: 127.0.0.1 itself by the machine's routable address, but keeps 127.0.0.2)
LOCAL_NODE_IP = "127.0.0.2" if sys.platform.startswith("linux") else "127.0.0.1"


def import_ray() -> Any:
    """The ``ray`` module; ``ConfigError`` saying how to install it if it is missing."""
    try:
        import ray
    except ImportError:
        raise ConfigError(f"the ray backend needs Ray: {install_extra('ray')}") from None
    return ray


def connect(address: str | None = None, timeout_s: float = CONNECT_TIMEOUT_S) -> str:
    """Join the Ray cluster at ``address`` (else ``RAY_ADDRESS``, else start a
    local one) within ``timeout_s``, unless this process already has; returns
    where it is. ``ClusterUnreachable`` says why not (``ConfigError``: an
    address that is not ``HOST:PORT``)."""
    ray = import_ray()
    if not timeout_s > 0:
        raise ConfigError(f"the connect timeout must be > 0 s, got {timeout_s}")
    if ray.is_initialized():
        here = str(ray.get_runtime_context().gcs_address)
        if address and address.split("://")[-1] != here:
            raise ConfigError(f"this process has already joined the Ray cluster at {here}; "
                              f"it cannot also join {address}")
        return here
    target = address or os.environ.get("RAY_ADDRESS") or None
    kw: dict[str, Any] = {"logging_level": logging.WARNING, "log_to_driver": True,
                          "configure_logging": False}
    if target is None:  # a private local Ray, as many CPUs as this machine has
        kw.update(num_cpus=default_workers(), include_dashboard=False,
                  _node_ip_address=LOCAL_NODE_IP,
                  object_store_memory=_LOCAL_OBJECT_STORE_BYTES)
    ctx = _Joining(ray, target, kw, timeout_s).join()
    log.info("ray backend: joined %s (%s)", target or "a local Ray",
             ctx.address_info.get("gcs_address", "?"))
    return str(ray.get_runtime_context().gcs_address)


def host_port(address: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST:PORT`` (``[IPv6]:PORT``, ``ray://HOST:PORT``);
    ``ConfigError`` otherwise."""
    rest = address.split("://", 1)[-1].rstrip("/")
    host, sep, port = rest.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"the Ray cluster's address {address!r} is not HOST:PORT (the "
                          f"head's address and port, as 'ray start --head' printed them, "
                          f"e.g. 10.0.0.5:6379)")
    return host, int(port)


class _QuietThreadWarning(logging.Filter):
    """Drops Ray's warning that ``ray.init`` outside the main thread sets no
    SIGTERM handler: not setting one is why it runs there."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("SIGTERM handler is not set")


_QUIET = _QuietThreadWarning()
#: an attempt to join given up on, still running (``_Joining``)
_abandoned: threading.Thread | None = None


class _Joining:
    """One attempt to join a cluster, in a thread, waited for here within a
    deadline and interruptibly (a signal handler that raises ends the wait)."""

    def __init__(self, ray: Any, target: str | None, kw: dict[str, Any],
                 timeout_s: float) -> None:
        self.ray, self.target, self.kw, self.timeout_s = ray, target, kw, timeout_s
        self.where = None if target in (None, "auto") else host_port(target)
        self.ctx: Any = None
        self.error: BaseException | None = None
        self.reached = False  # the TCP probe got through
        self.given_up = False
        self.lock = threading.Lock()
        self.done = threading.Event()

    def _attempt(self) -> None:
        try:
            if self.where is not None:  # nothing listening: said at once, not after retries
                with socket.create_connection(self.where, timeout=self.timeout_s):
                    self.reached = True
            ctx = self.ray.init(address=self.target, **self.kw)
            with self.lock:
                if self.given_up:  # too late: nobody uses it
                    self.ray.shutdown()
                    return
                self.ctx = ctx
        except BaseException as e:  # reported by join()
            self.error = e
        finally:
            self.done.set()

    def join(self) -> Any:
        global _abandoned
        if self.target is None:
            return self._start_here()
        if _abandoned is not None and _abandoned.is_alive():
            raise ClusterUnreachable("an earlier attempt of this process to join a Ray "
                                     "cluster, given up on, has not ended yet; start a new "
                                     "process to try again")
        logging.getLogger("ray._private.worker").addFilter(_QUIET)
        thread = threading.Thread(target=self._attempt, name="cosim-ray-join", daemon=True)
        deadline = time.monotonic() + self.timeout_s
        thread.start()
        try:
            while not self.done.wait(max(0.0, min(0.1, deadline - time.monotonic()))):
                if time.monotonic() >= deadline:
                    break
        finally:
            with self.lock:
                if self.ctx is None:  # interrupted, or out of time: left to end with us
                    self.given_up = True
                    _abandoned = thread
        if self.ctx is not None:
            return self.ctx
        raise ClusterUnreachable(self._why())

    def _start_here(self) -> Any:
        """A private local Ray, started from this thread: the processes Ray
        starts die with the thread that started them (PR_SET_PDEATHSIG), so
        not from a thread that ends. Ray's own SIGTERM handler (it exits the
        process) is undone."""
        main = threading.current_thread() is threading.main_thread()
        before = signal.getsignal(signal.SIGTERM) if main else None
        try:
            return self.ray.init(address=None, **self.kw)
        except Exception as e:
            self.error = e
            raise ClusterUnreachable(self._why()) from None
        finally:
            if main and before is not None:
                signal.signal(signal.SIGTERM, before)

    def _why(self) -> str:
        version = getattr(self.ray, "__version__", "?")
        if self.target is None:
            assert self.error is not None
            return f"a local Ray for this run could not be started: {_one_line(self.error)}"
        head = f"cannot join the Ray cluster at {self.target}"
        token = ("and that RAY_AUTH_TOKEN (or RAY_AUTH_TOKEN_PATH) holds its token if it "
                 "uses token authentication")
        if self.where is None:  # 'auto': Ray looks for a cluster on this machine
            return (f"{head}: {_one_line(self.error) if self.error else 'no answer'} (is a "
                    f"Ray cluster started on this machine with 'ray start --head'?)")
        host, port = self.where
        e = self.error
        if isinstance(e, ConnectionRefusedError):
            return (f"{head}: nothing listens there (connection refused). Check that the "
                    f"cluster's head is started on {host} ('ray start --head --port {port}') "
                    f"and that {host}:{port} is the address it printed")
        if isinstance(e, socket.gaierror):
            return (f"{head}: {host!r} is not a host name this machine knows "
                    f"({e.strerror or e}). Check the address: the head's IP address or name "
                    f"and the port 'ray start --head' printed")
        if e is None or isinstance(e, TimeoutError):
            if not self.reached:
                return (f"{head}: no answer within {self.timeout_s:g} s (--connect-timeout-s). "
                        f"Check that {host} is up and reachable from this machine on port "
                        f"{port} (a wrong address, a firewall that drops packets)")
            return (f"{head}: something listens there but did not take this process into a "
                    f"Ray cluster within {self.timeout_s:g} s (--connect-timeout-s). Check "
                    f"that it is a Ray head's port ('ray start --head --port {port}'), that "
                    f"the head runs Ray {version} as this machine does, {token}")
        if isinstance(e, OSError):
            return (f"{head}: {e.strerror or e}. Check that this machine reaches {host} "
                    f"(its network, routes and firewall)")
        return (f"{head}: {_one_line(e)}. Check that it is a Ray head ('ray start --head') "
                f"running Ray {version} as this machine does, {token}")


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return (text[:300] + " ...") if len(text) > 300 else (text or type(e).__name__)


@dataclasses.dataclass(frozen=True)
class Node:
    """A live machine of the cluster."""

    id: str
    ip: str
    cpus: int
    head: bool


def live_nodes() -> list[Node]:
    """The cluster's live machines with CPUs: the head first, then by node id."""
    ray = import_ray()
    out = [Node(n["NodeID"], n["NodeManagerAddress"], int(n["Resources"].get("CPU", 0)),
                "node:__internal_head__" in n["Resources"])
           for n in ray.nodes() if n["Alive"]]
    out = [n for n in out if n.cpus > 0]
    return sorted(out, key=lambda n: (not n.head, n.id))
