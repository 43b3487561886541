"""Run every combination of a sweep, in parallel, and tabulate the results.

Parallelism: one process per run (``spawn``), at most ``jobs`` at a time
(default: one per core), each running its scenario with the **inline**
backend and inline rendering (``cameras.render_workers`` forced to 0). The
runs are independent, so running whole runs side by side uses every core
with no per-tick communication at all, while worker processes inside each
run would multiply the process count past the cores and add a round trip
per tick; the inline backend is also the reference every other backend is
tested against, so the results are the same as ``cosim run`` gives. A run
that fails or whose process dies (even killed by the OS) is reported in
``sweep.json`` and on the console; the other runs go on.

Outputs in ``DIR``: one folder per run (named by ``SweepSpec.folder``),
``logs/<run>.log`` (each run's log), ``visibility.csv`` (one row per run,
camera and target), ``manifest.csv`` (one row per clip) and ``sweep.json``
(every run's status).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core import workers as worker_kit
from cosim.core.section import scenario_sections
from cosim.errors import ConfigError, CosimError
from cosim.scenario.placeholders import Scalar, format_value
from cosim.sweep.spec import SweepSpec, read_sweep

log = logging.getLogger(__name__)

#: measured columns of visibility.csv after the swept names
VISIBILITY_COLUMNS = ("speed_kt", "alt_agl_m", "target", "visible_s", "first_visible_s",
                      "last_visible_s", "passes", "overhead_s", "screen_direction",
                      "flown_speed_kt", "speed_off", "target_id", "vehicle", "camera", "run")
#: how far (fraction) the flown ground speed may be from a swept speed_kt before
#: the cell is flagged (``speed_off``): the visible time scales with 1 / speed
SPEED_TOLERANCE = 0.01
MANIFEST_COLUMNS = ("run", "vehicle", "camera", "video", "ground_truth", "frames", "rate_hz",
                    "width_px", "height_px", "hfov_deg", "vfov_deg")


@dataclass
class RunOutcome:
    name: str
    point: dict[str, Scalar]
    status: str = "pending"  # completed | failed | <the run's stop reason> | died
    error: str | None = None
    wall_s: float = 0.0


@dataclass
class SweepResult:
    out_dir: Path
    runs: list[RunOutcome] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def failed(self) -> list[RunOutcome]:
        return [r for r in self.runs if r.status != "completed"]


def load_point(scenario: str | Path, point: Mapping[str, Scalar], check_properties: bool = True
               ) -> Any:
    """The scenario at one combination, ready for a sweep run, which gets one
    core: each section as it runs on one core (``Section.one_core``: the
    cameras render inline)."""
    import dataclasses

    from cosim.scenario import load_scenario

    scn = load_scenario(scenario, check_properties=check_properties, sweep_point=dict(point))
    sections = scenario_sections()
    return dataclasses.replace(scn, sections={
        k: sections[k].one_core(v) if k in sections and v is not None else v
        for k, v in scn.sections.items()})


def _run_one(scenario: str, point: dict[str, Scalar], run_dir: str, log_path: str,
             duration_s: float | None) -> None:
    """Body of a run's process: one run, its log to ``log_path``, the outcome
    as JSON next to it. Never raises (the parent reads the outcome file)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"  # one core per run: the sweep fills the cores with runs
    import cv2  # OpenCV's own thread pool ignores OMP_NUM_THREADS

    cv2.setNumThreads(1)
    handler = logging.FileHandler(log_path, mode="w")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(logging.INFO)
    logging.getLogger("cosim.jsbsim").setLevel(logging.WARNING)
    outcome: dict[str, Any] = {"status": "failed", "error": None}
    t0 = time.monotonic()
    try:
        from cosim.sync import Run

        scn = load_point(scenario, point, check_properties=False)
        if duration_s:
            scn = scn.with_duration(duration_s)
        res = Run(scn, run_dir, backend="inline").run()
        outcome["status"] = res.stop_reason
        if res.error is not None:
            outcome["error"] = f"{type(res.error).__name__}: {res.error}"
    except BaseException as e:  # noqa: BLE001 - reported to the parent, never lost
        outcome["error"] = f"{type(e).__name__}: {e}"
        log.error("run failed:\n%s", traceback.format_exc())
    outcome["wall_s"] = round(time.monotonic() - t0, 3)
    Path(log_path).with_suffix(".json").write_text(json.dumps(outcome))


