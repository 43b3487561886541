"""The ``quadrotor`` class: a JSBSim multirotor (``aircraft/F450``) whose own
controller (a JSBSim system at the physics rate, in the model) holds a
position, a velocity, an altitude and a heading; cosim's guidance
(``guidance``) chooses what it holds: take-off, landing, hover, gotos that
stop on their point, waypoints, velocity setpoints. On MAVLink it is an
ArduCopter (``mavlink``). A model is of this class when its cosim profile
says ``class: quadrotor``.

It starts hovering where its entry puts it, or on the ground (motors
stopped) with ``alt_agl_m: 0``. Touching the ground is a landing, not a
crash.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import VehicleSpec
from cosim.guidance.commands import Command
from cosim.guidance.safety import Limits
from cosim.vehicles.base import SwarmLimits, VehicleClass, on_mavlink
from cosim.vehicles.quadrotor.guidance import (
    ALT,
    CHANNELS,
    ENGAGE,
    LAT,
    LON,
    POS_HOLD,
    SPEED,
    YAW,
    QuadGuidance,
)

if TYPE_CHECKING:
    from cosim.world.model import World

#: the fastest horizontal speed a command may ask for (m/s)
MAX_SPEED_MPS = 15.0


class Quadrotor(VehicleClass):
    name = "quadrotor"
    display_type = "Air+Rotorcraft"
    description = "JSBSim quadrotor with its own position/velocity/attitude control " \
                  "(ArduCopter on MAVLink)"
    model_kind = "jsbsim"
    vehicle_keys = ("set",)
    channels = CHANNELS
    default_camera_mount = "nadir"
    contact_is_impact = False
    hovers = True
    trims = False  # its own controller holds it from the first step
    mavlink = on_mavlink("cosim.vehicles.quadrotor.mavlink:ARDUCOPTER")

    def with_world(self, spec: VehicleSpec, world: World, sections: Mapping[str, Any],
                   origin: tuple[float, float, float]) -> VehicleSpec:
        """Its controller starts holding where it starts (motors on in the
        air, stopped on the ground)."""
        airborne = spec.alt_msl_m - spec.terrain_alt_m > 0.5
        if not airborne:  # standing on its legs (its profile's ground_clearance_m)
            spec = replace(spec, alt_msl_m=spec.terrain_alt_m
                           + float(spec.profile.get("ground_clearance_m", 0.0)))
        start = ((ENGAGE, 1.0 if airborne else 0.0), (POS_HOLD, 1.0),
                 (LAT, math.radians(spec.lat_deg)), (LON, math.radians(spec.lon_deg)),
                 (ALT, spec.alt_msl_m), (YAW, math.radians(spec.heading_deg)),
                 (SPEED, spec.airspeed_mps or 5.0))
        # a resolved scenario lists these already: the same pairs are not repeated
        own = tuple(p for p in spec.initial_props if p not in start)
        return replace(spec, airspeed_mps=0.0, initial_props=start + own)

    @property
    def commandable(self) -> bool:
        return True

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> QuadGuidance:
        return QuadGuidance(rows, frame, start_ne, channel_index)

    def swarm_problem(self, spec: VehicleSpec) -> str | None:
        return None  # it hovers at its goals

    def swarm_limits(self, spec: VehicleSpec, params: Any) -> SwarmLimits:
        return SwarmLimits(0.0, MAX_SPEED_MPS, 45.0, stalls=False)

    def command_problems(self, cmd: Command, spec: VehicleSpec, limits: Limits) -> list[str]:
        return self.safety_problems(cmd, limits, spec.id)

    def safety_problems(self, cmd: Command, limits: Limits, who: str) -> list[str]:
        out = []
        for spd in [cmd.airspeed_mps] + [p.airspeed_mps for p in cmd.points]:
            if spd is not None and not 0 < spd <= MAX_SPEED_MPS:
                out.append(f"{who}: a quadrotor flies at 0..{MAX_SPEED_MPS:g} m/s, "
                           f"not {spd:g}")
        if cmd.velocity_ne is not None and math.hypot(*cmd.velocity_ne) > MAX_SPEED_MPS:
            out.append(f"{who}: a velocity over {MAX_SPEED_MPS:g} m/s")
        if cmd.throttle is not None or cmd.bank_limit_deg is not None \
                or cmd.stall_protection is not None:
            out.append(f"{who}: throttle, bank limits and stall protection are for "
                       f"fixed-wings")
        alts = [(cmd.alt_m, cmd.alt_agl)] + [(p.alt_m, p.alt_agl) for p in cmd.points]
        for alt, agl in alts:
            if alt is not None and not cmd.land:
                above = alt if agl else alt - limits.terrain_alt_m
                if above < 1.0:
                    out.append(f"{who}: {above:.1f} m above the ground; a quadrotor is "
                               f"sent no lower than 1 m (land it instead)")
        return out


QUADROTOR = Quadrotor()
