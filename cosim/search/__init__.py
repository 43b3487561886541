"""Wide-area search: the scenario's ``search:`` section (area, base, fires),
the plan flown as MAVLink missions, detections from the cameras' geometry
(``sensing``) or their frames (``image_detect``), and the metrics."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cosim.scenario import Scenario
    from cosim.search.participant import SearchParticipant


def make_participant(scenario: Scenario) -> SearchParticipant:
    """The runner's factory (``cosim.sync.participants.PARTICIPANTS``)."""
    from cosim.search.participant import SearchParticipant

    return SearchParticipant(scenario)
