"""How a ground vehicle looks on MAVLink: ArduRover's modes and missions.

HEARTBEAT type GROUND_ROVER, autopilot ARDUPILOTMEGA; custom modes as
ArduRover numbers them: MANUAL 0 (refused: no driver in the simulation),
HOLD 4 (stop where it is), AUTO 10 (drive the mission), RTL 11 (drive home
and stop), GUIDED 15 (stop, then go where DO_REPOSITION or a guided
MISSION_ITEM says). Commands: COMPONENT_ARM_DISARM, NAV_RETURN_TO_LAUNCH,
DO_REPOSITION, DO_CHANGE_SPEED.
Missions: NAV_WAYPOINT (param1: hold seconds), NAV_LOITER_UNLIM and
NAV_LOITER_TIME (drive to the point and wait there), NAV_RETURN_TO_LAUNCH
(home, or the nearest rally point), and the DO/CONDITION items every
ArduPilot-like class runs (``cosim.mavlink.mission``); NAV_LOITER_TURNS,
NAV_TAKEOFF and NAV_LAND are not ArduRover's and are skipped.
Parameters: WP_SPEED (m/s: the speed of mission items without a
DO_CHANGE_SPEED; 0: the vehicle's cruise), WP_RADIUS (m: a waypoint's
acceptance radius), SYSID_THISMAV (read-only).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cosim.mavlink import adapter as mav
from cosim.mavlink.ardupilot import ArduPilotLike, home_goto
from cosim.mavlink.mission import COMMON_DO_ITEMS, LOITERS
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.mavlink.mission import MissionItem
    from cosim.mavlink.vehicle import MavVehicle

MANUAL, HOLD, AUTO, RTL, GUIDED = 0, 4, 10, 11, 15


class ArduRover(ArduPilotLike):
    """See the module docstring."""

    mav_type = mav.MAV_TYPE_GROUND_ROVER
    modes = {MANUAL: "MANUAL", HOLD: "HOLD", AUTO: "AUTO", RTL: "RTL", GUIDED: "GUIDED"}
    auto_mode = AUTO
    hold_mode = HOLD
    guided_mode = GUIDED
    reposition_alt = False  # it drives on the ground
    mode_vocab = {HOLD: lambda v: {"loiter": {}}, GUIDED: lambda v: {"loiter": {}},
                  RTL: lambda v: {"goto": home_goto(v)}}
    refused = {MANUAL: "no driver in the simulation"}
    rtl_mode = RTL
    #: ArduRover's waypoint parameters (m/s, m), as it names them
    param_defs = (SYSID_THISMAV,
                  ParamDef("WP_RADIUS", mav.MAV_PARAM_TYPE_REAL32, 2.0, 0.1, 100.0),
                  ParamDef("WP_SPEED", mav.MAV_PARAM_TYPE_REAL32, 0.0, 0.0, 100.0))
    speed_param = ("WP_SPEED", 1.0)
    radius_param = ("WP_RADIUS", 1.0)
    command_modes = {"loiter": HOLD, "goto": GUIDED, "heading": GUIDED, "velocity": GUIDED}
    mission_items = COMMON_DO_ITEMS | {
        mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM, mav.MAV_CMD_NAV_LOITER_TIME,
        mav.MAV_CMD_NAV_RETURN_TO_LAUNCH}

    def nav_vocab(self, ctx: Context, v: MavVehicle, item: MissionItem,
                  prev: tuple[float, float]) -> dict[str, Any] | str:
        """A loiter drives to its point and waits there (a car does not circle)."""
        d = super().nav_vocab(ctx, v, item, prev)
        if item.command in LOITERS and isinstance(d, dict):
            lo = d["loiter"]
            return {"goto": {**lo["center"], **{k: x for k, x in lo.items()
                                                if k == "airspeed_mps"}}}
        return d
