"""``cosim search-plan``: a scenario's search, its plan, the smallest fleet for
a deadline and how it changes with altitude (the search section's command)."""

from __future__ import annotations

import argparse

from cosim.core.args import EXIT_OK, altitudes, positive_float
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario YAML file with a search: section")
    p.add_argument("--deadline-s", type=positive_float, default=600.0, metavar="S",
                   help="the whole area covered within S (default 600: 10 minutes)")
    p.add_argument("--altitudes", type=altitudes, metavar="M,M,...",
                   help="altitudes (m AGL) to compare (default: a quarter to twice the "
                        "scenario's)")


def run(a: argparse.Namespace) -> int:
    from cosim.scenario import load_scenario
    from cosim.search.report import default_altitudes, fleet_table, format_report

    scn = load_scenario(a.scenario)
    spec = scn.sections.get("search")
    if spec is None:
        raise ConfigError(f"{a.scenario}: no search: section")
    alts = a.altitudes or default_altitudes(spec)
    print(format_report(spec, scn, fleet_table(spec, a.deadline_s, alts), a.deadline_s))
    return EXIT_OK


COMMAND = CliCommand(
    "search-plan",
    "a scenario's search: its plan, the smallest fleet for a deadline, and how it changes with "
    "altitude",
    add_arguments, run, rank=90)
