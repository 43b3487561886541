"""How a ground vehicle looks on MAVLink: ArduRover's modes and missions.

HEARTBEAT type GROUND_ROVER, autopilot ARDUPILOTMEGA; custom modes as
ArduRover numbers them: MANUAL 0 (refused: no driver in the simulation),
HOLD 4 (stop where it is), AUTO 10 (drive the mission), RTL 11 (drive home
and stop), GUIDED 15 (stop, then go where DO_REPOSITION or a guided
MISSION_ITEM says). Missions: NAV_WAYPOINT, DO_CHANGE_SPEED and
NAV_RETURN_TO_LAUNCH (items after it are never reached).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.personality import CommandFn, Personality
from cosim.mavlink.services.base import CommandRequest, Context, Outcome, text, vocab
from cosim.vehicles.spec import STATE_INDEX

if TYPE_CHECKING:
    from cosim.mavlink.mission import RoutePoint
    from cosim.mavlink.vehicle import MavVehicle

_S = STATE_INDEX
MANUAL, HOLD, AUTO, RTL, GUIDED = 0, 4, 10, 11, 15


class ArduRover(Personality):
    """See the module docstring."""

    mav_type = mav.MAV_TYPE_GROUND_ROVER
    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    autopilot = True
    modes = {MANUAL: "MANUAL", HOLD: "HOLD", AUTO: "AUTO", RTL: "RTL", GUIDED: "GUIDED"}
    auto_mode = AUTO
    hold_mode = HOLD
    mission_items = frozenset({mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_DO_CHANGE_SPEED,
                               mav.MAV_CMD_NAV_RETURN_TO_LAUNCH})

    def default_mode(self) -> int:
        return HOLD

    def manual(self, mode: int) -> bool:
        return mode == MANUAL

    def enter_mode(self, ctx: Context, v: MavVehicle, mode: int, tick: int,
                   out: Outcome) -> int:
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        d: dict[str, Any]
        if mode in (HOLD, GUIDED):
            d = {"loiter": {}}
        elif mode == RTL:
            d = {"goto": {"lat_deg": v.home[0], "lon_deg": v.home[1]}}
        elif mode == AUTO:
            return ctx.fly_mission(v, v.mission.current, out)
        elif mode == MANUAL:
            out.replies.extend(text("MANUAL: no driver in the simulation"))
            return mav.MAV_RESULT_FAILED
        else:
            out.replies.extend(text(f"{self.mode_name(mode)} is not supported by cosim"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, mode, d, out, self.mode_name(mode), mav.MAV_RESULT_FAILED)

    def command_handler(self, number: int) -> CommandFn | None:
        return {mav.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
                mav.MAV_CMD_DO_REPOSITION: self._reposition}.get(number)

    def supported_commands(self) -> frozenset[int]:
        return frozenset({mav.MAV_CMD_DO_CHANGE_SPEED, mav.MAV_CMD_DO_REPOSITION})

    @staticmethod
    def _change_speed(ctx: Context, v: Any, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        top = float(v.spec.class_params.get("max_speed_mps", 15.0))
        if not 0 < req.p[1] <= top:
            out.replies.extend(text(f"change speed: 0..{top:g} m/s"))
            return mav.MAV_RESULT_DENIED
        cmd = vocab({"airspeed_mps": req.p[1]})
        if isinstance(cmd, str):
            out.replies.extend(text(f"change speed: {cmd}"))
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    @staticmethod
    def _reposition(ctx: Context, v: Any, req: CommandRequest, tick: int,
                    out: Outcome) -> int:
        """DO_REPOSITION: drive to the point (speed param1 when > 0) and stop, in GUIDED."""
        if not req.is_int:
            out.replies.extend(text("reposition: send it as COMMAND_INT"))
            return mav.MAV_RESULT_DENIED
        goto: dict[str, Any] = {"lat_deg": req.x * 1e-7, "lon_deg": req.y * 1e-7}
        if req.p[0] > 0:
            goto["airspeed_mps"] = req.p[0]
        return ctx.switch_to(v, GUIDED, {"goto": goto}, out, "reposition")

    def mission_route(self, ctx: Context, v: MavVehicle, start: int
                      ) -> tuple[Command, list[RoutePoint]] | str:
        from cosim.mavlink.mission import RoutePoint

        points: list[dict[str, Any]] = []
        route: list[RoutePoint] = []
        speed: float | None = None
        for it in v.mission.items[start - 1:]:
            c = it.command
            if c == mav.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0:
                    speed = it.param2
                continue
            if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                lat, lon = v.home[0], v.home[1]
            elif c == mav.MAV_CMD_NAV_WAYPOINT:
                lat, lon = it.lat_deg, it.lon_deg
            else:
                continue
            p: dict[str, Any] = {"lat_deg": lat, "lon_deg": lon}
            if speed is not None:
                p["airspeed_mps"] = speed
            points.append(p)
            route.append(RoutePoint(it.seq, lat, lon))
            if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                break
        if not points:
            return "the mission has no point to drive to"
        route[-1] = RoutePoint(route[-1].seq, route[-1].lat_deg, route[-1].lon_deg, final=True)
        cmd = vocab({"waypoints": points})
        if isinstance(cmd, str):
            return cmd
        return cmd, route
