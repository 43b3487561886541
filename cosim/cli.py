"""The ``cosim`` command: run, validate, models, plot, export, bench, sweep,
visibility, swarm, recover.

``main(argv) -> int``: exit 0 ok, 1 runtime failure, 2 usage or config
error, 130 stopped by Ctrl-C (after a clean stop with everything flushed).
Only this module configures logging handlers.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import re
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, TextIO

from cosim import __version__
from cosim.errors import ConfigError, CosimError

if TYPE_CHECKING:
    from cosim.scenario import Scenario

log = logging.getLogger("cosim")

EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise _UsageError(f"{self.prog}: error: {message}")


def _positive_int_list(text: str) -> list[int]:
    try:
        vals = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated whole numbers, got {text!r}") from None
    if not vals or any(v < 1 for v in vals):
        raise argparse.ArgumentTypeError(f"expected positive whole numbers, got {text!r}")
    return vals


def _altitudes(text: str) -> list[float]:
    vals = [_positive_float(x) for x in text.split(",") if x.strip()]
    if not vals or len(vals) > 50 or any(not 10.0 <= v <= 10_000.0 for v in vals):
        raise argparse.ArgumentTypeError(f"expected 1 to 50 comma-separated altitudes of 10 to "
                                         f"10000 m, got {text!r}")
    return vals


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v


def _build_parser() -> _Parser:
    from cosim.plugins import BACKENDS, BUILTIN_BACKENDS, DEFAULT_BACKEND, plugin_names

    # registered ones included; nothing is loaded for --help
    names = plugin_names(BACKENDS, BUILTIN_BACKENDS)
    backend_help = ("inline runs every vehicle in this process (the reference), process "
                    "shards them over worker processes; packages may register more")
    p = _Parser(prog="cosim", description="Lockstep co-simulation of UAV swarms on JSBSim.")
    p.add_argument("--version", action="version", version=f"cosim {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    p.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    sub = p.add_subparsers(dest="cmd", metavar="COMMAND", parser_class=_Parser)

    r = sub.add_parser("run", help="run a scenario")
    r.add_argument("scenario", help="scenario YAML file")
    r.add_argument("--out", metavar="DIR",
                   help="output folder (default: runs/<scenario>-<date>-<time>)")
    r.add_argument("--overwrite", action="store_true",
                   help="allow writing into a folder that already holds a run")
    r.add_argument("--backend", choices=names, default=DEFAULT_BACKEND,
                   help=f"where the vehicles are stepped: {backend_help} (default "
                        f"{DEFAULT_BACKEND})")
    r.add_argument("--workers", type=int, metavar="N",
                   help="worker count (default: the backend's own, for process one per "
                        "core)")
    r.add_argument("--address", metavar="HOST:PORT",
                   help="the cluster to run on, for a backend that runs on one (ray: the "
                        "head's address from 'ray start --head'; default RAY_ADDRESS, else a "
                        "local Ray)")
    r.add_argument("--strict", action="store_true",
                   help="stop with an error when a machine of the cluster is lost, rather "
                        "than rebuild its vehicles elsewhere (which ends bit-exactness)")
    r.add_argument("--connect-timeout-s", type=_positive_float, metavar="S",
                   help="how long joining the cluster may take before the run fails, for a "
                        "backend that joins one (ray: default 30)")
    r.add_argument("--realtime", nargs="?", const=1.0, type=_positive_float, metavar="FACTOR",
                   help="pace to the wall clock (FACTOR x real time, default 1)")
    r.add_argument("--duration-s", type=_positive_float, metavar="S",
                   help="override the scenario's duration")
    r.add_argument("--mavlink", metavar="URL", nargs="?", const="udpout:127.0.0.1:14550",
                   help="present every vehicle on MAVLink (udpout:HOST:PORT sends there and "
                        "answers whoever talks; udpin:HOST:PORT listens; default "
                        "udpout:127.0.0.1:14550, where ground stations listen)")
    sg = r.add_mutually_exclusive_group()
    sg.add_argument("--mavlink-signing-key-file", metavar="PATH",
                    help="sign MAVLink 2 traffic with the passphrase in PATH (as MAVProxy's "
                         "'signing key'); unsigned or wrongly signed commands are dropped")
    sg.add_argument("--mavlink-signing-key-env", metavar="NAME",
                    help="the same, with the passphrase in environment variable NAME")
    r.add_argument("--mavlink-signing-link-id", type=int, default=0, metavar="N",
                   help="link id in outgoing signatures (0..255, default 0)")
    r.add_argument("--external-controller", action="store_true",
                   help="the scenario's swarm controller runs in another process (cosim swarm "
                        "SCENARIO --connect URL), kept in lockstep over --mavlink")
    r.add_argument("--step-timeout-s", type=_positive_float, default=60.0, metavar="S",
                   help="a physics worker silent this long in one exchange, or a render "
                        "worker this long with frames to render, fails the run (default 60)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    r.add_argument("--view", metavar="URL", nargs="?", const="spawn",
                   help="watch the run in 3-D in Rerun's viewer (the view extra): "
                        "alone, opens a viewer here; with URL, streams to a viewer running "
                        "there (e.g. rerun+http://127.0.0.1:9876/proxy)")
    r.add_argument("--record-view", metavar="FILE",
                   help="write the same 3-D view to FILE (.rrd) to open later: rerun FILE")
    r.add_argument("--video", metavar="SYSID[:CAM]=udp://HOST:PORT", action="append",
                   help="stream that vehicle's camera (its MAVLink system id; CAM: the "
                        "camera's name, default its first) as H.264 over RTP to HOST:PORT "
                        "(QGroundControl: UDP h.264 on 5600; add ?format=mpegts for MPEG-TS); "
                        "repeatable; loopback only unless --video-allow-remote")
    r.add_argument("--video-allow-remote", action="store_true",
                   help="allow --video to send to addresses other than this machine")
    r.add_argument("--view-rate-hz", type=_positive_float, default=10.0, metavar="HZ",
                   help="vehicle poses per second of simulation time in the view (default 10)")

    v = sub.add_parser("validate", help="check scenario files and report every problem")
    v.add_argument("scenarios", nargs="+", metavar="SCENARIO")
    v.add_argument("--deep", action="store_true",
                   help="also build and trim every vehicle (as a run would), so a vehicle "
                        "JSBSim cannot trim is found before a long run starts")
    v.add_argument("--workers", type=int, metavar="N",
                   help="worker processes for --deep (default: one per core)")

    m = sub.add_parser("models", help="list usable aircraft models")
    m.add_argument("--check", action="store_true", help="load each model to prove it works")
    m.add_argument("--properties", metavar="MODEL",
                   help="list the JSBSim properties of MODEL")
    m.add_argument("--classes", action="store_true",
                   help="list the vehicle classes instead (cosim's and installed packages')")

    pl = sub.add_parser("plot", help="plot a run's ground tracks, the aircraft's altitude and "
                                     "the ground vehicles' speed (PNG)")
    pl.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")
    pl.add_argument("--out", metavar="PNG", help="output file (default RUN_DIR/track.png)")
    pl.add_argument("--vehicles", metavar="IDS",
                    help="comma-separated vehicle ids or patterns (fleet00*) to draw "
                         "(default: every vehicle)")
    pl.add_argument("--max-vehicles", type=int, metavar="N",
                    help="draw at most the first N (in the scenario's order)")

    ex = sub.add_parser("export", help="write a run's tracks for Tacview (ACMI), Google Earth "
                                       "(KML) or Cesium (CZML)")
    ex.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")
    ex.add_argument("--format", required=True, choices=("acmi", "kml", "czml"),
                    help="acmi: Tacview 2.2 text; kml: one gx:Track per vehicle; czml: Cesium")
    ex.add_argument("--out", metavar="FILE",
                    help="output file (default RUN_DIR/track.<format>)")
    ex.add_argument("--rate-hz", type=_positive_float, default=10.0, metavar="HZ",
                    help="samples per second of simulation time (default 10)")
    ex.add_argument("--epoch", metavar="ISO",
                    help="the calendar time of simulation time 0, e.g. 2026-06-01T12:00:00Z "
                         "(default 2000-01-01T00:00:00Z)")

    rc = sub.add_parser("recover", help="make what a killed or failed run left readable "
                                         "(journalled ticks into Parquet, a summary)")
    rc.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")

    sw = sub.add_parser("sweep", help="run a scenario once per combination of its sweep: "
                                      "values, in parallel")
    sw.add_argument("scenario", help="scenario YAML file with a sweep: section")
    sw.add_argument("--out", metavar="DIR",
                    help="output folder: one subfolder per run, visibility.csv, manifest.csv "
                         "(default runs/<file name>-sweep-<date>-<time>)")
    sw.add_argument("--jobs", type=int, metavar="N",
                    help="runs at a time (default: one per core); each run is one process")
    sw.add_argument("--overwrite", action="store_true",
                    help="allow writing into a folder that already holds a sweep")
    sw.add_argument("--duration-s", type=_positive_float, metavar="S",
                    help="override every run's duration")

    vi = sub.add_parser("visibility", help="how long each target is in view, pass by pass "
                                           "(a run or a sweep folder)")
    vi.add_argument("run", metavar="RUN_DIR", help="a run folder (writes RUN_DIR/visibility.csv)"
                                                  " or a sweep folder (rewrites its tables)")

    sp = sub.add_parser("search-plan", help="a scenario's search: its plan, the smallest "
                                            "fleet for a deadline, and how it changes with "
                                            "altitude")
    sp.add_argument("scenario", help="scenario YAML file with a search: section")
    sp.add_argument("--deadline-s", type=_positive_float, default=600.0, metavar="S",
                    help="the whole area covered within S (default 600: 10 minutes)")
    sp.add_argument("--altitudes", type=_altitudes, metavar="M,M,...",
                    help="altitudes (m AGL) to compare (default: a quarter to twice the "
                         "scenario's)")

    tr = sub.add_parser("trials", help="conspicuity trials with people: a browser trial "
                                       "runner, its responses, their analysis")
    trs = tr.add_subparsers(dest="trials_cmd", metavar="ACTION", parser_class=_Parser)
    ts = trs.add_parser("serve", help="serve a study: the experimenter's and the "
                                      "participant's pages")
    ts.add_argument("study", metavar="STUDY.yaml")
    ts.add_argument("--host", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1: this machine only)")
    ts.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    ts.add_argument("--db", metavar="URL_OR_FILE",
                    help="responses database: a SQLite file or a SQLAlchemy URL (default "
                         "STUDY.sqlite beside the study)")
    ts.add_argument("--public", action="store_true",
                    help="allow listening on an address other machines reach")
    te = trs.add_parser("export", help="the responses as CSV")
    te.add_argument("db", metavar="DB", help="the study's database (file or URL)")
    te.add_argument("--out", metavar="CSV", required=True)
    ta = trs.add_parser("analyse", help="conspicuity angles and distances, the critical gap, "
                                        "recognition against altitude, speed and conspicuity")
    ta.add_argument("responses", metavar="DB_OR_CSV",
                    help="the study's database, or a responses CSV (cosim trials export)")
    ta.add_argument("--out", metavar="DIR", required=True, help="folder for the CSVs and PNGs")
    ta.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    ta.add_argument("--tolerance", type=float, default=0.1, metavar="SHARE",
                    help="how far a critical gap may change and still count as constant, "
                         "as a share of it (default 0.1: 10%%)")
    ta.add_argument("--exclude-reshown", action="store_true",
                    help="leave out trials shown a second time after the page was reloaded")

    sw = sub.add_parser("swarm", help="run a scenario's swarm controller in this process, "
                                      "connected to `cosim run --external-controller`")
    sw.add_argument("scenario", help="scenario YAML file (the one the simulation runs)")
    sw.add_argument("--connect", metavar="URL", required=True,
                    help="udpout:HOST:PORT where the simulation's --mavlink udpin:HOST:PORT "
                         "listens")
    sw.add_argument("--out", metavar="DIR",
                    help="write swarm.json, swarm_events.jsonl, swarm_commands.csv and "
                         "swarm.png here")
    sw.add_argument("--connect-timeout-s", type=_positive_float, default=60.0, metavar="S",
                    help="give up if the simulation does not answer within S (default 60)")

    b = sub.add_parser("bench", help="measure pool throughput against the serial loop",
                       epilog="One row per fleet size; what each column means is printed "
                              "under the table (and in benchmarks/README.md).")
    b.add_argument("--vehicles", type=_positive_int_list, default=[1, 16, 128, 512, 1024],
                   metavar="N,N,...",
                   help="fleet sizes to measure, one row each (default 1,16,128,512,1024)")
    b.add_argument("--model", default="c172p", metavar="MODEL",
                   help="the aircraft model, as in a scenario (default c172p; `cosim models` "
                        "lists them)")
    b.add_argument("--backend", choices=names, default=DEFAULT_BACKEND,
                   help=f"{backend_help} (default {DEFAULT_BACKEND})")
    b.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the pool (default: one per core)")
    b.add_argument("--seconds", type=_positive_float, default=5.0, metavar="S",
                   help="simulated seconds per measured segment (default 5)")
    b.add_argument("--repeat", type=int, default=3, metavar="R",
                   help="segments per configuration; the best is reported (default 3)")
    b.add_argument("--physics-hz", type=_positive_float, default=120.0, metavar="HZ",
                   help="JSBSim steps per simulated second (default 120)")
    b.add_argument("--control-hz", type=_positive_float, default=30.0, metavar="HZ",
                   help="exchanges (setpoints in, states out) per simulated second; must "
                        "divide --physics-hz (default 30)")
    b.add_argument("--no-baselines", action="store_true",
                   help="skip the serial and no-communication ceiling measurements")
    b.add_argument("--json", metavar="FILE", help="write the results as JSON")
    b.add_argument("--class", dest="vehicle_class", metavar="CLASS",
                   help="fly the model as this vehicle class (e.g. fixed_wing_batched); "
                        "default: the model's own")
    b.add_argument("--plot", metavar="FILE.png",
                   help="draw the real-time factor and the efficiency against N")
    b.add_argument("--whole-run", action="store_true",
                   help="also fly each fleet as a whole run (guidance, logging) and report "
                        "its real-time factor and where its tick loop's time goes")
    b.add_argument("--log-hz", type=_positive_float, default=10.0, metavar="HZ",
                   help="the whole run's logging rate (default 10)")
    b.add_argument("--gym", action="store_true",
                   help="also measure what an RL user would otherwise write: gymnasium's "
                        "AsyncVectorEnv, one aircraft per environment, at 16 and 64 aircraft "
                        "(needs the rl extra)")
    b.add_argument("--quick", action="store_true",
                   help="a look in under a minute: 1, 16 and 128 aircraft, 1 s, one round")
    return p


def _setup_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose >= 2 else logging.INFO)
    h = logging.StreamHandler(sys.stderr)
    h.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s",
                                     "%H:%M:%S"))
    root = logging.getLogger()
    root.handlers[:] = [h]
    root.setLevel(level)
    if verbose < 3:
        logging.getLogger("cosim.jsbsim").setLevel(logging.WARNING)


class Progress:
    """A bar on a terminal; a log line every ``every_s`` seconds otherwise.

    The real-time factor shown is the run's one definition (README, "Running
    scenarios"): simulated seconds over wall seconds of the tick loop, counted
    from the loop's first report (the build and trim are not in it), as
    ``summary.json``'s ``real_time_factor``; the final line of ``cosim run``
    prints the summary's figure, so the last bar shows none."""

    def __init__(self, stream: TextIO, hz: float, every_s: float = 10.0) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.hz = hz
        self.every_s = every_s if not self.tty else 0.1
        self.start: tuple[float, int] | None = None  # (wall, tick) of the first report
        self.last = 0.0

    def __call__(self, tick: int, total: int) -> None:
        now = time.monotonic()
        if self.start is None:
            self.start = (now, tick)
            self.last = now if not self.tty else 0.0
        if now - self.last < self.every_s and tick < total:
            return
        self.last = now
        wall = now - self.start[0]
        sim = tick / self.hz
        rtf = (tick - self.start[1]) / self.hz / wall if wall > 0 else 0.0
        frac = tick / total if total else 1.0
        done = tick >= total
        if self.tty:
            width = 30
            bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
            speed = "" if done else f"  {rtf:6.2f}x real time"
            self.stream.write(f"\r[{bar}] {frac:6.1%}  t={sim:8.1f} s{speed} ")
            if done:
                self.stream.write("\n")
            self.stream.flush()
        elif not done:
            log.info("progress: %.1f%% (sim %.1f s of %.1f s, %.2fx real time)", frac * 100,
                     sim, total / self.hz, rtf)


