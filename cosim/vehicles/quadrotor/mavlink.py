"""How a quadrotor looks on MAVLink: ArduCopter's modes, commands and missions.

HEARTBEAT type QUADROTOR, autopilot ARDUPILOTMEGA; custom modes as ArduCopter
numbers them: STABILIZE 0 (refused: no pilot in the simulation), AUTO 3
(fly the mission), GUIDED 4 and LOITER 5 (hold where it is; GUIDED then
goes where DO_REPOSITION or a guided MISSION_ITEM says), RTL 6 (fly home,
or to the nearest rally point, and land), CIRCLE 7 (orbit: 10 m round
where it is, or DO_ORBIT's circle), LAND 9 (land where it is). Commands:
COMPONENT_ARM_DISARM, NAV_TAKEOFF (param7: metres above the ground; armed
first), NAV_LAND, NAV_RETURN_TO_LAUNCH, DO_REPOSITION, DO_ORBIT,
DO_CHANGE_SPEED (param2, m/s).
Parameters: WPNAV_SPEED (cm/s: the speed of mission items without a
DO_CHANGE_SPEED), WPNAV_RADIUS (cm: a waypoint's acceptance radius),
SYSID_THISMAV (read-only).
Missions: NAV_TAKEOFF, NAV_WAYPOINT (param1: hold seconds), NAV_LOITER_UNLIM,
NAV_LOITER_TURNS, NAV_LOITER_TIME, NAV_LAND, NAV_RETURN_TO_LAUNCH, and the
DO/CONDITION items every ArduPilot-like class runs (``cosim.mavlink.mission``).
"""

from __future__ import annotations

from typing import Any

from cosim.mavlink import adapter as mav
from cosim.mavlink.ardupilot import ArduPilotLike, home_goto
from cosim.mavlink.mission import COMMON_DO_ITEMS
from cosim.mavlink.outcome import CommandRequest, Outcome, text
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.personality import CommandFn
from cosim.mavlink.services.base import Context

STABILIZE, AUTO, GUIDED, LOITER, RTL, CIRCLE, LAND = 0, 3, 4, 5, 6, 7, 9
#: CIRCLE mode's radius round where it is (ArduCopter's CIRCLE_RADIUS default)
CIRCLE_RADIUS_M = 10.0


class ArduCopter(ArduPilotLike):
    """See the module docstring."""

    mav_type = mav.MAV_TYPE_QUADROTOR
    modes = {STABILIZE: "STABILIZE", AUTO: "AUTO", GUIDED: "GUIDED", LOITER: "LOITER",
             RTL: "RTL", CIRCLE: "CIRCLE", LAND: "LAND"}
    auto_mode = AUTO
    hold_mode = LOITER
    guided_mode = GUIDED
    rtl_mode = RTL
    orbit_mode = CIRCLE
    rtl_lands = True
    mode_vocab = {GUIDED: lambda v: {"loiter": {}}, LOITER: lambda v: {"loiter": {}},
                  RTL: lambda v: {"goto": home_goto(v), "land": True},
                  CIRCLE: lambda v: {"loiter": {"radius_m": CIRCLE_RADIUS_M}},
                  LAND: lambda v: {"land": True}}
    refused = {STABILIZE: "no pilot in the simulation"}
    command_modes = {"takeoff": GUIDED, "land": LAND, "loiter": LOITER, "goto": GUIDED,
                     "heading": GUIDED, "velocity": GUIDED}
    #: ArduCopter's waypoint navigation parameters (cm/s, cm), as it names them
    param_defs = (SYSID_THISMAV,
                  ParamDef("WPNAV_RADIUS", mav.MAV_PARAM_TYPE_REAL32, 200.0, 5.0, 1000.0),
                  ParamDef("WPNAV_SPEED", mav.MAV_PARAM_TYPE_REAL32, 500.0, 20.0, 2000.0))
    speed_param = ("WPNAV_SPEED", 0.01)
    radius_param = ("WPNAV_RADIUS", 0.01)
    mission_items = COMMON_DO_ITEMS | {
        mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM,
        mav.MAV_CMD_NAV_LOITER_TURNS, mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_LAND,
        mav.MAV_CMD_NAV_RETURN_TO_LAUNCH}

    def _handlers(self) -> dict[int, CommandFn]:
        return {**super()._handlers(), mav.MAV_CMD_NAV_TAKEOFF: self._takeoff,
                mav.MAV_CMD_NAV_LAND: self._land}

    @staticmethod
    def _takeoff(ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        """NAV_TAKEOFF: climb to param7 metres above the ground, in GUIDED (armed)."""
        if not v.armed:
            out.replies.extend(text("takeoff: arm first"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, GUIDED, {"takeoff_agl_m": req.z}, out, "takeoff")

    @staticmethod
    def _land(ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        return ctx.switch_to(v, LAND, {"land": True}, out, "land")


ARDUCOPTER = ArduCopter()
