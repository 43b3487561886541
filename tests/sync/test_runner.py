"""The lockstep run loop: outputs, events, determinism, pacing, clean stops."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest
import yaml

from cosim.core.geo import LocalFrame
from cosim.logs import STATE_COLUMNS, read_states
from cosim.scenario import load_scenario
from cosim.sync import Run, run_scenario
from tests.helpers import same_states

SWARM1000 = Path(__file__).resolve().parent.parent.parent / "scenarios" / "swarm1000.yaml"
REQUIRED = ("tick", "time_s", "vehicle", "lat_deg", "lon_deg", "alt_msl_m", "north_m",
            "east_m", "down_m", "roll_deg", "pitch_deg", "yaw_deg", "vn_mps", "ve_mps",
            "vd_mps", "airspeed_mps", "alpha_deg")


def _events(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]


def test_run_writes_every_output(mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    res = run_scenario(scn, tmp_path / "out", backend="inline")
    assert res.ok, res.summary
    out = res.out_dir
    t = read_states(out)
    assert set(REQUIRED) <= set(t.column_names)
    # then the fixed-wings' own
    assert tuple(t.column_names) == STATE_COLUMNS + ("contact_force_n", "fuel_kg")
    logged_ticks = sorted(set(t["tick"].to_pylist()))
    assert logged_ticks == list(range(0, 721, 12))  # 10 Hz of 120 Hz, 6 s, incl. tick 0
    assert t.num_rows == len(logged_ticks) * 7
    assert t["time_s"].to_pylist()[-1] == 6.0
    s = json.loads((out / "summary.json").read_text())
    for key in ("scenario", "vehicles", "backend", "workers", "ticks", "sim_time_s",
                "wall_time_s", "real_time_factor"):
        assert key in s
    assert s["vehicles"] == 7 and s["ticks"] == 720 and s["sim_time_s"] == 6.0
    assert s["stop_reason"] == "completed" and s["backend"] == "inline"
    assert "realtime" not in s
    split = s["time_split_s"]  # every part of the loop, timed; together within the loop
    assert {"pool: stepping (waiting for the workers)", "Guidance.before_step",
            "StateLogger.after_step", "Schedule.before_step"} <= set(split)
    assert all(v >= 0 for v in split.values())
    assert 0 < sum(split.values()) <= s["wall_time_s"] * 1.01
    resolved = yaml.safe_load((out / "scenario.resolved.yaml").read_text())
    assert len(resolved["vehicles"]) == 7


def test_local_frame_columns_are_exact_wgs84(mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    res = run_scenario(scn, tmp_path / "o", backend="inline")
    t = read_states(res.out_dir)
    lat, lon, alt = (t[c].to_numpy() for c in ("lat_deg", "lon_deg", "alt_msl_m"))
    n, e, d = LocalFrame(47.0, 8.0, 400.0).geodetic_to_ned(lat, lon, alt)
    assert np.array_equal(n, t["north_m"].to_numpy())
    assert np.array_equal(e, t["east_m"].to_numpy())
    assert np.array_equal(d, t["down_m"].to_numpy())
    first = t.filter(pc.equal(t["vehicle"].cast("string"), "nan")).slice(0, 1)
    assert first["north_m"][0].as_py() == pytest.approx(0.0, abs=1e-6)
    assert first["east_m"][0].as_py() == pytest.approx(800.0, abs=1e-6)
    assert first["down_m"][0].as_py() == pytest.approx(-900.0, abs=0.1)  # curvature: 5 cm


def test_ground_impact_and_divergence_are_events_and_the_rest_fly_on(
        mixed_scenario: Path, tmp_path: Path) -> None:
    res = run_scenario(load_scenario(mixed_scenario), tmp_path / "o", backend="inline")
    ev = _events(res.out_dir)
    kinds = [e["event"] for e in ev]
    assert kinds[0] == "run_start" and kinds[-1] == "stop"
    assert ev[-1]["reason"] == "completed"
    impact = [e for e in ev if e["event"] == "ground_impact"]
    assert [e["vehicle"] for e in impact] == ["diver"]
    assert impact[0]["vd_mps"] > 0 and impact[0]["tick"] > 0
    div = [e for e in ev if e["event"] == "divergence"]
    # 2 s + 1 exchange: its states pass 1e9 (on their way to NaN) in that exchange
    assert [e["vehicle"] for e in div] == ["nan"] and div[0]["tick"] == 244
    for e in ev:
        assert {"event", "tick", "time_s", "vehicle"} <= set(e)
        assert e["time_s"] == e["tick"] / 120
    t = read_states(res.out_dir)
    veh = t["vehicle"].cast("string")
    diver = t.filter(pc.equal(veh, "diver"))
    after = diver.filter(pc.greater_equal(diver["tick"], impact[0]["tick"]))
    assert set(after["status"].to_pylist()) == {1}
    assert len(set(after["lat_deg"].to_pylist())) == 1  # frozen
    nan = t.filter(pc.equal(veh, "nan"))
    assert set(nan.filter(pc.greater(nan["tick"], 244))["status"].to_pylist()) == {2}
    for col in ("alt_msl_m", "north_m", "vn_mps", "airspeed_mps"):  # frozen where it was
        assert (np.abs(nan[col].to_numpy()) < 1e5).all(), col  # plausible, not 1e21
    a0 = t.filter(pc.equal(veh, "a0"))
    assert set(a0["status"].to_pylist()) == {0}
    assert a0["north_m"].to_numpy()[-1] - a0["north_m"].to_numpy()[0] > 200  # still flying
    s = json.loads((res.out_dir / "summary.json").read_text())
    assert s["events"]["ground_impact"] == 1 and s["events"]["divergence"] == 1


@pytest.mark.integration
def test_same_seed_bit_identical_across_backends_and_worker_counts(
        mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    ref = read_states(run_scenario(scn, tmp_path / "inline", backend="inline").out_dir)
    for w in (1, 2, 3):
        got = read_states(run_scenario(scn, tmp_path / f"p{w}", backend="process",
                                       workers=w).out_dir)
        assert got.num_rows == ref.num_rows
        for col in STATE_COLUMNS:
            a, b = ref[col], got[col]
            if col == "vehicle":
                a, b = a.cast("string"), b.cast("string")
            if not a.equals(b):
                an, bn = np.asarray(a.to_pylist()), np.asarray(b.to_pylist())
                i = int(np.flatnonzero(an != bn)[0])
                pytest.fail(f"workers={w}: column {col} differs first at row {i} "
                            f"({ref['vehicle'][i]} tick {ref['tick'][i]}): {an[i]!r} != {bn[i]!r}")


def test_resolved_scenario_reruns_to_identical_states(mixed_scenario: Path,
                                                      tmp_path: Path) -> None:
    a = run_scenario(load_scenario(mixed_scenario), tmp_path / "a", backend="inline")
    again = load_scenario(a.out_dir / "scenario.resolved.yaml")
    b = run_scenario(again, tmp_path / "b", backend="inline")
    assert same_states(read_states(a.out_dir), read_states(b.out_dir))


def test_different_seed_changes_only_random_state(write_scenario, tmp_path: Path) -> None:
    from tests.conftest import MIXED

    s1 = load_scenario(write_scenario(MIXED, "a.yaml"))
    s2 = load_scenario(write_scenario(MIXED.replace("seed: 7", "seed: 8"), "b.yaml"))
    assert [v.random_seed for v in s1.vehicles] != [v.random_seed for v in s2.vehicles]
    # the mixed scenario has no turbulence: the seeds must not change its physics
    a = run_scenario(s1.with_duration(1.0), tmp_path / "a", backend="inline")
    b = run_scenario(s2.with_duration(1.0), tmp_path / "b", backend="inline")
    assert same_states(read_states(a.out_dir), read_states(b.out_dir))


def test_realtime_pacing_holds_sim_time_to_the_wall_clock(mixed_scenario: Path,
                                                          tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario).with_duration(1.0)
    t0 = time.monotonic()
    res = Run(scn, tmp_path / "rt", backend="inline", realtime=2.0).run()
    wall = time.monotonic() - t0
    assert wall >= 0.5  # 1 s of sim at 2x real time cannot finish sooner
    rt = res.summary["realtime"]
    assert rt["factor"] == 2.0 and rt["ticks"] == 30
    for k in ("lateness_ms_p50", "lateness_ms_p99", "lateness_ms_max", "overruns"):
        assert k in rt
    assert rt["lateness_ms_p50"] <= rt["lateness_ms_p99"] <= rt["lateness_ms_max"]


@pytest.mark.integration
def test_stop_request_stops_cleanly_with_logs_flushed(mixed_scenario: Path,
                                                      tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    calls = []

    def progress(tick: int, total: int) -> None:
        calls.append(tick)
        if tick == 120:
            run.stop()

    run = Run(scn, tmp_path / "stop", backend="process", workers=2, progress=progress)
    res = run.run()
    assert res.stop_reason == "interrupted" and res.ticks == 120
    t = read_states(res.out_dir)
    assert max(t["tick"].to_pylist()) == 120
    assert _events(res.out_dir)[-1] == {"event": "stop", "tick": 120, "time_s": 1.0,
                                        "vehicle": None, "reason": "interrupted"}


def _cosim(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cosim", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def _wait_for_rows(out: Path, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if (out / "events.jsonl").exists() and any(
                e["event"] == "schedule" for e in _events(out)):
            return
        time.sleep(0.1)
    raise AssertionError("the run did not get going")


@pytest.mark.integration
def test_ctrl_c_stops_cleanly_exit_130(mixed_scenario: Path, tmp_path: Path) -> None:
    out = tmp_path / "c"
    p = _cosim("run", str(mixed_scenario), "--out", str(out), "--realtime", "1",
               "--duration-s", "120", "--workers", "2")
    _wait_for_rows(out)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=10)
    assert p.returncode == 130, err
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "interrupted" and s["realtime"]["ticks"] > 0
    t = read_states(out)
    assert max(t["tick"].to_pylist()) >= 120
    assert _events(out)[-1]["reason"] == "interrupted"


@pytest.mark.integration
def test_worker_killed_mid_run_exit_1_within_5_s_logs_intact(mixed_scenario: Path,
                                                              tmp_path: Path) -> None:
    from tests.fdm_pool.test_pool import _children

    out = tmp_path / "k"
    p = _cosim("run", str(mixed_scenario), "--out", str(out), "--realtime", "1",
               "--duration-s", "120", "--workers", "3")
    _wait_for_rows(out)
    kids = [c for c in _children(p.pid)
            if "cosim" in open(f"/proc/{c}/cmdline").read() or True]
    workers = [c for c in kids if b"spawn_main" in open(f"/proc/{c}/cmdline", "rb").read()]
    assert len(workers) == 2, kids
    t0 = time.monotonic()
    os.kill(workers[-1], signal.SIGKILL)
    _, err = p.communicate(timeout=10)
    assert time.monotonic() - t0 < 5.0
    assert p.returncode == 1, err
    assert "worker 2" in err and "killed by SIGKILL" in err and "nan" in err
    ev = _events(out)
    fail = [e for e in ev if e["event"] == "worker_failure"]
    assert len(fail) == 1 and fail[0]["worker"] == 2 and "nan" in fail[0]["vehicles"]
    assert ev[-1]["reason"] == "worker_failure"
    t = read_states(out)  # readable, every logged tick complete
    ticks = t["tick"].to_numpy()
    assert ticks.max() > 0 and all(np.bincount(ticks)[np.unique(ticks)] == 7)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and any(os.path.exists(f"/proc/{w}") for w in workers):
        time.sleep(0.05)
    assert not [w for w in workers if os.path.exists(f"/proc/{w}")], "orphan workers"


@pytest.mark.integration
def test_stopped_worker_ends_the_run_with_worker_failure(mixed_scenario: Path,
                                                          tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)

    def progress(tick: int, total: int) -> None:
        if tick == 40:
            os.kill(run.pool.pids[1], signal.SIGSTOP)  # type: ignore[union-attr]

    run = Run(scn, tmp_path / "s", backend="process", workers=2, progress=progress,
              step_timeout_s=0.5)
    res = run.run()
    assert res.stop_reason == "worker_failure" and res.ticks == 40
    fail = [e for e in _events(res.out_dir) if e["event"] == "worker_failure"]
    assert fail[0]["worker"] == 1 and "did not finish tick 44 within 0.5 s" in fail[0]["message"]
    assert max(read_states(res.out_dir)["tick"].to_pylist()) == 36


# --- errors name the vehicle ------------------------------------------------------

TERMINATE = """
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0}
duration_s: 1
vehicles:
  - id: v
    count: 4
    model: c172p
    formation: {type: line, spacing_m: 200}
    init: {north_m: 0, east_m: 0, alt_agl_m: 800, heading_deg: 0, airspeed_kt: 95}
