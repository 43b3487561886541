"""Failures must not look like success: a camera that cannot write, a killed
render worker, a full disk, a killed run. Each ends with a clear error
naming what failed, one ``error`` event, a ``summary.json`` that says
whether the outputs are complete, and files that ``cosim recover`` makes
readable."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from cosim.cli import main
from cosim.logs import EventLog, StateLog, read_states
from cosim.logs.runfolder import journal_batches
from cosim.scenario import load_scenario
from cosim.sync import run_scenario

REPO = Path(__file__).resolve().parent.parent.parent
FLYOVER = REPO / "scenarios" / "cameras" / "flyover.yaml"


def _events(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]


def _cosim(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cosim", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _spawned(pid: int) -> list[int]:
    """The spawned worker processes of ``pid`` (not its resource tracker)."""
    from tests.fdm_pool.test_pool import _children

    out = []
    for c in _children(pid):
        try:
            with open(f"/proc/{c}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if b"spawn_main" in cmd and b"resource_tracker" not in cmd:
            out.append(c)
    return out


def _flyover(tmp_path: Path, render_workers: int) -> Path:
    text = FLYOVER.read_text().replace("  operator_view: true\n",
                                       f"  operator_view: true\n  render_workers: "
                                       f"{render_workers}\n")
    p = tmp_path / "flyover.yaml"
    p.write_text(text)
    return p


# --- cameras --------------------------------------------------------------------------

@pytest.mark.parametrize("render_workers", [0, 1])
@pytest.mark.integration
def test_a_camera_that_cannot_write_fails_the_run_naming_it(tmp_path: Path, capsys,
                                                            render_workers: int) -> None:
    out = tmp_path / "run"
    (out / "cameras" / "uav1_belly.mp4").mkdir(parents=True)  # its video cannot be opened
    rc = main(["run", str(_flyover(tmp_path, render_workers)), "--out", str(out),
               "--duration-s", "1", "--backend", "inline", "--no-progress"])
    assert rc == 1
    assert "camera 'belly' of vehicle 'uav1'" in capsys.readouterr().err
    errors = [e for e in _events(out) if e["event"] == "error"]
    assert len(errors) == 1 and errors[0]["vehicle"] == "uav1"
    assert "camera 'belly' of vehicle 'uav1'" in errors[0]["message"]
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "error" and "RenderError" in s["error"]
    assert s["complete"] is False
    assert "camera 'belly'" in s["cameras"]["error"] and s["cameras"]["streams"]


def _render_worker_signalled(tmp_path: Path, sig: signal.Signals, *args: str
                             ) -> tuple[subprocess.Popen, Path, int, float | None, str]:
    """A real-time flyover with one render worker which gets ``sig`` once it has
    rendered some frames: the process, its run folder, the worker's pid, how
    long after the signal the run's error event came (None: not within 15 s)
    and the run's stderr (the run ended; the worker killed if still there)."""
    out = tmp_path / "run"
    p = _cosim("run", str(_flyover(tmp_path, 1)), "--out", str(out), "--backend", "inline",
               "--realtime", "1", "--no-progress", *args)
    gt = out / "cameras" / "uav1_belly.gt.csv"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not gt.exists() or gt.stat().st_size < 2000):
        time.sleep(0.05)
    workers = _spawned(p.pid)
    assert len(workers) == 1, workers
    os.kill(workers[0], sig)
    t0 = time.monotonic()
    noticed = None
    try:
        while noticed is None and time.monotonic() - t0 < 15:
            if any(e["event"] == "error" for e in _events(out)):
                noticed = time.monotonic() - t0
            time.sleep(0.02)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
        with contextlib.suppress(ProcessLookupError):
            os.kill(workers[0], signal.SIGKILL)
    return p, out, workers[0], noticed, err


