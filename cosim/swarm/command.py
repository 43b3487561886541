"""``cosim swarm``: a scenario's swarm controller in this process, connected to
``cosim run --external-controller`` (the swarm section's command)."""

from __future__ import annotations

import argparse

from cosim.core.args import EXIT_OK, positive_float
from cosim.core.section import CliCommand


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario YAML file (the one the simulation runs)")
    p.add_argument("--connect", metavar="URL", required=True,
                   help="udpout:HOST:PORT where the simulation's --mavlink udpin:HOST:PORT "
                        "listens")
    p.add_argument("--out", metavar="DIR",
                   help="write swarm.json, swarm_events.jsonl, swarm_commands.csv and "
                        "swarm.png here")
    p.add_argument("--connect-timeout-s", type=positive_float, default=60.0, metavar="S",
                   help="give up if the simulation does not answer within S (default 60)")


def run(a: argparse.Namespace) -> int:
    from cosim.scenario import load_scenario
    from cosim.swarm.external import UdpController

    scn = load_scenario(a.scenario)
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


COMMAND = CliCommand(
    "swarm",
    "run a scenario's swarm controller in this process, connected to "
    "`cosim run --external-controller`",
    add_arguments, run, rank=110)
