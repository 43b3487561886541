"""The fixed-wing class on MAVLink: an ArduPlane (MAV_TYPE_FIXED_WING,
ArduPilot's autopilot type, ArduPlane's custom modes, commands, mission
items and parameter names), flown by cosim's autopilot.

The personality is put together here from its parts: the modes
(``mav_modes``), the commands (``mav_commands``), the mission items
(``mav_missions``) and the parameters with what they make of a flight
(``mav_params``); each module's docstring lists what it supports. A command
from inside cosim (a schedule) reports the mode of what it does: a loiter
LOITER, a goto, waypoints or heading GUIDED, a take-off TAKEOFF.

What a ground station sees of the aircraft and what the safety rule is told
it can fly are this module's; the protocols are ``cosim.mavlink``'s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink import mission as mi
from cosim.mavlink.personality import Personality
from cosim.mavlink.services.base import Context
from cosim.vehicles.fixed_wing import mav_params
from cosim.vehicles.fixed_wing.mav_commands import PlaneCommands
from cosim.vehicles.fixed_wing.mav_missions import ARDUPLANE_ITEMS, PlaneMissions
from cosim.vehicles.fixed_wing.mav_modes import PlaneMode
from cosim.vehicles.fixed_wing.mav_params import ARDUPLANE_PARAMS

if TYPE_CHECKING:
    from cosim.core.state import VehicleSpec
    from cosim.mavlink.vehicle import MavVehicle


class ArduPlane(PlaneCommands, PlaneMissions):
    """ArduPlane, flown by cosim's autopilot (``autopilot``) or, for a JSBSim
    model without one, a plane in MANUAL that takes no commands."""

    mav_type = mav.MAV_TYPE_FIXED_WING
    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    modes = {int(m): m.name for m in PlaneMode}
    auto_mode = int(PlaneMode.AUTO)
    hold_mode = int(PlaneMode.LOITER)
    param_defs = ARDUPLANE_PARAMS
    mission_items = ARDUPLANE_ITEMS
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
        super().__init__()
        self.autopilot = autopilot
        #: ROLL_LIMIT_DEG follows the autopilot's actual bank limit
        self.followed_params = {"ROLL_LIMIT_DEG": "bank_limit_deg"} if autopilot else {}

    # -- what it can fly -------------------------------------------------------------
    def limits(self, v: MavVehicle) -> Limits:
        row = v.row_values
        speed = row[_S["airspeed_mps"]] if row is not None and math.isfinite(
            row[_S["airspeed_mps"]]) else v.params["AIRSPEED_CRUISE"]
        return Limits(v.home[2], v.spec.min_alt_agl_m, speed, v.params["ROLL_LIMIT_DEG"])

    def speed_problem(self, v: MavVehicle, spd: float) -> str | None:
        return mav_params.speed_problem(v, spd)

    def default_radius_m(self, v: MavVehicle, speed: float | None = None) -> float:
        """Guidance's loiter radius at ``speed`` (default: the airspeed flown)."""
        return mav_params.default_radius_m(v, speed)

    # -- parameters ----------------------------------------------------------------
    def spec_params(self, vehicle: VehicleSpec) -> dict[str, float]:
        return mav_params.spec_params(vehicle)

    def param_problem(self, ctx: Context, v: MavVehicle, name: str, value: float) -> str | None:
        return mav_params.param_problem(ctx, v, name, value)

    def param_command(self, v: MavVehicle, name: str) -> dict[str, Any] | None:
        return mav_params.param_command(v, name) if self.autopilot else None


#: the fixed-wing class's personality, and a plain JSBSim model's
ARDUPLANE = ArduPlane(autopilot=True)
ARDUPLANE_NO_AUTOPILOT = ArduPlane(autopilot=False)
