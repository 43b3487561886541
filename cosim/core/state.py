"""Picklable descriptions of vehicles and the layout of the state array.

JSBSim objects do not pickle, so workers receive ``VehicleSpec`` values and
build their own models. ``STATE_FIELDS`` are the columns every vehicle has
(its position, attitude, velocities, the autopilot's flags, ``status``),
in that order, at the same indices in every run (``STATE_INDEX``); a run's
``(n_vehicles, k)`` float64 state array has them, then the columns its
vehicle classes add (``registry.state_layout``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from cosim.core.units import FT_TO_M


class VehicleStatus(IntEnum):
    """Value of the ``status`` state column."""

    ACTIVE = 0
    GROUND_IMPACT = 1  # touched the ground while airborne: frozen
    #: a state became NaN, infinite or larger than ``MAX_STATE_ABS``: frozen
    #: at its last plausible state
    DIVERGED = 2


#: no state of a vehicle that still flies comes near this (metres, m/s,
#: degrees, newtons): a flight model that reaches it has diverged (a state
#: at 1e21 m is a blow-up on its way to NaN, not a flight)
MAX_STATE_ABS = 1e9


def plausible(states: Any) -> Any:
    """For each row of ``states`` (an ``(n, k)`` array of SI states): whether
    every value is finite and within ``MAX_STATE_ABS``."""
    import numpy as np

    a = np.asarray(states)
    with np.errstate(invalid="ignore"):
        return (np.abs(a) <= MAX_STATE_ABS).all(axis=1)


@dataclass(frozen=True)
class StateField:
    name: str
    prop: str | None  # JSBSim property read each exchange (None: computed)
    scale: float = 1.0
    #: models without this property (no cosim autopilot) read 0
    optional: bool = False


#: columns of the state array, in order
STATE_FIELDS: tuple[StateField, ...] = (
    StateField("lat_deg", "position/lat-geod-deg"),
    StateField("lon_deg", "position/long-gc-deg"),
    StateField("alt_msl_m", "position/h-sl-ft", FT_TO_M),
    StateField("alt_agl_m", "position/h-agl-ft", FT_TO_M),
    StateField("roll_deg", "attitude/phi-deg"),
    StateField("pitch_deg", "attitude/theta-deg"),
    StateField("yaw_deg", "attitude/psi-deg"),
    StateField("vn_mps", "velocities/v-north-fps", FT_TO_M),
    StateField("ve_mps", "velocities/v-east-fps", FT_TO_M),
    StateField("vd_mps", "velocities/v-down-fps", FT_TO_M),
    StateField("airspeed_mps", "velocities/vt-fps", FT_TO_M),
    StateField("alpha_deg", "aero/alpha-deg"),
    StateField("gear_force_lbs", "forces/fbz-gear-lbs"),
    StateField("throttle", "fcs/throttle-cmd-norm"),
    StateField("ap_engaged", "cosim/ap/engage", optional=True),
    StateField("bank_limit_deg", "cosim/ap/bank-limit-deg", optional=True),
    StateField("stalled", "cosim/ap/stalled", optional=True),
    StateField("stall_protection_active", "cosim/ap/stall-protection-active", optional=True),
    StateField("status", None),
)
STATE_INDEX: dict[str, int] = {f.name: i for i, f in enumerate(STATE_FIELDS)}
N_STATE = len(STATE_FIELDS)
STATUS_COL = STATE_INDEX["status"]


@dataclass(frozen=True)
class VehicleSpec:
    """Everything a worker needs to build and trim one vehicle."""

    id: str
    model: str  # model name
    aircraft_dir: str  # folder holding <model>/<model>.xml
    model_source: str  # "cosim", "jsbsim", "user"
    lat_deg: float
    lon_deg: float
    alt_msl_m: float
    heading_deg: float
    airspeed_mps: float
    terrain_alt_m: float = 0.0
    trim: bool = True
    random_seed: int = 0
    #: properties written once after trim, before the first step
    initial_props: tuple[tuple[str, float], ...] = field(default=())
    #: the model's cosim profile (autopilot attachment, clmax, envelope, ...)
    profile: dict[str, Any] = field(default_factory=dict)
    #: its vehicle class (``cosim.vehicles.registry``)
    vehicle_class: str = "jsbsim"
    #: what its class read from the scenario beyond the common keys
    class_params: dict[str, Any] = field(default_factory=dict)
    #: a rebuild: the JSBSim properties it starts from in place of a trim
    #: (``cosim.vehicles.resume``; empty: built from the fields above)
    resume: tuple[tuple[str, float], ...] = field(default=())

