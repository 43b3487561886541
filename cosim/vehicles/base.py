"""What a vehicle class supplies: the ``VehicleClass`` base every class
derives from (a class overrides what it has; the defaults describe a
vehicle that flies as its model says and takes no commands).

A class is found by name in the registry (``cosim.vehicles.registry``); a
scenario vehicle is of the class its entry names (``class:``), else the one
its model's cosim profile names (``class:`` in the profile), else
``jsbsim`` (a JSBSim model and nothing more). Everything outside
``cosim/vehicles/`` asks the class, never its name.

Model kinds (``model_kind``):

- ``"jsbsim"``: one JSBSim FDM per vehicle, built and trimmed in the worker
  that owns it (``cosim.vehicles.jsbsim_model``), stepped one vehicle after
  the other;
- ``"batched"``: all vehicles of the class in a worker advanced together,
  one vectorised call per substep (``BatchedModel``; ``make_batch``).

Both are stepped by the pool in lockstep and must give the same states for
any backend and worker count: a batched model must compute each vehicle's
state from that vehicle's inputs alone, with operations whose result does
not depend on the batch (elementwise arithmetic; avoid reductions across
vehicles and functions whose vectorised and scalar paths may round
differently).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from cosim.core.geo import LocalFrame
    from cosim.core.state import StateField, VehicleSpec
    from cosim.guidance.commands import Command
    from cosim.guidance.safety import Limits
    from cosim.world.model import World


@dataclass(frozen=True)
class ModelChoice:
    """The model a scenario vehicle uses, as a class resolves it: a name, the
    folder it comes from (JSBSim kinds) and the cosim profile (class data)."""

    name: str
    aircraft_dir: str = ""
    source: str = "cosim"
    profile: Mapping[str, Any] | None = None


@dataclass
class GuidanceEvent:
    """Something guidance noticed (``goal_reached``, ``waypoint_reached``, ...),
    for ``events.jsonl``; ``vehicle`` is the state row."""

    kind: str
    vehicle: int
    fields: dict[str, Any]


class Guidance(Protocol):
    """A class's guidance over the state rows of its vehicles: turns commands
    into setpoints (``command``) and follows paths at every exchange
    (``update``). It reads vehicles only through the state array and acts only
    by writing setpoints. ``labels[row]``: the active command of each row, for
    the ``command`` column of ``states.parquet``."""

    labels: list[str]

    def command(self, rows: list[int], cmd: Command, states: np.ndarray,
                sp: np.ndarray) -> None: ...

    def update(self, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]: ...


class BatchedModel(Protocol):
    """All vehicles of a batched class in one worker, built there from their
    specs (``VehicleClass.make_batch``) and advanced together.

    - ``apply(setpoints)``: a ``(m, channels)`` float64 block, NaN = leave as is;
    - ``step(nsub)``: ``nsub`` physics substeps of ``dt_s``, vectorised;
    - ``write_states(out)``: fill an ``(m, layout width)`` block, the status
      column included (``VehicleStatus``); a frozen vehicle keeps its row.

    Optionally (a model whose vehicles a camera may watch between exchanges):

    - ``step_watched(nsub, every, rows, out)``: ``step(nsub)`` ``every``
      substeps at a time, writing the states of the batch's ``rows`` after
      each piece ``c`` into ``out[c]`` (``(nsub // every, len(rows), layout
      width)``, holding those rows' states as they were), bit-identical to
      ``step(every)`` and ``write_states`` called in turn. The pool calls it
      instead of ``step`` only in exchanges where some of the batch's rows
      are watched; without it, watching them is refused.
    """

    def apply(self, setpoints: np.ndarray) -> None: ...

    def step(self, nsub: int) -> None: ...

    def write_states(self, out: np.ndarray) -> None: ...


@dataclass(frozen=True)
class SwarmLimits:
    """What the swarm controller may command one vehicle: speeds (m/s), the
    bank its turns are flown at, and whether it has a stall speed (then
    computed from its model's mass, wing area and CL_max)."""

    min_mps: float
    max_mps: float
    bank_limit_deg: float
    stalls: bool


#: JSBSim property prefixes a scenario may not write: they set the state the
#: flight model integrates (a write teleports the vehicle or corrupts the
#: integration) or the simulation itself
MOVES_BY_DECREE = ("position/", "velocities/", "attitude/", "accelerations/", "ic/",
                   "simulation/", "propagate/")
#: ... but for the fault a scenario may inject on purpose: the flight model
#: stops (JSBSim's run() fails), which the run reports naming the vehicle
FAULTS = ("simulation/terminate",)


class VehicleClass:
    """One kind of vehicle (see the module docstring). Subclass it, set
    ``name``, and override what the class has."""

    #: the registry key, as written in scenarios (``class: NAME``)
    name: str = ""
    #: one line for ``cosim models`` and the docs
    description: str = ""
    #: "jsbsim" or "batched" (see the module docstring)
    model_kind: str = "jsbsim"
    #: keys a scenario's vehicle entry may carry for this class, beyond the
    #: common ones (id, class, model, count, formation, init, random_seed)
    vehicle_keys: tuple[str, ...] = ("trim", "set")
    #: state columns it fills beyond the common ones (``StateField``s; for
    #: JSBSim kinds read from properties, for batched kinds written by the model)
    state_columns: tuple[StateField, ...] = ()
    #: whether its rows' ``fuel_kg`` column is the fuel on board (a SAGAT
    #: question of fuel is asked only of aircraft that carry it)
    logs_fuel: bool = False
    #: the camera mount of a camera that names none
    default_camera_mount: str = "nadir"
    #: how far above the vehicle's position (its state's altitude) its cameras sit
    camera_height_m: float = 0.0
    #: what replay tools call it (Tacview's object type: ``Air+FixedWing``,
    #: ``Air+Rotorcraft``, ``Ground+Vehicle``, ...), for ``cosim export``
    display_type: str = "Air"
    #: ground contact while airborne freezes the vehicle as a ground impact
    #: (aircraft); False: driving on the ground is normal (JSBSim kinds)
    contact_is_impact: bool = True
    #: a vehicle that drives on the ground: its scenario entry may leave out
    #: the altitude (the ground) and the speed (at rest)
    on_ground: bool = False
    #: a vehicle that can hover: its scenario entry may leave out the speed (at rest)
    hovers: bool = False
    #: JSBSim kinds: whether a vehicle is trimmed at its start (its entry's ``trim``)
    trims: bool = True
    #: state flag columns whose changes are events: column -> (event, on, off)
    flag_events: Mapping[str, tuple[str, str, str]] = {}

    # -- scenario --------------------------------------------------------------
    def resolve_model(self, model: str | None, aircraft_path: tuple[str, ...]
                      ) -> ModelChoice:
        """The model a vehicle entry names; ``CosimError`` (its message becomes
        a line-numbered problem) if there is none. JSBSim kinds: a JSBSim
        model on the aircraft search path."""
        from cosim.errors import ConfigError
        from cosim.vehicles.jsb import find_model

        if model is None:
            raise ConfigError("missing required key 'model'")
        m = find_model(model, aircraft_path)
        return ModelChoice(m.name, m.aircraft_dir, m.source, m.profile)

    def parse_vehicle(self, entry: Any, path: tuple[Any, ...]) -> dict[str, Any]:
        """Read the class's own keys (``vehicle_keys``) of a scenario vehicle
        entry: ``entry`` has ``num``, ``integer``, ``string``, ``boolean``,
        ``has`` and ``d`` (the mapping), and reports problems with their lines
        itself; ``ctx.err(path, message)`` reports others. The result becomes
        ``VehicleSpec.class_params``. JSBSim kinds' ``trim`` and ``set`` are read
        by the scenario loader."""
        return {}

    def check_start(self, spec: VehicleSpec) -> list[str]:
        """Problems with a vehicle's start (besides the common rules)."""
        return []

    def with_world(self, spec: VehicleSpec, world: World, sections: Mapping[str, Any],
                   origin: tuple[float, float, float]) -> VehicleSpec:
        """The vehicle given what of the scenario's ``world`` its class needs
        (``cosim.world.model.World``: the ground, targets, obstacles) and of its
        parsed ``sections`` (read only, e.g. ``cameras``; ``origin``: the
        scenario frame's lat, lon, ground altitude), usually in its
        ``class_params``; the workers see only the spec. Default: unchanged."""
        return spec

    def world_problems(self, spec: VehicleSpec) -> list[str]:
        """Problems with a vehicle's start in its world (``with_world`` done)."""
        return []

    # -- model -----------------------------------------------------------------
    def make_batch(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                   columns: Sequence[str]) -> BatchedModel:
        """Batched kinds: the model of ``specs``, built in the worker that owns
        them; ``channels`` name the setpoint columns, ``columns`` the state
        array's (``STATE_FIELDS`` first, then the run's classes' own). Vehicles
        it cannot build or trim: a ``BuildError`` naming every one, which the
        pool reports with the other classes' in one."""
        raise NotImplementedError(f"vehicle class {self.name!r} is not batched")

    # -- commands --------------------------------------------------------------
    #: setpoint channels its guidance writes (JSBSim properties for JSBSim kinds)
    channels: tuple[str, ...] = ()

    def writable_properties(self, spec: VehicleSpec) -> frozenset[str] | None:
        """The properties a scenario's ``set:`` may write on ``spec``'s
        vehicle, when the class knows them (a batched class: its channels);
        None: they are its JSBSim model's, looked up in JSBSim."""
        return None if self.model_kind == "jsbsim" else frozenset(self.channels)

    @property
    def commandable(self) -> bool:
        """Whether it takes commands (the schedule's ``command:``, MAVLink, the swarm)."""
        return False

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> Guidance:
        """Its guidance over state rows ``rows`` (``start_ne``: every row's start,
        ``specs``: every row's spec)."""
        raise NotImplementedError(f"vehicle class {self.name!r} takes no commands")

    def min_alt_agl_m(self, profile: Mapping[str, Any]) -> float:
        """How low a command may send it, above the ground."""
        return 0.0

    def command_problems(self, cmd: Command, spec: VehicleSpec, limits: Limits) -> list[str]:
        """Why the scenario's schedule must not give ``cmd`` to ``spec``'s vehicle
        (its model's envelope, then ``safety_problems``); empty: it may."""
        return [f"{spec.id} ({self.name}) takes no commands"]

    def write_problems(self, name: str, value: float, spec: VehicleSpec) -> list[str]:
        """Why a scenario's raw property write (a ``set:`` of the vehicle or of
        the schedule) must not reach ``spec``'s vehicle; empty: it may. JSBSim
        kinds: nothing that moves the vehicle by decree (``MOVES_BY_DECREE``:
        its position, velocities, attitude, initial conditions, the clock),
        which no command could do either."""
        if self.model_kind == "jsbsim" and name.startswith(MOVES_BY_DECREE) \
                and name not in FAULTS:
            return [f"{name!r} would move the vehicle by decree (position, velocity, "
                    f"attitude, initial condition or the simulation clock), bypassing the "
                    f"flight model and the rule every command path keeps; fly it there "
                    f"with a command: instead"]
        return []

    def safety_problems(self, cmd: Command, limits: Limits, who: str) -> list[str]:
        """Why ``cmd`` would fly the vehicle into the ground or ask what it cannot
        do (``cosim.guidance.safety``): asked on every command path, MAVLink's
        included; empty: safe."""
        return []

    # -- swarm -----------------------------------------------------------------
    def swarm_problem(self, spec: VehicleSpec) -> str | None:
        """Why ``spec``'s vehicle cannot fly in a consensus swarm (None: it can)."""
        return f"vehicle {spec.id!r} (class {self.name}) cannot be commanded"

    def swarm_limits(self, spec: VehicleSpec, params: Any) -> SwarmLimits:
        """The speeds the swarm controller may command ``spec``'s vehicle, from
        its MAVLink parameters ``params``: a vehicle that can stop (hover,
        stand) has no stall speed and no floor."""
        return SwarmLimits(0.0, 15.0, 45.0, stalls=False)

    # -- MAVLink ---------------------------------------------------------------
    #: how its vehicles look on MAVLink (``cosim.mavlink.personality``), None: they
    #: are not shown (``on_mavlink``: imported when first read)
    mavlink: Any = None

    def __repr__(self) -> str:
        return f"<vehicle class {self.name}>"


def on_mavlink(target: str) -> Any:
    """A class's ``mavlink`` personality, ``"module:attribute"``, imported when
    first read: a physics worker, which builds and steps vehicles but never
    speaks MAVLink, then starts without ``cosim.mavlink`` and pymavlink
    (0.2-0.3 s of its start-up)."""
    module, attr = target.split(":")
    return property(lambda self: getattr(importlib.import_module(module), attr))
