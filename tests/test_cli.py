"""The cosim command line: exit codes, messages, every bundled scenario runs."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.logs import read_states

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = sorted((REPO / "scenarios").rglob("*.yaml"))


def test_quickstart_runs_and_says_where_outputs_are(tmp_path: Path, capsys) -> None:
    out = tmp_path / "q"
    assert main(["run", str(REPO / "scenarios/quickstart.yaml"), "--out", str(out),
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "completed: 5 vehicles" in printed and str(out) in printed
    s = json.loads((out / "summary.json").read_text())
    assert s["backend"] == "process" and s["stop_reason"] == "completed"
    assert read_states(out).num_rows == 5 * (600 + 1)


def test_refuses_to_overwrite_a_run_unless_asked(tmp_path: Path, capsys) -> None:
    args = ["run", str(REPO / "scenarios/quickstart.yaml"), "--out", str(tmp_path / "o"),
            "--duration-s", "0.5", "--backend", "inline", "--no-progress"]
    assert main(args) == 0
    assert main(args) == 2
    assert "already holds a run" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    assert read_states(tmp_path / "o").num_rows == 5 * 6


def test_bad_scenario_exit_2_lists_every_problem_with_lines(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "swarm8.yaml"
    bad.write_text(
        "schema_version: 1\n"
        "origin: {lat_deg: 37, lon_deg: -122}\n"
        "duration_s: 10\n"
        "rates: {physics_hz: 100, control_hz: 30}\n"
        "vehicles:\n"
        "  - id: x\n"
        "    model: c172q\n"
        "    init: {alt_m: high, airspeed_kt: 90}\n")
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert f"{bad}:4: rates.control_hz: control_hz 30 must divide physics_hz 100" in err[0]
    assert any(line.startswith(f"{bad}:7: vehicles[0].model: unknown aircraft model 'c172q'")
               and "c172p" in line for line in err)
    assert any(line.startswith(f"{bad}:8: vehicles[0].init.alt_m: unknown key 'alt_m'")
               for line in err)
    assert any("missing the altitude" in line for line in err)
    assert main(["run", str(bad), "--out", str(tmp_path / "r")]) == 2
    assert not (tmp_path / "r").exists()


def test_usage_errors_exit_2(tmp_path: Path, capsys) -> None:
    assert main(["run"]) == 2
    assert main(["run", "x.yaml", "--backend", "gpu"]) == 2
    assert main(["run", "x.yaml", "--realtime", "0"]) == 2
    assert main(["bench", "--vehicles", "0,5"]) == 2
    assert main(["run", str(tmp_path / "missing.yaml")]) == 2
    assert "cannot read scenario" in capsys.readouterr().err
    assert main([]) == 2
    # an option the backend does not take: refused before anything is built
    out = tmp_path / "r"
    assert main(["run", str(REPO / "scenarios" / "quickstart.yaml"), "--address", "10.0.0.1:6379",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--address: the process backend does not take it; backends that do: ray" in err
    assert not out.exists()
    assert main(["run", str(REPO / "scenarios" / "quickstart.yaml"), "--backend", "inline",
                 "--coordinating-driver", "--out", str(out)]) == 2
    assert ("--coordinating-driver: the inline backend has no driver share to give up; "
            "backends that do: process") in capsys.readouterr().err
    assert main(["bench", "--backend", "inline", "--coordinating-driver", "--vehicles", "2"]) == 2
    assert "--coordinating-driver: the inline backend" in capsys.readouterr().err
    assert not out.exists()


def test_a_backend_missing_its_library_is_a_usage_error(tmp_path: Path, capsys,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    out = tmp_path / "r"
    assert main(["run", str(REPO / "scenarios" / "quickstart.yaml"), "--backend", "ray",
                 "--out", str(out)]) == 2
    # this cosim is a checkout: the extra is installed from it, not from PyPI
    assert f"the ray backend needs Ray: pip install -e '{REPO}[ray]'" in capsys.readouterr().err
    assert not out.exists()


def test_an_extra_is_installed_the_way_cosim_was(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path) -> None:
    from cosim import errors

    assert errors.install_extra("view") == f"pip install -e '{REPO}[view]'"
    installed = tmp_path / "site-packages" / "cosim"
    installed.mkdir(parents=True)
    monkeypatch.setattr(errors, "__file__", str(installed / "errors.py"))
    assert errors.install_extra("view") == "pip install 'cosim[view]'"


def test_help_lists_every_command_in_its_rank_order(capsys) -> None:
    """The sections' commands (sweep, search-plan, swarm) sit among the
    CLI's own where their ranks put them, as they always have."""
    assert main(["--help"]) == 0
    listed = re.findall(r"^    (\S+)  ", capsys.readouterr().out, flags=re.M)
    assert listed == ["run", "validate", "models", "plot", "export", "recover", "replay",
                      "sweep", "visibility", "search-plan", "trials", "swarm", "bench"]


