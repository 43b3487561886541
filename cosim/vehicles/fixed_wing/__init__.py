"""The ``fixed_wing`` class: a JSBSim fixed-wing aircraft flown by cosim's
autopilot (JSBSim systems running at the physics rate, ``aircraft/systems``)
through the command vocabulary (``cosim.guidance.commands``): headings,
altitudes, airspeeds, gotos, waypoints and loiters, followed by this class's
guidance (``guidance``: L1 path following, bank-limited turns). On MAVLink
it is an ArduPlane (``mavlink``).

A model is of this class when its cosim profile says ``class: fixed_wing``
(``aircraft/profiles/<model>.yaml`` or ``aircraft/<model>/cosim.yaml``: the
autopilot attachment, CL_max for stall speeds, the airspeed envelope, and
optionally ``min_alt_agl_m``, the lowest height above the ground a command
may ask for, 20 m unless set).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import StateField, VehicleSpec
from cosim.core.units import KT_TO_MPS, LB_TO_KG, LBF_TO_N
from cosim.guidance.commands import Command
from cosim.guidance.safety import Limits, floor_problems, radius_problems
from cosim.vehicles.base import Guidance, SwarmLimits, VehicleClass, on_mavlink
from cosim.vehicles.fixed_wing.guidance import AP_CHANNELS, FixedWingGuidance

#: how low a fixed-wing may be commanded, above the ground (m); the study's
#: lowest passes were 30 m above the ground
DEFAULT_MIN_ALT_AGL_M = 20.0
#: newtons in a pound-force


class FixedWing(VehicleClass):
    name = "fixed_wing"
    display_type = "Air+FixedWing"
    description = "JSBSim fixed-wing aircraft flown by cosim's autopilot (ArduPlane on MAVLink)"
    model_kind = "jsbsim"
    channels = AP_CHANNELS
    default_camera_mount = "nadir"
    contact_is_impact = True
    #: the ground's push on skids or wheels (N; 0 in the air): a landing's
    #: load, in the log
    #: and the fuel on board (kg; every tank's), for the operator's questions
    state_columns: tuple[StateField, ...] = (
        StateField("contact_force_n", "forces/fbz-gear-lbs", -LBF_TO_N),
        StateField("fuel_kg", "propulsion/total-fuel-lbs", LB_TO_KG))
    logs_fuel = True
    flag_events = {"stalled": ("stall", "onset", "recovery"),
                   "stall_protection_active": ("stall_protection", "active", "inactive")}
    mavlink = on_mavlink("cosim.vehicles.fixed_wing.mavlink:ARDUPLANE")

    @property
    def commandable(self) -> bool:
        return True

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> Guidance:
        return FixedWingGuidance(len(start_ne), frame, start_ne, dict(channel_index))

    def min_alt_agl_m(self, profile: Mapping[str, Any]) -> float:
        v = profile.get("min_alt_agl_m", DEFAULT_MIN_ALT_AGL_M)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) \
            else DEFAULT_MIN_ALT_AGL_M

    def check_start(self, spec: VehicleSpec) -> list[str]:
        """A trimmed start inside the model's envelope (its profile's airspeed
        range): JSBSim cannot trim a fixed-wing below its stall speed."""
        lo, hi = spec.profile.get("airspeed_min_kt"), spec.profile.get("airspeed_max_kt")
        kt = spec.airspeed_mps / KT_TO_MPS
        if spec.trim and ((lo is not None and kt < lo - 1e-9)
                          or (hi is not None and kt > hi + 1e-9)):
            return [f"starts at {kt:.1f} kt, outside the envelope of {spec.model} "
                    f"({_envelope(lo, hi)} kt TAS): it could not be trimmed there (give an "
                    f"airspeed inside it)"]
        return []

    def write_problems(self, name: str, value: float, spec: VehicleSpec) -> list[str]:
        """Besides the state (``VehicleClass.write_problems``): the autopilot's
        setpoints are commands' (a raw altitude, heading or speed would skip
        the floor, the envelope and the turn-radius rule), and the pilot's
        normalised controls stay in their range."""
        if name.startswith(_SETPOINTS):
            return [f"{name!r} is an autopilot setpoint: give it as a command: (heading_deg, "
                    f"alt_agl_m, airspeed_kt, loiter, ...), which is checked against the "
                    f"ground and the aircraft's envelope"]
        lo = 0.0 if name.startswith(("fcs/throttle", "fcs/mixture", "fcs/left-brake",
                                     "fcs/right-brake", "fcs/center-brake")) else -1.0
        if name.startswith("fcs/") and name.endswith("-norm") and not lo <= value <= 1.0:
            return [f"{name!r} is a normalised control: {lo:g} to 1, got {value:g}"]
        return super().write_problems(name, value, spec)

    def command_problems(self, cmd: Command, spec: VehicleSpec, limits: Limits) -> list[str]:
        """Airspeeds inside the model's envelope (its profile), then the rule of
        every command path: no altitude below the class minimum above the
        ground, no loiter tighter than the minimum turn radius."""
        prof = spec.profile
        lo, hi = prof.get("airspeed_min_kt"), prof.get("airspeed_max_kt")
        for spd in [cmd.airspeed_mps] + [p.airspeed_mps for p in cmd.points]:
            if spd is None:
                continue
            kt = spd / KT_TO_MPS
            if (lo is not None and kt < lo - 1e-9) or (hi is not None and kt > hi + 1e-9):
                return [f"airspeed {kt:.1f} kt is outside the envelope of {spec.model} "
                        f"({_envelope(lo, hi)} kt TAS)"]
        return self.safety_problems(cmd, limits, spec.id)

    def safety_problems(self, cmd: Command, limits: Limits, who: str) -> list[str]:
        lift = [f"{who}: a fixed-wing cannot {what}" for what, asked in (
            ("take off vertically", cmd.takeoff_agl_m is not None),
            ("fly a velocity setpoint", cmd.velocity_ne is not None)) if asked]
        return lift + floor_problems(cmd, limits, who) + radius_problems(cmd, limits, who)

    def swarm_limits(self, spec: VehicleSpec, params: Any) -> SwarmLimits:
        """ArduPlane's envelope (AIRSPEED_MIN/MAX) and bank limit; it stalls."""
        return SwarmLimits(params["AIRSPEED_MIN"], params["AIRSPEED_MAX"],
                           params["ROLL_LIMIT_DEG"], stalls=True)

    def swarm_problem(self, spec: VehicleSpec) -> str | None:
        if "clmax" not in spec.profile:
            return f"model {spec.model} has no clmax in its cosim profile: its stall speed " \
                   f"is unknown"
        return None


#: the autopilot setpoints (aircraft/systems/cosim_autopilot.xml) only commands
#: write: what to hold, and where
_SETPOINTS = ("cosim/ap/engage", "cosim/ap/heading-", "cosim/ap/bank-limit", "cosim/ap/alt-",
              "cosim/ap/speed-", "cosim/ap/landing", "cosim/ap/vs-")


def _envelope(lo: float | None, hi: float | None) -> str:
    """A profile's airspeed range as text, either end possibly open."""
    return f"{'0' if lo is None else f'{lo:g}'}..{'' if hi is None else f'{hi:g}'}"


FIXED_WING = FixedWing()
