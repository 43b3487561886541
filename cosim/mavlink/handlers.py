"""The router of incoming MAVLink messages: each goes to its microservice
(``cosim.mavlink.services``), which answers with an ``Outcome`` (replies to
send, commands for guidance) and never touches sockets."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import Outcome, Reply
from cosim.mavlink.services.base import Context
from cosim.mavlink.services.commands import CommandService
from cosim.mavlink.services.missions import MissionService
from cosim.mavlink.services.parameters import ParamService
from cosim.mavlink.services.targets import TargetService
from cosim.mavlink.vehicle import MavVehicle


class Handler:
    """The services of one endpoint, routing each message to its service."""

    def __init__(self, counts: Counter[str], physics_hz: float) -> None:
        self.ctx = Context(counts, physics_hz)
        self.missions = MissionService(self.ctx)
        self.commands = CommandService(self.ctx, self.missions)
        self.params = ParamService(self.ctx)
        self.targets = TargetService(self.ctx)
        self.by_name: dict[str, Callable[[MavVehicle, mav.Message, int], Outcome]] = {}
        for service in (self.commands, self.missions, self.params, self.targets):
            self.by_name.update(service.messages)

    def handle(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        """Handle one message for vehicle ``v`` at ``tick`` (its row observed)."""
        self.ctx.tick = tick
        fn = self.by_name.get(m.name)
        if fn is None:
            self.ctx.counts["ignored_messages"] += 1
            return Outcome()
        return fn(v, m, tick)

    def local_command(self, v: MavVehicle, cmd: Command) -> Command:
        """A command from inside cosim (a schedule item) for ``v``: its MAVLink
        state follows as for a ground station's command (its personality's
        rule); the command for guidance, unchanged."""
        return v.personality.local_command(v, cmd)

    def load_mission(self, v: MavVehicle, items: list[Any], fly: bool, tick: int) -> Outcome:
        """A mission put on board from inside cosim (``load_mission``):
        checked and stored as an upload would be, flown with ``fly``."""
        self.ctx.tick = tick
        return self.missions.load(v, items, fly)

    def param_value(self, v: MavVehicle, name: str) -> Reply:
        """The PARAM_VALUE of one parameter (to announce a change)."""
        return self.params.value(v, name)

    def mission_update(self, v: MavVehicle, tick: int) -> Outcome:
        """Once per exchange before the step: mission upload retries, the
        fence, and the mission being flown (its commands)."""
        return self.missions.update(v, tick)
