"""ArduPlane's mission items: which are flown and how, when it is in the air
or landed, and the guided MISSION_ITEMs.

Missions (flown in AUTO item by item, ``cosim.mavlink.mission_runner``):
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME,
NAV_LOITER_TO_ALT, NAV_TAKEOFF, NAV_RETURN_TO_LAUNCH, NAV_LAND (the leg to
its point becomes the approach, then the glide path; reached once stopped
on the ground, where the aircraft disarms) and the DO/CONDITION items every
ArduPilot-like class runs. MISSION_ITEM(_INT) with current=2 is a guided
goto (GUIDED only), current=3 an altitude change.

What an item makes the vehicle do (``PlaneMissions``, a base of
``mavlink.ArduPlane``); the mission protocol, the plan and running it item
by item are ``cosim.mavlink``'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX as _S
from cosim.guidance.commands import DEFAULT_BANK_LIMIT_DEG, waypoint_accept_radius_m
from cosim.mavlink import adapter as mav
from cosim.mavlink import mission as mi
from cosim.mavlink.mission import COMMON_DO_ITEMS, MissionItem
from cosim.mavlink.outcome import Outcome, mission_ack, text, vocab
from cosim.mavlink.personality import Personality, stopped
from cosim.mavlink.services.base import Context
from cosim.vehicles.fixed_wing.mav_modes import FLYING_MODES, PlaneMode
from cosim.vehicles.fixed_wing.mav_params import (
    default_radius_m,
    land_vocab,
    loiter_here,
    loiter_radius,
    rtl_point,
)

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle

#: the mission items ArduPlane flies (the others are stored and skipped)
ARDUPLANE_ITEMS = COMMON_DO_ITEMS | {
    mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM, mav.MAV_CMD_NAV_LOITER_TURNS,
    mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_LOITER_TO_ALT, mav.MAV_CMD_NAV_TAKEOFF,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_NAV_LAND}


class PlaneMissions(Personality):
    """ArduPlane's mission items (see the module docstring)."""

    def in_air(self, row: Sequence[float]) -> bool:
        """Off the ground: no force on its wheels or skids (on its wheels a
        c172p's position, its centre of gravity, is 1.3 m up)."""
        return float(row[_S["gear_force_lbs"]]) == 0.0 and float(row[_S["alt_agl_m"]]) > 0.0

    def landed(self, row: Sequence[float]) -> bool:
        """Stopped on its wheels or skids (a fixed-wing cannot hover)."""
        return not self.in_air(row) and stopped(row)

    def item_problem(self, ctx: Context, v: MavVehicle, item: MissionItem) -> str | None:
        """An item's altitude below the class minimum above the ground (the
        rule of ``Context.unsafe``), counted as unsafe."""
        if item.command not in mi.NAV_COMMANDS or item.command not in mi.POSITION_COMMANDS \
                or item.command == mav.MAV_CMD_NAV_LAND:  # a landing goes to the ground
            return None
        alt = ctx.alt(v, item.frame, item.z)
        if alt is None:
            return None
        agl = alt[1] if alt[0] == "alt_agl_m" else alt[1] - v.home[2]
        if agl >= v.spec.min_alt_agl_m - 1e-6:
            return None
        ctx.counts["commands_unsafe"] += 1
        return (f"at {agl:.0f} m above the ground refused (at least "
                f"{v.spec.min_alt_agl_m:g} m)")

    def accept_radius_m(self, v: MavVehicle, row: list[float]) -> float:
        bank = float(row[_S["bank_limit_deg"]])
        if not 5.0 <= bank <= 75.0:
            bank = DEFAULT_BANK_LIMIT_DEG
        speed = float(row[_S["airspeed_mps"]])
        return waypoint_accept_radius_m(max(speed if math.isfinite(speed) else 0.0, 1.0), bank)

    def nav_vocab(self, ctx: Context, v: MavVehicle, item: MissionItem,
                  prev: tuple[float, float]) -> dict[str, Any] | str:
        """A navigation item as ArduPlane flies it.

        NAV_WAYPOINT: a goto (its end loiters with WP_LOITER_RAD, so a last
        waypoint is circled as in ArduPlane); the loiters: a loiter round the
        point with param3's radius (LOITER_TO_ALT: param2; negative:
        counter-clockwise; 0: WP_LOITER_RAD, else guidance's bank-limited
        radius); NAV_RETURN_TO_LAUNCH: the RTL point, circled with
        RTL_RADIUS; NAV_TAKEOFF: in the air, a climbing loiter where it is;
        on the ground, a point 1 km ahead at the take-off altitude. Speed:
        the mission's last DO_CHANGE_SPEED, else AIRSPEED_CRUISE; none while
        disarmed.
        """
        if not self.autopilot:
            return "this vehicle has no autopilot"
        c = item.command
        row = v.row_or_raise()
        speed = (v.mission.speed_mps if v.mission.speed_mps is not None
                 else v.params["AIRSPEED_CRUISE"]) if v.armed else None
        if c == mav.MAV_CMD_NAV_LAND:
            return land_vocab(v, None if item.here else (item.lat_deg, item.lon_deg),
                              v.mission.speed_mps)
        if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            goto = rtl_point(ctx, v, row)
            radius, ccw = loiter_radius(v, "RTL_RADIUS")
            goto["loiter_radius_m"] = radius or default_radius_m(v, speed)
            if speed is not None:
                goto["airspeed_mps"] = speed
            return {"goto": goto, "cw": not ccw}
        alt = ctx.alt(v, item.frame, item.z)
        if alt is None:
            return f"frame {item.frame} not supported"
        lat, lon = mi.point_of(v, item, prev)
        extra: dict[str, Any] = {}
        if not (item.z == 0 and item.frame not in (mav.MAV_FRAME_GLOBAL,
                                                   mav.MAV_FRAME_GLOBAL_INT)):
            extra[alt[0]] = alt[1]
        if speed is not None:
            extra["airspeed_mps"] = speed
        if c == mav.MAV_CMD_NAV_TAKEOFF:
            if v.in_air():
                lo = loiter_here(v)
                lo.setdefault("radius_m", default_radius_m(v, speed))
                lo[alt[0]] = alt[1]
                return {"loiter": lo}
            psi = math.radians(float(row[_S["yaw_deg"]]))
            here = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
            la, lo_ = LocalFrame(here[0], here[1], v.home[2]).place(
                1000.0 * math.cos(psi), 1000.0 * math.sin(psi), v.home[2])
            return {"goto": {"lat_deg": float(la), "lon_deg": float(lo_), alt[0]: alt[1]}}
        default_r, default_ccw = loiter_radius(v)
        if c == mav.MAV_CMD_NAV_WAYPOINT:  # ArduPlane tracks the leg from the last one
            last = v.mission.nav
            if last is not None and last.item.command == mav.MAV_CMD_NAV_WAYPOINT:
                extra["from"] = {"lat_deg": prev[0], "lon_deg": prev[1]}
            if any(it.command in mi.NAV_COMMANDS for it in v.mission.items[item.seq:]):
                extra["continue"] = True  # on past it until the next is flown
            return {"goto": {"lat_deg": lat, "lon_deg": lon, **extra,
                             "loiter_radius_m": default_r or default_radius_m(v, speed)},
                    "cw": not default_ccw}
        if c in mi.LOITERS:
            r = item.param2 if c == mav.MAV_CMD_NAV_LOITER_TO_ALT else item.param3
            radius = abs(r) if r else (default_r or default_radius_m(v, speed))
            ccw = r < 0 if r else default_ccw
            return {"loiter": {"center": {"lat_deg": lat, "lon_deg": lon}, "radius_m": radius,
                               "direction": "ccw" if ccw else "cw", **extra}}
        return f"{mav.command_name(c)} is not flown by ArduPlane in cosim"

    def guided_item(self, ctx: Context, v: MavVehicle, m: mav.Message, item: MissionItem,
                    current: int) -> Outcome:
        """current=2: "fly to here" in GUIDED (MAVProxy's and older stations'
        guided goto); current=3: change the altitude (GUIDED and the other
        autopilot modes). Answered with a MISSION_ACK."""
        out = Outcome()
        alt = ctx.alt(v, item.frame, item.z)
        if current == 3:
            if not self.autopilot or v.mode not in FLYING_MODES or alt is None:
                out.replies.append(mission_ack(m, mav.MAV_MISSION_ERROR))
                ctx.counts["commands_refused"] += 1
                return out
            return self._guided_answer(ctx, v, m, {alt[0]: alt[1]}, "change altitude", out)
        if not self.autopilot or v.mode != PlaneMode.GUIDED:
            out.replies.extend(text("guided goto: switch to GUIDED first"))
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ERROR))
            ctx.counts["commands_refused"] += 1
            return out
        result = item.check() if item.command == mav.MAV_CMD_NAV_WAYPOINT \
            else mav.MAV_MISSION_UNSUPPORTED
        if result != mav.MAV_MISSION_ACCEPTED or alt is None:
            out.replies.append(mission_ack(m, result if result != mav.MAV_MISSION_ACCEPTED
                                           else mav.MAV_MISSION_UNSUPPORTED_FRAME))
            ctx.counts["commands_refused"] += 1
            return out
        goto: dict[str, Any] = {"lat_deg": item.lat_deg, "lon_deg": item.lon_deg, alt[0]: alt[1]}
        radius, ccw = loiter_radius(v)
        if radius:
            goto["loiter_radius_m"] = radius
        return self._guided_answer(ctx, v, m, {"goto": goto}, "guided goto", out, cw=not ccw)

    @staticmethod
    def _guided_answer(ctx: Context, v: MavVehicle, m: mav.Message, d: dict[str, Any],
                       what: str, out: Outcome, cw: bool | None = None) -> Outcome:
        """A guided item's command from vocabulary mapping ``d``, answered with a
        MISSION_ACK: ERROR if the vocabulary refuses it, INVALID_PARAM7 if it
        would crash (``unsafe``), else ACCEPTED."""
        cmd = vocab(d)
        problem = cmd if isinstance(cmd, str) else ctx.unsafe(v, cmd)
        if problem is not None or isinstance(cmd, str):
            out.replies.extend(text(f"{what}: {problem}"))
            out.replies.append(mission_ack(m, mav.MAV_MISSION_ERROR if isinstance(cmd, str)
                                           else mav.MAV_MISSION_INVALID_PARAM7))
            ctx.counts["commands_refused"] += 1
            return out
        out.commands.append(cmd if cw is None else replace(cmd, loiter_cw=cw))
        out.replies.append(mission_ack(m, mav.MAV_MISSION_ACCEPTED))
        return out
