"""The benchmark scripts still run and their breakdowns add up (a few frames; the
figures themselves are for benchmarks/README.md, not for assertions)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))

pytest.importorskip("av")


pytestmark = pytest.mark.integration  # the benchmark scripts


def test_render_bench_parts_add_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import render_bench

    from cosim.core.cache import CACHE_ENV
    from cosim.renderer import tile_cache

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))  # per_frame sets it: restored after the test
    monkeypatch.delenv(tile_cache.CACHE_ENV, raising=False)  # the tile cache on
    monkeypatch.setattr(cv2, "setNumThreads", lambda n: None)  # and this, for the process
    f = render_bench.per_frame(6, str(tmp_path / "ground"))
    assert f["tiles_generated"] > 0 and f["tiles_from_disk"] == 0
    # each part was caught where it runs, and the parts fit inside the whole
    assert 0 < f["codec_ms"] < f["encode_ms"]
    assert f["warp_ms"] > 0 and f["tiles_ms"] > 0
    assert f["encode_ms"] + f["warp_ms"] + f["tiles_ms"] < f["cpu_ms"]
    again = render_bench.per_frame(6, str(tmp_path / "ground"))
    assert again["tiles_generated"] == 0 and again["tiles_from_disk"] == f["tiles_generated"]


def test_render_bench_times_the_sensor_apart(tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import render_bench

    from cosim.core.cache import CACHE_ENV
    from cosim.core.camera import SensorSpec

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(cv2, "setNumThreads", lambda n: None)
    sensor = render_bench._sensor("{vignetting: cos4, snr_db: 30}")
    assert sensor == SensorSpec(vignetting=1.0, snr_db=30.0)
    f = render_bench.per_frame(3, str(tmp_path / "ground"), sensor=sensor)
    assert 0 < f["sensor_ms"] < f["cpu_ms"]
    assert render_bench.per_frame(3, str(tmp_path / "ground"))["sensor_ms"] == 0


def test_render_bench_times_the_datalink_apart(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import render_bench

    from cosim.core.cache import CACHE_ENV

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(cv2, "setNumThreads", lambda n: None)
    link = render_bench._camera("datalink", "{bitrate_kbps: 1000}", 15.0).datalink
    assert link is not None and link.rate_hz == 15.0 and link.every == 1
    f = render_bench.per_frame(3, str(tmp_path / "ground"), datalink=link)
    assert 0 < f["datalink_ms"] < f["cpu_ms"] and f["encode_ms"] == 0


def test_floor_bench_runs() -> None:
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks/floor_bench.py"),
                           "--frames", "4", "--rounds", "1"], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "encoder mpeg4 q4 (mp4v, the default)" in out and "(4 frames decoded)" in out
    assert "warp bilinear BGRA perspective (the renderer's)" in out
    assert "floor of a frame with these libraries" in out


def test_camera_rate_renders_the_same_frames_either_way() -> None:
    """Exit 1 if the two ways of making a 30 Hz camera's frames differ."""
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks/camera_rate.py"),
                           "--vehicles", "3", "--seconds", "1", "--rounds", "1"], cwd=REPO,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "frames identical: True" in proc.stdout and "30 frames" in proc.stdout


def test_the_gymnasium_reference_steps_the_same_aircraft_as_the_pool() -> None:
    """The reference is like for like: after the same exchanges, gymnasium's
    observations are the pool's state rows, bit for bit."""
    pytest.importorskip("gymnasium")
    from gymnasium.vector import AsyncVectorEnv

    from cosim.bench.fleet import bench_specs
    from cosim.bench.gym import _make, compare
    from cosim.fdm_pool import make_pool

    n, dt = 3, 1 / 120
    envs = AsyncVectorEnv([_make(i, n, dt, 4) for i in range(n)], shared_memory=True)
    try:
        envs.reset(seed=0)
        for _ in range(5):
            obs = envs.step(np.zeros((n, 1)))[0]
    finally:
        envs.close()
    with make_pool(bench_specs(n, "uav700"), dt, (), "process", 2) as pool:
        for _ in range(5):
            states = pool.step(4)
        assert np.array_equal(obs, states)
    r = compare(n, 0.2, 1)
    assert r["gym_steps_per_s"] > 0 and r["pool_over_gym"] > 0


def test_trials_error_rates_runs() -> None:
    import trials_error_rates

    r = trials_error_rates.rates(2)
    assert r["sets"] == 2 and r["screen_false_plateau"] == 0
    assert r["ground_plateau"] == 2 and r["step_flagged"] <= r["step_plateau"]
    covered, fits = trials_error_rates.coverage(2, 10)
    assert 0 <= covered <= fits <= 2
    found, bad, good = trials_error_rates.off_level(2, 12, 0.25)
    assert bad == found and good == 0