def _load_scenario(path: str) -> Scenario:
    from cosim.scenario import load_scenario  # imported here: a fast --help

    return load_scenario(path)


def _backend_options(a: argparse.Namespace) -> dict[str, Any]:
    """``--address``, ``--strict`` and ``--connect-timeout-s``, for the backend
    to take or refuse; a refusal, or a backend that cannot run here, is a
    usage error before anything is built."""
    from cosim.fdm_pool import get_backend

    get_backend(a.backend).check()  # a library it needs, missing: said before anything runs
    opts: dict[str, Any] = {}
    if a.address:
        opts["address"] = a.address
    if a.strict:
        opts["strict"] = True
    if a.connect_timeout_s is not None:
        opts["connect_timeout_s"] = a.connect_timeout_s
    unknown = sorted(set(opts) - set(get_backend(a.backend).options))
    if unknown:
        raise ConfigError(f"--{unknown[0].replace('_', '-')}: the {a.backend} backend does "
                          f"not take it; backends that do: "
                          + (", ".join(b.name for b in _backends_with(unknown[0])) or "none"))
    return opts


def _backends_with(option: str) -> list[Any]:
    from cosim.fdm_pool import backends

    return [b for b in backends().values() if option in b.options]


def _cmd_run(a: argparse.Namespace) -> int:
    from cosim.sync import Run

    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    scn = _load_scenario(a.scenario)
    if a.duration_s:
        scn = scn.with_duration(a.duration_s)
    out = Path(a.out) if a.out else Path("runs") / (
        f"{scn.folder_name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a folder")
    if (out / "summary.json").exists() or (out / "events.jsonl").exists():
        if not a.overwrite:
            raise ConfigError(f"{out} already holds a run; choose another --out or pass "
                              f"--overwrite")  # Run clears it: never mixed with the new one
    progress = None if a.no_progress else Progress(sys.stderr, scn.rates.physics_hz)
    mav_cfg = None
    if a.mavlink:  # overrides the scenario's URL, keeps its stream rates
        from cosim.mavlink import MavlinkConfig
        from cosim.mavlink.link import LinkUrl

        LinkUrl.parse(a.mavlink)  # a bad URL is a usage error before anything is built
        mav_cfg = dataclasses.replace(MavlinkConfig.of_scenario(
            scn.mavlink, [v.id for v in scn.vehicles]) or MavlinkConfig(), url=a.mavlink)
    signing = a.mavlink_signing_key_file or a.mavlink_signing_key_env
    if signing:
        from cosim.mavlink import MavlinkConfig, load_signing_key

        if mav_cfg is None and scn.mavlink is None:
            raise ConfigError("--mavlink-signing-key-* needs MAVLink: pass --mavlink or give "
                              "the scenario a mavlink: section")
        mav_cfg = mav_cfg or MavlinkConfig.of_scenario(scn.mavlink)
        assert mav_cfg is not None
        mav_cfg = dataclasses.replace(mav_cfg, signing_key_file=a.mavlink_signing_key_file,
                                      signing_key_env=a.mavlink_signing_key_env,
                                      signing_link_id=a.mavlink_signing_link_id)
        load_signing_key(mav_cfg)  # a missing or bad key is a usage error before the build
    if a.external_controller:
        from cosim.mavlink import CONTROLLER_SYSID
        if "swarm" not in scn.sections:  # the part an outside controller runs
            raise ConfigError(f"--external-controller: {a.scenario} has no controller section "
                              "(swarm:) for an outside controller to run")
        if mav_cfg is None:
            raise ConfigError("--external-controller needs a network link: pass --mavlink URL "
                              "(e.g. udpin:127.0.0.1:14560, where the controller connects)")
        if mav_cfg.signing:
            raise ConfigError("--external-controller with MAVLink signing: cosim swarm "
                              "--connect does not sign its messages yet, so the lockstep "
                              "would wait for answers it drops; run without signing on a "
                              "loopback link")
        mav_cfg = dataclasses.replace(mav_cfg, lockstep_sysid=CONTROLLER_SYSID)
    extra: list[Any] = []
    if a.view is not None or a.record_view is not None:
        from cosim.view import ViewParticipant

        extra.append(ViewParticipant(Path(a.record_view) if a.record_view else None, a.view,
                                     a.view_rate_hz))
    if a.video:
        from cosim.renderer.stream import VideoParticipant, parse_target

        extra.append(VideoParticipant([parse_target(t, a.video_allow_remote)
                                       for t in a.video], scn))
    run = Run(scn, out, backend=a.backend, workers=a.workers, realtime=a.realtime,
              progress=progress, step_timeout_s=a.step_timeout_s, mavlink=mav_cfg,
              external_controller=a.external_controller, extra_participants=extra,
              backend_options=_backend_options(a))

    interrupts = 0

    def on_signal(signum: int, frame: FrameType | None) -> None:
        nonlocal interrupts
        interrupts += 1
        run.stop("interrupted" if signum == signal.SIGINT else "terminated")
        if interrupts > 1 or run.building:
            raise KeyboardInterrupt  # abort the build (or a second Ctrl-C: everything)

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        res = run.run()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    sm = res.summary
    print(f"{res.stop_reason}: {sm['vehicles']} vehicles, {sm['sim_time_s']:.2f} s simulated "
          f"in {sm['wall_time_s']:.2f} s ({sm['real_time_factor'] or 0:.2f}x real time, "
          f"{sm['workers']} worker(s), {sm['backend']})")
    print(f"outputs in {out}/: {_outputs(out)}")
    if res.error is not None:
        print(f"cosim run: {res.error}", file=sys.stderr)
    if res.stop_reason == "completed":
        return EXIT_OK
    if res.stop_reason in ("interrupted", "terminated"):
        return EXIT_INTERRUPTED
    from cosim.errors import BuildError

    if isinstance(res.error, (BuildError, ConfigError)):  # the scenario's or a flag's fault
        return EXIT_USAGE
    return EXIT_FAIL


