"""What the propulsion plan (``cosim.rigid.propulsion_plan``) and its
engines' plans (``turbine_plan``, ``piston_plan``) share: the ``Engine``
protocol each engine's plan answers, the fuel ``Tank``, the ``props`` keys
of the commands and flight inputs they read, JSBSim's indexed property
names and ``PropulsionError``. It computes nothing and imports no engine."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from cosim.errors import CosimError

CG = ("inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in")
FLIGHT = ("atmosphere/sigma", "atmosphere/T-R")
FREEZE = "propulsion/fuel_freeze"
CUTOFF, STARTER = "propulsion/cutoff_cmd", "propulsion/starter_cmd"
POSITION = ("x-position", "y-position", "z-position")

#: an engine's body forces and moments about the CG (None: a term JSBSim's
#: zero products leave out)
Terms = list[np.ndarray | None]


def indexed(base: str, i: int) -> str:
    """JSBSim's property name of index ``i`` as its tree lists it."""
    head, _, tail = base.partition("/#")
    return f"{head}{'' if i == 0 else f'[{i}]'}{tail}"


class PropulsionError(CosimError):
    """A compiled propulsion plan met a state it does not compile (an
    engine without fuel, which JSBSim would shut down)."""


@dataclass(frozen=True)
class Tank:
    """One fuel tank: where it is and where its contents live in ``props``."""

    index: int
    location_in: tuple[float, float, float]
    capacity_lbs: float
    initial_lbs: float
    unusable_lbs: float
    priority: int

    @property
    def contents_key(self) -> str:
        return indexed("propulsion/tank/#/contents-lbs", self.index)


class EngineLoop(Protocol):
    """An engine's running frame compiled to one loop over the aircraft."""

    #: which of the six sums (forces x, y, z, moments l, m, n) it adds a term to
    terms: np.ndarray

    def ready(self, props: dict[str, np.ndarray]) -> bool:
        """Whether every aircraft's engine is in the state the loop computes."""
        ...

    def run(self, props: dict[str, np.ndarray], dt_s: float, have: np.ndarray,
            acc: tuple[np.ndarray, ...]) -> None:
        """The frame, its terms added to ``acc`` where ``have`` says an
        engine before it gave one."""
        ...


class Engine(Protocol):
    """What ``Propulsion`` asks of an engine and its thruster, in
    FGPropulsion's order: the fuel it burns is ``Propulsion``'s (its tanks)."""

    @property
    def index(self) -> int: ...

    @property
    def feeds(self) -> tuple[int, ...]:
        """The tanks it burns from."""
        ...

    def key(self, leaf: str) -> str:
        """Its property ``propulsion/engine[i]/<leaf>``."""
        ...

    @property
    def rolls_and_yaws(self) -> bool:
        """Whether its thruster rolls and yaws the airframe in level flight
        (a propeller's torque and P-factor): the trim then balances it with
        aileron, rudder and bank."""
        ...

    @property
    def inputs(self) -> frozenset[str]: ...

    @property
    def outputs(self) -> frozenset[str]: ...

    def init(self, props: dict[str, np.ndarray], n: int) -> None:
        """The engine running, as ``propulsion/set-running`` = -1 leaves it."""
        ...

    def set_running(self, props: dict[str, np.ndarray], current: np.ndarray, source: str,
                    engines: int) -> np.ndarray:
        """``InitRunning`` and ``GetSteadyState`` for this engine
        (``current``: the last engine's thrust; returns this one's)."""
        ...

    def frame(self, props: dict[str, np.ndarray], dt_s: float, cg: list[np.ndarray],
              source: str, engines: int) -> tuple[np.ndarray, Terms, Terms]:
        """One frame of the engine and its thruster: the fuel it would burn
        (pounds a second), its body forces and moments."""
        ...

    def starve(self, props: dict[str, np.ndarray], fed: np.ndarray) -> None:
        """What starving does to it where ``fed`` is false."""
        ...

    def loop(self, tank: Tank, tanks: int) -> EngineLoop | None:
        """Its running frame as one loop, fed by ``tank`` alone (None: none)."""
        ...