def _died(exitcode: int | None) -> str:
    from cosim.errors import how_it_ended

    how = how_it_ended(exitcode)
    if exitcode is not None and exitcode < 0:
        return f"its process was {how}"  # killed by SIGKILL
    return f"its process {how} without a result"  # exited with code 3


def check_out_dir(out: Path, spec: SweepSpec, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a folder")
    if not overwrite and out.is_dir():
        taken = [p for p in spec.points() if (out / spec.folder(p) / "summary.json").exists()]
        if taken or (out / "manifest.csv").exists():
            raise ConfigError(f"{out} already holds a sweep; choose another --out or pass "
                              f"--overwrite")


def run_sweep(scenario: str | Path, out_dir: str | Path, jobs: int | None = None,
              overwrite: bool = False, duration_s: float | None = None,
              on_done: Callable[[RunOutcome, int, int, float], None] | None = None
              ) -> SweepResult:
    """Run every combination of ``scenario``'s sweep into ``out_dir``.

    Every combination is validated first (all problems at once, before any
    run starts). ``on_done(outcome, done, total, elapsed_s)`` is called as
    each run ends (progress).
    """
    spec = read_sweep(scenario)
    out = Path(out_dir)
    check_out_dir(out, spec, overwrite)
    points = spec.points()
    problems: list[str] = []
    for i, p in enumerate(points):  # properties do not depend on the values: check once
        try:
            load_point(scenario, p, check_properties=(i == 0))
        except ConfigError as e:
            problems.extend(x for x in e.problems if x not in problems)
    if problems:
        raise ConfigError(problems)
    folders = [spec.folder(p) for p in points]
    if len(set(folders)) != len(folders):
        raise ConfigError(f"{scenario}: two combinations give the same folder name; make the "
                          f"swept values differ in letters, digits, '.', '+' or '-'")
    (out / "logs").mkdir(parents=True, exist_ok=True)
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(points)))
    outcomes = [RunOutcome(name=f, point=dict(p)) for f, p in zip(folders, points)]
    result = SweepResult(out_dir=out, runs=outcomes)
    log.info("sweep %s: %d runs (%s), %d at a time, into %s", scenario, len(points),
             " x ".join(f"{len(v)} {k}" for k, v in spec.values.items() if len(v) > 1) or "1",
             jobs, out)
    pending = list(range(len(points)))
    running: dict[int, tuple[Any, float]] = {}
    t0 = time.monotonic()
    done = 0
    try:
        while pending or running:
            while pending and len(running) < jobs:
                i = pending.pop(0)
                o = outcomes[i]
                logf = out / "logs" / f"{o.name}.log"
                logf.with_suffix(".json").unlink(missing_ok=True)
                # unshielded, with its own log: Ctrl-C stops each run as it
                # would stop a run on its own (a summary, interrupted)
                proc = worker_kit.start(_run_one, (str(scenario), o.point, str(out / o.name),
                                                str(logf), duration_s),
                                     name=f"sweep-{o.name}", shielded=False,
                                     inherit_logging=False, daemon=False)
                running[i] = (proc, time.monotonic())
            worker_kit.ended([p for p, _ in running.values()], timeout_s=5.0)
            for i, (proc, started) in list(running.items()):
                if proc.is_alive():
                    continue
                proc.join()
                del running[i]
                o = outcomes[i]
                o.wall_s = round(time.monotonic() - started, 3)
                res_file = out / "logs" / f"{o.name}.json"
                if res_file.exists():
                    r = json.loads(res_file.read_text())
                    o.status, o.error = r["status"], r.get("error")
                else:
                    o.status, o.error = "died", _died(proc.exitcode)
                done += 1
                if on_done:
                    on_done(o, done, len(points), time.monotonic() - t0)
    except BaseException:
        # Ctrl-C or an error here: stop every run cleanly
        worker_kit.stop([p for p, _ in running.values()], 10.0, terminate=True)
        for i in running:
            outcomes[i].status, outcomes[i].error = "interrupted", "the sweep was stopped"
        raise
    finally:
        result.wall_s = round(time.monotonic() - t0, 3)
        write_tables(result, spec)
    return result


def _states(run_dir: Path) -> dict[str, list[Any]] | None:
    """The columns ``_measured`` reads from a run's states (None: unreadable)."""
    from cosim.logs import read_states

    try:
        return read_states(run_dir, ["vehicle", "time_s", "airspeed_mps", "alt_agl_m", "vn_mps",
                                     "ve_mps"]).to_pydict()
    except (OSError, CosimError):
        return None


