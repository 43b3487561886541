"""The ``sweep:`` section as the scenario sees it (``cosim.core.section``):
after the placeholders are substituted it holds the combination in use
(name -> value), ``Scenario.sections["sweep"]``; ``cosim sweep`` runs every
combination (``runner``)."""

from __future__ import annotations

from typing import Any

from cosim.core.section import P, Section, SectionContext
from cosim.sweep.command import COMMAND


class SweepSection(Section):
    key = "sweep"
    description = "values to sweep, used as ${name} placeholders; cosim sweep runs each combination"

    commands = (COMMAND,)

    def parse(self, info: SectionContext, node: Any, path: P) -> dict[str, Any]:
        return dict(node) if isinstance(node, dict) else {}


SWEEP = SweepSection()
