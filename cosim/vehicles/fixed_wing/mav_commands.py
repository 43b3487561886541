"""ArduPlane's commands (MAV_CMD in COMMAND_LONG and COMMAND_INT).

ARM_DISARM, NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF, DO_CHANGE_SPEED,
DO_REPOSITION, NAV_LOITER_UNLIM, DO_ORBIT (a loiter: radius param1,
negative counter-clockwise; speed param2). Disarmed vehicles keep their
engine off: arming restores the cruise airspeed, disarming sets throttle 0,
and no other command carries a speed while disarmed. NAV_LAND (in GUIDED):
land at the point, or straight ahead, down a 3-degree glide path at 1.1 x
AIRSPEED_MIN, sliding to a stop on the airframe's skids.

What each command does to its vehicle (``PlaneCommands``, a base of
``mavlink.ArduPlane``); the one COMMAND_ACK per command and the commands
every vehicle answers alike are the services' (``cosim.mavlink.services``).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.ardupilot import FORCE_MAGIC
from cosim.mavlink.outcome import CommandRequest, Outcome, as_int, text, vocab
from cosim.mavlink.personality import CommandFn
from cosim.mavlink.services.base import Context
from cosim.vehicles.fixed_wing.mav_modes import FLYING_MODES, PlaneMode, PlaneModes
from cosim.vehicles.fixed_wing.mav_params import land_vocab, loiter_here, loiter_radius

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle


class PlaneCommands(PlaneModes):
    """ArduPlane's commands (see the module docstring)."""

    def __init__(self) -> None:
        self._commands: dict[int, CommandFn] = {
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._rtl,
            mav.MAV_CMD_NAV_TAKEOFF: self._nav_takeoff,
            mav.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
            mav.MAV_CMD_DO_REPOSITION: self._reposition,
            mav.MAV_CMD_NAV_LOITER_UNLIM: self._loiter_unlim,
            mav.MAV_CMD_DO_ORBIT: self._orbit,
            mav.MAV_CMD_NAV_LAND: self._nav_land,
        }

    def command_handler(self, number: int) -> CommandFn | None:
        return self._commands.get(number)

    def supported_commands(self) -> frozenset[int]:
        return frozenset(self._commands)

    def _speed_into(self, v: MavVehicle, speed: float, d: dict[str, Any], out: Outcome) -> bool:
        """A command's optional speed (> 0; ignored while disarmed) into
        mapping ``d``; False (with a STATUSTEXT) when out of limits."""
        if math.isfinite(speed) and speed > 0 and v.armed:
            problem = self.speed_problem(v, speed)
            if problem:
                out.replies.extend(text(problem))
                return False
            d["airspeed_mps"] = speed
        return True

    def _arm_disarm(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                    out: Outcome) -> int:
        want, force = as_int(req.p[0]), as_int(req.p[1]) == FORCE_MAGIC
        if want == 1:
            if v.armed:
                return mav.MAV_RESULT_ACCEPTED
            if v.params["ARMING_CHECK"] != 0 and not force and not v.prearm_ok():
                out.replies.extend(text("PreArm: vehicle crashed or diverged"))
                return mav.MAV_RESULT_FAILED
            v.armed = True
            if self.autopilot and v.mode in FLYING_MODES:
                cmd = vocab({"airspeed_mps": v.params["AIRSPEED_CRUISE"]})
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
            return mav.MAV_RESULT_ACCEPTED
        if want == 0:
            if not v.armed:
                return mav.MAV_RESULT_ACCEPTED
            if v.in_air() and not force:
                out.replies.extend(text(f"Disarm refused in flight (param2={FORCE_MAGIC} "
                                        f"forces)"))
                return mav.MAV_RESULT_FAILED
            v.armed = False
            if self.autopilot:
                cmd = vocab({"throttle": 0.0})
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_DENIED

    def _rtl(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
             out: Outcome) -> int:
        return self.enter_mode(ctx, v, PlaneMode.RTL, tick, out)

    def _nav_takeoff(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                     out: Outcome) -> int:
        if math.isfinite(req.z) and req.z > 0:
            a = ctx.alt(v, req.frame, req.z)
            if a is None or a[0] != "alt_msl_m":
                out.replies.extend(text("TAKEOFF: altitude frame not supported"))
                return mav.MAV_RESULT_DENIED
            alt = a[1]
        else:
            alt = v.home[2] + v.params["TKOFF_ALT"]
        return self._takeoff(ctx, v, alt, out)

    def _change_speed(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        kind, spd, thr = as_int(req.p[0]), req.p[1], req.p[2]
        refused = self._no_autopilot("change speed", out)
        if refused is not None:
            return refused
        if kind not in (0, 1):  # airspeed; ground speed flown as airspeed (no wind)
            return mav.MAV_RESULT_DENIED
        if not v.armed:
            out.replies.extend(text("change speed: disarmed"))
            return mav.MAV_RESULT_FAILED
        d: dict[str, Any]
        if math.isfinite(spd) and spd > 0:
            problem = self.speed_problem(v, spd)
            if problem:
                out.replies.extend(text(problem))
                return mav.MAV_RESULT_DENIED
            d = {"airspeed_mps": spd}
        elif math.isfinite(thr) and 0 <= thr <= 100:
            d = {"throttle": thr / 100.0}
        else:
            return mav.MAV_RESULT_DENIED
        cmd = vocab(d)
        if isinstance(cmd, str):
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    @staticmethod
    def _position(ctx: Context, v: MavVehicle, req: CommandRequest, out: Outcome
                  ) -> tuple[dict[str, Any], str | None] | None:
        """The horizontal point and altitude of a positional command (None: DENIED)."""
        loc = req.location()
        if loc is None:
            row = v.row_or_raise()
            loc = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
        lat, lon = loc
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            out.replies.extend(text(f"bad position {lat:g}, {lon:g}"))
            return None
        d: dict[str, Any] = {"lat_deg": lat, "lon_deg": lon}
        alt_key = None
        if math.isfinite(req.z):
            a = ctx.alt(v, req.frame, req.z)
            if a is None:
                out.replies.extend(text(f"frame {req.frame} not supported"))
                return None
            alt_key = a[0]
            d[a[0]] = a[1]
        return d, alt_key

    def _reposition(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                    out: Outcome) -> int:
        refused = self._no_autopilot("reposition", out)
        if refused is not None:
            return refused
        pos = self._position(ctx, v, req, out)
        if pos is None:
            return mav.MAV_RESULT_DENIED
        goto, _ = pos
        spd, flags, radius, direction = req.p
        if not self._speed_into(v, spd, goto, out):
            return mav.MAV_RESULT_DENIED
        default_r, default_ccw = loiter_radius(v)
        if math.isfinite(radius) and radius != 0:
            goto["loiter_radius_m"] = abs(radius)
            ccw = math.isfinite(direction) and direction != 0
        else:
            if default_r:
                goto["loiter_radius_m"] = default_r
            ccw = (math.isfinite(direction) and direction != 0) or default_ccw
        change = (as_int(flags) or 0) & mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        if v.mode != PlaneMode.GUIDED and not change:
            out.replies.extend(text("reposition: switch to GUIDED first"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, PlaneMode.GUIDED, {"goto": goto}, out, "reposition", cw=not ccw)

    def _loiter_unlim(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        refused = self._no_autopilot("loiter", out)
        if refused is not None:
            return refused
        radius = req.p[2]
        lo = loiter_here(v)
        if math.isfinite(radius) and radius != 0:  # ArduPilot: negative = counter-clockwise
            lo["radius_m"] = abs(radius)
            lo["direction"] = "ccw" if radius < 0 else "cw"
        z = req.z if math.isfinite(req.z) and req.z != 0 else math.nan
        pos = self._position(ctx, v, replace(req, z=z), out)
        if pos is None:
            return mav.MAV_RESULT_DENIED
        point, alt_key = pos
        if req.location() is not None:
            lo["center"] = {"lat_deg": point["lat_deg"], "lon_deg": point["lon_deg"]}
        if alt_key is not None:
            lo[alt_key] = point[alt_key]
        return ctx.switch_to(v, PlaneMode.LOITER, {"loiter": lo}, out, "loiter")

    def _nav_land(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
                  out: Outcome) -> int:
        """NAV_LAND: land at the position (none: straight ahead), in GUIDED:
        down a 3-degree glide path, sliding to a stop on its skids."""
        refused = self._no_autopilot("land", out)
        if refused is not None:
            return refused
        if v.mode != PlaneMode.GUIDED:
            out.replies.extend(text("land: switch to GUIDED first"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, PlaneMode.GUIDED, land_vocab(v, req.location(), None),
                             out, "land")

    def _orbit(self, ctx: Context, v: MavVehicle, req: CommandRequest, tick: int,
               out: Outcome) -> int:
        """DO_ORBIT: a loiter round the centre (x/y; none: where it is) at
        radius param1 (negative: counter-clockwise), speed param2 when > 0."""
        refused = self._no_autopilot("orbit", out)
        if refused is not None:
            return refused
        radius, speed = req.p[0], req.p[1]
        if not (math.isfinite(radius) and radius != 0 and abs(radius) <= 10_000.0):
            out.replies.extend(text("orbit: radius must be non-zero, at most 10000 m (param1)"))
            return mav.MAV_RESULT_DENIED
        pos = self._position(ctx, v, replace(req, z=req.z if req.z else math.nan), out)
        if pos is None:
            return mav.MAV_RESULT_DENIED
        point, alt_key = pos
        lo: dict[str, Any] = {"radius_m": abs(radius), "direction": "ccw" if radius < 0 else "cw"}
        if req.location() is not None:
            lo["center"] = {"lat_deg": point["lat_deg"], "lon_deg": point["lon_deg"]}
        if alt_key is not None:
            lo[alt_key] = point[alt_key]
        if not self._speed_into(v, speed, lo, out):
            return mav.MAV_RESULT_DENIED
        return ctx.switch_to(v, PlaneMode.LOITER, {"loiter": lo}, out, "orbit")