def _measured(t: dict[str, list[Any]] | None, vehicle: str, t0_s: float | None,
              t1_s: float | None) -> tuple[float, float, float]:
    """Mean airspeed (kt), height above ground (m) and ground speed (kt) of
    ``vehicle`` between t0_s and t1_s (the whole run when None), from ``_states``."""
    from cosim.core.units import KT_TO_MPS

    if t is None:
        return math.nan, math.nan, math.nan
    rows = [i for i, v in enumerate(t["vehicle"]) if v == vehicle
            and (t0_s is None or t0_s - 1e-9 <= t["time_s"][i])
            and (t1_s is None or t["time_s"][i] <= t1_s + 1e-9)]
    if not rows:
        return math.nan, math.nan, math.nan
    spd = sum(t["airspeed_mps"][i] for i in rows) / len(rows) / KT_TO_MPS
    agl = sum(t["alt_agl_m"][i] for i in rows) / len(rows)
    gs = sum(math.hypot(t["vn_mps"][i], t["ve_mps"][i]) for i in rows) / len(rows) / KT_TO_MPS
    return spd, agl, gs


def _f(x: float | None, nd: int = 6) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    return f"{round(x, nd):g}"


def visibility_rows(spec: SweepSpec, outcome: RunOutcome, run_dir: Path
                    ) -> list[dict[str, str]]:
    """visibility.csv rows of one completed run: one per camera and target."""
    from cosim.conspicuity import run_visibility

    rows = []
    swept = {n: format_value(outcome.point[n]) for n in spec.swept}
    states = _states(run_dir)  # once per run, not per target
    for tv in run_visibility(run_dir):
        spd, agl, gs = _measured(states, tv.vehicle, tv.first_visible_s, tv.last_visible_s)
        commanded = outcome.point.get("speed_kt") if "speed_kt" in spec.swept else None
        off = ""
        if isinstance(commanded, (int, float)) and commanded > 0 and math.isfinite(gs):
            off = "true" if abs(gs - commanded) > SPEED_TOLERANCE * commanded else "false"
        row = {"speed_kt": _f(spd, 2), "alt_agl_m": _f(agl, 2), "target": tv.target,
               "flown_speed_kt": _f(gs, 2), "speed_off": off,
               "visible_s": _f(tv.visible_s), "first_visible_s": _f(tv.first_visible_s),
               "last_visible_s": _f(tv.last_visible_s), "passes": str(len(tv.passes)),
               "overhead_s": _f(tv.passes[0].overhead_s) if tv.passes else "",
               "screen_direction": tv.passes[0].screen_direction if tv.passes else "",
               "target_id": tv.target, "vehicle": tv.vehicle, "camera": tv.camera,
               "run": outcome.name}
        row.update(swept)  # a swept value wins over the measured one of the same name
        rows.append(row)
    return rows


def manifest_rows(spec: SweepSpec, outcome: RunOutcome, out: Path) -> list[dict[str, str]]:
    """manifest.csv rows of one run: one per clip, paths relative to the sweep folder."""
    from cosim.conspicuity.visibility import camera_entries

    rows = []
    swept = {n: format_value(outcome.point[n]) for n in spec.swept}
    for e in camera_entries(out / outcome.name):
        row = {k: str(e.get(k, "")) for k in MANIFEST_COLUMNS}
        for key in ("video", "ground_truth"):
            if e.get(key):
                row[key] = os.path.relpath(e[key], out)
        row["run"] = outcome.name
        rows.append({**swept, **row})
    return rows


def rewrite_tables(out_dir: str | Path) -> SweepResult:
    """Rebuild a finished sweep's tables from its ``sweep.json`` (e.g. after
    changing the analysis). The folder is untrusted input, read as a run
    folder is (``cosim.logs.runfolder``): ``sweep.json`` is checked, and each
    run's folder must be a plain name inside the sweep folder."""
    from cosim.logs import RunFolder

    folder = RunFolder(out_dir)
    if not folder.has("sweep.json"):
        raise ConfigError(f"{folder.path}: not a sweep folder (no sweep.json)")
    where = folder.path / "sweep.json"
    s = folder.json("sweep.json")
    if not isinstance(s, dict):
        raise ConfigError(f"{where}: expected a JSON object, got {type(s).__name__}")
    swept = s.get("swept")
    if not (isinstance(swept, dict) and all(isinstance(v, list) and all(map(_scalar, v))
                                            for v in swept.values())):
        raise ConfigError(f"{where}: swept: expected an object of lists of values")
    scenario, results = s.get("scenario"), s.get("results")
    if not isinstance(scenario, str):
        raise ConfigError(f"{where}: scenario: expected the scenario's path")
    if not isinstance(results, list):
        raise ConfigError(f"{where}: results: expected a list of runs")
    spec = SweepSpec(path=scenario, values={k: tuple(v) for k, v in swept.items()},
                     swept=tuple(swept))
    result = SweepResult(out_dir=folder.path, wall_s=_number(s.get("wall_time_s")),
                         runs=[_outcome(r, i, spec, folder, where)
                               for i, r in enumerate(results)])
    write_tables(result, spec)
    return result