def test_trials_analyse_speed_writes_what_it_analyses(tmp_path: Path) -> None:
    """The speed benchmark's responses are valid, and continuous altitudes
    are binned (the figures' sizes are for benchmarks/README.md)."""
    import trials_analyse_speed

    from cosim.trials.analysis import analyse
    from cosim.trials.conditions import MAX_LEVELS

    src = tmp_path / "r.csv"
    assert trials_analyse_speed.responses_csv(src, 600, 20, "continuous") == 600
    s = analyse(src, tmp_path / "out", n_boot=20, plots=False)
    assert s["rows"] == 600
    assert len(s["binned_conditions"]["conspicuity"]["condition_alt_agl_m"]) == MAX_LEVELS


def test_realism_measures_each_camera(tmp_path: Path) -> None:
    import json

    out = tmp_path / "a.json"
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks/realism.py"), "--frames", "2",
                           "--max-s", "1", "--json", str(out), "scenarios/cameras/flyover.yaml"],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "scenarios/cameras/flyover.yaml" in proc.stdout and "uav1/belly" in proc.stdout
    assert "goal: 1.6 to 2.6" in proc.stdout
    got = json.loads(out.read_text())["scenarios/cameras/flyover.yaml:uav1/belly"]
    assert len(got["exponent"]) == 2 and all(1.0 < a < 4.0 for a in got["exponent"])
    # each camera's verdict on its median, and how many met the goal
    row = next(r for r in proc.stdout.splitlines() if "uav1/belly" in r)
    assert row.rsplit("| ", 1)[1] in ("met", "too flat", "too steep")
    assert "of 1 cameras within the goal" in proc.stdout


def test_realism_verdict() -> None:
    from realism import within

    assert [within(a) for a in (1.6, 2.0, 2.6)] == ["met"] * 3
    assert within(1.59) == "too flat" and within(2.61) == "too steep"
    assert within(float("nan")) == "no fit (flat image)"


