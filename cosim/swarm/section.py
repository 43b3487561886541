"""The ``swarm:`` section as the scenario, the runner and the CLI see it
(``cosim.core.section``): parsed by ``config``, run by the swarm controller's
participant in process, or by ``cosim swarm`` in another process beside
``cosim run --external-controller``."""

from __future__ import annotations

from typing import Any

from cosim.core.section import P, Section, SectionContext
from cosim.swarm.command import COMMAND


class SwarmSection(Section):
    key = "swarm"
    description = "consensus behaviours (rendezvous, anti-rendezvous, flocking) flown over MAVLink"
    talks_mavlink = True
    controller = True
    outputs = ("swarm.json", "swarm_events.jsonl", "swarm_commands.csv", "swarm.png")

    commands = (COMMAND,)

    def parse(self, info: SectionContext, node: Any, path: P) -> Any:
        from cosim.swarm.config import parse_swarm

        return parse_swarm(info, node, path)

    def participant(self, scenario: Any) -> Any:
        from cosim.swarm.participant import SwarmParticipant

        return SwarmParticipant(scenario)


SWARM = SwarmSection()
