"""The JSBSim-backed model kind: one vehicle's FDM inside whichever process
owns it: build, trim, step, read raw state, detect ground contact.

Used by every backend, so all of them step FDMs the same way. Scaling to SI
units and the NaN check are done per shard in numpy
(``cosim.fdm_pool.shard``). What ground contact means comes from the
vehicle's class (``VehicleClass.contact_is_impact``); the columns its class
adds (``VehicleClass.state_columns``) are read from their properties.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import jsbsim

from cosim.core.state import STATE_FIELDS, StateField, VehicleSpec, VehicleStatus
from cosim.core.units import FT_TO_M, KT_TO_MPS
from cosim.errors import JSBSimError
from cosim.vehicles.jsb import ModelInfo, has_property, held_messages, new_fdm, release

_MPS_TO_FPS = 1.0 / FT_TO_M
_IN_TO_M = FT_TO_M / 12.0
_get = jsbsim.FGPropertyNode.get_double_value


def contact_radius_m(fdm: jsbsim.FGFDMExec) -> float:
    """The largest distance (m) from the CG to any ground-contact point of the
    model (landing gear and structural contacts such as wingtips and tail).

    Whatever the attitude, no contact point is lower than this below the CG,
    so a vehicle whose CG is higher than this above the ground is not
    touching it. Read after ``run_ic()`` (the CG is computed there). Unit
    ``i``'s point is read from its ``x-position`` (y, z) properties, under
    ``gear/unit[i]`` (a BOGEY) or ``contact/unit[i]`` (a STRUCTURE): the
    doubles ``FGLGear.get_location()`` returns, without the numpy matrix it
    builds per unit (a quarter of the cost).
    """
    pm = fdm.get_property_manager()
    cg = (fdm["inertia/cg-x-in"], fdm["inertia/cg-y-in"], fdm["inertia/cg-z-in"])
    r_in = 0.0
    for i in range(fdm.get_ground_reactions().get_num_gear_units()):
        unit = f"gear/unit[{i}]"
        if not pm.hasNode(f"{unit}/x-position"):
            unit = f"contact/unit[{i}]"
        at = [fdm[f"{unit}/{axis}-position"] for axis in "xyz"]
        r_in = max(r_in, math.dist(at, cg))  # structural frame, inches
    return r_in * _IN_TO_M


#: the autopilot property that makes a gentle touchdown a landing
LANDING_PROP = "cosim/ap/landing"
#: the fastest sink (ft/s, 3 m/s) and the largest bank (rad, 20 deg) of a landing
LANDING_SINK_FPS = 9.84
LANDING_ROLL_RAD = 0.35


class Vehicle:
    """A built, trimmed FDM with cached property nodes."""

    __slots__ = ("spec", "fdm", "_read", "_channels", "_agl", "_gear", "_landing", "status",
                 "airborne", "contact_radius_m", "contact_is_impact", "_extra")

    def __init__(self, spec: VehicleSpec, dt_s: float, channels: Sequence[str]) -> None:
        from cosim.vehicles.registry import get_class

        self.spec = spec
        cls = get_class(spec.vehicle_class)
        self.contact_is_impact = cls.contact_is_impact
        model = ModelInfo(spec.model, spec.aircraft_dir, spec.model_source, profile=spec.profile)
        fdm = new_fdm(model, dt_s)
        self.fdm = fdm
        if spec.resume:  # a rebuild: where it was, as it was
            from cosim.vehicles.resume import restore

            restore(fdm, spec)
        else:
            self._set_ic()
        #: ground contact is possible only with the CG this close to the ground
        self.contact_radius_m = contact_radius_m(fdm)
        pm = fdm.get_property_manager()
        self._read = []
        zero = None
        for f in STATE_FIELDS:
            if f.prop is not None:
                node = pm.get_node(f.prop) if has_property(fdm, f.prop) else None
                if node is None and f.optional:
                    if zero is None:  # reads as 0 for models without the property
                        zero = pm.get_node("cosim/absent", True)
                    node = zero
                if node is None:
                    raise JSBSimError(f"vehicle {spec.id!r}: model {spec.model!r} lacks {f.prop}",
                                      spec.id)
                self._read.append(node)
        self._extra = [self._node(f, pm, spec) for f in cls.state_columns]
        self._channels = []
        for name in channels:
            node = pm.get_node(name) if has_property(fdm, name) else None
            self._channels.append(node)  # None: this model lacks the property
        agl, gear = pm.get_node("position/h-agl-ft"), pm.get_node("forces/fbz-gear-lbs")
        assert agl is not None and gear is not None
        self._agl, self._gear = agl, gear
        #: a model whose autopilot can land (cosim/ap/landing): a gentle touchdown
        #: while it is set is a landing, not an impact
        self._landing = pm.get_node(LANDING_PROP) if has_property(fdm, LANDING_PROP) else None
        self.status = VehicleStatus.ACTIVE
        self.airborne = not self._touching()

    def _node(self, f: StateField, pm: Any, spec: VehicleSpec) -> tuple[Any, float]:
        """(property node, scale) of a class's own column."""
        node = pm.get_node(f.prop) if f.prop and has_property(self.fdm, f.prop) else None
        if node is None:
            raise JSBSimError(f"vehicle {spec.id!r}: model {spec.model!r} lacks {f.prop} "
                              f"(column {f.name} of class {spec.vehicle_class})", spec.id)
        return node, f.scale

    def extra_state(self) -> list[float]:
        """The class's own columns, in SI units."""
        return [node.get_double_value() * scale for node, scale in self._extra]

    def _set_ic(self) -> None:
        s, fdm = self.spec, self.fdm
        fdm["simulation/randomseed"] = float(s.random_seed)
        # latitude/longitude before altitude and speed, or the speed drifts
        fdm["ic/lat-geod-deg"] = s.lat_deg
        fdm["ic/long-gc-deg"] = s.lon_deg
        fdm["ic/terrain-elevation-ft"] = s.terrain_alt_m * _MPS_TO_FPS
        fdm["ic/h-sl-ft"] = s.alt_msl_m * _MPS_TO_FPS
        fdm["ic/psi-true-deg"] = s.heading_deg
        fdm["ic/vt-fps"] = s.airspeed_mps * _MPS_TO_FPS
        if not fdm.run_ic():
            raise JSBSimError(f"vehicle {s.id!r}: JSBSim run_ic() failed", s.id)
        fdm["propulsion/set-running"] = -1
        if s.trim:
            with held_messages() as said:  # JSBSim's reason goes into the error, once
                try:
                    fdm.do_trim(1)  # full trim
                except (jsbsim.BaseError, RuntimeError) as e:
                    agl = s.alt_msl_m - s.terrain_alt_m
                    why = "; ".join(dict.fromkeys(t for _, t in said))
                    raise JSBSimError(
                        f"vehicle {s.id!r} ({s.model}): JSBSim could not trim at "
                        f"{s.airspeed_mps:.1f} m/s TAS ({s.airspeed_mps / KT_TO_MPS:.0f} kt), "
                        f"{s.alt_msl_m:.1f} m MSL ({agl:.1f} m above the ground), heading "
                        f"{s.heading_deg:.1f} deg: {' '.join(str(e).split())}"
                        + (f" ({why})" if why else ""), s.id) from None
            release(said)
        for name, value in s.initial_props:
            fdm[name] = value

    def _landed(self) -> bool:
        """A touchdown its autopilot asked for: landing set, sinking slower
        than ``LANDING_SINK_FPS``, wings within ``LANDING_ROLL_RAD`` of level."""
        node = self._landing
        if node is None or node.get_double_value() < 0.5:
            return False
        fdm = self.fdm
        return (fdm["velocities/v-down-fps"] < LANDING_SINK_FPS
                and abs(fdm["attitude/phi-rad"]) < LANDING_ROLL_RAD)

    def _touching(self) -> bool:
        return self._gear.get_double_value() != 0.0 or self._agl.get_double_value() <= 0.0

    def apply(self, channel: int, value: float) -> None:
        """Write one setpoint channel's value into the FDM (nothing for a
        channel its model lacks). The shard finds the values to write (the
        non-NaN ones) for all its vehicles at once."""
        node = self._channels[channel]
        if node is not None:
            node.set_double_value(value)

    def step(self, n: int, check_ground: bool) -> None:
        """Run ``n`` physics substeps. With ``check_ground``, look for ground
        contact after every substep and stop at the first one (status becomes
        GROUND_IMPACT if the vehicle had been airborne)."""
        run = self.fdm.run
        if not check_ground:
            for _ in range(n):
                if not run():
                    self._run_failed()
            return
        for _ in range(n):
            if not run():
                self._run_failed()
            if self.airborne:
                if self._touching():
                    if not self.contact_is_impact or self._landed():  # as it should be
                        self.airborne = False
                        continue
                    self.status = VehicleStatus.GROUND_IMPACT
                    return
            elif not self._touching():
                self.airborne = True

    def _run_failed(self) -> None:
        # the shard adds the vehicle and the tick (VehicleError)
        raise JSBSimError("JSBSim run() returned False (the simulation was told to terminate: "
                          "simulation/terminate is set)", self.spec.id)

    def raw_state(self) -> list[float]:
        """The state properties in JSBSim's units (``STATE_FIELDS`` order, no status)."""
        return list(map(_get, self._read))
