"""The ``fixed_wing_batched`` class: a fixed-wing aircraft as a point mass
(``model``), every aircraft of a worker advanced together with numpy, for
runs of tens of thousands of aircraft. It flies the fixed-wing class's
command vocabulary through the same guidance (``cosim.vehicles.fixed_wing``)
and is an ArduPlane on MAVLink; only the physics is simpler.

Scenario::

    vehicles:
      - {id: uav, class: fixed_wing_batched, model: uav700, count: 10000,
         formation: {type: grid, spacing_m: 200},
         init: {north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}

The model is a fixed-wing JSBSim model with a cosim profile: its weight and
wing area (read once from the JSBSim model) and the profile's ``clmax`` give
the stall speed, ``airspeed_max_kt`` the level top speed at full thrust, and
the profile's ``max_thrust_n`` the thrust (the class refuses a model whose
profile lacks it). How closely it follows JSBSim is measured by
``benchmarks/batched_fidelity.py`` (the table is in ``benchmarks/README.md``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import StateField, VehicleSpec
from cosim.core.units import G_MPS2, KT_TO_MPS
from cosim.errors import ConfigError
from cosim.vehicles.base import Guidance, ModelChoice
from cosim.vehicles.fixed_wing import FIXED_WING, LBF_TO_N, FixedWing
from cosim.vehicles.fixed_wing.guidance import FixedWingGuidance
from cosim.vehicles.fixed_wing_batched.model import PointMassModel
from cosim.vehicles.registry import state_layout

if TYPE_CHECKING:
    from cosim.world.model import World

#: sea-level density of the standard atmosphere (kg/m^3)
RHO0 = 1.225
_FT2_TO_M2 = 0.09290304


@functools.lru_cache(maxsize=32)
def class_params(model: str, aircraft_dir: str, source: str,
                 origin: tuple[float, float, float]) -> dict[str, Any]:
    """The point mass's figures for a JSBSim model with its cosim profile (its
    weight and wing area read once from a loaded FDM) and the scenario origin:
    one dict, shared by every vehicle of the model (a scenario may hold
    100,000 of them)."""
    from cosim.vehicles.jsb import find_model, new_fdm

    info = find_model(model, (aircraft_dir,) if source == "user" else ())
    fdm = new_fdm(info, 1 / 120)
    fdm.run_ic()  # the fuel and payload load with the initial conditions
    weight = float(fdm["inertia/weight-lbs"]) * LBF_TO_N
    area = float(fdm["metrics/Sw-sqft"]) * _FT2_TO_M2
    prof = info.profile
    return {"origin": origin, "weight_n": weight,
            "vs1g_sl_mps": float(np.sqrt(2.0 * weight / (RHO0 * area * prof["clmax"]))),
            "v_max_mps": float(prof["airspeed_max_kt"]) * KT_TO_MPS,
            "thrust_accel_mps2": float(prof["max_thrust_n"]) * G_MPS2 / weight,
            "alpha_stall_deg": float(prof["alpha_stall_deg"])}


class FixedWingBatched(FixedWing):
    """The fixed-wing class with a batched point-mass model: its commands,
    limits, safety rules, swarm figures and MAVLink personality are the
    fixed-wing's (inherited); its model, guidance and start are its own."""

    name = "fixed_wing_batched"
    description = ("fixed-wing as a batched point mass (coordinated turns, climb and "
                   "speed limits, stall), the fixed-wing commands; ArduPlane on MAVLink")
    model_kind = "batched"
    vehicle_keys = ()
    #: the fixed-wing's, and its position in the scenario frame (it flies in
    #: that flat frame; guidance reads it rather than converting lat/lon)
    state_columns = (*FIXED_WING.state_columns, StateField("frame_north_m", None),
                     StateField("frame_east_m", None))
    #: a constant mass: its fuel_kg column is NaN
    logs_fuel = False
    trims = False

    def resolve_model(self, model: str | None, aircraft_path: tuple[str, ...]) -> ModelChoice:
        choice = super().resolve_model(model, aircraft_path)
        prof = choice.profile or {}
        missing = [k for k in ("clmax", "alpha_stall_deg", "airspeed_min_kt",
                               "airspeed_max_kt", "max_thrust_n") if k not in prof]
        if prof.get("class") != "fixed_wing" or missing:
            raise ConfigError(f"the fixed_wing_batched class needs a fixed-wing model whose "
                              f"cosim profile gives clmax, alpha_stall_deg, airspeed_min_kt, "
                              f"airspeed_max_kt and max_thrust_n; {choice.name} "
                              + (f"lacks {', '.join(missing)}" if missing else
                                 "is not a fixed-wing"))
        return choice

    def with_world(self, spec: VehicleSpec, world: World, sections: Mapping[str, Any],
                   origin: tuple[float, float, float]) -> VehicleSpec:
        o = (float(origin[0]), float(origin[1]), float(origin[2]))
        return replace(spec, class_params=class_params(spec.model, spec.aircraft_dir,
                                                       spec.model_source, o))

    def make_batch(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                   columns: Sequence[str]) -> PointMassModel:
        return PointMassModel(specs, dt_s, channels, columns)

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> Guidance:
        names = [f.name for f in state_layout(specs)]
        return FixedWingGuidance(len(start_ne), frame, start_ne, dict(channel_index),
                                 (names.index("frame_north_m"), names.index("frame_east_m")))

    def swarm_problem(self, spec: VehicleSpec) -> str | None:
        return None  # its profile has clmax (resolve_model)


FIXED_WING_BATCHED = FixedWingBatched()

__all__ = ["FIXED_WING_BATCHED", "FixedWingBatched", "class_params"]
