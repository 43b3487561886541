"""``cosim run``: one scenario from start to a clean stop, with its MAVLink
link, live view and video streams as the flags ask (the run is built by
``cosim.api.prepare_run``, as ``cosim.run()`` builds it)."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from types import FrameType

from cosim.cli.common import (
    EXIT_FAIL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    add_coordinating_driver,
    backend_names,
    driver_options,
    load_scenario,
    positive_float,
)
from cosim.cli.progress import Progress
from cosim.core.section import CliCommand
from cosim.errors import ConfigError

#: the options as ``cosim run``'s messages call them
FLAGS = {"out": "--out", "overwrite": "--overwrite", "mavlink_url": "--mavlink",
         "signing": "--mavlink-signing-key-*", "external_controller": "--external-controller"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    names, DEFAULT_BACKEND, backend_help = backend_names()  # noqa: N806
    p.add_argument("scenario", help="scenario YAML file")
    p.add_argument("--out", metavar="DIR",
                   help="output folder (default: runs/<scenario>-<date>-<time>)")
    p.add_argument("--overwrite", action="store_true",
                   help="allow writing into a folder that already holds a run")
    p.add_argument("--backend", choices=names, default=DEFAULT_BACKEND,
                   help=f"where the vehicles are stepped: {backend_help} (default "
                        f"{DEFAULT_BACKEND})")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker count (default: the backend's own, for process one per "
                        "core)")
    p.add_argument("--address", metavar="HOST:PORT",
                   help="the cluster to run on, for a backend that runs on one (ray: the "
                        "head's address from 'ray start --head'; default RAY_ADDRESS, else a "
                        "local Ray)")
    p.add_argument("--strict", action="store_true",
                   help="stop with an error when a machine of the cluster is lost, rather "
                        "than rebuild its vehicles elsewhere (which ends bit-exactness)")
    p.add_argument("--connect-timeout-s", type=positive_float, metavar="S",
                   help="how long joining the cluster may take before the run fails, for a "
                        "backend that joins one (ray: default 30)")
    add_coordinating_driver(p)
    p.add_argument("--realtime", nargs="?", const=1.0, type=positive_float, metavar="FACTOR",
                   help="pace to the wall clock (FACTOR x real time, default 1)")
    p.add_argument("--duration-s", type=positive_float, metavar="S",
                   help="override the scenario's duration")
    p.add_argument("--mavlink", metavar="URL", nargs="?", const="udpout:127.0.0.1:14550",
                   help="present every vehicle on MAVLink (udpout:HOST:PORT sends there and "
                        "answers whoever talks; udpin:HOST:PORT listens; default "
                        "udpout:127.0.0.1:14550, where ground stations listen)")
    sg = p.add_mutually_exclusive_group()
    sg.add_argument("--mavlink-signing-key-file", metavar="PATH",
                    help="sign MAVLink 2 traffic with the passphrase in PATH (as MAVProxy's "
                         "'signing key'); unsigned or wrongly signed commands are dropped")
    sg.add_argument("--mavlink-signing-key-env", metavar="NAME",
                    help="the same, with the passphrase in environment variable NAME")
    p.add_argument("--mavlink-signing-link-id", type=int, default=0, metavar="N",
                   help="link id in outgoing signatures (0..255, default 0)")
    p.add_argument("--external-controller", action="store_true",
                   help="the scenario's swarm controller runs in another process (cosim swarm "
                        "SCENARIO --connect URL), kept in lockstep over --mavlink")
    p.add_argument("--step-timeout-s", type=positive_float, default=60.0, metavar="S",
                   help="a physics worker silent this long in one exchange, or a render "
                        "worker this long with frames to render, fails the run (default 60)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    p.add_argument("--view", metavar="URL", nargs="?", const="spawn",
                   help="watch the run in 3-D in Rerun's viewer (the view extra): "
                        "alone, opens a viewer here; with URL, streams to a viewer running "
                        "there (e.g. rerun+http://127.0.0.1:9876/proxy)")
    p.add_argument("--record-view", metavar="FILE",
                   help="write the same 3-D view to FILE (.rrd) to open later: rerun FILE")
    p.add_argument("--video", metavar="SYSID[:CAM]=udp://HOST:PORT", action="append",
                   help="stream that vehicle's camera (its MAVLink system id; CAM: the "
                        "camera's name, default its first) as H.264 over RTP to HOST:PORT "
                        "(QGroundControl: UDP h.264 on 5600; add ?format=mpegts for MPEG-TS); "
                        "repeatable; loopback only unless --video-allow-remote")
    p.add_argument("--video-allow-remote", action="store_true",
                   help="allow --video to send to addresses other than this machine")
    p.add_argument("--view-rate-hz", type=positive_float, default=10.0, metavar="HZ",
                   help="vehicle poses per second of simulation time in the view (default 10)")


def run(a: argparse.Namespace) -> int:
    from cosim.api import prepare_run

    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    scn = load_scenario(a.scenario)
    backend_options = {k: v for k, v in (("address", a.address), ("strict", a.strict or None),
                                         ("connect_timeout_s", a.connect_timeout_s))
                       if v is not None}
    backend_options.update(driver_options(a.backend, a.coordinating_driver))
    run = prepare_run(
        scn, a.out, duration_s=a.duration_s, overwrite=a.overwrite, mavlink_url=a.mavlink,
        signing_key_file=a.mavlink_signing_key_file, signing_key_env=a.mavlink_signing_key_env,
        signing_link_id=a.mavlink_signing_link_id, external_controller=a.external_controller,
        view=a.view, record_view=a.record_view, view_rate_hz=a.view_rate_hz,
        video=a.video or (), video_allow_remote=a.video_allow_remote, backend=a.backend,
        backend_options=backend_options, names=FLAGS, workers=a.workers,
        realtime=a.realtime, step_timeout_s=a.step_timeout_s,
        progress=None if a.no_progress else Progress(sys.stderr, scn.rates.physics_hz))
    out = run.out

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


COMMAND = CliCommand(
    "run",
    "run a scenario",
    add_arguments, run, rank=10, flies_aircraft=True)