def test_models_lists_bundled_aircraft(capsys) -> None:
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert any(line.split()[0] == "c172p" and "jsbsim" in line for line in out.splitlines())


def test_models_say_which_take_commands(capsys) -> None:
    assert main(["models"]) == 0
    rows = {line.split()[0]: line.split() for line in capsys.readouterr().out.splitlines()[1:]
            if line.strip() and not line.startswith("COMMANDS")}
    assert rows["c172p"][2:4] == ["fixed_wing", "yes"]
    assert rows["F450"][2:4] == ["quadrotor", "yes"]
    assert rows["737"][2:4] == ["jsbsim", "no"]


def test_models_check_keeps_jsbsim_quiet_and_says_why_one_fails(capsys) -> None:
    """JSBSim's console messages (78 lines: warnings of every bundled model)
    are held; a model that does not load says its first error, once."""
    assert main(["models", "--check"]) == 1  # JSBSim's bundled 'blank' does not load
    out, err = capsys.readouterr()
    assert err == ""
    assert re.search(r"^(\d+) of \1 models load$", out, re.M) is None
    assert re.search(r"^\d+ of \d+ models load\n  blank: YOU HAVE AN INCOMPATIBLE CFG FILE",
                     out, re.M)


def test_models_classes_lists_the_registered_classes(capsys) -> None:
    from cosim.vehicles import vehicle_classes

    assert main(["models", "--classes"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert names == list(vehicle_classes()) and names[:2] == ["fixed_wing", "jsbsim"]


def test_models_properties(capsys) -> None:
    assert main(["models", "--properties", "c172p"]) == 0
    assert "fcs/throttle-cmd-norm" in capsys.readouterr().out


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
@pytest.mark.integration
def test_every_bundled_scenario_validates_and_runs(path: Path, tmp_path: Path) -> None:
    assert main(["validate", str(path)]) == 0
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--duration-s", "1",
                 "--no-progress"]) == 0
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["stop_reason"] == "completed" and s["sim_time_s"] == 1.0