@pytest.mark.integration
def test_a_killed_render_worker_is_noticed_within_a_second_and_named(tmp_path: Path) -> None:
    p, out, worker, noticed, err = _render_worker_signalled(tmp_path, signal.SIGKILL)
    assert noticed is not None and noticed < 1.0, noticed
    assert p.returncode == 1, err
    assert f"render worker 0 (pid {worker}) killed by SIGKILL" in err
    assert "its cameras (vehicle/camera): uav1/belly" in err
    errors = [e for e in _events(out) if e["event"] == "error"]
    assert len(errors) == 1 and errors[0]["vehicle"] == "uav1"
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "error" and "RenderWorkerDied" in s["error"]


@pytest.mark.integration
def test_a_stopped_render_worker_fails_the_run_within_the_step_timeout(tmp_path: Path) -> None:
    """A render worker that stops (SIGSTOP) is alive but silent: the run ends
    within --step-timeout-s of its last frame with an error naming it, the frame
    it was on and its cameras, everything logged so far on disk, exit 1; the
    stopped process is killed."""
    p, out, worker, noticed, err = _render_worker_signalled(tmp_path, signal.SIGSTOP,
                                                            "--step-timeout-s", "1")
    # the timeout, then the next exchange (10 Hz) or poll (0.2 s)
    assert noticed is not None and noticed < 2.0, noticed
    assert p.returncode == 1, err
    assert re.search(rf"render worker 0 \(pid {worker}\) sent nothing for 1 s while "
                     r"rendering the frame at tick \d+ of uav1/belly at tick \d+ \(stopped or "
                     r"stuck; --step-timeout-s\); its cameras \(vehicle/camera\): uav1/belly",
                     err), err
    errors = [e for e in _events(out) if e["event"] == "error"]
    assert len(errors) == 1 and errors[0]["vehicle"] == "uav1"
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "error" and "RenderWorkerTimeout" in s["error"]
    ticks = read_states(out)["tick"].to_numpy()  # the states so far, readable
    assert ticks.max() >= errors[0]["tick"] - 12
    deadline = time.monotonic() + 5  # killed, not left stopped
    while time.monotonic() < deadline and os.path.exists(f"/proc/{worker}"):
        time.sleep(0.05)
    assert not os.path.exists(f"/proc/{worker}"), "the stopped worker is still there"


# --- full disk ------------------------------------------------------------------------

FILLER = """
schema_version: 1
name: diskfill
origin: {lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 10}
rates: {physics_hz: 120, control_hz: 120, log_hz: 120}
duration_s: 600
vehicles:
  - {id: a, model: c172p, count: 60, formation: {type: grid, spacing_m: 100},
     init: {north_m: 0, east_m: 0, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 100}}
"""


