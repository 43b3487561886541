"""What ArduPilot's vehicle firmwares share on MAVLink, for the personalities
that copy one (ArduCopter, ArduRover): modes by a table, arming
(COMPONENT_ARM_DISARM; disarming in the air needs param2 = 21196, as in
ArduPilot), DO_REPOSITION, DO_CHANGE_SPEED and DO_ORBIT (where the class
has an orbit mode). Each mode of the table is a vocabulary mapping (a
function of the vehicle: home, ...); a mode in ``refused`` is refused with
its reason; the mission mode flies the mission, each navigation item as the
mapping ``nav_vocab`` makes of it."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav
from cosim.mavlink import mission as mi
from cosim.mavlink.mission import MissionItem, return_point
from cosim.mavlink.outcome import CommandRequest, Outcome, as_int, text
from cosim.mavlink.personality import CommandFn, Personality
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle

ModeVocab = Callable[["MavVehicle"], dict[str, Any]]
#: COMPONENT_ARM_DISARM param2 that forces a disarm in the air (ArduPilot's)
FORCE_MAGIC = 21196


class ArduPilotLike(Personality):
    """See the module docstring."""

    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    autopilot = True
    #: mode -> the vocabulary mapping it flies (modes not here: not supported)
    mode_vocab: Mapping[int, ModeVocab] = {}
    #: mode -> why cosim refuses it (e.g. a pilot's mode)
    refused: Mapping[int, str] = {}
    #: the mode DO_REPOSITION switches to
    guided_mode: int = 0
    #: whether DO_REPOSITION keeps its altitude (aircraft) or drops it (ground)
    reposition_alt: bool = True
    #: the mode DO_ORBIT flies in (None: DO_ORBIT unsupported)
    orbit_mode: int | None = None
    #: (parameter, scale to m/s) of the default speed of mission items and
    #: guided gotos (0: the class's own default)
    speed_param: tuple[str, float] | None = None
    #: (parameter, scale to m) of the waypoint acceptance radius
    radius_param: tuple[str, float] | None = None

    def default_speed_mps(self, v: MavVehicle) -> float | None:
        """The speed missions fly without a DO_CHANGE_SPEED (None: the class's)."""
        if self.speed_param is None:
            return None
        name, scale = self.speed_param
        speed = v.params[name] * scale
        return speed if speed > 0 else None

    def accept_radius_m(self, v: MavVehicle, row: list[float]) -> float:
        if self.radius_param is None:
            return super().accept_radius_m(v, row)
        name, scale = self.radius_param
        return max(v.params[name] * scale, 0.1)

    def default_mode(self) -> int:
        return self.hold_mode if self.hold_mode is not None else super().default_mode()

    def manual(self, mode: int) -> bool:
        return mode in self.refused

    def enter_mode(self, ctx: Context, v: MavVehicle, mode: int, tick: int,
                   out: Outcome) -> int:
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        name = self.mode_name(mode)
        if mode == self.auto_mode:
            return ctx.fly_mission(v, v.mission.current, out)
        if mode in self.refused:
            out.replies.extend(text(f"{name}: {self.refused[mode]}"))
            return mav.MAV_RESULT_FAILED
        vocab_of = self.mode_vocab.get(mode)
        if vocab_of is None:
            out.replies.extend(text(f"{name} is not supported by cosim"))
            return mav.MAV_RESULT_FAILED
        d = self.rtl_vocab(ctx, v) if mode == self.rtl_mode else vocab_of(v)
        return ctx.switch_to(v, mode, d, out, name, mav.MAV_RESULT_FAILED)

    def _handlers(self) -> dict[int, CommandFn]:
        own: dict[int, CommandFn] = {mav.MAV_CMD_DO_REPOSITION: self._reposition,
                                     mav.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
                                     mav.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
                                     mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._rtl}
        if self.orbit_mode is not None:
            own[mav.MAV_CMD_DO_ORBIT] = self._orbit
        return own

    def command_handler(self, number: int) -> CommandFn | None:
        return self._handlers().get(number)

    def supported_commands(self) -> frozenset[int]:
        return frozenset(self._handlers())

    def _rtl(self, ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        if self.rtl_mode is None:
            return mav.MAV_RESULT_UNSUPPORTED
        return self.enter_mode(ctx, v, self.rtl_mode, tick, out)

    def _orbit(self, ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        """DO_ORBIT: circle a centre (x/y; none: where it is) at radius param1
        (negative: counter-clockwise), speed param2 when > 0, in the orbit mode."""
        radius, speed = req.p[0], req.p[1]
        if not (math.isfinite(radius) and 1.0 <= abs(radius) <= 10_000.0):
            out.replies.extend(text("orbit: radius must be 1..10000 m (param1)"))
            return mav.MAV_RESULT_DENIED
        row = v.row_or_raise()
        centre = req.location() or (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
        lo: dict[str, Any] = {"center": {"lat_deg": centre[0], "lon_deg": centre[1]},
                              "radius_m": abs(radius), "direction": "ccw" if radius < 0 else "cw"}
        if math.isfinite(req.z) and req.z != 0 and self.reposition_alt:
            a = ctx.alt(v, req.frame, req.z)
            if a is not None:
                lo[a[0]] = a[1]
        if math.isfinite(speed) and speed > 0:
            lo["airspeed_mps"] = speed
        assert self.orbit_mode is not None
        return ctx.switch_to(v, self.orbit_mode, {"loiter": lo}, out, "orbit")

    # -- missions ------------------------------------------------------------------
    def rtl_vocab(self, ctx: Context, v: MavVehicle) -> dict[str, Any]:
        """What its RTL flies (the RTL mode's mapping, to the return point)."""
        of = self.mode_vocab.get(self.rtl_mode) if self.rtl_mode is not None else None
        d = dict(of(v)) if of is not None else {}
        if "goto" in d:
            d["goto"] = return_point(ctx, v)
        return d

    def nav_vocab(self, ctx: Context, v: MavVehicle, item: MissionItem,
                  prev: tuple[float, float]) -> dict[str, Any] | str:
        c = item.command
        lat, lon = mi.point_of(v, item, prev)
        pt: dict[str, Any] = {"lat_deg": lat, "lon_deg": lon}
        alt = ctx.alt(v, item.frame, item.z) if self.reposition_alt else None
        keeps_alt = item.z == 0 and item.frame not in (mav.MAV_FRAME_GLOBAL,
                                                       mav.MAV_FRAME_GLOBAL_INT)
        if alt is not None and not keeps_alt:  # altitude 0 above home: hold it
            pt[alt[0]] = alt[1]
        speed = v.mission.speed_mps
        if speed is None:
            speed = self.default_speed_mps(v)
        if speed is not None:
            pt["airspeed_mps"] = speed
        if c == mav.MAV_CMD_NAV_WAYPOINT:
            return {"goto": pt}
        if c in mi.LOITERS:
            r = item.param2 if c == mav.MAV_CMD_NAV_LOITER_TO_ALT else item.param3
            lo = {"center": {"lat_deg": lat, "lon_deg": lon},
                  **{k: x for k, x in pt.items() if k not in ("lat_deg", "lon_deg")}}
            if r:
                lo["radius_m"] = abs(r)
                lo["direction"] = "ccw" if r < 0 else "cw"
            return {"loiter": lo}
        if c == mav.MAV_CMD_NAV_TAKEOFF:
            if alt is None:
                return f"frame {item.frame} not supported"
            return {"takeoff_agl_m": alt[1] - v.home[2] if alt[0] == "alt_msl_m" else alt[1]}
        if c == mav.MAV_CMD_NAV_LAND:
            return {"land": True} if item.here else {"goto": pt, "land": True}
        if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self.rtl_vocab(ctx, v)
        return f"{mav.command_name(c)} is not flown by this vehicle"

    @staticmethod
    def _arm_disarm(ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        want, force = as_int(req.p[0]), as_int(req.p[1]) == FORCE_MAGIC
        if want == 1:
            if not v.armed and not force and not v.prearm_ok():
                out.replies.extend(text("PreArm: vehicle crashed or diverged"))
                return mav.MAV_RESULT_FAILED
            v.armed = True
            return mav.MAV_RESULT_ACCEPTED
        if want == 0:
            if v.armed and v.in_air() and not force:
                out.replies.extend(text(f"Disarm refused in flight (param2={FORCE_MAGIC} "
                                        f"forces)"))
                return mav.MAV_RESULT_FAILED
            v.armed = False
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_DENIED

    @staticmethod
    def _change_speed(ctx: Context, v: Any, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        """DO_CHANGE_SPEED: param2 m/s, checked by the class's rule."""
        return ctx.switch_to(v, v.mode, {"airspeed_mps": req.p[1]}, out, "change speed")

    def _reposition(self, ctx: Context, v: Any, req: CommandRequest, tick: int,
                    out: Outcome) -> int:
        """DO_REPOSITION: go to the point (speed param1 when > 0) and stop there,
        in the guided mode."""
        if not req.is_int:
            out.replies.extend(text("reposition: send it as COMMAND_INT"))
            return mav.MAV_RESULT_DENIED
        goto: dict[str, Any] = {"lat_deg": req.x * 1e-7, "lon_deg": req.y * 1e-7}
        alt = ctx.alt(v, req.frame, req.z) if self.reposition_alt else None
        if alt is not None:
            goto[alt[0]] = alt[1]
        if req.p[0] > 0:
            goto["airspeed_mps"] = req.p[0]
        return ctx.switch_to(v, self.guided_mode, {"goto": goto}, out, "reposition")


def home_goto(v: MavVehicle) -> dict[str, Any]:
    """A vocabulary point at the vehicle's home."""
    return {"lat_deg": v.home[0], "lon_deg": v.home[1]}
