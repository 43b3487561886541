"""The ``cameras:`` section as the scenario, the runner and a sweep see it
(``cosim.core.section``): parsed by ``config``, rendered by the camera
participant, inline when a run gets one core (a sweep's runs)."""

from __future__ import annotations

import dataclasses
from typing import Any

from cosim.core.section import P, Section, SectionContext


class CamerasSection(Section):
    key = "cameras"
    description = "cameras on vehicles: video and per-frame ground truth of the world"
    outputs = ("cameras/",)

    def parse(self, info: SectionContext, node: Any, path: P) -> Any:
        from cosim.renderer.config import parse_cameras

        return parse_cameras(info, node, path)

    def participant(self, scenario: Any) -> Any:
        from cosim.renderer.participant import CameraParticipant

        return CameraParticipant(scenario)

    def one_core(self, parsed: Any) -> Any:
        """Rendered in the run's own process (``render_workers: 0``)."""
        return dataclasses.replace(parsed, render_workers=0)


CAMERAS = CamerasSection()