@pytest.fixture
def small_disk(tmp_path: Path):
    """A 12 MB tmpfs (the run's reserve is 9 MB of it): root only."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=12m", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.mark.integration
def test_a_full_disk_keeps_the_summary_one_error_and_every_logged_tick(
        tmp_path: Path, small_disk: Path, capsys) -> None:
    scn = tmp_path / "fill.yaml"
    scn.write_text(textwrap.dedent(FILLER))
    out = small_disk / "run"
    rc = main(["run", str(scn), "--out", str(out), "--backend", "inline", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1
    # the file that filled the disk: the first journal, a later one where a part
    # was written on time (flush_s) before the disk was full, or, on a loaded
    # machine, the part being written when it filled
    journal = re.search(r"states\.parquet/(_journal-\d{6}\.arrows|part-\d{6}\.parquet)", err)
    assert "No space left on device" in err and journal, err
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "error" and journal.group(1) in s["error"]
    errors = [e for e in _events(out) if e["event"] == "error"]
    assert len(errors) == 1, errors
    assert not list(out.rglob("*.tmp")) and not list(out.glob(".cosim-reserve*"))
    # the reserve made room for the last part: every logged tick is in Parquet
    table = pq.read_table(out / "states.parquet")
    assert table.num_rows == s["state_rows"] == 60 * (s["ticks"] + 1)
    assert s["complete"] is True


@pytest.mark.integration
def test_when_the_last_part_cannot_be_written_the_summary_says_incomplete(
        tmp_path: Path, monkeypatch, capsys) -> None:
    import cosim.logs.writers as w

    real = w.pq.write_table

    def disk_full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(w.pq, "write_table", disk_full)
    res = run_scenario(load_scenario(FLYOVER).with_duration(2.0), tmp_path / "o",
                       backend="inline")
    assert res.stop_reason == "error"
    s = json.loads((res.out_dir / "summary.json").read_text())
    assert s["complete"] is False and "part-000000.parquet" in s["error"]
    assert [e["event"] for e in _events(res.out_dir)].count("error") == 1
    assert pq.read_table(res.out_dir / "states.parquet").num_rows == 0  # in the journal
    monkeypatch.setattr(w.pq, "write_table", real)
    assert main(["recover", str(res.out_dir)]) == 0
    assert "wrote part-000000.parquet from _journal-000000.arrows" in capsys.readouterr().out
    s = json.loads((res.out_dir / "summary.json").read_text())
    assert s["complete"] is False and s["recovered"] is True and s["stop_reason"] == "error"
    t = pq.read_table(res.out_dir / "states.parquet")
    assert sorted(set(t["tick"].to_pylist())) == list(range(0, 241, 12))


_LIMITED = """
import errno, json, resource, signal, sys
import numpy as np
from pathlib import Path
from cosim.fdm_pool import N_STATE
from cosim.core.geo import LocalFrame
from cosim.logs import EventLog, StateLog
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write over the limit fails with EFBIG
resource.setrlimit(resource.RLIMIT_FSIZE, (__LIMIT__, __LIMIT__))
out = Path(sys.argv[1])
log = StateLog(out / "states.parquet", [f"v{i}" for i in range(50)], LocalFrame(47, 8, 0),
               120.0, flush_s=1e9)
appended = 0
raised = []
for t in range(0, 100000, 4):
    try:
        log.append(t, np.full((50, N_STATE), 1.0 + t))
        appended += 1
    except OSError as e:
        raised.append(str(e))
        break
log.append(t + 4, np.full((50, N_STATE), 2.0))  # after the failure: kept, not raised
events = EventLog(out / "events.jsonl", 120.0)
for i in range(100000):
    events.emit("note", i, text="x" * 200)  # never raises
events.close()
print(json.dumps({"appended": appended, "raised": raised, "dropped": events.dropped,
                  "complete": events.complete}))
