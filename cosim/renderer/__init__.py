"""renderer: per-vehicle cameras over geo-referenced ground imagery with 3-D
targets; frames to video plus a ground-truth record per frame.

Owns ``cameras:``/``ground:``/``targets:`` (``config``), the camera model
(``camera``), the ground texture (``ground``; georeferenced files: ``geotiff``;
what a ground image may read and declare, checked before anything opens it:
``imagery``, ``headers``), target drawing and ground truth
(``targets``), one frame (``frame``) and the render pool and outputs
(``participant``). It reads the loop's state array at exchange ticks and never
touches the FDM pool, the logs' files or other participants. Frames depend only
on the scenario, the seed and the simulated pose at the frame's tick: never on
wall-clock time or the number of render workers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cosim.renderer.participant import CameraParticipant
    from cosim.scenario import Scenario


def make_participant(scenario: Scenario) -> CameraParticipant:
    from cosim.renderer.participant import CameraParticipant

    return CameraParticipant(scenario)
