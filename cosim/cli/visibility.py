"""``cosim visibility``: how long each target is in view, pass by pass, for a
run folder or (rewriting its tables) a sweep folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from cosim.cli.common import EXIT_OK
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN_DIR", help="a run folder (writes RUN_DIR/visibility.csv)"
                                                  " or a sweep folder (rewrites its tables)")


def run(a: argparse.Namespace) -> int:
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


COMMAND = CliCommand(
    "visibility",
    "how long each target is in view, pass by pass (a run or a sweep folder)",
    add_arguments, run, rank=80)
