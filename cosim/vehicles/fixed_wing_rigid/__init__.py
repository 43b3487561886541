"""The ``fixed_wing_rigid`` class: a fixed-wing aircraft flown by its own
JSBSim files compiled to a batched rigid body (``cosim.rigid``): the six
degrees of freedom, the aircraft's aerodynamics, engines and cosim
autopilot as JSBSim computes them, every aircraft of a worker advanced
together with numpy. It takes the fixed-wing class's commands and guidance
and is an ArduPlane on MAVLink; its states have attitude, so cameras work on
it as on the JSBSim tier.

Scenario::

    vehicles:
      - {id: uav, class: fixed_wing_rigid, model: uav700, count: 5000,
         formation: {type: grid, spacing_m: 200},
         init: {north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}

The model must compile: ``cosim models --check`` lists what a model's files
use that the compiler does not support (the class refuses such a model with
that list). Touching the ground ends a flight by the JSBSim tier's rule (a
landing or an impact); take-off is not modelled.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.core.state import VehicleSpec
from cosim.errors import ConfigError
from cosim.vehicles.base import ModelChoice
from cosim.vehicles.fixed_wing import FixedWing
from cosim.vehicles.fixed_wing_rigid.model import RigidBatch

if TYPE_CHECKING:
    from cosim.world.model import World


def model_files(choice_dir: str, model: str, source: str = "cosim",
                profile: Mapping[str, Any] | None = None) -> tuple[Path, Path, Path]:
    """A model's aircraft file, the systems folder and the engines folder
    the rigid tier compiles it with (those cosim gives JSBSim: for a
    ``profile`` saying ``autopilot: attach``, the model's files with the
    cosim autopilot attached)."""
    from cosim.vehicles.jsb import JSBSIM_ROOT, SYSTEMS_DIR, ModelInfo, wrapper_root

    systems = JSBSIM_ROOT / "systems" if source == "jsbsim" else SYSTEMS_DIR
    if (profile or {}).get("autopilot") == "attach":
        choice_dir = str(wrapper_root(ModelInfo(model, choice_dir, source)))
    return Path(choice_dir) / model / f"{model}.xml", systems, JSBSIM_ROOT / "engine"


class FixedWingRigid(FixedWing):
    """The fixed-wing class with a compiled rigid-body model: its commands,
    limits, safety rules, swarm figures and MAVLink personality are the
    fixed-wing's (inherited); its model is its own."""

    name = "fixed_wing_rigid"
    description = ("fixed-wing flown by its JSBSim files compiled to a batched rigid body "
                   "(6-DOF, its own aerodynamics, engine and autopilot); ArduPlane on MAVLink")
    model_kind = "batched"

    def resolve_model(self, model: str | None, aircraft_path: tuple[str, ...]) -> ModelChoice:
        from cosim.rigid.aircraft import problems

        choice = super().resolve_model(model, aircraft_path)
        prof = choice.profile or {}
        if prof.get("class") != "fixed_wing":
            raise ConfigError(f"the fixed_wing_rigid class needs a fixed-wing model; "
                              f"{choice.name} is not one")
        if prof.get("autopilot") not in ("native", "attach"):
            raise ConfigError(f"the fixed_wing_rigid class needs a model flown by the cosim "
                              f"autopilot (profile autopilot: native or attach); "
                              f"{choice.name}'s profile says {prof.get('autopilot')!r}")
        found = problems(*model_files(choice.aircraft_dir, choice.name, choice.source, prof))
        if found:
            more = f" (and {len(found) - 8} more)" if len(found) > 8 else ""
            raise ConfigError(f"the fixed_wing_rigid class cannot compile {choice.name}: "
                              + "; ".join(str(e) for e in found[:8]) + more
                              + " (cosim models --check lists them)")
        return choice

    def with_world(self, spec: VehicleSpec, world: World, sections: Mapping[str, Any],
                   origin: tuple[float, float, float]) -> VehicleSpec:
        xml, systems, engines = model_files(spec.aircraft_dir, spec.model, spec.model_source,
                                            spec.profile)
        prof = spec.profile or {}
        props: list[tuple[str, float]] = []
        if "clmax" in prof:
            props.append(("cosim/ap/clmax", float(prof["clmax"])))
        if "alpha_stall_deg" in prof:
            props.append(("cosim/ap/alpha-stall-deg", float(prof["alpha_stall_deg"])))
            props.append(("cosim/ap/alpha-recover-deg", float(prof["alpha_stall_deg"]) - 2.0))
        props += [(k, float(v)) for k, v in (prof.get("properties") or {}).items()]
        return replace(spec, class_params={"xml": str(xml), "systems_dir": str(systems),
                                           "engine_dir": str(engines),
                                           "properties": tuple(props)})

    def writable_properties(self, spec: VehicleSpec) -> frozenset[str] | None:
        """Every property of the compiled model (not the private state)."""
        from cosim.vehicles.fixed_wing_rigid.model import compiled

        xml, systems, engines = model_files(spec.aircraft_dir, spec.model, spec.model_source,
                                            spec.profile)
        return compiled(str(xml), str(systems), str(engines)).property_names \
            | frozenset(self.channels)

    def make_batch(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                   columns: Sequence[str]) -> RigidBatch:
        return RigidBatch(specs, dt_s, channels, columns)


FIXED_WING_RIGID = FixedWingRigid()

__all__ = ["FIXED_WING_RIGID", "FixedWingRigid", "model_files"]
