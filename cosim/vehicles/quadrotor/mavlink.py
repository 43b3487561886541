"""How a quadrotor looks on MAVLink: ArduCopter's modes, commands and missions.

HEARTBEAT type QUADROTOR, autopilot ARDUPILOTMEGA; custom modes as ArduCopter
numbers them: STABILIZE 0 (refused: no pilot in the simulation), AUTO 3
(fly the mission), GUIDED 4 and LOITER 5 (hold where it is; GUIDED then
goes where DO_REPOSITION or a guided MISSION_ITEM says), RTL 6 (fly home
and land), LAND 9 (land where it is). Commands: COMPONENT_ARM_DISARM, NAV_TAKEOFF
(param7: metres above the ground; armed first), NAV_LAND, DO_REPOSITION,
DO_CHANGE_SPEED (param2, m/s).
Missions: NAV_TAKEOFF, NAV_WAYPOINT, NAV_LAND, NAV_RETURN_TO_LAUNCH and
DO_CHANGE_SPEED.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.ardupilot import ArduPilotLike, home_goto
from cosim.mavlink.personality import CommandFn
from cosim.mavlink.services.base import CommandRequest, Context, Outcome, text

if TYPE_CHECKING:
    from cosim.mavlink.mission import RoutePoint
    from cosim.mavlink.vehicle import MavVehicle

STABILIZE, AUTO, GUIDED, LOITER, RTL, LAND = 0, 3, 4, 5, 6, 9


class ArduCopter(ArduPilotLike):
    """See the module docstring."""

    mav_type = mav.MAV_TYPE_QUADROTOR
    modes = {STABILIZE: "STABILIZE", AUTO: "AUTO", GUIDED: "GUIDED", LOITER: "LOITER",
             RTL: "RTL", LAND: "LAND"}
    auto_mode = AUTO
    hold_mode = LOITER
    guided_mode = GUIDED
    mode_vocab = {GUIDED: lambda v: {"loiter": {}}, LOITER: lambda v: {"loiter": {}},
                  RTL: lambda v: {"goto": home_goto(v), "land": True},
                  LAND: lambda v: {"land": True}}
    refused = {STABILIZE: "no pilot in the simulation"}
    mission_items = frozenset({mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_WAYPOINT,
                               mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                               mav.MAV_CMD_DO_CHANGE_SPEED})

    def command_handler(self, number: int) -> CommandFn | None:
        own = {mav.MAV_CMD_NAV_TAKEOFF: self._takeoff, mav.MAV_CMD_NAV_LAND: self._land}
        return own.get(number) or super().command_handler(number)

    def supported_commands(self) -> frozenset[int]:
        return super().supported_commands() | {mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_LAND}

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

    def mission_route(self, ctx: Context, v: MavVehicle, start: int
                      ) -> tuple[Command, list[RoutePoint]] | str:
        from cosim.mavlink.mission import RoutePoint
        from cosim.mavlink.services.base import vocab

        d: dict[str, Any] = {}
        points: list[dict[str, Any]] = []
        route: list[RoutePoint] = []
        speed: float | None = None
        for it in v.mission.items[start - 1:]:
            c = it.command
            if c == mav.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0:
                    speed = it.param2
                continue
            if c == mav.MAV_CMD_NAV_TAKEOFF:
                d["takeoff_agl_m"] = it.z
                continue
            if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                p: dict[str, Any] = home_goto(v)
            else:
                p = {"lat_deg": it.lat_deg, "lon_deg": it.lon_deg}
                alt = ctx.alt(v, it.frame, it.z) if c == mav.MAV_CMD_NAV_WAYPOINT else None
                if alt is not None:
                    p[alt[0]] = alt[1]
                if c == mav.MAV_CMD_NAV_LAND and it.x == 0 and it.y == 0 and points:
                    p = dict(points[-1])  # land where it is
            if speed is not None:
                p["airspeed_mps"] = speed
            points.append(p)
            route.append(RoutePoint(it.seq, p["lat_deg"], p["lon_deg"]))
            if c in (mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH):
                d["land"] = True
                break
        if not points:
            return "the mission has no point to fly to"
        route[-1] = RoutePoint(route[-1].seq, route[-1].lat_deg, route[-1].lon_deg, final=True)
        cmd = vocab({**d, "waypoints": points})
        if isinstance(cmd, str):
            return cmd
        return cmd, route


ARDUCOPTER = ArduCopter()