def _scalar(v: Any) -> bool:
    return isinstance(v, (str, bool, int)) or (isinstance(v, float) and math.isfinite(v))


def _number(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else 0.0


def _outcome(r: Any, i: int, spec: SweepSpec, folder: Any, where: Path) -> RunOutcome:
    """One run of sweep.json's results, checked: its folder a plain name
    inside the sweep folder, its point a value for every swept name."""
    at = f"{where}: results[{i}]"
    if not isinstance(r, dict):
        raise ConfigError(f"{at}: expected an object, got {type(r).__name__}")
    name, point, status, error = r.get("run"), r.get("point"), r.get("status"), r.get("error")
    if not (isinstance(name, str) and 0 < len(name) <= 255 and "/" not in name
            and "\\" not in name and name not in (".", "..")):
        raise ConfigError(f"{at}.run: expected a run folder's name (no / or ..), got "
                          f"{str(name)[:80]!r}")
    folder.file(name)  # a symlink out of the sweep folder is refused
    if not (isinstance(point, dict) and all(n in point and _scalar(point[n])
                                            for n in spec.swept)):
        raise ConfigError(f"{at}.point: expected a value for each of "
                          f"{', '.join(spec.swept) or 'no name'}")
    if not isinstance(status, str) or not (error is None or isinstance(error, str)):
        raise ConfigError(f"{at}: status (text) and error (text or null) expected")
    return RunOutcome(name=name, point=point, status=status, error=error,
                      wall_s=_number(r.get("wall_s")))


def write_tables(result: SweepResult, spec: SweepSpec) -> None:
    """visibility.csv, manifest.csv and sweep.json from the runs that completed."""
    from cosim.conspicuity.visibility import write_csv
    from cosim.logs import replacing

    out = result.out_dir
    vis: list[dict[str, str]] = []
    man: list[dict[str, str]] = []
    for o in result.runs:
        if o.status != "completed":
            continue
        try:
            vis.extend(visibility_rows(spec, o, out / o.name))
            man.extend(manifest_rows(spec, o, out))
        except ConfigError as e:  # its ground truth or its summary (GroundTruthError, ...)
            o.status, o.error = "failed", f"reading its ground truth: {e}"
    off = sorted({r["run"] for r in vis if r.get("speed_off") == "true"})
    if off:
        log.warning("%d run(s) flew more than %g%% off their swept speed_kt (speed_off in "
                    "visibility.csv; the visible time scales with 1/speed): %s", len(off),
                    SPEED_TOLERANCE * 100, ", ".join(off[:10]) + (" ..." if len(off) > 10
                                                                  else ""))
    swept = list(spec.swept)
    write_csv(out / "visibility.csv",
              swept + [c for c in VISIBILITY_COLUMNS if c not in swept], vis)
    write_csv(out / "manifest.csv", swept + [c for c in MANIFEST_COLUMNS if c not in swept],
              man)
    for key, section in scenario_sections().items():  # the sections' own tables
        for table in section.sweep_tables:
            try:
                table(result, spec)
            except Exception as e:  # a table never loses the sweep
                log.warning("%s: %s: %s: %s", key, getattr(table, "__name__", table),
                            type(e).__name__, e)
    summary = {"scenario": spec.path, "runs": len(result.runs),
               "completed": sum(o.status == "completed" for o in result.runs),
               "wall_time_s": result.wall_s, "swept": {k: list(spec.values[k]) for k in swept},
               "results": [{"run": o.name, "point": o.point, "status": o.status,
                            "error": o.error, "wall_s": o.wall_s} for o in result.runs]}
    with replacing(out / "sweep.json") as f:
        f.write(json.dumps(summary, indent=1))