def _outputs(out: Path) -> str:
    """What the run folder holds (a folder with a slash and its file count;
    more than three files of one kind as a count), read from the folder."""
    if not out.is_dir():
        return "(nothing)"
    names: list[str] = []
    kinds: dict[str, list[str]] = {}
    for p in sorted(out.iterdir()):
        if p.name.startswith((".", "_")):
            continue
        if p.is_dir() and not p.name.endswith(".parquet"):
            n = sum(1 for q in p.rglob("*") if q.is_file())
            names.append(f"{p.name}/ ({n} file{'s' if n != 1 else ''})")
        else:
            kinds.setdefault(p.suffix if p.is_file() else p.name, []).append(p.name)
    for suffix, files in kinds.items():
        names += files if len(files) <= 3 else [f"{len(files)} *{suffix} files"]
    return ", ".join(sorted(names, key=lambda s: s.lower()))


def _cmd_validate(a: argparse.Namespace) -> int:
    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    bad = 0
    for f in a.scenarios:
        try:
            scn, combos, built = _validate_file(f, a.deep, a.workers)
        except ConfigError as e:
            bad += 1
            print(e, file=sys.stderr)
            continue
        except (CosimError, OSError) as e:  # e.g. a model JSBSim cannot load
            bad += 1
            print(f"{f}: {e}", file=sys.stderr)
            continue
        deep = ""
        if a.deep:
            deep = ", every vehicle built and trimmed" if combos == 1 else \
                f", the vehicles of {built} distinct combination(s) built and trimmed"
        sweep = f"; all {combos} sweep combinations" if combos > 1 else ""
        print(f"{f}: ok ({len(scn.vehicles)} vehicles, {scn.duration_s:g} s, "
              f"{scn.rates.physics_hz:g}/{scn.rates.control_hz:g}/{scn.rates.log_hz:g} Hz"
              f"{sweep}{deep})")
    return EXIT_USAGE if bad else EXIT_OK


