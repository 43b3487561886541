"""A vehicle class's MAVLink personality: what a ground station sees of it
and what its modes, commands, mission items and parameters do. Each class
supplies one (``VehicleClass.mavlink``); the endpoint and its services
(``cosim.mavlink.services``) ask the vehicle's personality and never which
class it is.

The services own the protocols (the one COMMAND_ACK per command, the mission
upload and download, PARAM_* and streams) and the commands every vehicle
answers alike (requests for messages, stream intervals, the current mission
item); a personality owns what a command *does* to its vehicle. The base
here is a vehicle with one mode, no autopilot and no missions; a class's
personality (e.g. ArduPlane's, ``cosim.vehicles.fixed_wing.mavlink``)
overrides what it supports.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from cosim.guidance.commands import DEFAULT_BANK_LIMIT_DEG, Command
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.services.base import CommandRequest, Context, Outcome, mission_ack, text
from cosim.vehicles.spec import STATE_INDEX

if TYPE_CHECKING:
    from cosim.mavlink.mission import MissionItem, RoutePoint
    from cosim.mavlink.vehicle import MavVehicle
    from cosim.vehicles.spec import VehicleSpec

#: a class's handler of one MAV_CMD: (context, vehicle, request, tick, outcome) -> MAV_RESULT
CommandFn = Callable[[Context, "MavVehicle", CommandRequest, int, Outcome], int]


class Personality:
    """How one class of vehicle appears on MAVLink (see the module docstring)."""

    #: HEARTBEAT.type
    mav_type: int = mav.MAV_TYPE_GENERIC
    #: HEARTBEAT.autopilot
    autopilot_type: int = mav.MAV_AUTOPILOT_GENERIC
    #: whether the vehicle takes commands (modes, navigation) at all
    autopilot: bool = False
    #: custom mode number -> name
    modes: Mapping[int, str] = {0: "MANUAL"}
    #: the mode a mission is flown in (None: no missions)
    auto_mode: int | None = None
    #: the mode a vehicle falls back to when its mission ends under it (None: none)
    hold_mode: int | None = None
    #: the parameters it exposes, in index order (PARAM_VALUE.param_index)
    param_defs: tuple[ParamDef, ...] = (SYSID_THISMAV,)
    #: parameters that follow a state column (name -> column), announced on change
    followed_params: Mapping[str, str] = {}
    #: the mission items it flies (MAV_CMD numbers; ``MissionItem.check``)
    mission_items: frozenset[int] = frozenset()
    #: AUTOPILOT_VERSION.capabilities (MAV_PROTOCOL_CAPABILITY flags)
    capabilities: int = mav.CAP_MAVLINK2 | mav.CAP_COMMAND_INT | mav.CAP_PARAM_ENCODE_C_CAST
    #: AUTOPILOT_VERSION.flight_sw_version (ground stations gate features on it)
    flight_sw_version: int = 0

    # -- modes and heartbeat ---------------------------------------------------
    def default_mode(self) -> int:
        """The mode a vehicle starts in."""
        return next(iter(self.modes))

    def mode_name(self, number: int) -> str:
        return self.modes.get(number, f"mode {number}")

    def manual(self, mode: int) -> bool:
        """Whether ``mode`` is flown by a pilot (no autopilot loops enabled)."""
        return True

    def base_mode(self, mode: int, armed: bool) -> int:
        """HEARTBEAT.base_mode in ``mode``."""
        bm = mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED if self.manual(mode) \
            else mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if armed:
            bm |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        return bm | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED

    def enter_mode(self, ctx: Context, v: MavVehicle, mode: int, tick: int,
                   out: Outcome) -> int:
        """Switch ``v`` to ``mode`` (SET_MODE, DO_SET_MODE); the MAV_RESULT,
        a STATUSTEXT in ``out`` saying why not."""
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        why = "not supported by cosim" if self.autopilot else "this vehicle has no autopilot"
        out.replies.extend(text(f"{self.mode_name(mode)}: {why}"))
        return mav.MAV_RESULT_FAILED

    # -- commands ------------------------------------------------------------------
    def command_handler(self, number: int) -> CommandFn | None:
        """The handler of MAV_CMD ``number`` (None: UNSUPPORTED), beyond those
        every vehicle answers (``cosim.mavlink.services.commands``)."""
        return None

    def supported_commands(self) -> frozenset[int]:
        """The MAV_CMD numbers ``command_handler`` answers."""
        return frozenset()

    def local_command(self, v: MavVehicle, cmd: Command) -> Command:
        """A command from inside cosim (a schedule item) for ``v``: its MAVLink
        state follows as for a ground station's command; returns the command
        for guidance, unchanged (one command path)."""
        return cmd

    def limits(self, v: MavVehicle) -> Limits:
        """What ``v`` can fly now (the safety rule's input)."""
        row = v.row_values
        speed = row[STATE_INDEX["airspeed_mps"]] if row is not None else math.nan
        return Limits(v.home[2], v.spec.min_alt_agl_m, speed if math.isfinite(speed) else 0.0,
                      DEFAULT_BANK_LIMIT_DEG)

    def takes_targets(self, v: MavVehicle) -> bool:
        """Whether SET_POSITION_TARGET_* steer ``v`` now (else they are ignored)."""
        return False

    # -- parameters ----------------------------------------------------------------
    def spec_params(self, vehicle: VehicleSpec) -> dict[str, float]:
        """Parameter values a scenario vehicle starts with (from its model's
        profile), before the scenario's own."""
        return {}

    def param_problem(self, ctx: Context, v: MavVehicle, name: str, value: float) -> str | None:
        """Why setting ``name`` to ``value`` would make a later command unsafe
        (None: fine); beyond the table's range checks."""
        return None

    def param_command(self, v: MavVehicle, name: str) -> dict[str, Any] | None:
        """The vocabulary mapping that applies a parameter just set (None: the
        parameter is read when used)."""
        return None

    # -- missions ------------------------------------------------------------------
    def item_problem(self, ctx: Context, v: MavVehicle, item: MissionItem) -> str | None:
        """Why a mission item that passed ``MissionItem.check`` is refused at
        upload (None: fine)."""
        return None

    def mission_route(self, ctx: Context, v: MavVehicle, start: int
                      ) -> tuple[Command, list[RoutePoint]] | str:
        """The command flying the mission from item ``start`` and the route it
        flies, or why it cannot be flown."""
        return "this vehicle flies no missions"

    def guided_item(self, ctx: Context, v: MavVehicle, m: mav.Message, item: MissionItem,
                    current: int) -> Outcome:
        """MISSION_ITEM(_INT) with current=2 (fly to a point) or 3 (change the
        altitude), outside the mission protocol; answered with a MISSION_ACK."""
        ctx.counts["commands_refused"] += 1
        return Outcome(replies=[mission_ack(m, mav.MAV_MISSION_ERROR)])
