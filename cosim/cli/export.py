"""``cosim export``: a run's tracks for Tacview, Google Earth or Cesium."""

from __future__ import annotations

import argparse
from pathlib import Path

from cosim.cli.common import EXIT_OK, positive_float
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")
    from cosim.export import EXPORTERS

    p.add_argument("--format", required=True, choices=list(EXPORTERS),
                   help="; ".join(f"{e.name}: {e.description}" for e in EXPORTERS.values()))
    p.add_argument("--out", metavar="FILE",
                   help="output file (default RUN_DIR/track.<format>)")
    p.add_argument("--rate-hz", type=positive_float, default=10.0, metavar="HZ",
                   help="samples per second of simulation time (default 10)")
    p.add_argument("--epoch", metavar="ISO",
                   help="the calendar time of simulation time 0, e.g. 2026-06-01T12:00:00Z "
                        "(default 2000-01-01T00:00:00Z)")


def run(a: argparse.Namespace) -> int:
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


COMMAND = CliCommand(
    "export",
    "write a run's tracks for Tacview (ACMI), Google Earth (KML) or Cesium (CZML)",
    add_arguments, run, rank=50)
