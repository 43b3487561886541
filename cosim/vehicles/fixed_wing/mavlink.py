"""The fixed-wing class on MAVLink: an ArduPlane (MAV_TYPE_FIXED_WING,
ArduPilot's autopilot type, ArduPlane's custom modes, commands, mission
items and parameter names), flown by cosim's autopilot.

Modes: GUIDED (the default; outside guidance and ground stations steer),
LOITER, CIRCLE (a loiter where it is), RTL (home or the nearest rally
point), TAKEOFF and AUTO (the mission) can be entered; the pilot's modes are
refused (no pilot in the simulation); MANUAL is the mode of a plain JSBSim
model without an autopilot, which takes no commands. A command from inside
cosim (a schedule) reports the mode of what it does: a loiter LOITER, a
goto, waypoints or heading GUIDED, a take-off TAKEOFF.

Commands: ARM_DISARM, NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF, DO_CHANGE_SPEED,
DO_REPOSITION, NAV_LOITER_UNLIM, DO_ORBIT (a loiter: radius param1,
negative counter-clockwise; speed param2). Disarmed vehicles keep their
engine off: arming restores the cruise airspeed, disarming sets throttle 0,
and no other command carries a speed while disarmed. NAV_LAND (in GUIDED):
land at the point, or straight ahead, down a 3-degree glide path at 1.1 x
AIRSPEED_MIN, sliding to a stop on the airframe's skids.

Missions (flown in AUTO item by item, ``cosim.mavlink.mission_runner``):
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME,
NAV_LOITER_TO_ALT, NAV_TAKEOFF, NAV_RETURN_TO_LAUNCH, NAV_LAND (the leg to
its point becomes the approach, then the glide path; reached once stopped
on the ground, where the aircraft disarms) and the DO/CONDITION items every
ArduPilot-like class runs. MISSION_ITEM(_INT)
with current=2 is a guided goto (GUIDED only), current=3 an altitude change.

Parameters (a small, real set: every one changes what the vehicle does):

=================  =======  ========  ==================================================
name               type     default   effect
=================  =======  ========  ==================================================
ARMING_CHECK       INT32    1         0: arm without pre-arm checks; otherwise arming a
                                      crashed or diverged vehicle fails
ALT_HOLD_RTL       INT32    10000     RTL altitude above home (cm); -1: keep altitude
RTL_RADIUS         INT16    0         RTL loiter radius (m, <0 ccw); 0: WP_LOITER_RAD
WP_LOITER_RAD      INT16    0         loiter radius (m, <0 ccw) for LOITER, GUIDED and
                                      repositions without their own radius; 0 (cosim):
                                      guidance's bank-limited default
TKOFF_ALT          INT16    50        TAKEOFF climb target above home (m)
AIRSPEED_CRUISE    REAL32   (model)   airspeed restored on arming and flown in RTL (m/s)
AIRSPEED_MIN       INT16    (model)   lowest speed DO_CHANGE_SPEED/DO_REPOSITION accept
AIRSPEED_MAX       INT16    (model)   highest speed they accept (m/s)
ROLL_LIMIT_DEG     REAL32   45        guidance bank limit (sent as a command on change)
STALL_PREVENTION   INT8     1         the autopilot's stall protection (sent on change)
SYSID_THISMAV      INT16    (sysid)   read-only here (ArduPilot needs a reboot too)
=================  =======  ========  ==================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from enum import IntEnum
from typing import TYPE_CHECKING, Any

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX as _S
from cosim.core.units import KT_TO_MPS
from cosim.guidance.commands import (
    DEFAULT_BANK_LIMIT_DEG,
    Command,
    min_turn_radius_m,
    waypoint_accept_radius_m,
)
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink import mission as mi
from cosim.mavlink.mission import COMMON_DO_ITEMS, MissionItem
from cosim.mavlink.outcome import CommandRequest, Outcome, as_int, mission_ack, text, vocab
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.personality import CommandFn, Personality, stopped
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.core.state import VehicleSpec
    from cosim.mavlink.vehicle import MavVehicle


class PlaneMode(IntEnum):
    """ArduPlane custom mode numbers (HEARTBEAT.custom_mode)."""

    MANUAL = 0
    CIRCLE = 1
    STABILIZE = 2
    TRAINING = 3
    ACRO = 4
    FBWA = 5
    FBWB = 6
    CRUISE = 7
    AUTOTUNE = 8
    AUTO = 10
    RTL = 11
    LOITER = 12
    TAKEOFF = 13
    AVOID_ADSB = 14
    GUIDED = 15
    THERMAL = 24


#: modes in which ArduPlane reports MAV_MODE_FLAG_MANUAL_INPUT_ENABLED only
_MANUAL_MODES = {PlaneMode.MANUAL, PlaneMode.TRAINING, PlaneMode.ACRO}
#: modes ArduPlane reports as GUIDED_ENABLED | STABILIZE_ENABLED
_GUIDED_MODES = {PlaneMode.AUTO, PlaneMode.RTL, PlaneMode.LOITER, PlaneMode.AVOID_ADSB,
                 PlaneMode.GUIDED, PlaneMode.CIRCLE, PlaneMode.TAKEOFF, PlaneMode.THERMAL}
#: modes a vehicle with an autopilot can be switched to by a ground station
SETTABLE_MODES = (PlaneMode.GUIDED, PlaneMode.LOITER, PlaneMode.RTL, PlaneMode.TAKEOFF)
#: modes in which the autopilot flies (settable ones and the mission)
_FLYING_MODES = SETTABLE_MODES + (PlaneMode.AUTO,)
#: ArduPilot's magic number in ARM_DISARM's param2: force (skip the checks)
FORCE_MAGIC = 21196

#: the parameter table, in index order (PARAM_VALUE.param_index)
ARDUPLANE_PARAMS: tuple[ParamDef, ...] = (
    ParamDef("AIRSPEED_CRUISE", mav.MAV_PARAM_TYPE_REAL32, 25.0, 1.0, 300.0),
    ParamDef("AIRSPEED_MAX", mav.MAV_PARAM_TYPE_INT16, 100, 1, 300),
    ParamDef("AIRSPEED_MIN", mav.MAV_PARAM_TYPE_INT16, 10, 1, 300),
    ParamDef("ALT_HOLD_RTL", mav.MAV_PARAM_TYPE_INT32, 10000, -1, 3_000_000),
    ParamDef("ARMING_CHECK", mav.MAV_PARAM_TYPE_INT32, 1, 0, 2 ** 31 - 1),
    ParamDef("ROLL_LIMIT_DEG", mav.MAV_PARAM_TYPE_REAL32, DEFAULT_BANK_LIMIT_DEG, 5.0, 75.0),
    ParamDef("RTL_RADIUS", mav.MAV_PARAM_TYPE_INT16, 0, -32767, 32767),
    ParamDef("STALL_PREVENTION", mav.MAV_PARAM_TYPE_INT8, 1, 0, 1),
    SYSID_THISMAV,
    ParamDef("TKOFF_ALT", mav.MAV_PARAM_TYPE_INT16, 50, 0, 30000),
    ParamDef("WP_LOITER_RAD", mav.MAV_PARAM_TYPE_INT16, 0, -32767, 32767),
)


class ArduPlane(Personality):
    """ArduPlane, flown by cosim's autopilot (``autopilot``) or, for a JSBSim
    model without one, a plane in MANUAL that takes no commands."""

    mav_type = mav.MAV_TYPE_FIXED_WING
    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    modes = {int(m): m.name for m in PlaneMode}
    auto_mode = int(PlaneMode.AUTO)
    hold_mode = int(PlaneMode.LOITER)
    param_defs = ARDUPLANE_PARAMS
    mission_items = COMMON_DO_ITEMS | {
        mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM, mav.MAV_CMD_NAV_LOITER_TURNS,
        mav.MAV_CMD_NAV_LOITER_TIME, mav.MAV_CMD_NAV_LOITER_TO_ALT, mav.MAV_CMD_NAV_TAKEOFF,
        mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_NAV_LAND}
    rtl_mode = int(PlaneMode.RTL)
    command_modes = {"loiter": int(PlaneMode.LOITER), "goto": int(PlaneMode.GUIDED),
                     "heading": int(PlaneMode.GUIDED), "velocity": int(PlaneMode.GUIDED),
                     "takeoff": int(PlaneMode.TAKEOFF)}
    passes_waypoints = True
    waypoint_hold = False  # ArduPlane ignores a waypoint's hold time
    takeoff_tolerance_m = mi.ALT_TOLERANCE_M
    extra_sensors = mav.SENSOR_DIFF_PRESSURE  # an airspeed sensor
    capabilities = (Personality.capabilities | mav.CAP_SET_POSITION_TARGET_GLOBAL_INT
                    | mav.CAP_SET_POSITION_TARGET_LOCAL_NED)
    #: what ArduPlane 4.5.0 (official) would report
    flight_sw_version = (4 << 24) | (5 << 16) | (0 << 8) | mav.FIRMWARE_VERSION_TYPE_OFFICIAL

    def __init__(self, autopilot: bool = True) -> None:
        self.autopilot = autopilot
        #: ROLL_LIMIT_DEG follows the autopilot's actual bank limit
        self.followed_params = {"ROLL_LIMIT_DEG": "bank_limit_deg"} if autopilot else {}
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

    # -- heartbeat -----------------------------------------------------------------
    def default_mode(self) -> int:
        return int(PlaneMode.GUIDED if self.autopilot else PlaneMode.MANUAL)

    def manual(self, mode: int) -> bool:
        return mode in _MANUAL_MODES

    def base_mode(self, mode: int, armed: bool) -> int:
        """As ArduPlane computes it (stick mixing off: no RC)."""
        if mode in _MANUAL_MODES:
            bm = mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        elif mode in _GUIDED_MODES:
            bm = mav.MAV_MODE_FLAG_GUIDED_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        else:
            bm = mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if armed:
            bm |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        return bm | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED

    # -- what it can fly -------------------------------------------------------------
    def limits(self, v: MavVehicle) -> Limits:
        row = v.row_values
        speed = row[_S["airspeed_mps"]] if row is not None and math.isfinite(
            row[_S["airspeed_mps"]]) else v.params["AIRSPEED_CRUISE"]
        return Limits(v.home[2], v.spec.min_alt_agl_m, speed, v.params["ROLL_LIMIT_DEG"])

    @staticmethod
    def _radius(v: MavVehicle, name: str = "WP_LOITER_RAD") -> tuple[float | None, bool]:
        """(radius_m or None for guidance's default, counter-clockwise)."""
        r = v.params[name]
        if name == "RTL_RADIUS" and r == 0:
            r = v.params["WP_LOITER_RAD"]
        return (abs(r) if r else None), r < 0

    def speed_problem(self, v: MavVehicle, spd: float) -> str | None:
        lo, hi = v.params["AIRSPEED_MIN"], v.params["AIRSPEED_MAX"]
        if not lo <= spd <= hi:
            return f"speed {spd:g} m/s outside AIRSPEED_MIN..MAX {lo:g}..{hi:g}"
        return None

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

    def _loiter_here(self, v: MavVehicle) -> dict[str, Any]:
        radius, ccw = self._radius(v)
        lo: dict[str, Any] = {}
        if radius:
            lo["radius_m"] = radius
        if ccw:
            lo["direction"] = "ccw"
        return lo

    @staticmethod
    def _rtl_point(ctx: Context, v: MavVehicle, row: list[float]) -> dict[str, Any]:
        """The nearest rally point at its altitude, else home at the RTL
        altitude (ALT_HOLD_RTL; -1: the altitude it is at)."""
        point = mi.return_point(ctx, v)
        if "alt_msl_m" not in point and "alt_agl_m" not in point:
            alt_cm = v.params["ALT_HOLD_RTL"]
            point["alt_msl_m"] = float(row[_S["alt_msl_m"]]) if alt_cm < 0 \
                else v.home[2] + alt_cm / 100.0
        return point

    def default_radius_m(self, v: MavVehicle, speed: float | None = None) -> float:
        """Guidance's loiter radius at ``speed`` (default: the airspeed flown)."""
        if speed is None:
            row = v.row_values
            speed = float(row[_S["airspeed_mps"]]) if row is not None and math.isfinite(
                row[_S["airspeed_mps"]]) else v.params["AIRSPEED_CRUISE"]
        return max(1.5 * min_turn_radius_m(speed, v.params["ROLL_LIMIT_DEG"]), 150.0)

    def _no_autopilot(self, what: str, out: Outcome) -> int | None:
        """FAILED with a STATUSTEXT for a vehicle without an autopilot."""
        if self.autopilot:
            return None
        out.replies.extend(text(f"{what}: this vehicle has no autopilot"))
        return mav.MAV_RESULT_FAILED

    # -- modes ---------------------------------------------------------------------
    def takes_targets(self, v: MavVehicle) -> bool:
        return self.autopilot and v.mode == PlaneMode.GUIDED  # ArduPlane: GUIDED only

    def enter_mode(self, ctx: Context, v: MavVehicle, mode: int, tick: int,
                   out: Outcome) -> int:
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        refused = self._no_autopilot(self.mode_name(mode), out)
        if refused is not None:
            return refused
        row = v.row_or_raise()
        d: dict[str, Any]
        cw_override: bool | None = None
        if mode in (PlaneMode.GUIDED, PlaneMode.LOITER, PlaneMode.CIRCLE):
            d = {"loiter": self._loiter_here(v)}
        elif mode == PlaneMode.RTL:
            goto = self._rtl_point(ctx, v, row)
            radius, ccw = self._radius(v, "RTL_RADIUS")
            if radius:
                goto["loiter_radius_m"] = radius
            cw_override = not ccw
            if v.armed:
                goto["airspeed_mps"] = v.params["AIRSPEED_CRUISE"]
            d = {"goto": goto}
        elif mode == PlaneMode.TAKEOFF:
            return self._takeoff(ctx, v, v.home[2] + v.params["TKOFF_ALT"], out)
        elif mode == PlaneMode.AUTO:
            return ctx.fly_mission(v, v.mission.current, out)
        elif mode == PlaneMode.MANUAL:
            out.replies.extend(text("MANUAL: no pilot in the simulation"))
            return mav.MAV_RESULT_FAILED
        else:
            out.replies.extend(text(f"{self.mode_name(mode)} is not supported by cosim"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, mode, d, out, self.mode_name(mode), mav.MAV_RESULT_FAILED,
                             cw_override)

    def _takeoff(self, ctx: Context, v: MavVehicle, alt_msl_m: float, out: Outcome) -> int:
        refused = self._no_autopilot("TAKEOFF", out)
        if refused is not None:
            return refused
        if not v.armed:
            out.replies.extend(text("TAKEOFF: arm first"))
            return mav.MAV_RESULT_FAILED
        lo = self._loiter_here(v)
        if float(v.row_or_raise()[_S["alt_msl_m"]]) < alt_msl_m:  # takeoff climbs, never descends
            lo["alt_msl_m"] = alt_msl_m
        return ctx.switch_to(v, PlaneMode.TAKEOFF, {"loiter": lo}, out, "TAKEOFF")

    # -- commands ------------------------------------------------------------------
    def command_handler(self, number: int) -> CommandFn | None:
        return self._commands.get(number)

    def supported_commands(self) -> frozenset[int]:
        return frozenset(self._commands)

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
            if self.autopilot and v.mode in _FLYING_MODES:
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
        default_r, default_ccw = self._radius(v)
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
        lo = self._loiter_here(v)
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

    # -- parameters ----------------------------------------------------------------
    def spec_params(self, vehicle: VehicleSpec) -> dict[str, float]:
        """Airspeed limits from the model's profile, the cruise speed from the
        vehicle's initial airspeed (within them)."""
        params: dict[str, float] = {}
        lo_kt = vehicle.profile.get("airspeed_min_kt")
        hi_kt = vehicle.profile.get("airspeed_max_kt")
        lo = math.ceil(lo_kt * KT_TO_MPS) if isinstance(lo_kt, (int, float)) else None
        hi = math.floor(hi_kt * KT_TO_MPS) if isinstance(hi_kt, (int, float)) else None
        cruise = vehicle.airspeed_mps
        if lo is not None:
            params["AIRSPEED_MIN"] = lo
            cruise = max(cruise, lo)
        if hi is not None:
            params["AIRSPEED_MAX"] = hi
            cruise = min(cruise, hi)
        params["AIRSPEED_CRUISE"] = round(cruise, 2)
        return params

    def param_problem(self, ctx: Context, v: MavVehicle, name: str, value: float) -> str | None:
        """A value that would make a later command crash the vehicle (the RTL
        and takeoff heights, the loiter radii), counted as unsafe."""
        floor = v.spec.min_alt_agl_m
        problem = None
        if name == "ALT_HOLD_RTL" and value != -1 and value / 100.0 < floor:
            problem = f"RTL at {value / 100:g} m above home: at least {floor:g} m (or -1)"
        elif name == "TKOFF_ALT" and value < floor:
            problem = f"takeoff to {value:g} m above home: at least {floor:g} m"
        elif name in ("WP_LOITER_RAD", "RTL_RADIUS") and value != 0:
            r_min = min_turn_radius_m(v.params["AIRSPEED_CRUISE"], v.params["ROLL_LIMIT_DEG"])
            if abs(value) < r_min:
                problem = (f"radius {abs(value):g} m is below the minimum turn radius "
                           f"({r_min:.0f} m at AIRSPEED_CRUISE and ROLL_LIMIT_DEG; or 0)")
        if problem is not None:
            ctx.counts["commands_unsafe"] += 1
        return problem

    def param_command(self, v: MavVehicle, name: str) -> dict[str, Any] | None:
        if not self.autopilot:
            return None
        if name == "ROLL_LIMIT_DEG":
            return {"bank_limit_deg": v.params[name]}
        if name == "STALL_PREVENTION":
            return {"stall_protection": bool(v.params[name])}
        return None

    # -- missions ------------------------------------------------------------------
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
            return self._land_vocab(v, None if item.here else (item.lat_deg, item.lon_deg),
                                    v.mission.speed_mps)
        if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            goto = self._rtl_point(ctx, v, row)
            radius, ccw = self._radius(v, "RTL_RADIUS")
            goto["loiter_radius_m"] = radius or self.default_radius_m(v, speed)
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
                lo = self._loiter_here(v)
                lo.setdefault("radius_m", self.default_radius_m(v, speed))
                lo[alt[0]] = alt[1]
                return {"loiter": lo}
            psi = math.radians(float(row[_S["yaw_deg"]]))
            here = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
            la, lo_ = LocalFrame(here[0], here[1], v.home[2]).place(
                1000.0 * math.cos(psi), 1000.0 * math.sin(psi), v.home[2])
            return {"goto": {"lat_deg": float(la), "lon_deg": float(lo_), alt[0]: alt[1]}}
        default_r, default_ccw = self._radius(v)
        if c == mav.MAV_CMD_NAV_WAYPOINT:  # ArduPlane tracks the leg from the last one
            last = v.mission.nav
            if last is not None and last.item.command == mav.MAV_CMD_NAV_WAYPOINT:
                extra["from"] = {"lat_deg": prev[0], "lon_deg": prev[1]}
            if any(it.command in mi.NAV_COMMANDS for it in v.mission.items[item.seq:]):
                extra["continue"] = True  # on past it until the next is flown
            return {"goto": {"lat_deg": lat, "lon_deg": lon, **extra,
                             "loiter_radius_m": default_r or self.default_radius_m(v, speed)},
                    "cw": not default_ccw}
        if c in mi.LOITERS:
            r = item.param2 if c == mav.MAV_CMD_NAV_LOITER_TO_ALT else item.param3
            radius = abs(r) if r else (default_r or self.default_radius_m(v, speed))
            ccw = r < 0 if r else default_ccw
            return {"loiter": {"center": {"lat_deg": lat, "lon_deg": lon}, "radius_m": radius,
                               "direction": "ccw" if ccw else "cw", **extra}}
        return f"{mav.command_name(c)} is not flown by ArduPlane in cosim"

    def _land_vocab(self, v: MavVehicle, point: tuple[float, float] | None,
                    speed: float | None) -> dict[str, Any]:
        """Land at ``point`` (None: straight ahead, where the glide path meets
        the ground), at ``speed`` or the approach speed: 1.1 x AIRSPEED_MIN
        (at most AIRSPEED_CRUISE)."""
        if speed is None:
            speed = min(1.1 * v.params["AIRSPEED_MIN"], v.params["AIRSPEED_CRUISE"])
        d: dict[str, Any] = {"land": True}
        if v.armed:
            d["airspeed_mps"] = round(float(speed), 2)
        if point is not None:
            d["goto"] = {"lat_deg": point[0], "lon_deg": point[1]}
        return d

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
        return ctx.switch_to(v, PlaneMode.GUIDED, self._land_vocab(v, req.location(), None),
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

    def guided_item(self, ctx: Context, v: MavVehicle, m: mav.Message, item: MissionItem,
                    current: int) -> Outcome:
        """current=2: "fly to here" in GUIDED (MAVProxy's and older stations'
        guided goto); current=3: change the altitude (GUIDED and the other
        autopilot modes). Answered with a MISSION_ACK."""
        out = Outcome()
        alt = ctx.alt(v, item.frame, item.z)
        if current == 3:
            if not self.autopilot or v.mode not in _FLYING_MODES or alt is None:
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
        radius, ccw = self._radius(v)
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


#: the fixed-wing class's personality, and a plain JSBSim model's
ARDUPLANE = ArduPlane(autopilot=True)
ARDUPLANE_NO_AUTOPILOT = ArduPlane(autopilot=False)