def test_bench_whole_run_says_where_the_tick_loop_time_goes(tmp_path: Path, capsys) -> None:
    out = tmp_path / "b.json"
    assert main(["bench", "--model", "uav700", "--vehicles", "6", "--seconds", "0.5",
                 "--repeat", "1", "--no-baselines", "--whole-run", "--control-hz", "10",
                 "--log-hz", "5", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["whole_run"] and doc["log_hz"] == 5
    r = doc["results"][0]
    assert r["run_rtf"] > 0 and r["run_startup_s"] > 0 and r["log_hz"] == 5
    split = r["run_split"]
    assert set(split) == {"stepping", "guidance", "logging", "other"}
    assert sum(split.values()) == pytest.approx(1.0, abs=0.02)
    # the loiter command reached guidance, the states were logged, the pool stepped
    assert split["stepping"] > 0 and split["guidance"] > 0 and split["logging"] > 0
    assert "Guidance.before_step" in r["run_time_split_s"]
    assert "run RTF" in capsys.readouterr().out


@pytest.mark.integration
def test_bench_reports_ratios_measured_in_the_same_run(tmp_path: Path, capsys) -> None:
    out = tmp_path / "b.json"
    assert main(["bench", "--vehicles", "4", "--seconds", "0.5", "--workers", "2", "--repeat", "2",
                 "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    r = doc["results"][0]
    for key in ("pool_steps_per_s", "pool_rtf", "serial_steps_per_s", "speedup_vs_serial",
                "ceiling_steps_per_s", "fraction_of_ceiling", "overhead_us_per_exchange",
                "startup_s", "pool_mib", "kib_per_aircraft"):
        assert r[key] > 0, key
    assert r["kib_per_aircraft"] == pytest.approx(r["pool_mib"] * 1024 / 4)
    assert len(r["pool_s_all"]) == len(r["serial_s_all"]) == len(r["ceiling_s_all"]) == 2
    per_round = sorted(s / p for s, p in zip(r["serial_s_all"], r["pool_s_all"]))
    assert r["speedup_vs_serial"] == pytest.approx(sum(per_round) / 2)  # median of two
    assert r["pool_steps_per_s"] == pytest.approx(4 * 60 / min(r["pool_s_all"]))
    assert r["vehicles"] == 4 and r["ticks"] == 60
    # the hot-step limit: the cores the pool can use, each stepping a hot flight model
    cores = min(2, len(os.sched_getaffinity(0)))
    assert r["hot_step_us"] > 0
    assert r["hot_limit_steps_per_s"] == pytest.approx(cores / (r["hot_step_us"] * 1e-6))
    assert 0 < r["fraction_of_hot_limit"] < 2
    assert "of hot" in capsys.readouterr().out


@pytest.mark.integration
def test_bench_flies_the_batched_tier_and_draws_the_scaling_plot(tmp_path: Path,
                                                                 capsys) -> None:
    """--class fixed_wing_batched benches the point-mass tier (its baselines
    step the same batched model); --plot draws real-time factor and
    efficiency against N, one point per size."""
    import matplotlib.image

    out, png = tmp_path / "b.json", tmp_path / "scaling.png"
    assert main(["bench", "--model", "uav700", "--class", "fixed_wing_batched", "--vehicles",
                 "50,500", "--seconds", "0.5", "--workers", "2", "--repeat", "1",
                 "--json", str(out), "--plot", str(png)]) == 0
    doc = json.loads(out.read_text())
    assert doc["class"] == "fixed_wing_batched"
    assert [r["vehicles"] for r in doc["results"]] == [50, 500]
    for r in doc["results"]:  # the baselines step the batched model too
        assert r["pool_rtf"] > 0
        assert 0.1 < r["speedup_vs_serial"] < 10 and 0.1 < r["fraction_of_ceiling"] < 10
    img = matplotlib.image.imread(png)
    assert img.shape[0] > 300 and img.shape[1] > 800
    assert "(fixed_wing_batched)" in capsys.readouterr().out
    assert main(["bench", "--class", "nope", "--vehicles", "2"]) == 2
    assert "unknown vehicle class 'nope'" in capsys.readouterr().err


def test_plot_writes_a_png_for_a_run(tmp_path: Path, capsys) -> None:
    scn = tmp_path / "p.yaml"
    scn.write_text((REPO / "scenarios/quickstart.yaml").read_text()
                   .replace("duration_s: 60", "duration_s: 12\nplot: true"))
    out = tmp_path / "run"
    assert main(["run", str(scn), "--out", str(out), "--backend", "inline",
                 "--no-progress"]) == 0
    png = out / "track.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    png.unlink()
    assert main(["plot", str(out)]) == 0
    assert png.exists()
    assert main(["plot", str(tmp_path)]) == 2
    assert "not a cosim run folder" in capsys.readouterr().err


# --- every failure is one line and an exit code, never a traceback --------------------

def _quick_run(tmp_path: Path, out: Path | str, *extra: str) -> list[str]:
    return ["run", str(REPO / "scenarios/quickstart.yaml"), "--out", str(out),
            "--duration-s", "0.5", "--backend", "inline", "--no-progress", *extra]


def test_out_that_is_a_file_is_a_usage_error(tmp_path: Path, capsys) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    assert main(_quick_run(tmp_path, f)) == 2
    assert f"--out {f}: exists and is not a folder" in capsys.readouterr().err
    assert main(_quick_run(tmp_path, f / "sub")) == 1  # an OSError: one line, exit 1
    err = capsys.readouterr().err
    assert err.startswith("cosim run: [Errno 20] Not a directory") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_a_failed_state_write_exits_1_with_one_line(tmp_path: Path, capsys,
                                                    monkeypatch) -> None:
    import errno

    import cosim.logs.writers as w

    def disk_full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(w.pq, "write_table", disk_full)
    out = tmp_path / "o"
    assert main(["-q"] + _quick_run(tmp_path, out)) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"cosim run: [Errno 28] cannot write {out}/states.parquet/part-000000.parquet: " \
           f"No space left on device" in err.splitlines()
    assert json.loads((out / "summary.json").read_text())["stop_reason"] == "error"


def test_a_scenario_that_is_not_utf8_is_a_config_error(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes("name: caf\xe9\n".encode("latin-1"))
    assert main(["validate", str(bad)]) == 2
    assert f"{bad}:1: cannot read scenario: not UTF-8 text (byte 0xe9 at offset 9)" in \
        capsys.readouterr().err
    assert main(["run", str(bad), "--out", str(tmp_path / "o")]) == 2


def test_validate_reports_every_file_even_after_a_jsbsim_error(tmp_path: Path,
                                                               capsys) -> None:
    (tmp_path / "acft" / "broken").mkdir(parents=True)
    (tmp_path / "acft" / "broken" / "broken.xml").write_text(
        '<?xml version="1.0"?>\n<fdm_config name="broken"><metrics>')
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        "schema_version: 1\naircraft_path: acft\nvehicles:\n"
        "  - {id: a, model: broken, init: {alt_msl_m: 500, airspeed_kt: 90},"
        " set: {fcs/throttle-cmd-norm: 1}}\n")
    good = REPO / "scenarios/quickstart.yaml"
    assert main(["-q", "validate", str(broken), str(good)]) == 2
    out, err = capsys.readouterr()
    assert f"{good}: ok" in out
    assert f"{broken}: JSBSim could not load model 'broken'" in err and "Traceback" not in err


def test_bench_usage_errors_exit_2_before_running_anything(tmp_path: Path, capsys,
                                                           monkeypatch) -> None:
    import cosim.bench.pool as bench_pool

    def must_not_run(*a, **k):
        raise AssertionError("the bench ran")

    monkeypatch.setattr(bench_pool, "bench_size", must_not_run)
    assert main(["bench", "--vehicles", "2", "--workers", "0"]) == 2
    assert "--workers must be >= 1, got 0" in capsys.readouterr().err
    assert main(["bench", "--vehicles", "2", "--json", "/nonexistent/dir/x.json"]) == 2
    assert "--json /nonexistent/dir/x.json: folder /nonexistent/dir does not exist" in \
        capsys.readouterr().err
    assert main(["bench", "--vehicles", "2", "--json", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert main(["bench", "--vehicles", "2", "--physics-hz", "100", "--control-hz", "30"]) == 2
    assert "control_hz 30 must divide physics_hz 100" in capsys.readouterr().err


def test_a_bad_value_past_the_parser_is_exit_2(monkeypatch, capsys) -> None:
    import cosim.bench.pool as bench_pool

    def bad(*a, **k):
        raise ValueError("repeat must be small")

    monkeypatch.setattr(bench_pool, "run_bench", bad)
    assert main(["bench", "--vehicles", "2"]) == 2
    assert capsys.readouterr().err == "cosim bench: repeat must be small\n"


def test_bench_closes_the_pool_when_the_baselines_fail(monkeypatch) -> None:
    import cosim.bench.pool as bench

    closed = []
    real = bench.make_pool

    def spy(*a, **k):
        pool = real(*a, **k)
        orig = pool.close
        pool.close = lambda: (closed.append(True), orig())[1]  # type: ignore[method-assign]
        return pool

    class Boom(Exception):
        pass

    def no_ceiling(*a, **k):
        raise Boom

    monkeypatch.setattr(bench, "make_pool", spy)
    monkeypatch.setattr(bench, "_Ceiling", no_ceiling)
    with pytest.raises(Boom):
        bench.bench_size(2, "c172p", "process", 2, 0.1, 120.0, 30.0)
    assert closed == [True]


def test_a_dead_ceiling_process_is_an_error_not_a_hang() -> None:
    import os
    import re
    import signal
    import threading
    import time

    from cosim.bench.fleet import bench_specs
    from cosim.bench.pool import _Ceiling
    from cosim.errors import CosimError

    c = _Ceiling(bench_specs(2), 1 / 120, 8, 4, workers=2)
    errors: list[BaseException] = []

    def measure() -> None:  # in a thread: a regression must fail, not hang the suite
        try:
            c.segment()
            c.segment()
        except BaseException as e:
            errors.append(e)

    try:
        os.kill(c.procs[1].pid, signal.SIGKILL)
        t0 = time.monotonic()
        th = threading.Thread(target=measure, daemon=True)
        th.start()
        th.join(5.0)
        assert not th.is_alive(), "segment() hangs on a dead ceiling process"
        assert time.monotonic() - t0 < 3.0
    finally:
        c.close()
    assert len(errors) == 1 and isinstance(errors[0], CosimError), errors
    assert re.search(r"ceiling process 1 \(pid \d+\) ended with code -9", str(errors[0]))
    assert not any(p.is_alive() for p in c.procs)


def test_validate_checks_every_sweep_combination(tmp_path: Path, capsys) -> None:
    """A cell the first combination does not reach (400 kt, beyond the
    uav700's envelope) fails validate as it would fail the sweep, named by
    its combination; the bundled sweep passes with every combination."""
    src = (Path(__file__).resolve().parent.parent / "scenarios" / "conspicuity" /
           "altitude_speed.yaml")
    bad = tmp_path / "fast.yaml"
    bad.write_text(src.read_text().replace("speed_kt: [50, 100, 200]", "speed_kt: [50, 100, 400]"))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    # the 12 combinations at 400 kt, said once for the start and once for the command
    lines = err.splitlines()
    assert len(lines) == 2 and all(line.startswith(
        "sweep combinations speed_kt=400, alt_agl_m=any, target=any (12 of 36): ")
        for line in lines), err
    assert "starts at 400.0 kt, outside the envelope" in lines[0]
    assert "airspeed 400.0 kt is outside the envelope" in lines[1]
    assert main(["validate", str(src)]) == 0
    assert "all 36 sweep combinations" in capsys.readouterr().out


def test_sweep_has_a_default_out_folder(tmp_path: Path, monkeypatch, capsys) -> None:
    """Like cosim run, cosim sweep needs no --out: runs/<file>-sweep-<time>."""
    src = Path(__file__).resolve().parent.parent / "scenarios" / "conspicuity" / \
        "altitude_speed.yaml"
    small = tmp_path / "tiny.yaml"
    text = src.read_text().replace("speed_kt: [50, 100, 200]", "speed_kt: [100]")
    text = text.replace("alt_agl_m: [30, 100, 200, 250, 300, 500]", "alt_agl_m: [100]")
    small.write_text(text.replace("target: [truck, fire_truck]", "target: [truck]"))
    monkeypatch.chdir(tmp_path)
    assert main(["-q", "sweep", str(small), "--duration-s", "1"]) == 0
    made = list((tmp_path / "runs").glob("tiny-sweep-*"))
    assert len(made) == 1 and (made[0] / "visibility.csv").exists()
    assert str(Path("runs") / made[0].name) in capsys.readouterr().out


def test_user_facing_text_names_no_issues_and_no_internal_documents() -> None:
    """README, docs, benchmarks' README, the scenario files and the code's own
    comments are for users and contributors: no issue numbers they cannot
    look up, no links to design notes outside the repository (the equations
    the code cites are in docs/physics.md)."""
    import re

    root = Path(__file__).resolve().parent.parent
    files = [root / "README.md", root / "benchmarks" / "README.md",
             *(root / "docs").glob("*.md"), *(root / "scenarios").rglob("*.yaml"),
             *(p for d in ("cosim", "benchmarks", "examples") for p in (root / d).rglob("*.py")),
             *(p for p in (root / "tests").rglob("*.py") if p.name != "test_cli.py")]
    bad = re.compile(r"\b[Ii]ssues? #?\d+\b|DESIGN\.md|\.\./shared")
    found = [f"{p.relative_to(root)}:{n}: {line.strip()}" for p in files
             for n, line in enumerate(p.read_text().splitlines(), 1) if bad.search(line)]
    assert not found, "\n".join(found)
