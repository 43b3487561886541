"""ArduPlane's parameters: the table, the checks on setting them, and what
they make of a flight (loiter radii, the RTL point, the accepted speeds, a
landing's approach speed), read by the modes, commands and mission items.

A small, real set: every one changes what the vehicle does.

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

Functions of a vehicle's parameters only: the personality's state (whether
it has an autopilot, its modes) is the other modules' (``mavlink``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.core.units import KT_TO_MPS
from cosim.guidance.commands import DEFAULT_BANK_LIMIT_DEG, min_turn_radius_m
from cosim.mavlink import adapter as mav
from cosim.mavlink import mission as mi
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.services.base import Context

if TYPE_CHECKING:
    from cosim.core.state import VehicleSpec
    from cosim.mavlink.vehicle import MavVehicle

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


# -- what the parameters make of a flight ---------------------------------------------
def loiter_radius(v: MavVehicle, name: str = "WP_LOITER_RAD") -> tuple[float | None, bool]:
    """(radius_m or None for guidance's default, counter-clockwise)."""
    r = v.params[name]
    if name == "RTL_RADIUS" and r == 0:
        r = v.params["WP_LOITER_RAD"]
    return (abs(r) if r else None), r < 0


def loiter_here(v: MavVehicle) -> dict[str, Any]:
    """A loiter where it is, with WP_LOITER_RAD's radius and way round."""
    radius, ccw = loiter_radius(v)
    lo: dict[str, Any] = {}
    if radius:
        lo["radius_m"] = radius
    if ccw:
        lo["direction"] = "ccw"
    return lo


def rtl_point(ctx: Context, v: MavVehicle, row: list[float]) -> dict[str, Any]:
    """The nearest rally point at its altitude, else home at the RTL
    altitude (ALT_HOLD_RTL; -1: the altitude it is at)."""
    point = mi.return_point(ctx, v)
    if "alt_msl_m" not in point and "alt_agl_m" not in point:
        alt_cm = v.params["ALT_HOLD_RTL"]
        point["alt_msl_m"] = float(row[_S["alt_msl_m"]]) if alt_cm < 0 \
            else v.home[2] + alt_cm / 100.0
    return point


def default_radius_m(v: MavVehicle, speed: float | None = None) -> float:
    """Guidance's loiter radius at ``speed`` (default: the airspeed flown)."""
    if speed is None:
        row = v.row_values
        speed = float(row[_S["airspeed_mps"]]) if row is not None and math.isfinite(
            row[_S["airspeed_mps"]]) else v.params["AIRSPEED_CRUISE"]
    return max(1.5 * min_turn_radius_m(speed, v.params["ROLL_LIMIT_DEG"]), 150.0)


def speed_problem(v: MavVehicle, spd: float) -> str | None:
    """Why a commanded airspeed is refused: outside AIRSPEED_MIN..MAX."""
    lo, hi = v.params["AIRSPEED_MIN"], v.params["AIRSPEED_MAX"]
    if not lo <= spd <= hi:
        return f"speed {spd:g} m/s outside AIRSPEED_MIN..MAX {lo:g}..{hi:g}"
    return None


def land_vocab(v: MavVehicle, point: tuple[float, float] | None,
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


# -- setting them ---------------------------------------------------------------------
def spec_params(vehicle: VehicleSpec) -> dict[str, float]:
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


def param_problem(ctx: Context, v: MavVehicle, name: str, value: float) -> str | None:
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


def param_command(v: MavVehicle, name: str) -> dict[str, Any] | None:
    """The vocabulary mapping that applies a parameter just set to the
    autopilot (None: the parameter is read when used)."""
    if name == "ROLL_LIMIT_DEG":
        return {"bank_limit_deg": v.params[name]}
    if name == "STALL_PREVENTION":
        return {"stall_protection": bool(v.params[name])}
    return None
