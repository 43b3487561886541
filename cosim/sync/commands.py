"""The one place commands become setpoints.

Every command source (the scenario's schedule, MAVLink clients, the swarm
controller and outside controllers through MAVLink) hands the runner
``Command`` objects for state rows; ``Commander.command`` routes each to the
guidance of the vehicle's class (``VehicleClass.make_guidance``), which
writes the setpoints. Raw JSBSim property writes (the schedule's ``set:``)
go through ``set_properties``. ``update`` advances every class's guidance
once per exchange.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from cosim.vehicles import Guidance, GuidanceEvent, get_class

if TYPE_CHECKING:
    from cosim.core.geo import LocalFrame
    from cosim.guidance.commands import Command
    from cosim.scenario import Scenario


class Commander:
    """Routes commands to the guidance of each vehicle's class (see the module docstring)."""

    def __init__(self, scn: Scenario, frame: LocalFrame, start_ne: np.ndarray,
                 channel_index: dict[str, int]) -> None:
        self.row_class = [v.vehicle_class for v in scn.vehicles]
        self.channel_index = channel_index
        self.guidance: dict[str, Guidance] = {}
        for name in scn.classes:
            vc = get_class(name)
            if vc.commandable:
                rows = [i for i, c in enumerate(self.row_class) if c == name]
                self.guidance[name] = vc.make_guidance(rows, frame, start_ne, channel_index,
                                                      specs=scn.vehicles)
        self._rows_of = {name: [i for i, c in enumerate(self.row_class) if c == name]
                         for name in self.guidance}
        #: ``observe(row, command, source)`` for every command, before guidance sees it
        self.observers: list[Callable[[int, Command, str], None]] = []

    @property
    def active(self) -> bool:
        """Whether any vehicle of the run takes commands."""
        return bool(self.guidance)

    def command(self, rows: Sequence[int], cmd: Command, states: np.ndarray,
                setpoints: np.ndarray, source: str = "schedule") -> None:
        """Apply ``cmd`` from ``source`` ("schedule", "mavlink", ...) to state rows
        ``rows``: the observers hear of it row by row, then each row's class
        guidance turns it into setpoints."""
        for r in rows:
            for observe in self.observers:
                observe(r, cmd, source)
        if not cmd.flies:  # only gimbal angles: for the cameras (an observer)
            return
        for name, g in self.guidance.items():
            mine = [r for r in rows if self.row_class[r] == name]
            if mine:
                g.command(mine, cmd, states, setpoints)

    def set_properties(self, rows: Sequence[int], sets: Sequence[tuple[str, float]],
                       setpoints: np.ndarray) -> None:
        """Write raw channel values (the schedule's ``set:``) for ``rows``."""
        for name, value in sets:
            setpoints[list(rows), self.channel_index[name]] = value

    def update(self, states: np.ndarray, setpoints: np.ndarray) -> list[GuidanceEvent]:
        """Advance every class's guidance (path following); its events."""
        events: list[GuidanceEvent] = []
        for g in self.guidance.values():
            events += g.update(states, setpoints)
        return events

    @property
    def labels(self) -> list[str] | None:
        """Each row's active command (None: no vehicle takes commands)."""
        if not self.guidance:
            return None
        if len(self.guidance) == 1:
            return next(iter(self.guidance.values())).labels
        out = [""] * len(self.row_class)
        for name, g in self.guidance.items():
            for r in self._rows_of[name]:
                out[r] = g.labels[r]
        return out