def _validate_file(f: str, deep: bool, workers: int | None) -> tuple[Scenario, int, int]:
    """Check a scenario file, every combination of its sweep (values the first
    combination does not have can fail: a speed beyond the model's envelope);
    with ``deep``, build the vehicles of each distinct combination. Returns
    the first combination's scenario, the combinations checked and built."""
    from cosim.scenario import load_scenario
    from cosim.scenario.schema import Memo, check_scenario
    from cosim.sweep.spec import read_sweep

    memo = Memo()  # the file parsed once; parts the same in two combinations checked once
    data, lines, _, _ = memo.parsed(memo.read(Path(f)), f)
    spec = read_sweep(f, (data, lines))
    points: list[dict[str, Any] | None] = list(spec.points()) if spec.values else [None]
    found: dict[str, list[int]] = {}  # problem -> the combinations that have it
    more = 0  # problems counted beyond those kept
    first: Scenario | None = None
    seen: set[tuple[Any, ...]] = set()
    built = 0
    t0 = last = time.monotonic()
    for done, point in enumerate(points):
        if time.monotonic() - last >= 5.0:
            last = time.monotonic()
            log.info("%s: %d of %d sweep combinations checked (%.0f s)", f, done, len(points),
                     last - t0)
        problems: list[str] = []
        try:
            if first is not None and not deep:  # only the problems matter
                check_scenario(f, sweep_point=point, memo=memo)
                continue
            scn = load_scenario(f, sweep_point=point, memo=memo)
            if first is None:
                first = scn
            key = tuple((v.model, v.vehicle_class, v.alt_msl_m, v.airspeed_mps, v.trim,
                         v.initial_props) for v in scn.vehicles)
            if deep and key not in seen:
                seen.add(key)
                built += 1
                _build_all(scn, f, workers)
        except ConfigError as e:
            problems, more = e.problems, more + e.more
        except (CosimError, OSError) as e:
            problems = [f"{f}: {e}"]
        for m in problems:
            where = found.setdefault(m, [])
            if not where or where[-1] != done:
                where.append(done)
    if found:
        def line(problem: str) -> int:  # in file order, as one combination's are
            m = re.match(rf"{re.escape(f)}:(\d+): ", problem)
            return int(m.group(1)) if m else 0

        raise ConfigError([_in_combinations(m, [points[i] for i in rows], len(points),
                                            spec.values, spec.swept)
                           for m, rows in sorted(found.items(), key=lambda kv: line(kv[0]))],
                          more)
    assert first is not None
    return first, len(points), built


