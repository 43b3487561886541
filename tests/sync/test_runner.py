"""The lockstep run loop: outputs, events, determinism, pacing, clean stops."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest
import yaml

from cosim.geo import LocalFrame
from cosim.logs import STATE_COLUMNS, read_states
from cosim.scenario import load_scenario
from cosim.sync import Run, run_scenario

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
    assert tuple(t.column_names) == STATE_COLUMNS
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
    assert [e["vehicle"] for e in div] == ["nan"] and div[0]["tick"] == 244  # 2 s + 1 exchange
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
    assert all(np.isfinite(nan["alt_msl_m"].to_numpy()))
    a0 = t.filter(pc.equal(veh, "a0"))
    assert set(a0["status"].to_pylist()) == {0}
    assert a0["north_m"].to_numpy()[-1] - a0["north_m"].to_numpy()[0] > 200  # still flying
    s = json.loads((res.out_dir / "summary.json").read_text())
    assert s["events"]["ground_impact"] == 1 and s["events"]["divergence"] == 1


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
    assert read_states(a.out_dir).equals(read_states(b.out_dir))


def test_different_seed_changes_only_random_state(write_scenario, tmp_path: Path) -> None:
    text = (Path(__file__).parent.parent / "conftest.py").read_text()
    del text  # the mixed scenario has no turbulence: seeds must not change its physics
    from tests.conftest import MIXED

    s1 = load_scenario(write_scenario(MIXED, "a.yaml"))
    s2 = load_scenario(write_scenario(MIXED.replace("seed: 7", "seed: 8"), "b.yaml"))
    assert [v.random_seed for v in s1.vehicles] != [v.random_seed for v in s2.vehicles]


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
