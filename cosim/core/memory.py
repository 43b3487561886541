"""How the physics processes get their memory: which allocator, and whether
it asks the kernel for transparent huge pages.

A JSBSim aircraft's flight model is about 0.45 MiB of small objects spread
over the heap. Stepping thousands of them in turn, each exchange brings every
aircraft's memory back into the CPU's caches and its translation buffer
(TLB); with 2 MiB pages instead of 4 KiB ones the TLB covers 512 times more
memory, so that refill costs less (``benchmarks/README.md``: huge pages).

``COSIM_ALLOCATOR`` says what to use: a comma-separated list, the allocator
first, then optionally ``hugepages`` or ``nohugepages``:

- ``auto`` (the default): jemalloc (or mimalloc) preloaded into the worker
  processes where the system has it, else the system's allocator;
- ``system``: the system's allocator (glibc's malloc);
- a path: that allocator library, preloaded into the workers;
- ``hugepages`` / ``nohugepages``: ask for huge pages or not (default: ask,
  where the kernel's transparent huge pages are ``always`` or ``madvise``).

Huge pages are asked for through the allocators' own settings, in the
environment a process starts with (``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``
for glibc, ``MALLOC_CONF=thp:always,metadata_thp:always`` for jemalloc): a
running process cannot change them. Workers get them at their start. The
driver, which steps a share of the aircraft itself, gets them at the start
of a ``cosim`` command that flies aircraft: the command starts itself again,
once, with the settings (``reexec_driver``). A driver that started without
them (``cosim.run()`` from a script) asks for huge pages over its flight
models' memory once they are built (``advise_heap``).

Nothing here changes what is computed: states are bit-identical with any
allocator and either page size.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import CosimError

log = logging.getLogger(__name__)

#: shared libraries tried, in order, as the physics workers' allocator
ALLOCATORS = ("/usr/lib/x86_64-linux-gnu/libjemalloc.so.2", "/usr/lib64/libjemalloc.so.2",
              "/usr/lib/libjemalloc.so.2", "/usr/lib/x86_64-linux-gnu/libmimalloc.so.2",
              "/usr/lib/x86_64-linux-gnu/libmimalloc.so")
#: the kernel's transparent huge page mode
THP_ENABLED = Path("/sys/kernel/mm/transparent_hugepage/enabled")
#: glibc's malloc: madvise its heap for transparent huge pages
GLIBC_HUGE = "glibc.malloc.hugetlb=1"
#: jemalloc: huge pages for its extents and its own metadata
JEMALLOC_HUGE = "thp:always,metadata_thp:always"
#: set in a driver started again by ``reexec_driver`` (so it never loops)
REEXEC_MARK = "COSIM_DRIVER_REEXEC"
#: Linux madvise advice
MADV_HUGEPAGE, MADV_COLLAPSE = 14, 25
_HUGE = 1 << 21

_FLAGS = {"hugepages": True, "nohugepages": False}


@dataclass(frozen=True)
class Allocator:
    """What a physics process allocates with: a library preloaded into it
    (None: the system's malloc) and whether it asks for huge pages."""

    preload: str | None
    huge_pages: bool

    def describe(self) -> str:
        name = os.path.basename(self.preload) if self.preload else "system malloc"
        return f"{name}, {'huge pages' if self.huge_pages else '4 KiB pages'}"

    def child_env(self, environ: Mapping[str, str]) -> dict[str, str]:
        """The variables to set, on top of ``environ``, in a child's
        environment so that it starts with this allocator."""
        out: dict[str, str] = {}
        if self.preload:
            out["LD_PRELOAD"] = _joined(environ.get("LD_PRELOAD"), self.preload, " ", first=True)
        out.update(self.driver_env(environ))
        if self.huge_pages and self.preload and "jemalloc" in os.path.basename(self.preload):
            out["MALLOC_CONF"] = _joined(environ.get("MALLOC_CONF"), JEMALLOC_HUGE, ",")
        return out

    def driver_env(self, environ: Mapping[str, str]) -> dict[str, str]:
        """The variables the driver needs in its environment (it keeps the
        system's malloc: the libraries a run loads beside the flight models,
        a browser's or a cluster's processes, inherit what it has)."""
        if self.huge_pages and GLIBC_HUGE not in environ.get("GLIBC_TUNABLES", "").split(":"):
            return {"GLIBC_TUNABLES": _joined(environ.get("GLIBC_TUNABLES"), GLIBC_HUGE, ":")}
        return {}


def _joined(old: str | None, new: str, sep: str, first: bool = False) -> str:
    if not old:
        return new
    have = old.split(sep)
    add = sep.join(x for x in new.split(sep) if x not in have)
    if not add:
        return old
    return f"{add}{sep}{old}" if first else f"{old}{sep}{add}"


def thp_mode(path: Path = THP_ENABLED) -> str:
    """The kernel's transparent huge page mode: ``always``, ``madvise``,
    ``never``, or ``""`` where the system does not say."""
    try:
        text = path.read_text()
    except OSError:
        return ""
    return next((w[1:-1] for w in text.split() if w.startswith("[") and w.endswith("]")), "")


def allocator(environ: Mapping[str, str] | None = None, thp: str | None = None) -> Allocator:
    """The physics processes' allocator from ``COSIM_ALLOCATOR`` (see the
    module docstring); ``CosimError`` naming the value for a bad one."""
    env = os.environ if environ is None else environ
    raw = env.get("COSIM_ALLOCATOR", "auto")
    words = [w.strip() for w in raw.split(",")]
    name, flags = words[0] or "auto", words[1:]
    bad = [f for f in flags if f not in _FLAGS]
    if bad or len(flags) > 1:
        raise CosimError(f"COSIM_ALLOCATOR={raw}: expected an allocator ('auto', 'system' or "
                         f"a library's path), then optionally ',hugepages' or ',nohugepages'")
    if name == "system":
        preload = None
    elif name == "auto":
        preload = next((p for p in ALLOCATORS if os.path.isfile(p)), None)
    elif os.path.isfile(name):
        preload = name
    else:
        raise CosimError(f"COSIM_ALLOCATOR={raw}: {name}: no such file (give 'system', "
                         f"'auto' or the path of an allocator library)")
    mode = thp_mode() if thp is None else thp
    huge = _FLAGS[flags[0]] if flags else mode in ("always", "madvise")
    return Allocator(preload, huge)


def reexec_driver(argv: Sequence[str] | None = None) -> None:
    """Start this ``cosim`` command again, once, in place (same pid, same
    terminal), with the environment the driver's allocator needs; returns
    without doing anything when it has it already, when it was started
    again already, or when the command line is not known (``sys.orig_argv``)."""
    if os.environ.get(REEXEC_MARK):
        return
    try:
        extra = allocator().driver_env(os.environ)
    except CosimError:
        return  # the pool says so, where it matters
    args = list(argv if argv is not None else getattr(sys, "orig_argv", []))
    if not extra or not args:
        return
    env = {**os.environ, **extra, REEXEC_MARK: "1"}
    log.debug("starting again with %s", " ".join(f"{k}={v}" for k, v in extra.items()))
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    try:
        os.execve(sys.executable, args, env)
    except OSError as e:  # cannot: go on as we are
        log.warning("could not start again with huge pages (%s); going on without", e)


def driver_has_huge_pages(alloc: Allocator) -> bool:
    """Whether this process started with what ``alloc`` asks of a driver."""
    return not alloc.driver_env(os.environ)


def _libc_madvise() -> Any:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None
    fn = getattr(libc, "madvise", None)
    if fn is not None:
        fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
        fn.restype = ctypes.c_int
    return fn


def advise_heap(maps: Path = Path("/proc/self/maps")) -> int:
    """Ask for huge pages over this process's heap as it is now (the
    anonymous writable mappings and ``[heap]``, each trimmed to whole 2 MiB
    pages) and have the kernel gather it into them at once (``MADV_COLLAPSE``,
    Linux 6.1+). The bytes gathered (0 where the system cannot)."""
    madvise = _libc_madvise()
    if madvise is None:
        return 0
    try:
        lines = maps.read_text().splitlines()
    except OSError:
        return 0
    done = 0
    for line in lines:
        parts = line.split()
        if len(parts) < 5 or parts[1] != "rw-p" or (len(parts) > 5 and parts[5] != "[heap]"):
            continue
        lo, hi = (int(x, 16) for x in parts[0].split("-"))
        lo, hi = (lo + _HUGE - 1) & ~(_HUGE - 1), hi & ~(_HUGE - 1)
        if hi <= lo:
            continue
        if madvise(lo, hi - lo, MADV_HUGEPAGE) == 0 and madvise(lo, hi - lo, MADV_COLLAPSE) == 0:
            done += hi - lo
    return done
