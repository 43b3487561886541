"""``cosim replay``: a run folder's scenario run again with the operator's
logged commands, and the outputs compared with the original's."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cosim.cli.common import EXIT_FAIL, EXIT_OK, backend_names
from cosim.cli.progress import Progress
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    names, default, what = backend_names()
    p.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")
    p.add_argument("--out", metavar="DIR",
                   help="where the replay writes its run folder (default RUN_DIR-replay)")
    p.add_argument("--backend", choices=names, default="inline",
                   help=f"{what} (default inline)")
    p.add_argument("--workers", type=int, metavar="N", help="worker processes (process backend)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar or lines")


def run(a: argparse.Namespace) -> int:
    from cosim.logs.runfolder import RunFolder, physics_hz
    from cosim.sync.replay import replay_run

    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    src = Path(a.run)
    out = Path(a.out) if a.out else src.absolute().with_name(src.absolute().name + "-replay")
    hz = physics_hz(RunFolder(src).summary() or {})  # checked again by replay_run
    res = replay_run(src, out, backend=a.backend, workers=a.workers,
                     progress=False if a.no_progress or hz is None else Progress(sys.stderr, hz))
    for line in res.compared:
        print(f"compared {line}")
    if res.identical:
        print(f"identical: {out} reproduces {src}")
        return EXIT_OK
    for line in res.differences:
        print(f"different: {line}")
    return EXIT_FAIL


COMMAND = CliCommand(
    "replay",
    "run a run folder's scenario again with its logged operator commands and compare the "
    "states and videos with the original's (exit 0 identical, 1 different)",
    add_arguments, run, rank=62, flies_aircraft=True)
