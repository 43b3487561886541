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
from cosim.mavlink.ardupilot import ArduPilotLike, home_goto
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.mavlink.mission import RoutePoint
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
    mission_items = frozenset({mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_DO_CHANGE_SPEED,
                               mav.MAV_CMD_NAV_RETURN_TO_LAUNCH})

    def mission_route(self, ctx: Context, v: MavVehicle, start: int
                      ) -> tuple[Command, list[RoutePoint]] | str:
        from cosim.mavlink.mission import RoutePoint
        from cosim.mavlink.services.base import vocab

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
                p = home_goto(v)
            elif c == mav.MAV_CMD_NAV_WAYPOINT:
                p = {"lat_deg": it.lat_deg, "lon_deg": it.lon_deg}
            else:
                continue
            if speed is not None:
                p["airspeed_mps"] = speed
            points.append(p)
            route.append(RoutePoint(it.seq, p["lat_deg"], p["lon_deg"]))
            if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                break
        if not points:
            return "the mission has no point to drive to"
        route[-1] = RoutePoint(route[-1].seq, route[-1].lat_deg, route[-1].lon_deg, final=True)
        cmd = vocab({"waypoints": points})
        if isinstance(cmd, str):
            return cmd
        return cmd, route
