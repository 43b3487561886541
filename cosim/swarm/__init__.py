"""swarm: consensus behaviours for fixed-wing swarms (DESIGN.md 3.4, issue 5).

Owns the ``swarm:`` scenario section (``config``), the consensus laws
(``laws``: centroid, rendezvous, anti-rendezvous, biased flocking, stall
speeds), the controller that turns MAVLink telemetry into DO_REPOSITION
commands (``controller``), the run's separation and phase metrics
(``metrics``), ``swarm.png`` (``plot``), and its two transports: in-process
inside ``cosim run`` (``participant``) and over UDP as ``cosim swarm
--connect`` (``external``).

It sees vehicles only through MAVLink telemetry and commands them only with
MAVLink messages; it must not touch the pool, guidance or setpoints. Only
the metrics read the ground truth (the state array), in-process.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cosim.scenario import Scenario
    from cosim.swarm.participant import SwarmParticipant


def make_participant(scenario: Scenario) -> SwarmParticipant:
    """The runner's factory (``cosim.sync.participants.PARTICIPANTS``)."""
    from cosim.swarm.participant import SwarmParticipant

    return SwarmParticipant(scenario)
