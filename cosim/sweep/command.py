"""``cosim sweep``: a scenario once per combination of its ``sweep:`` values,
in parallel (the sweep section's command)."""

from __future__ import annotations

import argparse
import logging
import re
import sys
import time
from pathlib import Path
from typing import Any

from cosim.core.args import EXIT_FAIL, EXIT_OK, positive_float
from cosim.core.section import CliCommand
from cosim.errors import ConfigError

log = logging.getLogger("cosim")

def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario YAML file with a sweep: section")
    p.add_argument("--out", metavar="DIR",
                   help="output folder: one subfolder per run, visibility.csv, manifest.csv "
                        "(default runs/<file name>-sweep-<date>-<time>)")
    p.add_argument("--jobs", type=int, metavar="N",
                   help="runs at a time (default: one per core); each run is one process")
    p.add_argument("--overwrite", action="store_true",
                   help="allow writing into a folder that already holds a sweep")
    p.add_argument("--duration-s", type=positive_float, metavar="S",
                   help="override every run's duration")


def run(a: argparse.Namespace) -> int:
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


COMMAND = CliCommand(
    "sweep",
    "run a scenario once per combination of its sweep: values, in parallel",
    add_arguments, run, rank=70, flies_aircraft=True)