def test_live_console_bench_reports_one_small_trial(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """One feed of studies/live_search.yaml at 160 x 90 for 2 s, followed by
    headless Debian Chromium: the row's counts are those of the run and the
    page, in order, and its shares and costs are worked out from them."""
    import json
    import re

    if not Path("/usr/bin/chromium").exists():
        pytest.skip("no /usr/bin/chromium")
    import live_console_bench as bench

    out = tmp_path / "live.json"
    assert bench.main(["--condition", "feeds1", "--size", "160x90", "--duration-s", "2",
                       "--backend", "inline", "--out", str(out)]) == 0
    (r,) = json.loads(out.read_text())["rows"]
    assert (r["condition"], r["feeds"], r["size"], r["stop_reason"]) == (
        "feeds1", 1, "160x90", "completed")
    # the tap publishes every frame the feed's camera rendered (only it renders)
    assert r["frames_published"] == r["frames_rendered"] >= 20
    assert 0 < r["frames_drawn"] <= r["frames_received"] <= r["frames_published"]
    assert r["page_skipped"] == r["frames_received"] - r["frames_drawn"]
    assert r["lost_percent"] == pytest.approx(
        100 * (r["server_dropped"] + r["page_skipped"]) / r["frames_published"], abs=0.01)
    # the page's clock offset is known to within half its quickest round trip
    # (tens of ms under load), more than a 160 x 90 frame's latency on loopback
    assert 0 <= r["clock_rtt_ms"] < 1000
    assert -r["clock_rtt_ms"] / 2 <= r["latency_ms_p50"] <= r["latency_ms_p95"] \
        <= r["latency_ms_max"] < 60_000
    assert r["counter_mismatches"] == 0 and r["real_time_factor"] > 0.2
    assert r["jpeg_ms_per_frame"] > 0 and r["lateness_ms_p50"] >= 0
    # inline: the flight models step in the run's thread, no fdm workers
    assert all(r["cores"][k] > 0 for k in ("run", "render", "browser")) and "fdm" not in r["cores"]
    parts = {k: v for k, v in r["cores"].items() if k not in ("machine", "others", "browser")}
    assert r["cores"]["machine"] >= sum(parts.values()) - 0.01
    assert r["cores"]["browser"] == pytest.approx(
        sum(v for k, v in parts.items() if k.startswith("browser:")), abs=0.005)
    assert r["cores"]["browser:renderer"] > 0  # the page's own process
    for argv, said in ((["--vary", "colour=red"], "expected LEVER=V1,V2 with a lever of size"),
                       (["--condition", "feeds3"], "no condition feeds3 in .*live_search.yaml; "
                                                   "it has feeds1, feeds4, feeds9, feeds16")):
        with pytest.raises(SystemExit, match="^2$"):
            bench.main(argv)
        assert re.search(said, capsys.readouterr().err)
    # the page's earlier variants still apply to static/live.js as it is
    now = bench.page_script("now")
    assert all(bench.page_script(v) != now for v in bench.PAGE_VARIANTS if v != "now")


def test_startup_cost_splits_a_pools_start(tmp_path: Path) -> None:
    """Its parts fit together: the worker's start-up and build make the
    start, the driver builds within it, JSBSim's calls within a Vehicle's
    build, and the floor is half the aircraft times JSBSim's cost."""
    import json

    out = tmp_path / "startup.json"
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks/startup_cost.py"),
                           "--vehicles", "4", "--phases", "2", "--rounds", "1",
                           "--json", str(out)], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "4 uav700, 2 workers; medians of 1 rounds" in proc.stdout
    (row,) = next(iter(json.loads(out.read_text())["runs"].values()))
    assert 0 < row["worker_build_s"] < row["start_s"]
    assert row["worker_startup_s"] == pytest.approx(row["start_s"] - row["worker_build_s"])
    assert 0 < row["driver_build_s"] < row["start_s"]
    assert row["jsbsim_ms"] == pytest.approx(
        row["ctor_ms"] + row["load_ms"] + row["ic_ms"] + row["trim_ms"])
    assert row["floor_s"] == pytest.approx(2 * row["jsbsim_ms"] / 1e3)
    bad = subprocess.run([sys.executable, str(REPO / "benchmarks/startup_cost.py"),
                          "--tree", str(tmp_path)], cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "not a cosim source tree" in bad.stderr


def test_whole_run_pool_replays_the_runs_flight_through_the_pool() -> None:
    """The pool alone is given the run's setpoints and must end in the run's
    states (exit 1 otherwise); bad sizes are a usage error."""
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks/whole_run_pool.py"),
                           "--vehicles", "4", "--rounds", "1"], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "N 4 round 1 (load" in proc.stdout and "N 4: medians run / pool" in proc.stdout
    bad = subprocess.run([sys.executable, str(REPO / "benchmarks/whole_run_pool.py"),
                          "--vehicles", "4,x"], cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2
    assert "expected fleet sizes such as 1024,2048, got '4,x'" in bad.stderr


def test_rigid_fidelity_flies_the_tiers_beside_jsbsim(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Five seconds of the 100 kt level turn: the rigid tier within the bar
    everywhere (a drift of half a metre, knot or degree fails it), the point
    mass, which turns later than JSBSim, outside it on heading and bank; the
    trims at every point, the rigid's within 0.1 deg; bad names exit 2."""
    import json
    import re

    import rigid_fidelity

    out = tmp_path / "f.json"
    assert rigid_fidelity.main(["--manoeuvres", "turn_100kt", "--duration", "5",
                                "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    assert "| level turns at 100 kt (45 deg bank) | rigid |" in capsys.readouterr().out
    (turn,) = got["manoeuvres"].values()
    rigid, pm = turn["rigid"], turn["point_mass"]
    assert rigid["same_length"] and rigid["seconds"] == pytest.approx(5.0, abs=0.05)
    for q in ("alt_m", "airspeed_kt", "heading_deg", "bank_deg"):
        assert rigid[q]["within"] and rigid[q]["max_diff"] < rigid[q]["bar_there"], q
    assert rigid["within_bar"]
    assert rigid["bank_deg"]["value_range"][1] > 40  # it banked to the limit
    assert not pm["within_bar"] and not pm["heading_deg"]["within"]
    assert [(r["airspeed_kt"], r["alt_msl_m"]) for r in got["trim"]] == list(
        rigid_fidelity.TRIM_POINTS)
    for row in got["trim"]:
        assert row["rigid"]["within_bar"], row
        assert abs(row["rigid"]["diff"]["alpha_deg"]) < 1e-3
        assert abs(row["rigid"]["diff"]["throttle"]) < 1e-4
    with pytest.raises(SystemExit) as ei:
        rigid_fidelity.main(["--manoeuvres", "loop", "--tiers", "rigid"])
    assert ei.value.code == 2
    assert re.search(r"unknown manoeuvre or tier \['loop'\]", capsys.readouterr().err)
