"""ArduPlane's modes: their numbers, how HEARTBEAT reports them, and what
entering each does.

GUIDED (the default; outside guidance and ground stations steer), LOITER,
CIRCLE (a loiter where it is), RTL (home or the nearest rally point),
TAKEOFF and AUTO (the mission) can be entered; the pilot's modes are refused
(no pilot in the simulation); MANUAL is the mode of a plain JSBSim model
without an autopilot, which takes no commands.

The modes' part of the personality (``PlaneModes``, a base of
``mavlink.ArduPlane``); the commands and mission items are the other
modules'.
"""

from __future__ import annotations

from enum import IntEnum
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import Outcome, text
from cosim.mavlink.personality import Personality
from cosim.mavlink.services.base import Context
from cosim.vehicles.fixed_wing.mav_params import loiter_here, loiter_radius, rtl_point

if TYPE_CHECKING:
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
FLYING_MODES = SETTABLE_MODES + (PlaneMode.AUTO,)


class PlaneModes(Personality):
    """ArduPlane's modes (see the module docstring)."""

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

    def takes_targets(self, v: MavVehicle) -> bool:
        return self.autopilot and v.mode == PlaneMode.GUIDED  # ArduPlane: GUIDED only

    def _no_autopilot(self, what: str, out: Outcome) -> int | None:
        """FAILED with a STATUSTEXT for a vehicle without an autopilot."""
        if self.autopilot:
            return None
        out.replies.extend(text(f"{what}: this vehicle has no autopilot"))
        return mav.MAV_RESULT_FAILED

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
            d = {"loiter": loiter_here(v)}
        elif mode == PlaneMode.RTL:
            goto = rtl_point(ctx, v, row)
            radius, ccw = loiter_radius(v, "RTL_RADIUS")
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
        """TAKEOFF (the mode, and NAV_TAKEOFF): a loiter where it is, climbing
        to ``alt_msl_m`` (never descending); armed first."""
        refused = self._no_autopilot("TAKEOFF", out)
        if refused is not None:
            return refused
        if not v.armed:
            out.replies.extend(text("TAKEOFF: arm first"))
            return mav.MAV_RESULT_FAILED
        lo = loiter_here(v)
        if float(v.row_or_raise()[_S["alt_msl_m"]]) < alt_msl_m:  # takeoff climbs, never descends
            lo["alt_msl_m"] = alt_msl_m
        return ctx.switch_to(v, PlaneMode.TAKEOFF, {"loiter": lo}, out, "TAKEOFF")