schedule:
  - {at_s: 0.5, vehicles: VICTIM, set: {simulation/terminate: 1}}
"""


@pytest.mark.parametrize("backend, workers, victim, where", [
    ("inline", None, "v1", "inline"),
    ("process", 2, "v0", "driver's own shard"),
    ("process", 2, "v3", "child worker"),
], ids=["inline", "process-driver-shard", "process-child"])
def test_a_vehicle_failing_mid_run_is_named_in_the_error_event(
        write_scenario, tmp_path: Path, backend: str, workers: int | None, victim: str,
        where: str) -> None:
    """JSBSim's run() returns False once simulation/terminate is set: a
    VehicleError in-process, a WorkerError from a child; both name the vehicle."""
    scn = load_scenario(write_scenario(TERMINATE.replace("VICTIM", victim)))
    res = run_scenario(scn, tmp_path / "o", backend=backend, workers=workers)
    assert res.stop_reason == "error" and res.ticks == 60, where
    err = [e for e in _events(res.out_dir) if e["event"] == "error"]
    assert len(err) == 1 and err[0]["vehicle"] == victim and err[0]["tick"] == 60, err
    assert "JSBSim run() returned False" in err[0]["message"]
    if where == "child worker":
        from cosim.errors import WorkerError

        assert isinstance(res.error, WorkerError)
        assert err[0]["worker"] == 1 and res.error.vehicle == victim
        assert "VehicleError" in res.error.remote_traceback
    else:
        from cosim.errors import VehicleError

        assert isinstance(res.error, VehicleError)
        assert res.error.vehicle == victim and res.error.tick == 60
        assert str(res.error).startswith(f"vehicle {victim!r} at tick 60: JSBSim run() "
                                         f"returned False")


# --- the schedule, the last tick ---------------------------------------------------

def test_items_a_shorter_duration_leaves_out_are_schedule_skipped_events(
        mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario).with_duration(1.5)  # items at 1 s and 2 s
    res = run_scenario(scn, tmp_path / "o", backend="inline")
    assert res.ok
    ev = _events(res.out_dir)
    assert [e["tick"] for e in ev if e["event"] == "schedule"] == [120]
    skipped = [e for e in ev if e["event"] == "schedule_skipped"]
    assert len(skipped) == 1
    assert skipped[0]["index"] == 1 and skipped[0]["at_s"] == 2.0
    assert skipped[0]["tick"] == 180 and skipped[0]["vehicles"] == 1
    assert ev[-1]["event"] == "stop"  # reported at the end, before the stop
    assert res.summary["events"]["schedule_skipped"] == 1


def test_the_tick_a_run_ends_on_is_logged_once(mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario).with_duration(1.05)  # 128 ticks; logged every 12
    assert scn.total_ticks == 128
    res = run_scenario(scn, tmp_path / "o", backend="inline")
    t = read_states(res.out_dir)
    ticks = t["tick"].to_pylist()
    assert sorted(set(ticks)) == list(range(0, 121, 12)) + [128]
    assert ticks.count(128) == 7 and res.summary["state_rows"] == t.num_rows

    calls = []

    def progress(tick: int, total: int) -> None:  # stopped on a tick that is not logged
        calls.append(tick)
        if tick == 40:
            run.stop()

    run = Run(load_scenario(mixed_scenario), tmp_path / "s", backend="inline",
              progress=progress)
    res = run.run()
    assert res.stop_reason == "interrupted" and res.ticks == 40
    ticks = read_states(res.out_dir)["tick"].to_pylist()
    assert sorted(set(ticks)) == [0, 12, 24, 36, 40] and ticks.count(40) == 7


# --- states survive failures ---------------------------------------------------------

def test_a_failed_state_write_is_an_error_and_the_summary_is_still_written(
        mixed_scenario: Path, tmp_path: Path, monkeypatch) -> None:
    import errno

    import cosim.logs.writers as w

    def disk_full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(w.pq, "write_table", disk_full)
    res = run_scenario(load_scenario(mixed_scenario).with_duration(1.0), tmp_path / "o",
                       backend="inline")
    assert res.stop_reason == "error" and isinstance(res.error, OSError)
    s = json.loads((res.out_dir / "summary.json").read_text())
    assert s["stop_reason"] == "error" and "No space left on device" in s["error"]
    ev = _events(res.out_dir)
    err = [e for e in ev if e["event"] == "error"]
    assert len(err) == 1 and "writing states.parquet failed" in err[0]["message"]
    assert "part-000000.parquet" in err[0]["message"]
    assert ev[-1] == {"event": "stop", "tick": 120, "time_s": 1.0, "vehicle": None,
                      "reason": "error"}
    assert not list((res.out_dir / "states.parquet").glob("*.tmp"))
    monkeypatch.undo()
    t = read_states(res.out_dir)  # every tick is still there, in the journal
    assert sorted(set(t["tick"].to_pylist())) == list(range(0, 121, 12))


def _log_ticks(folder: Path, ticks: list[int], n: int = 3, **kw):
    from cosim.fdm_pool import N_STATE, STATE_INDEX
    from cosim.logs import StateLog

    log = StateLog(folder, [f"v{i}" for i in range(n)], LocalFrame(47.0, 8.0, 400.0), 120.0,
                   **kw)
    for t in ticks:
        s = np.zeros((n, N_STATE))
        s[:, STATE_INDEX["lat_deg"]] = 47.0 + t * 1e-5
        s[:, STATE_INDEX["lon_deg"]] = 8.0
        s[:, STATE_INDEX["alt_msl_m"]] = 1000.0 + np.arange(n)
        log.append(t, s, [f"cmd{t}"] * n)
    return log


def test_state_log_journal_keeps_every_complete_tick_of_a_crashed_run(tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    folder = tmp_path / "states.parquet"
    ticks = [0, 12, 24, 36, 48]
    log = _log_ticks(folder, ticks, flush_rows=9)  # part 0: ticks 0-24; 36, 48 journalled
    # the driver "dies" here: no close(), no part for 36 and 48
    assert sorted(p.name for p in folder.iterdir()) == ["_journal-000001.arrows",
                                                        "part-000000.parquet"]
    ref = _log_ticks(tmp_path / "ref", ticks)
    ref.close()
    t = read_states(folder)
    assert t["tick"].to_pylist() == [x for x in ticks for _ in range(3)]
    assert t.to_pylist() == read_states(tmp_path / "ref").to_pylist()
    assert pq.read_table(folder).num_rows == 9  # other readers see the parts only
    journal = folder / "_journal-000001.arrows"
    data = journal.read_bytes()
    journal.write_bytes(data[:-7])  # the crash cut the last batch short: it is ignored
    assert read_states(folder)["tick"].to_pylist()[-4:] == [24, 36, 36, 36]
    journal.write_bytes(data[:5])  # not even the schema
    assert read_states(folder)["tick"].to_pylist()[-1] == 24
    del log


def test_parts_keep_dictionaries_off_the_columns_that_change_every_tick(tmp_path: Path
                                                                        ) -> None:
    """Written by the log and by ``cosim recover``, a part stores the columns
    that differ in every row (positions, attitudes, speeds) without a
    dictionary (it would overflow: wasted work and bytes) and the others
    (tick, vehicle, command, flags) with one; the values read back the same."""
    import pyarrow.parquet as pq

    from cosim.logs.recover import recover_run

    ticks = [0, 12, 24, 36]
    ref = _log_ticks(tmp_path / "ref", ticks)
    ref.close()
    run = tmp_path / "run"
    log = _log_ticks(run / "states.parquet", ticks, flush_rows=6)  # part 0, then a journal
    recover_run(run)  # the rest of a "killed" run: the journal becomes part 1
    parts = sorted((run / "states.parquet").glob("part-*.parquet"))
    assert [p.name for p in parts] == ["part-000000.parquet", "part-000001.parquet"]
    for part in parts:
        meta = pq.ParquetFile(part).metadata.row_group(0)
        dictionary = {meta.column(i).path_in_schema: meta.column(i).has_dictionary_page
                      for i in range(meta.num_columns)}
        assert not any(dictionary[c] for c in ("lat_deg", "north_m", "yaw_deg", "vd_mps")), part
        assert all(dictionary[c] for c in ("tick", "vehicle", "command", "status")), part
    assert read_states(run).to_pylist() == read_states(tmp_path / "ref").to_pylist()
    del log


def test_a_part_in_place_makes_its_leftover_journal_redundant(tmp_path: Path) -> None:
    folder = tmp_path / "states.parquet"
    log = _log_ticks(folder, [0, 12])
    journal = folder / "_journal-000000.arrows"
    saved = journal.read_bytes()
    log.close()  # writes part 0 and deletes its journal
    journal.write_bytes(saved)  # killed between the rename and the delete
    assert read_states(folder)["tick"].to_pylist() == [0] * 3 + [12] * 3


def test_driver_crash_mid_run_keeps_journalled_ticks_and_a_fault_trace(
        mixed_scenario: Path, tmp_path: Path) -> None:
    """A segfault in the driver: the ticks logged so far are readable and
    faulthandler.log holds the Python traceback."""
    out = tmp_path / "crash"
    script = tmp_path / "crash.py"
    script.write_text(textwrap.dedent(f"""
        import faulthandler
        from cosim.scenario import load_scenario
        from cosim.sync import Run

        def progress(tick, total):
            if tick == 60:
                faulthandler._sigsegv()

        Run(load_scenario({str(mixed_scenario)!r}), {str(out)!r}, backend="inline",
            progress=progress).run()
    """))
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == -signal.SIGSEGV, p.stderr
    s = json.loads((out / "summary.json").read_text())  # the one written at the start
    assert s["complete"] is False and s["stop_reason"] == "running"
    trace = (out / "faulthandler.log").read_text()
    assert "Fatal Python error: Segmentation fault" in trace and "progress" in trace
    t = read_states(out)
    assert sorted(set(t["tick"].to_pylist())) == [0, 12, 24, 36, 48, 60]
    assert t.num_rows == 6 * 7


def test_faulthandler_log_is_removed_when_empty(mixed_scenario: Path, tmp_path: Path) -> None:
    import faulthandler

    was = faulthandler.is_enabled()
    res = run_scenario(load_scenario(mixed_scenario).with_duration(0.2), tmp_path / "o",
                       backend="inline")
    assert res.ok and not (res.out_dir / "faulthandler.log").exists()
    assert faulthandler.is_enabled() == was


def test_a_run_into_an_old_runs_folder_starts_from_empty_outputs(
        mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    out = tmp_path / "o"
    run_scenario(scn.with_duration(2.0), out, backend="inline")
    (out / "states.parquet" / "_journal-000007.arrows").write_bytes(b"left by a crash")
    (out / "notes.txt").write_text("mine")
    res = run_scenario(scn.with_duration(0.5), out, backend="inline")
    assert res.ok
    t = read_states(out)
    assert sorted(set(t["tick"].to_pylist())) == [0, 12, 24, 36, 48, 60]
    ev = _events(out)
    assert [e["event"] for e in ev].count("run_start") == 1
    assert sorted(p.name for p in (out / "states.parquet").iterdir()) == ["part-000000.parquet"]
    assert (out / "notes.txt").read_text() == "mine"


# --- signals -----------------------------------------------------------------------------

def _wait_for(path: Path, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.005)


@pytest.mark.parametrize("delay_s", [0.0, 0.05, 0.2, 1.0])
@pytest.mark.integration
def test_sigterm_to_the_process_group_is_a_clean_stop(mixed_scenario: Path, tmp_path: Path,
                                                      delay_s: float) -> None:
    """What `timeout`, systemd and Ctrl-C in a terminal do: the signal reaches
    the workers too. They ignore it (even while starting up); the driver stops
    the run cleanly."""
    out = tmp_path / "t"
    p = _cosim("-q", "run", str(mixed_scenario), "--out", str(out), "--duration-s", "600",
               "--workers", "3", "--no-progress", start_new_session=True)
    try:
        _wait_for(out / "events.jsonl")  # the CLI's handlers are in place
        time.sleep(delay_s)
        os.killpg(p.pid, signal.SIGTERM)
        _, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "terminated", err
    ev = _events(out)
    assert not [e for e in ev if e["event"] in ("worker_failure", "error")], ev
    assert ev[-1]["reason"] == "terminated"


@pytest.mark.integration
def test_ctrl_c_during_the_build_aborts_it_promptly(tmp_path: Path) -> None:
    """1000 vehicles take seconds to build: Ctrl-C stops the build, not after it."""
    out = tmp_path / "b"
    p = _cosim("-q", "run", str(SWARM1000), "--out", str(out), "--workers", "2",
               "--no-progress", start_new_session=True)
    try:
        _wait_for(out / "events.jsonl")
        time.sleep(1.0)
        os.killpg(p.pid, signal.SIGINT)
        t0 = time.monotonic()
        _, err = p.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert took < 2.0, f"took {took:.1f} s to stop"
    s = json.loads((out / "summary.json").read_text())
    assert s["stop_reason"] == "interrupted" and s["ticks"] == 0
    assert _events(out)[-1]["reason"] == "interrupted"