def _in_combinations(problem: str, where: list[dict[str, Any] | None], total: int,
                     values: dict[str, tuple[Any, ...]], swept: Sequence[str]) -> str:
    """A problem found in the sweep combinations ``where`` (of ``total``; the
    sweep's ``values``), said once: ``sweep combinations speed_kt=400,
    alt_agl_m=any (12 of 36): ...``; combinations that do not make such a
    product are named by the first and counted."""
    from cosim.scenario.placeholders import format_value

    points = [p for p in where if p is not None]
    if total == 1 or not points:  # no sweep
        return problem
    if len(points) == total:
        return f"every sweep combination: {problem}"
    seen = {n: list(dict.fromkeys(p[n] for p in points)) for n in swept}

    def named(n: str, vals: list[Any]) -> str:
        if len(vals) > 1 and len(vals) == len(values[n]):
            return f"{n}=any"
        return f"{n}={'|'.join(format_value(v) for v in vals)}"

    product = 1
    for vals in seen.values():
        product *= len(vals)
    if len(points) == 1:
        return f"sweep combination {', '.join(named(n, v) for n, v in seen.items())}: {problem}"
    if product == len(points):  # every combination of the values seen
        return (f"sweep combinations {', '.join(named(n, v) for n, v in seen.items())} "
                f"({len(points)} of {total}): {problem}")
    first = ", ".join(named(n, [points[0][n]]) for n in swept)
    return (f"sweep combination {first} (and {len(points) - 1} other "
            f"combination{'s' * (len(points) > 2)}): {problem}")


