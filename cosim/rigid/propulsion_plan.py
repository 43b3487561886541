"""The plan ``cosim.rigid.propulsion`` compiles: the engines and the fuel
tanks of every aircraft stepped together (``Propulsion.init``,
``set_running``, ``run``, ``inputs``, ``outputs``), their state in the
caller's ``props``. ``Propulsion`` coordinates them in FGPropulsion's
order: each engine's frame (its plan answers the ``Engine`` protocol of
``cosim.rigid.propulsion_base``: the turbine's in ``turbine_plan``, the
piston's in ``piston_plan``), the fuel it burns from its feed tanks, the
sums of their forces and moments, the total fuel; a frame every engine of
which can run as one loop (the turbine's running frame) runs so. What it
computes is said in ``cosim.rigid.propulsion``; this module holds no XML
and no engine's arithmetic."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cosim.rigid.piston_plan import Piston
from cosim.rigid.propulsion_base import (
    CG,
    CUTOFF,
    FLIGHT,
    FREEZE,
    STARTER,
    Engine,
    EngineLoop,
    PropulsionError,
    Tank,
)
from cosim.rigid.turbine_plan import Turbine

__all__ = ["Piston", "Propulsion", "PropulsionError", "Tank", "Turbine"]

_FORCES = ("forces/fbx-prop-lbs", "forces/fby-prop-lbs", "forces/fbz-prop-lbs")
_MOMENTS = ("moments/l-prop-lbsft", "moments/m-prop-lbsft", "moments/n-prop-lbsft")
_TOTAL = "propulsion/total-fuel-lbs"


@dataclass(frozen=True)
class Propulsion:
    """The compiled ``<propulsion>``: engines and tanks, a stateless plan."""

    source: str
    engines: tuple[Turbine | Piston, ...]
    tanks: tuple[Tank, ...]

    @property
    def lateral_trim(self) -> bool:
        """Whether a thruster rolls and yaws the airframe in level flight (a
        propeller's torque and P-factor), so that a level trim balances it
        with aileron, rudder and bank."""
        return any(e.rolls_and_yaws for e in self.engines)

    @property
    def inputs(self) -> frozenset[str]:
        names: set[str] = {*CG, *FLIGHT, FREEZE, "aero/qbar-psf"}
        for e in self.engines:
            names |= e.inputs
        return frozenset(names)

    @property
    def outputs(self) -> frozenset[str]:
        names: set[str] = {*_FORCES, *_MOMENTS, _TOTAL}
        for e in self.engines:
            names |= e.outputs
        return frozenset(names | {t.contents_key for t in self.tanks})

    def init(self, props: dict[str, np.ndarray], n: int) -> None:
        """Every engine running (``propulsion/set-running`` = -1), every
        tank at its initial contents, the settings at the file's values."""
        zeros = np.zeros(n)
        for k in (FREEZE, CUTOFF, STARTER):
            props.setdefault(k, zeros.copy())
        for t in self.tanks:
            props[t.contents_key] = np.full(n, t.initial_lbs)
        props[_TOTAL] = self._total(props, n)
        for k in (*_FORCES, *_MOMENTS):
            props[k] = zeros.copy()
        for e in self.engines:
            e.init(props, n)

    def set_running(self, props: dict[str, np.ndarray]) -> None:
        """``propulsion/set-running`` = -1 written after the initial
        conditions' frame (``place``), as JSBSim 1.3 does it: no engine cut
        off, then each engine's ``InitRunning`` and
        ``FGPropulsion::GetSteadyState`` (``Engine.set_running``), the last
        engine's thrust carried to the next, as JSBSim compares them."""
        n = len(props[CG[0]])
        props[CUTOFF] = np.zeros(n)
        current = np.zeros(n)  # JSBSim's, kept from one engine to the next
        for e in self.engines:
            current = e.set_running(props, current, self.source, len(self.engines))

    def _total(self, props: dict[str, np.ndarray], n: int) -> np.ndarray:
        if not self.tanks:
            return np.zeros(n)
        total = 0.0 + props[self.tanks[0].contents_key]
        for t in self.tanks[1:]:
            total = total + props[t.contents_key]
        return total

    def run(self, props: dict[str, np.ndarray], dt_s: float, *, trimming: bool = False,
            loop: bool = True) -> None:
        """One physics frame of every aircraft (``dt_s`` 0: a frame of
        suspended integration, JSBSim's trim phase; ``trimming``: while
        JSBSim's trim status is set, no fuel is consumed, as if frozen).
        The common case runs as one loop an engine, unless ``loop`` is
        false: the numpy steps, the same doubles."""
        if not dt_s >= 0:
            raise ValueError(f"dt_s must be 0 or more, got {dt_s}")
        n = len(props[CG[0]])
        if loop and dt_s > 0.0 and not trimming and self._running(props):
            self._run_loop(props, dt_s, n)
            props[_TOTAL] = self._total(props, n)
            return
        cg = [props[k] for k in CG]
        frozen = np.ones(n, dtype=bool) if trimming else props[FREEZE] != 0.0
        force: list[np.ndarray | None] = [None, None, None]
        moment: list[np.ndarray | None] = [None, None, None]
        for e in self.engines:
            rate, fb, mb = e.frame(props, dt_s, cg, self.source, len(self.engines))
            self._burn(e, props, dt_s, rate, frozen)
            for acc, part in ((force, fb), (moment, mb)):
                for k in range(3):
                    a, b = acc[k], part[k]
                    acc[k] = b if a is None else a if b is None else a + b
        for keys, acc in ((_FORCES, force), (_MOMENTS, moment)):
            for k in range(3):
                got = acc[k]
                props[keys[k]] = np.zeros(n) if got is None else got
        props[_TOTAL] = self._total(props, n)

    @cached_property
    def _loop_plan(self) -> tuple[tuple[EngineLoop, np.ndarray], ...] | None:
        """Per engine, its running frame's loop and which of the sums an
        engine before it gave a term (``have``); None when an engine is not
        fed by exactly one tank, has no loop, or there is no engine: the
        numpy steps always."""
        if not self.engines or any(len(e.feeds) != 1 for e in self.engines):
            return None
        loops = [e.loop(self.tanks[e.feeds[0]], len(self.tanks)) for e in self.engines]
        plan = []
        have = np.zeros(6, dtype=np.bool_)
        for loop in loops:
            if loop is None:
                return None
            plan.append((loop, have.copy()))
            have |= loop.terms
        return tuple(plan)

    def _running(self, props: dict[str, np.ndarray]) -> bool:
        """Whether the frame is the loop's: every engine's loop ready, none
        cut off or starting."""
        return self._loop_plan is not None and not bool(props[CUTOFF].any()) and not bool(
            props[STARTER].any()) and all(loop.ready(props) for loop, _ in self._loop_plan)

    def _run_loop(self, props: dict[str, np.ndarray], dt_s: float, n: int) -> None:
        """``run``'s common case: each engine's loop in turn (a tank two
        engines share drained by the first before the second reads it)."""
        assert self._loop_plan is not None
        acc = tuple(np.empty(n) for _ in range(6))
        for loop, have in self._loop_plan:
            loop.run(props, dt_s, have, acc)
        props.update(zip((*_FORCES, *_MOMENTS), acc))

    def _burn(self, e: Engine, props: dict[str, np.ndarray], dt_s: float,
              rate: np.ndarray, frozen: np.ndarray) -> None:
        """``FGPropulsion::ConsumeFuel`` for one engine at ``rate`` pounds a
        second (nothing while frozen): an engine whose feed tanks hold no
        usable fuel starves (a turbine's next frame turns it off, a piston's
        gets no fuel) and burns nothing."""
        if bool(frozen.all()):
            return
        feeds = [self.tanks[i] for i in e.feeds]
        has = [props[t.contents_key] > t.unusable_lbs for t in feeds]
        best = np.full(len(rate), np.inf)
        for t, h in zip(feeds, has):
            if 1 <= t.priority <= len(self.tanks):
                best = np.where(h, np.minimum(best, t.priority), best)
        starved_key = "_" + e.key("starved")
        starved = np.isinf(best)
        props[starved_key] = np.where(frozen, props[starved_key], starved)
        live = ~frozen & ~starved
        if bool(starved.any()):
            e.starve(props, live | frozen)
        burned = rate * dt_s
        ff_key, used_key = e.key("fuel-flow-rate-pps"), e.key("fuel-used-lbs")
        props[ff_key] = np.where(live, rate, props[ff_key])
        props[used_key] = np.where(live, props[used_key] + burned, props[used_key])
        feeding = [h & (best == t.priority) for t, h in zip(feeds, has)]
        if len(feeds) == 1:
            each = burned
        else:
            count = feeding[0].astype(np.float64)
            for f in feeding[1:]:
                count = count + f
            with np.errstate(divide="ignore", invalid="ignore"):  # none fed: not drained
                each = burned / count
        for t, f in zip(feeds, feeding):
            c = props[t.contents_key]
            left = c - each
            drained = np.where(left >= t.unusable_lbs, left, np.minimum(c, t.unusable_lbs))
            props[t.contents_key] = np.where(f & live, drained, c)
