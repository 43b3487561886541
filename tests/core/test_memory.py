"""The physics processes' allocator and huge pages (``cosim.core.memory``):
``COSIM_ALLOCATOR`` is read as documented, a child started with the
allocator's environment really gets huge pages where this driver does not,
a ``cosim`` command that flies aircraft starts itself again once with the
driver's setting, and a driver that started without it gathers its heap
into huge pages."""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
import textwrap
from multiprocessing.connection import Connection
from pathlib import Path

import pytest

from cosim.core import memory
from cosim.core import workers as worker_kit
from cosim.errors import CosimError

THP = memory.thp_mode()
needs_madvise = pytest.mark.skipif(
    THP != "madvise", reason=f"transparent huge pages are {THP or 'unknown'} here: the "
                             "difference the allocator's setting makes shows in madvise mode")


def test_cosim_allocator_is_read_as_documented(monkeypatch) -> None:
    env = {"COSIM_ALLOCATOR": "system"}
    assert memory.allocator(env, "madvise") == memory.Allocator(None, True)
    assert memory.allocator(env, "never") == memory.Allocator(None, False)
    assert memory.allocator(env, "always").huge_pages
    env["COSIM_ALLOCATOR"] = "system,nohugepages"
    assert memory.allocator(env, "madvise") == memory.Allocator(None, False)
    env["COSIM_ALLOCATOR"] = "system, hugepages"
    assert memory.allocator(env, "never").huge_pages  # asked for: the kernel decides
    present = [p for p in memory.ALLOCATORS if os.path.isfile(p)]
    assert memory.allocator({}, "madvise").preload == (present[0] if present else None)
    with pytest.raises(CosimError, match=r"COSIM_ALLOCATOR=/no/such/lib.so: /no/such/lib.so: "
                                         r"no such file"):
        memory.allocator({"COSIM_ALLOCATOR": "/no/such/lib.so"}, "madvise")
    for bad in ("auto,huge", "auto,hugepages,nohugepages"):
        with pytest.raises(CosimError, match=rf"COSIM_ALLOCATOR={bad}: expected an allocator "
                                             r".*',hugepages' or ',nohugepages'"):
            memory.allocator({"COSIM_ALLOCATOR": bad}, "madvise")


def test_the_childs_environment_adds_to_what_is_there() -> None:
    jem = memory.Allocator("/x/libjemalloc.so.2", True)
    env = jem.child_env({"LD_PRELOAD": "/a.so", "GLIBC_TUNABLES": "glibc.malloc.arena_max=2",
                         "MALLOC_CONF": "narenas:2"})
    assert env == {"LD_PRELOAD": "/x/libjemalloc.so.2 /a.so",
                   "GLIBC_TUNABLES": "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1",
                   "MALLOC_CONF": "narenas:2,thp:always,metadata_thp:always"}
    assert {**env, **jem.child_env(env)} == env  # said once, never twice
    assert memory.Allocator(None, True).child_env({}) == {
        "GLIBC_TUNABLES": "glibc.malloc.hugetlb=1"}
    assert memory.Allocator("/x/libjemalloc.so.2", False).child_env({}) == {
        "LD_PRELOAD": "/x/libjemalloc.so.2"}


def test_thp_mode_reads_the_bracketed_word(tmp_path: Path) -> None:
    f = tmp_path / "enabled"
    f.write_text("always [madvise] never\n")
    assert memory.thp_mode(f) == "madvise"
    assert memory.thp_mode(tmp_path / "missing") == ""


#: small blocks, as a flight model's objects are (below malloc's mmap threshold)
BLOCK, BLOCKS = 4096, 16384


def _fill_heap(conn: Connection, advise: bool) -> None:
    """64 MiB of small malloc'd blocks, touched; then (``advise``) the heap
    gathered into huge pages; sends the process's AnonHugePages (KiB)."""
    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    for _ in range(BLOCKS):
        ctypes.memset(libc.malloc(BLOCK), 1, BLOCK)
    if advise:
        memory.advise_heap()
    with open("/proc/self/smaps_rollup") as f:
        conn.send(next(int(ln.split()[1]) for ln in f if ln.startswith("AnonHugePages:")))