def _build_all(scn: Scenario, fname: str, workers: int | None) -> None:
    """Build and trim every vehicle of ``scn`` as a run would (process
    backend); the vehicles that fail become a ``ConfigError`` with the line of
    each one's scenario entry."""
    from cosim.errors import BuildError
    from cosim.fdm_pool import make_pool
    from cosim.scenario.yaml_lines import format_path

    try:
        with make_pool(scn.vehicles, scn.rates.dt_s, scn.channels, "process", workers):
            pass
    except BuildError as e:
        index = {v.id: i for i, v in enumerate(scn.vehicles)}
        paths, lines = scn.extra.get("vehicle_paths", []), scn.extra.get("vehicle_lines", [])
        problems = []
        for vid, msg in e.failures:
            i = index.get(vid)
            where = f"{lines[i]}: {format_path(paths[i])}" if i is not None and i < len(
                lines) else "1: vehicles"
            problems.append(f"{fname}:{where}: {msg}")
        raise ConfigError(problems) from None


def _cmd_models(a: argparse.Namespace) -> int:
    from cosim.jsb import find_model, list_models, new_fdm

    if a.properties:
        fdm = new_fdm(find_model(a.properties), 1 / 120)
        print(fdm.query_property_catalog(""))
        return EXIT_OK
    if a.classes:
        from cosim.vehicles import vehicle_classes

        for name, cls in vehicle_classes().items():
            print(f"{name:12s} {cls.model_kind:8s} {type(cls).__module__:28s} {cls.description}")
        return EXIT_OK
    from cosim.jsb import held_messages
    from cosim.vehicles import DEFAULT_CLASS, vehicle_classes

    classes = vehicle_classes()
    failed: list[str] = []
    models = list_models()
    print(f"{'check   ' if a.check else ''}{'MODEL':18s} {'SOURCE':7s} {'CLASS':12s} "
          f"{'COMMANDS':8s} DESCRIPTION")
    for m in models:
        status = ""
        if a.check:  # JSBSim's own messages are held: a failure says its first error
            with held_messages() as said:
                try:
                    new_fdm(m, 1 / 120)
                    status = "ok      "
                except CosimError as e:
                    status = "FAILED  "
                    errors = [t for level, t in said if level >= logging.ERROR]
                    failed.append(f"{m.name}: {(errors or [str(e)])[0].splitlines()[0]}")
            for _level, text in said:
                log.debug("%s: %s", m.name, text)
        name = str((m.profile or {}).get("class", DEFAULT_CLASS))
        commands = "yes" if name in classes and classes[name].commandable else "no"
        print(f"{status}{m.name:18s} {m.source:7s} {name:12s} {commands:8s} {m.description}")
    print("COMMANDS yes: the model has a cosim profile (aircraft/profiles/, "
          "aircraft/<model>/cosim.yaml) that makes it a vehicle class taking command:, "
          "MAVLink commands, missions and the swarm; no: it flies open-loop, worked by set: "
          "only (JSBSim properties).")
    if a.check:
        print(f"{len(models) - len(failed)} of {len(models)} models load"
              + "".join(f"\n  {f}" for f in failed))
    return EXIT_FAIL if failed else EXIT_OK


def _cmd_plot(a: argparse.Namespace) -> int:
    from cosim.logs.plot import plot_run

    run = Path(a.run)
    if not (run / "states.parquet").exists():
        raise ConfigError(f"{run}: not a cosim run folder (no states.parquet)")
    patterns = [x.strip() for x in a.vehicles.split(",") if x.strip()] if a.vehicles else None
    print(plot_run(run, a.out, patterns, a.max_vehicles))
    return EXIT_OK


def _cmd_export(a: argparse.Namespace) -> int:
    from datetime import datetime, timezone

    from cosim.export import DEFAULT_EPOCH, export_run

    epoch = DEFAULT_EPOCH
    if a.epoch:
        try:
            epoch = datetime.fromisoformat(a.epoch.replace("Z", "+00:00"))
        except ValueError:
            raise ConfigError(f"--epoch: expected an ISO 8601 time such as "
                              f"2026-06-01T12:00:00Z, got {a.epoch!r}") from None
        if epoch.tzinfo is None:
            epoch = epoch.replace(tzinfo=timezone.utc)
        epoch = epoch.astimezone(timezone.utc)
    print(export_run(Path(a.run), a.format, Path(a.out) if a.out else None, a.rate_hz, epoch))
    return EXIT_OK


def _cmd_recover(a: argparse.Namespace) -> int:
    from cosim.logs.recover import recover_run

    rec = recover_run(a.run)
    if not rec.changed:
        print(f"{a.run}: nothing to recover ({rec.rows} state rows readable)")
        return EXIT_OK
    for line in rec.actions:
        print(f"{a.run}: {line}")
    print(f"{a.run}: recovered; {rec.rows} state rows readable"
          + (f", up to tick {rec.ticks}" if rec.ticks is not None else ""))
    return EXIT_OK


