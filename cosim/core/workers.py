"""The worker toolkit cosim's process pools share: the physics pool
(``cosim.fdm_pool.process``), the render workers (``cosim.renderer.
participant``), the sweep's runs (``cosim.sweep.runner``) and the bench's
ceiling processes (``cosim.bench``).

- ``start``: a child by the ``spawn`` method (no inherited threads, locks or
  JSBSim state), set up by ``_child_main`` before its target runs: a
  *shielded* child ignores SIGINT and SIGTERM (its driver decides when it
  stops, so Ctrl-C ends a run cleanly instead of killing its workers
  mid-write; the signals stay blocked from before the start until they are
  ignored), logs as its driver does, and remembers its driver's pid;
- ``parent_gone``: whether the driver has ended (an orphan then stops
  rather than lingering);
- ``ended``: which children have ended, at once or within a timeout (their
  sentinels), reaped so that their exit codes are known;
- ``remote_traceback``: the traceback being handled, bounded in size, for a
  child to send its driver;
- ``stop``: join the children within a grace period, then kill what is left.

The protocols between a driver and its children (shared memory, queues,
pipes) are each pool's own: their needs differ.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait as _wait
from multiprocessing.process import BaseProcess
from typing import Any

#: the driver's to act on, never a shielded child's
STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})
#: the longest traceback a child sends (its end is kept: the error is there)
MAX_TRACEBACK_CHARS = 64_000
#: the loggers whose levels a child takes from its driver
_LOGGERS = ("cosim", "cosim.jsbsim")

_parent_pid: int | None = None


@dataclass(frozen=True)
class _Setup:
    """What a child does before its target (picklable: it travels to the child)."""

    parent_pid: int
    shielded: bool
    levels: dict[str, int] | None  # None: leave logging alone
    fmt: str | None
    datefmt: str | None


def _log_setup() -> tuple[dict[str, int], str | None, str | None]:
    """The driver's levels and the format of its root logger's first stream
    handler (None: it configured none)."""
    fmt = datefmt = None
    for h in logging.getLogger().handlers:
        if isinstance(h, logging.StreamHandler) and h.formatter is not None:
            fmt, datefmt = h.formatter._fmt, h.formatter.datefmt
            break
    return {n: logging.getLogger(n).getEffectiveLevel() for n in _LOGGERS}, fmt, datefmt


def _child_main(setup: _Setup, target: Callable[..., Any], args: tuple[Any, ...]) -> None:
    global _parent_pid
    _parent_pid = setup.parent_pid
    if setup.shielded:
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    if setup.levels is not None:
        for name, level in setup.levels.items():
            logging.getLogger(name).setLevel(level)
        if setup.fmt is not None:
            h = logging.StreamHandler(sys.stderr)
            h.setFormatter(logging.Formatter(setup.fmt, setup.datefmt))
            logging.getLogger().handlers[:] = [h]
    target(*args)


def context() -> Any:
    """The multiprocessing context every pool uses (``spawn``), for the
    shared arrays, queues and pipes that go with its children."""
    return mp.get_context("spawn")


def start(target: Callable[..., Any], args: tuple[Any, ...], name: str, *,
          shielded: bool = True, inherit_logging: bool = True,
          daemon: bool = True, env: Mapping[str, str] | None = None,
          on_start: Callable[[BaseProcess], None] | None = None) -> BaseProcess:
    """Start ``target(*args)`` in a spawned child named ``name`` (see the
    module docstring). ``daemon``: ended with the driver (a daemonic child
    cannot start children of its own). ``env``: variables set in the child's
    environment only (an allocator to preload and its settings,
    ``cosim.core.memory.Allocator.child_env``). ``on_start(process)``: called
    once the child runs, before a stop signal that arrived meanwhile is
    handled: a caller records the child there, so that a handler raising
    (Ctrl-C while a pool starts) cannot leave a child it does not know of,
    which would ignore the interpreter's own SIGTERM at exit and hang it."""
    levels, fmt, datefmt = _log_setup() if inherit_logging else (None, None, None)
    setup = _Setup(os.getpid(), shielded, levels, fmt, datefmt)
    p = context().Process(target=_child_main, name=name, daemon=daemon,
                          args=(setup, target, args))
    # blocked until the child ignores them; in the driver, a stop signal
    # arriving meanwhile is handled right after
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if shielded else None
    # the spawned child's environment is ours at start()
    before = {k: os.environ.get(k) for k in (env or {})}
    os.environ.update(env or {})
    try:
        p.start()
        if on_start is not None:
            on_start(p)
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
    return p


def parent_gone() -> bool:
    """In a child started by ``start``: whether its driver has ended."""
    return _parent_pid is not None and os.getppid() != _parent_pid


def ended(procs: Sequence[BaseProcess], timeout_s: float | None = 0.0) -> list[int]:
    """The indices of the children in ``procs`` that have ended, waiting up
    to ``timeout_s`` (None: until one has) for the first."""
    if not procs:
        return []
    fired = set(_wait([p.sentinel for p in procs], timeout=timeout_s))
    out = [i for i, p in enumerate(procs) if p.sentinel in fired]
    for i in out:  # reaped, so that its exit code is known
        procs[i].join(1.0)
    return out


def remote_traceback() -> str:
    """The traceback of the exception being handled, for a child to send its
    driver: whole, or if longer than ``MAX_TRACEBACK_CHARS`` its beginning
    and the exception itself (type, and both ends of a long message)."""
    tb = traceback.format_exc()
    if len(tb) <= MAX_TRACEBACK_CHARS:
        return tb
    quarter = MAX_TRACEBACK_CHARS // 4
    exc = "".join(traceback.format_exception_only(*sys.exc_info()[:2]))
    if len(exc) > quarter:
        exc = f"{exc[:quarter // 2]} ... {exc[-quarter // 2:]}"
    return f"{tb[:2 * quarter]}\n... (traceback cut: {len(tb)} characters) ...\n{exc}"


def stop(procs: Sequence[BaseProcess], grace_s: float, *, terminate: bool = False) -> None:
    """End the children in ``procs``: (``terminate``: send SIGTERM first, for
    unshielded ones) join each within ``grace_s`` in all, then kill the ones
    still alive (stuck, or shielded and never asked to stop)."""
    if terminate:
        for p in procs:
            if p.is_alive():
                p.terminate()
    deadline = time.monotonic() + grace_s
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs:
        if p.is_alive():
            p.kill()
            p.join(1.0)
