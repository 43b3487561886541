"""``cosim recover``: what a killed or failed run left, made readable."""

from __future__ import annotations

import argparse

from cosim.cli.common import EXIT_OK
from cosim.core.section import CliCommand


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN_DIR", help="a cosim run output folder")


def run(a: argparse.Namespace) -> int:
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


COMMAND = CliCommand(
    "recover",
    "make what a killed or failed run left readable (journalled ticks into Parquet, a summary)",
    add_arguments, run, rank=60)