def _cmd_sweep(a: argparse.Namespace) -> int:
    from cosim.sweep.runner import run_sweep

    if a.jobs is not None and a.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {a.jobs}")

    def on_done(o: Any, done: int, total: int, elapsed_s: float) -> None:
        left_s = elapsed_s / done * (total - done)
        how = "completed" if o.status == "completed" else f"{o.status.upper()}: {o.error}"
        log.info("[%d/%d] %s: %s in %.1f s (elapsed %.0f s, about %.0f s left)", done, total,
                 o.name, how, o.wall_s, elapsed_s, left_s)

    if a.out is None:
        from cosim.sweep.spec import read_sweep

        read_sweep(a.scenario)  # the file's problems first, with their lines
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", Path(a.scenario).stem) or "sweep"
        a.out = str(Path("runs") / f"{name}-sweep-{time.strftime('%Y%m%d-%H%M%S')}")
    res = run_sweep(a.scenario, a.out, jobs=a.jobs, overwrite=a.overwrite,
                    duration_s=a.duration_s, on_done=on_done)
    ok = len(res.runs) - len(res.failed)
    print(f"{ok} of {len(res.runs)} runs completed in {res.wall_s:.1f} s; outputs in {a.out}/: "
          f"visibility.csv, manifest.csv, sweep.json, logs/, one folder per run")
    for o in res.failed:
        print(f"cosim sweep: run {o.name} {o.status}: {o.error} (log: "
              f"{Path(a.out) / 'logs' / (o.name + '.log')})", file=sys.stderr)
    return EXIT_FAIL if res.failed else EXIT_OK


def _cmd_search_plan(a: argparse.Namespace) -> int:
    from cosim.search.report import default_altitudes, fleet_table, format_report

    scn = _load_scenario(a.scenario)
    spec = scn.sections.get("search")
    if spec is None:
        raise ConfigError(f"{a.scenario}: no search: section")
    alts = a.altitudes or default_altitudes(spec)
    print(format_report(spec, scn, fleet_table(spec, a.deadline_s, alts), a.deadline_s))
    return EXIT_OK


def _gap_summary(fit: dict[str, Any], verdicts: list[str]) -> str:
    """One line of ``cosim trials analyse``'s print-out for a critical-gap fit."""
    u, sym = fit.get("unit"), "d" if fit.get("unit") == "mm" else "h"
    if fit.get("cg") is None:
        return f"{fit.get('status')} ({fit.get('detail')})"
    lo, hi = fit["cg_ci"]
    where = (f"from {sym}0 = {fit['threshold']:.0f} {u}" if fit["status"] == "plateau" else
             f"constant from the lowest level tested ({fit['threshold']:g} {u}) on")
    counts = {v: verdicts.count(v) for v in ("fails", "inconclusive", "untested")}
    total = verdicts.count("holds") + sum(counts.values())
    others = ", ".join(f"{k} at {n}" for k, n in counts.items() if n)
    people = fit.get("participants") or 0
    return (f"{fit['status']}: CG {fit['cg']:.3g} {u} (95% CI {lo:.3g}-{hi:.3g}, "
            f"{fit.get('interval')}, {people} participant{'' if people == 1 else 's'}), "
            f"{where}; the relation holds at {verdicts.count('holds')} of {total} plateau "
            f"levels" + (f" ({others})" if others else ""))


def _existing_db(db: str) -> None:
    """A database file to read must be there (opening a mistyped path would
    make an empty one; ``Store`` refuses one that is not a regular file)."""
    if "://" not in db and not Path(db).exists():
        raise ConfigError(f"{db}: no such trial database")


def _cmd_trials(a: argparse.Namespace) -> int:
    if a.trials_cmd == "serve":
        from cosim.trials.server import serve

        if not 0 < a.port < 65536:
            raise ConfigError(f"--port must be 1..65535, got {a.port}")
        serve(a.study, host=a.host, port=a.port, db_url=a.db, public=a.public)
        return EXIT_OK
    if a.trials_cmd == "export":
        from cosim.trials.store import export_csv

        _existing_db(a.db)
        print(export_csv(a.db, a.out))
        return EXIT_OK
    if a.trials_cmd == "analyse":
        import tempfile

        from cosim.trials.analysis import MAX_PANELS, analyse, shown_first
        from cosim.trials.store import export_csv

        src = Path(a.responses)
        with tempfile.TemporaryDirectory() as tmp:
            if src.suffix.lower() != ".csv":  # a database: its responses first
                _existing_db(a.responses)
                src = export_csv(a.responses, Path(tmp) / "responses.csv")
            summary = analyse(src, a.out, seed=a.seed, exclude_reshown=a.exclude_reshown,
                              tolerance=a.tolerance)
        verdicts: dict[str, list[str]] = {}
        for c in summary.get("critical_gap_check", []):
            verdicts.setdefault(c["fit"], []).append(c["verdict"])
        fits = summary.get("critical_gap", {})
        labels = list(fits)
        order = shown_first([fits[label].get("status", "") for label in labels])
        for i in order[:MAX_PANELS]:  # those with a critical gap first, as in the figure
            fit = fits[labels[i]]
            print(f"critical gap, {labels[i]}: {_gap_summary(fit, verdicts.get(labels[i], []))}")
        if len(order) > MAX_PANELS:
            print(f"critical gap: {len(order) - MAX_PANELS} more of the {len(order)} fits in "
                  f"critical_gap.csv (those above have a critical gap first)")
        for which, columns in summary.get("binned_conditions", {}).items():
            for column, bins in columns.items():
                print(f"{column}: {sum(b['values'] for b in bins)} values in the {which} "
                      f"responses, cut into {len(bins)} bins of about equal trials, each "
                      f"analysed at its trials' mean (the bins in analysis.json)")
        model = (summary.get("recognise") or {}).get("logistic") or {}
        for name, c in (model.get("coefficients") or {}).items():
            if name != "intercept":
                print(f"recognition, {name}: {c['estimate']:+.2f} (95% CI {c['ci'][0]:+.2f} "
                      f"to {c['ci'][1]:+.2f}) on the log-odds")
        print(f"outputs in {a.out}/: " + ", ".join(Path(f).name for f in summary.get("files", [])))
        return EXIT_OK
    raise ConfigError("cosim trials: give serve, export or analyse (cosim trials --help)")


