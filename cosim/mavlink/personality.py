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
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX
from cosim.guidance.commands import DEFAULT_BANK_LIMIT_DEG, Command
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import CommandRequest, Outcome, mission_ack, text
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.core.state import VehicleSpec
    from cosim.mavlink.mission import MissionItem
    from cosim.mavlink.vehicle import MavVehicle

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
    #: the mission items it flies (MAV_CMD numbers); others are stored and skipped
    mission_items: frozenset[int] = frozenset()
    #: the mode RTL is (a fence breach switches to it; None: none)
    rtl_mode: int | None = None
    #: the mode each kind of command from inside cosim (``command_kind``) puts it
    #: in, so that the mode reported is what the vehicle is doing
    command_modes: Mapping[str, int] = {}
    #: whether a waypoint counts as reached once its leg is passed (fixed-wings)
    passes_waypoints: bool = False
    #: whether NAV_WAYPOINT's param1 (hold seconds) is honoured
    waypoint_hold: bool = True
    #: how close (m) below its altitude a NAV_TAKEOFF counts as done
    takeoff_tolerance_m: float = 1.0
    #: whether its RTL ends on the ground (a mission's RTL then ends when landed)
    rtl_lands: bool = False
    #: SYS_STATUS: the sensors it has beyond GPS and attitude (an airspeed sensor)
    extra_sensors: int = 0
    #: AUTOPILOT_VERSION.capabilities (MAV_PROTOCOL_CAPABILITY flags), beyond
    #: those of missions (``capability_flags``)
    capabilities: int = (mav.CAP_MAVLINK2 | mav.CAP_COMMAND_INT | mav.CAP_PARAM_ENCODE_C_CAST
                         | mav.CAP_PARAM_FLOAT)
    #: AUTOPILOT_VERSION.flight_sw_version (ground stations gate features on it)
    flight_sw_version: int = 0

    def capability_flags(self) -> int:
        """AUTOPILOT_VERSION.capabilities: ``capabilities``, and the mission
        protocol (MISSION_INT and MISSION_ITEM, fence and rally lists) for a
        vehicle that flies missions."""
        flags = self.capabilities
        if self.auto_mode is not None and self.autopilot:
            flags |= (mav.CAP_MISSION_INT | mav.CAP_MISSION_FLOAT | mav.CAP_MISSION_FENCE
                      | mav.CAP_MISSION_RALLY)
        return flags

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
        state follows as for a ground station's command (the mode of what it
        now does, ``command_modes``); returns the command for guidance,
        unchanged (one command path)."""
        mode = self.command_modes.get(command_kind(cmd) or "")
        if self.autopilot and mode is not None:
            v.mode = mode
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

    def nav_vocab(self, ctx: Context, v: MavVehicle, item: MissionItem,
                  prev: tuple[float, float]) -> dict[str, Any] | str:
        """The vocabulary mapping flying navigation item ``item`` (``prev``: the
        point flown to before, for items at "here"), or why it cannot."""
        return "this vehicle flies no missions"

    def loiter_radius_m(self, v: MavVehicle, d: Mapping[str, Any]) -> float:
        """The loiter radius a navigation mapping flies (0: a point)."""
        lo = d.get("loiter")
        if isinstance(lo, Mapping):
            return float(lo.get("radius_m", 0.0))
        goto = d.get("goto")
        if isinstance(goto, Mapping):
            return float(goto.get("loiter_radius_m", 0.0))
        return 0.0

    def in_air(self, row: Sequence[float]) -> bool:
        """Whether a vehicle in this state row is flying (EXTENDED_SYS_STATE's
        landed state): more than 1 m above the ground."""
        return float(row[STATE_INDEX["alt_agl_m"]]) > 1.0

    def landed(self, row: Sequence[float]) -> bool:
        """Whether a vehicle in this state row is at rest on the ground (a
        mission's LAND, and an RTL that lands, end there): within 0.5 m of
        it, not moving."""
        return (float(row[STATE_INDEX["alt_agl_m"]]) < 0.5 and stopped(row))

    def accept_radius_m(self, v: MavVehicle, row: list[float]) -> float:
        """How close a waypoint counts as reached (ArduPilot's WP_RADIUS)."""
        return 2.0

    def speed_problem(self, v: MavVehicle, speed_mps: float) -> str | None:
        """Why a commanded speed is refused (None: fine)."""
        return None

    def guided_item(self, ctx: Context, v: MavVehicle, m: mav.Message, item: MissionItem,
                    current: int) -> Outcome:
        """MISSION_ITEM(_INT) with current=2 (fly to a point) or 3 (change the
        altitude), outside the mission protocol; answered with a MISSION_ACK."""
        ctx.counts["commands_refused"] += 1
        return Outcome(replies=[mission_ack(m, mav.MAV_MISSION_ERROR)])


def stopped(row: Sequence[float]) -> bool:
    """Not moving: under 0.5 m/s over the ground and 0.3 m/s vertically."""
    return (abs(float(row[STATE_INDEX["vd_mps"]])) < 0.3
            and math.hypot(float(row[STATE_INDEX["vn_mps"]]),
                           float(row[STATE_INDEX["ve_mps"]])) < 0.5)


def command_kind(cmd: Command) -> str | None:
    """What a command makes the vehicle do, for its mode: ``takeoff``,
    ``land``, ``loiter``, ``goto`` (also ``waypoints``), ``heading``,
    ``velocity``; None for settings (speed, altitude, limits, gimbal)."""
    if cmd.takeoff_agl_m is not None:
        return "takeoff"
    if cmd.land and cmd.nav is None:
        return "land"
    if cmd.nav == "loiter":
        return "loiter"
    if cmd.nav in ("goto", "waypoints"):
        return "goto"
    if cmd.heading_deg is not None:
        return "heading"
    if cmd.velocity_ne is not None:
        return "velocity"
    return None
