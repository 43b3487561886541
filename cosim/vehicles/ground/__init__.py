"""The ground vehicle class (``class: ground``): a car or UGV as a batched
kinematic bicycle (``model``), driving on the ground, following routes
planned around the scenario's obstacles and never entering one
(``guidance``), an ArduRover on MAVLink (``mavlink``).

Scenario::

    vehicles:
      - {id: car, class: ground, wheelbase_m: 2.7, max_speed_mps: 12,
         init: {north_m: 0, east_m: 0, heading_deg: 90, airspeed_mps: 0}}
    obstacles:
      - {id: barn, polygon: [[40, -10], [40, 10], [60, 10], [60, -10]], height_m: 6}

Its own keys, all optional: ``wheelbase_m`` (2.7), ``max_speed_mps`` (15),
``accel_mps2`` (2), ``brake_mps2`` (4), ``max_steer_deg`` (35),
``steer_rate_dps`` (60), ``margin_m`` (the clearance its routes keep from
obstacles, 2), ``knows_obstacles`` (true: it plans around every obstacle
from the start; false: only around those it learns of during the run),
``scout`` (a camera name: an obstacle is learnt, and the route planned
again, once any of its corners falls in the ground footprint of that camera
on any vehicle carrying it, or the footprint's corner in it; an
``obstacle_discovered`` event says when and by whom).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import StateField, VehicleSpec
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.guidance.safety import Limits
from cosim.vehicles.base import ModelChoice, SwarmLimits, VehicleClass
from cosim.vehicles.ground.guidance import GroundGuidance
from cosim.vehicles.ground.mavlink import ArduRover
from cosim.vehicles.ground.model import SPEED_CMD, STEER_CMD, BicycleModel
from cosim.world.obstacles import Obstacle, inside

if TYPE_CHECKING:
    from cosim.world.model import World

#: key -> (default, low, high)
KEYS: dict[str, tuple[float, float, float]] = {
    "wheelbase_m": (2.7, 0.2, 20.0),
    "max_speed_mps": (15.0, 0.5, 60.0),
    "accel_mps2": (2.0, 0.1, 15.0),
    "brake_mps2": (4.0, 0.1, 15.0),
    "max_steer_deg": (35.0, 1.0, 60.0),
    "steer_rate_dps": (60.0, 1.0, 720.0),
    "margin_m": (2.0, 0.0, 50.0),
}


class Ground(VehicleClass):
    name = "ground"
    display_type = "Ground+Vehicle"
    description = "a car or UGV: batched kinematic bicycle, keeps out of obstacles"
    model_kind = "batched"
    vehicle_keys = (*KEYS, "knows_obstacles", "scout")
    state_columns = (StateField("steer_deg", None), StateField("blocked", None))
    default_camera_mount = "forward"
    camera_height_m = 1.5  # a camera on the roof
    contact_is_impact = False
    on_ground = True
    channels = (SPEED_CMD, STEER_CMD)
    mavlink = ArduRover()

    def resolve_model(self, model: str | None, aircraft_path: tuple[str, ...]) -> ModelChoice:
        if model not in (None, "car"):
            raise ConfigError(f"the ground class has one model, 'car' (its size and limits "
                              f"are the vehicle's own keys); got {model!r}")
        return ModelChoice("car")

    def parse_vehicle(self, entry: Any, path: tuple[Any, ...]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, (default, lo, hi) in KEYS.items():
            v = entry.num(key, default, lo=lo, hi=hi)
            out[key] = default if v is None else v
        known = entry.boolean("knows_obstacles", True)
        out["knows_obstacles"] = True if known is None else known
        out["scout"] = entry.string("scout", None)
        return out

    def with_world(self, spec: VehicleSpec, world: World, sections: Mapping[str, Any],
                   origin: tuple[float, float, float]) -> VehicleSpec:
        obstacles: tuple[Obstacle, ...] = world.obstacles
        frame = LocalFrame(*origin)
        n, e, _ = frame.geodetic_to_ned(spec.lat_deg, spec.lon_deg, spec.terrain_alt_m)
        known = spec.class_params.get("knows_obstacles", True)
        params = {**spec.class_params, "origin": tuple(origin),
                  "obstacles": tuple(o.polygon for o in obstacles),
                  "obstacle_ids": tuple(o.id for o in obstacles),
                  "known": tuple(bool(known) for _ in obstacles),
                  "start_ne": (float(n), float(e))}
        scout = spec.class_params.get("scout")
        cams = sections.get("cameras")
        views = [c for c in (cams.views if cams is not None else ()) if c.name == scout]
        params["scout_camera"] = views[0] if views else None
        # on the ground, whatever altitude the entry gave
        return replace(spec, alt_msl_m=spec.terrain_alt_m, class_params=params)

    def world_problems(self, spec: VehicleSpec) -> list[str]:
        p = np.array([spec.class_params["start_ne"]])
        scout = spec.class_params.get("scout")
        missing = [f"{spec.id}: scout camera {scout!r} is not in the scenario's cameras"] \
            if scout is not None and spec.class_params.get("scout_camera") is None else []
        return missing + [f"{spec.id} starts inside obstacle {oid!r}"
                for oid, poly in zip(spec.class_params["obstacle_ids"],
                                     spec.class_params["obstacles"])
                if inside(np.array(poly), p)[0]]

    def make_batch(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                   columns: Sequence[str]) -> BicycleModel:
        return BicycleModel(specs, dt_s, channels, columns)

    @property
    def commandable(self) -> bool:
        return True

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> GroundGuidance:
        return GroundGuidance(rows, frame, start_ne, channel_index, specs)

    def swarm_problem(self, spec: VehicleSpec) -> str | None:
        return None  # it drives to its goals on the ground and stops there

    def swarm_limits(self, spec: VehicleSpec, params: Any) -> SwarmLimits:
        return SwarmLimits(0.0, float(spec.class_params["max_speed_mps"]), 45.0, stalls=False)

    def command_problems(self, cmd: Command, spec: VehicleSpec, limits: Limits) -> list[str]:
        return self.safety_problems(cmd, limits, spec.id)

    def safety_problems(self, cmd: Command, limits: Limits, who: str) -> list[str]:
        out = []
        if cmd.throttle is not None:
            out.append(f"{who}: a ground vehicle takes a speed, not a throttle")
        if cmd.bank_limit_deg is not None or cmd.stall_protection is not None:
            out.append(f"{who}: bank limits and stall protection are for aircraft")
        if cmd.takeoff_agl_m is not None or cmd.land or cmd.velocity_ne is not None:
            out.append(f"{who}: take-off, landing and velocity setpoints are for aircraft "
                       f"that hover")
        return out


GROUND = Ground()