def _huge_kib(env: dict[str, str], advise: bool = False) -> int:
    a, b = worker_kit.context().Pipe(duplex=False)
    p = worker_kit.start(_fill_heap, (b, advise), "cosim-test-pages", env=env)
    try:
        assert a.poll(60), "the child sent nothing"
        return int(a.recv())
    finally:
        p.join(10)


@needs_madvise
def test_a_child_started_with_the_allocators_environment_gets_huge_pages(monkeypatch) -> None:
    """glibc's setting in the child's environment (only there: this process's
    own environment is left as it was) gives its heap huge pages; without it,
    none."""
    monkeypatch.delenv("GLIBC_TUNABLES", raising=False)
    with_env = _huge_kib(memory.Allocator(None, True).child_env(os.environ))
    without = _huge_kib({})
    assert "GLIBC_TUNABLES" not in os.environ
    assert with_env >= 32 * 1024, with_env  # most of the 64 MiB
    assert without < 8 * 1024, without


@needs_madvise
def test_a_process_started_without_it_gathers_its_heap_into_huge_pages() -> None:
    if memory.advise_heap(Path("/nonexistent")) != 0:
        pytest.fail("advise_heap read a missing maps file")
    got = _huge_kib({}, advise=True)
    assert got >= 32 * 1024, got


def _child(code: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=60,
                          env={k: v for k, v in {**os.environ, **env}.items()
                               if k not in ("GLIBC_TUNABLES", memory.REEXEC_MARK)
                               or k in env})


REEXEC = """
    import os
    print("start", os.getpid(), flush=True)
    from cosim.core.memory import reexec_driver
    reexec_driver()
    print("after", os.getpid(), os.environ.get("GLIBC_TUNABLES"))
"""


def test_the_driver_starts_itself_again_once_with_huge_pages() -> None:
    p = _child(REEXEC, {"COSIM_ALLOCATOR": "system,hugepages"})
    lines = p.stdout.split("\n")
    pid = lines[0].split()[1]
    assert lines[:3] == [f"start {pid}", f"start {pid}",
                         f"after {pid} glibc.malloc.hugetlb=1"], p.stdout + p.stderr
    p = _child(REEXEC, {"COSIM_ALLOCATOR": "system,nohugepages"})
    assert p.stdout.count("start") == 1 and "after" in p.stdout and "None" in p.stdout


@needs_madvise
@pytest.mark.integration  # two benches in subprocesses: about 5 s
def test_cosim_bench_runs_its_driver_with_huge_pages(tmp_path: Path) -> None:
    """The ``cosim`` command (not a call of ``main`` in this process) starts
    again with the setting: the bench says so, and the pool's processes hold
    huge pages; with ``nohugepages`` neither."""
    figures = {}
    for pages in ("hugepages", "nohugepages"):
        out = tmp_path / f"{pages}.json"
        p = subprocess.run(
            [sys.executable, "-m", "cosim", "bench", "--model", "uav700", "--vehicles", "64",
             "--seconds", "0.25", "--repeat", "1", "--no-baselines", "--json", str(out)],
            capture_output=True, text=True, timeout=180,
            env={**{k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"},
                 "COSIM_ALLOCATOR": f"auto,{pages}"})
        assert p.returncode == 0, p.stderr
        doc = json.loads(out.read_text())
        figures[pages] = (doc["memory"]["driver_huge_pages"],
                          doc["results"][0]["huge_pages_mib"])
        assert ("the driver with huge pages" in p.stdout) == (pages == "hugepages"), p.stdout
    assert figures["hugepages"][0] and not figures["nohugepages"][0]
    # 64 uav700s hold about 28 MiB of flight models, half of them in the driver
    assert figures["hugepages"][1] >= 8 and figures["nohugepages"][1] < 4, figures
