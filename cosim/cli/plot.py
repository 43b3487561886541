"""``cosim plot``: a run's ground tracks and altitude (or speed) as a PNG."""

from __future__ import annotations

import argparse
from pathlib import Path

from cosim.cli.common import EXIT_OK
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")
    p.add_argument("--out", metavar="PNG", help="output file (default RUN_DIR/track.png)")
    p.add_argument("--vehicles", metavar="IDS",
                   help="comma-separated vehicle ids or patterns (fleet00*) to draw "
                        "(default: every vehicle)")
    p.add_argument("--max-vehicles", type=int, metavar="N",
                   help="draw at most the first N (in the scenario's order)")


def run(a: argparse.Namespace) -> int:
    from cosim.logs.plot import plot_run

    run = Path(a.run)
    if not (run / "states.parquet").exists():
        raise ConfigError(f"{run}: not a cosim run folder (no states.parquet)")
    patterns = [x.strip() for x in a.vehicles.split(",") if x.strip()] if a.vehicles else None
    print(plot_run(run, a.out, patterns, a.max_vehicles))
    return EXIT_OK


COMMAND = CliCommand(
    "plot",
    "plot a run's ground tracks, the aircraft's altitude and the ground vehicles' speed (PNG)",
    add_arguments, run, rank=40)