"""


def test_a_failed_journal_append_is_cut_back_to_its_last_complete_tick(tmp_path: Path) -> None:
    """With the file size limited by the OS (RLIMIT_FSIZE: writes past it fail
    with EFBIG, as on a full disk), the journal keeps every complete tick and
    no partial one; the failure is raised once; the event log never raises."""
    limit = 300_000
    r = subprocess.run([sys.executable, "-c", _LIMITED.replace("__LIMIT__", str(limit)),
                        str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    appended, raised = got["appended"], got["raised"]
    assert len(raised) == 1 and "_journal-000000.arrows" in raised[0]
    assert "File too large" in raised[0]
    journal = tmp_path / "states.parquet" / "_journal-000000.arrows"
    batches, clean = journal_batches(journal)
    assert clean and len(batches) == appended > 0
    assert journal.stat().st_size <= limit
    ticks = read_states(tmp_path, ["tick"])["tick"].to_numpy()  # (made-up positions)
    assert np.array_equal(np.unique(ticks), np.arange(0, 4 * appended, 4))
    assert got["dropped"] > 0 and got["complete"] is False
    lines = (tmp_path / "events.jsonl").read_text().splitlines()
    assert lines and all(json.loads(x)["event"] == "note" for x in lines)  # no partial line


def test_state_log_close_after_a_failure_does_not_raise_it_again(tmp_path: Path,
                                                                 monkeypatch) -> None:
    import cosim.logs.writers as w
    from cosim.core.geo import LocalFrame
    from cosim.fdm_pool import N_STATE

    log = StateLog(tmp_path / "s", ["a"], LocalFrame(47, 8, 0), 120.0, flush_rows=2)

    def disk_full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(w.pq, "write_table", disk_full)
    log.append(0, np.zeros((1, N_STATE)))
    with pytest.raises(OSError, match=r"cannot write .*part-000000\.parquet"):
        log.append(4, np.zeros((1, N_STATE)))
    log.append(8, np.zeros((1, N_STATE)))
    log.close()  # the same failure again: not raised twice
    assert not log.complete
    monkeypatch.undo()
    assert read_states(tmp_path / "s")["tick"].to_pylist() == [0, 4]


def test_event_log_keeps_lines_it_could_not_write_and_writes_them_later(tmp_path: Path,
                                                                        monkeypatch) -> None:
    log = EventLog(tmp_path / "events.jsonl", 120.0)
    real = os.write
    full = True

    def write(fd: int, data: bytes) -> int:
        if full:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data)

    monkeypatch.setattr(os, "write", write)
    log.emit("a", 0)
    log.emit("b", 4)
    assert log.failed is not None and not log.complete
    full = False
    log.emit("c", 8)
    log.close()
    assert [json.loads(x)["event"] for x in (tmp_path / "events.jsonl").read_text().split(
        "\n") if x] == ["a", "b", "c"]
    assert log.complete


# --- cosim recover --------------------------------------------------------------------

@pytest.mark.integration
def test_recover_turns_a_killed_run_into_readable_output(tmp_path: Path, capsys) -> None:
    scn = tmp_path / "fill.yaml"
    scn.write_text(textwrap.dedent(FILLER).replace("count: 60", "count: 20"))
    out = tmp_path / "run"
    p = _cosim("run", str(scn), "--out", str(out), "--backend", "inline", "--realtime", "4",
               "--no-progress")
    journal = out / "states.parquet" / "_journal-000000.arrows"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not journal.exists()
                                           or journal.stat().st_size < 200_000):
        time.sleep(0.05)
    p.kill()
    p.communicate(timeout=10)
    assert pq.read_table(out / "states.parquet").num_rows == 0  # all in the journal
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["stop_reason"] == "running"
    journalled = sum(b.num_rows for b in journal_batches(journal)[0])
    # a record cut short at the end (the kill came mid-write, or we make one)
    with open(journal, "ab") as f:
        f.write(b"\xff\xff\xff\xff\x10\x00\x00\x00partial")
    assert main(["recover", str(out)]) == 0
    said = capsys.readouterr().out
    assert "wrote part-000000.parquet from _journal-000000.arrows" in said
    assert "dropped a record cut short at the end of _journal-000000.arrows" in said
    assert "removed .cosim-reserve" in said
    table = pq.read_table(out / "states.parquet")  # what pandas.read_parquet reads
    assert table.num_rows == journalled > 0
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["recovered"] is True and s["stop_reason"] == "killed"
    assert s["state_rows"] == journalled and s["ticks"] == max(table["tick"].to_pylist())
    assert not list(out.glob(".cosim-reserve*")) and not journal.exists()
    before = {f: f.stat().st_mtime_ns for f in out.rglob("*")}
    assert main(["recover", str(out)]) == 0  # idempotent
    assert "nothing to recover" in capsys.readouterr().out
    assert {f: f.stat().st_mtime_ns for f in out.rglob("*")} == before


def test_recover_refuses_a_folder_that_is_not_a_run(tmp_path: Path, capsys) -> None:
    assert main(["recover", str(tmp_path)]) == 2
    assert "not a cosim run folder" in capsys.readouterr().err


def test_recover_leaves_a_complete_run_alone(tmp_path: Path, capsys) -> None:
    out = tmp_path / "q"
    assert main(["run", str(REPO / "scenarios" / "quickstart.yaml"), "--out", str(out),
                 "--duration-s", "1", "--backend", "inline", "--no-progress"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is True and s["stop_reason"] == "completed"
    before = {f: f.stat().st_mtime_ns for f in out.rglob("*")}
    assert main(["recover", str(out)]) == 0
    assert "nothing to recover" in capsys.readouterr().out
    assert {f: f.stat().st_mtime_ns for f in out.rglob("*")} == before