def _cmd_visibility(a: argparse.Namespace) -> int:
    from cosim.conspicuity.visibility import PASS_COLUMNS, physics_hz_of, write_csv
    from cosim.sweep.runner import rewrite_tables

    run = Path(a.run)
    if (run / "sweep.json").exists():
        res = rewrite_tables(run)
        print(f"{run}/visibility.csv and manifest.csv rewritten from {len(res.runs)} runs")
        return EXIT_OK
    if not (run / "summary.json").exists() and not (run / "cameras").is_dir():
        raise ConfigError(f"{run}: not a cosim run or sweep folder (no summary.json, "
                          f"sweep.json or cameras/)")
    from cosim.conspicuity import run_visibility
    from cosim.conspicuity.visibility import pass_rows

    rows = pass_rows(run_visibility(run), physics_hz_of(run))
    if not rows:
        print(f"{run}: no cameras with ground truth in this run")
        return EXIT_OK
    for r in rows:
        where = f"{r['vehicle']}/{r['camera']} {r['target']}"
        if r["pass"] == "0":
            print(f"{where}: never in view")
            continue
        print(f"{where} pass {r['pass']}: visible {r['visible_s']} s "
              f"(t = {r['first_visible_s']} .. {r['last_visible_s']} s, {r['frames']} frames), "
              f"nearest the centre at t = {r['overhead_s']} s (tick {r['overhead_tick'] or '?'})")
    print(write_csv(run / "visibility.csv", PASS_COLUMNS, rows))
    return EXIT_OK


def _cmd_swarm(a: argparse.Namespace) -> int:
    from cosim.swarm.external import UdpController

    scn = _load_scenario(a.scenario)
    ctl = UdpController(scn, a.connect, a.out, connect_timeout_s=a.connect_timeout_s)
    s = ctl.run()
    for name, g in s["groups"].items():
        for ph in g["phases"]:
            print(f"{name} phase {ph['phase']} {ph['behaviour']}: {ph.get('reason')} after "
                  f"{ph.get('time_s', 0.0):.1f} s")
    if a.out:
        print(f"outputs in {a.out}/: swarm.json, swarm_events.jsonl, swarm_commands.csv, "
              f"swarm.png")
    return EXIT_OK


def _cmd_bench(a: argparse.Namespace) -> int:
    from cosim.bench import check_rates, run_bench

    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    try:
        check_rates(a.physics_hz, a.control_hz)
    except ValueError as e:
        raise ConfigError(f"--physics-hz/--control-hz: {e}") from None
    for opt, path in (("--json", a.json), ("--plot", a.plot)):
        if not path:
            continue
        folder = Path(path).resolve().parent
        if not folder.is_dir():
            raise ConfigError(f"{opt} {path}: folder {folder} does not exist")
        if not os.access(folder, os.W_OK):
            raise ConfigError(f"{opt} {path}: folder {folder} is not writable")
        if Path(path).is_dir():
            raise ConfigError(f"{opt} {path}: is a folder")
    if a.vehicle_class is not None:
        from cosim.vehicles.registry import get_class

        get_class(a.vehicle_class)  # an unknown class: ConfigError naming the known ones
    if a.gym:
        from cosim.bench_gym import require_gymnasium

        require_gymnasium()  # not installed: a usage error before anything runs
    if a.quick:
        a.vehicles, a.seconds, a.repeat = [1, 16, 128], 1.0, 1
    run_bench(vehicles=a.vehicles, model=a.model, backend=a.backend, workers=a.workers,
              seconds=a.seconds, physics_hz=a.physics_hz, control_hz=a.control_hz,
              baselines=not a.no_baselines, repeat=max(1, a.repeat), json_path=a.json,
              vehicle_class=a.vehicle_class, plot_path=a.plot, whole=a.whole_run,
              log_hz=a.log_hz, gym=a.gym)
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    parser = _build_parser()
    try:
        a = parser.parse_args(list(argv) if argv is not None else None)
    except _UsageError as e:
        print(e, file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as e:  # --help, --version
        return int(e.code or 0)
    if a.cmd is None:
        parser.print_help()
        return EXIT_USAGE
    _setup_logging(a.verbose, a.quiet)
    handlers = {"run": _cmd_run, "validate": _cmd_validate, "models": _cmd_models,
                "plot": _cmd_plot, "bench": _cmd_bench, "sweep": _cmd_sweep,
                "recover": _cmd_recover, "export": _cmd_export,
                "swarm": _cmd_swarm, "search-plan": _cmd_search_plan, "trials": _cmd_trials,
                "visibility": _cmd_visibility}
    try:
        return handlers[a.cmd](a)
    except ConfigError as e:
        print(e, file=sys.stderr)
        return EXIT_USAGE
    except CosimError as e:
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_FAIL
    except KeyboardInterrupt:
        print("cosim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAIL
    except OSError as e:  # a file that cannot be written, a full disk, ...
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_FAIL
    except ValueError as e:  # a bad value that got past the parser
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
