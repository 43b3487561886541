"""The turbine engine and its direct thruster of ``cosim.rigid.propulsion``'s
plan: JSBSim 1.3's ``FGTurbine::Calculate`` (its phases, its trim, its
steady state) and ``FGForce`` for every aircraft at once, their state in the
caller's ``props`` (what they compute, refuse and leave out is said in
``cosim.rigid.propulsion``). This module holds no XML; the fuel it burns is
``Propulsion``'s.

A frame's common case, time passing (``dt_s`` > 0) outside a trim with
every engine of every aircraft running, none cut off or starting, each
engine fed by one tank, runs as one numba loop an engine (``_turbine``:
the turbine, its thruster, the fuel it burns and its share of the forces
and moments, one aircraft at a time; ``TurbineLoop``); any other frame runs
the numpy steps of ``Turbine.frame`` for every aircraft. Both compute the
same doubles, operation for operation (numpy's ``maximum`` and ``minimum``
as numpy has them, NaN and signed zeros included; the thrust tables are
evaluated before the loop), and leave the same keys, so a frame may take
either."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from cosim.rigid.functions import Compiled
from cosim.rigid.propulsion_base import (
    CG,
    CUTOFF,
    FLIGHT,
    FREEZE,
    POSITION,
    STARTER,
    PropulsionError,
    Tank,
    Terms,
    indexed,
)
from cosim.rigid.units import IN_TO_FT

#: FGTurbine's phases (as floats: they live in props)
_OFF, _RUN, _SPINUP, _START, _TRIM = 0.0, 1.0, 2.0, 3.0, 4.0


def _seek(v: np.ndarray, target: np.ndarray | float, up: np.ndarray | float,
          down: np.ndarray | float, dt_s: float, den: np.ndarray | None = None) -> np.ndarray:
    """``FGTurbine::Seek``: ``v`` moved towards ``target`` by dt x ``up``
    or dt x ``down`` (each divided by ``den`` first when given), never past
    it. A rate's sign is exact in every product and quotient, so v - dt x
    (down / den) is v + dt x (-down / den) to the bit."""
    above = v > target
    if den is None:
        step = np.where(above, -dt_s * down, dt_s * up)
    else:
        step = dt_s * (np.where(above, -down, up) / den)
    moved = v + step
    return np.where(above, np.maximum(moved, target), np.minimum(moved, target))


def _position(tp: np.ndarray) -> np.ndarray:
    """The throttle position an engine runs at (``FGTurbine::Calculate``:
    above 1 is augmentation, taken off)."""
    if bool((tp > 1.0).any()):
        over = tp - 1.0
        tp = np.where(over > 0.0, tp - over, tp)
    return tp


def _times(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    return None if a is None or b is None else a * b


def _minus(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """a - b, a missing term a zero (0 - b is -b exactly)."""
    if b is None:
        return a
    return -b if a is None else a - b


# ------------------------------------------- the running frame as a loop --

_jit = numba.njit(cache=True, error_model="numpy", nogil=True)


@_jit
def _maximum(a: float, b: float) -> float:
    """``np.maximum``: NaN if either is, ``b`` when they are equal (+0, -0)."""
    return a if a > b or a != a else b


@_jit
def _minimum(a: float, b: float) -> float:
    """``np.minimum``: NaN if either is, ``b`` when they are equal."""
    return a if a < b or a != a else b


@_jit
def _seek_one(v: float, target: float, up: float, down: float, dt_s: float, den: float
              ) -> float:
    """``_seek`` of one value with a divisor: v + dt x (-down / den) or
    dt x (up / den), never past the target."""
    if v > target:
        return _maximum(v + dt_s * (-down / den), target)
    return _minimum(v + dt_s * (up / den), target)


@_jit
def _moment(first: bool, second: bool, a: float, b: float) -> float:
    """``_minus(a, b)`` of two products, each there when its force is."""
    if first and second:
        return a - b
    return a if first else -b


@_jit
def _sum(have: bool, there: bool, before: float, term: float) -> float:
    """``run``'s sum over the engines: the term added to those of the
    engines before it (``have``), the first one kept, 0 where no engine
    gives one (scalars: an array passed to a call costs its reference
    count every aircraft)."""
    if there:
        return before + term if have else term
    return before if have else 0.0


#: the rows of ``_turbine``'s constants
(_C_MIL, _C_IDLE_N1, _C_IDLE_N2, _C_N1_FACTOR, _C_N2_FACTOR, _C_TSFC, _C_BLEED, _C_IDLE_FF,
 _C_D2U, _C_D2D, _C_D1U, _C_D1D, _C_UNUSABLE, _C_FEEDS, _C_AX, _C_AY, _C_AZ) = range(17)


@_jit
def _turbine(dt_s: float, c: np.ndarray, have: np.ndarray, ins: tuple, outs: tuple,
             acc: tuple) -> None:
    """One running engine of every aircraft, what ``Propulsion._engine``
    computes with the slow phases, the trim and the multi-tank feeds left
    out: ``_calculate``, the reverser, ``_burn`` with one feed tank and
    the thruster's force and moment, added to ``acc`` (forces then moments)
    where ``have`` says an engine before this one gave a term (else its
    term, else 0). ``ins``: throttle, idle and mil fractions, N1, N2,
    N2norm, fuel flow (pph), sigma, T-R, reverser angle, fuel freeze,
    starved, phase, fuel flow (pps), fuel used, the feed tank's contents,
    the CG and the acting location; ``outs``: N1, N2, N2norm, TSFC, fuel
    flow (pph), thrust, starved, phase, fuel flow (pps), fuel used, contents."""
    (throttle, idle_fraction, mil_fraction, n1, n2, norm, pph, sigma, t_r, reverser, freeze,
     starved, phase, ff, used, contents, cg_x, cg_y, cg_z, x, y, z) = ins
    (n1_out, n2_out, norm_out, tsfc_out, pph_out, thrust_out, starved_out, phase_out, ff_out,
     used_out, contents_out) = outs
    milthrust, idle_n1, idle_n2 = c[_C_MIL], c[_C_IDLE_N1], c[_C_IDLE_N2]
    n1_factor, n2_factor, bleed = c[_C_N1_FACTOR], c[_C_N2_FACTOR], c[_C_BLEED]
    unusable, fed = c[_C_UNUSABLE], c[_C_FEEDS] != 0.0
    d2u, d2d, d1u, d1d = c[_C_D2U], c[_C_D2D], c[_C_D1U], c[_C_D1D]
    force_x, force_y, force_z, moment_l, moment_m, moment_n = acc
    h_fx, h_fy, h_fz, h_l, h_m, h_n = have[0], have[1], have[2], have[3], have[4], have[5]
    ax, ay, az = c[_C_AX], c[_C_AY], c[_C_AZ]
    px, py, pz = ax != 0.0, ay != 0.0, az != 0.0
    pph_up, pph_down = dt_s * 1000.0, -dt_s * 10000.0
    for i in range(len(throttle)):
        # _position, then _calculate's running engine
        tp = throttle[i]
        over = tp - 1.0
        if over > 0.0:
            tp = tp - over
        idle = milthrust * idle_fraction[i]
        mil = (milthrust - idle) * mil_fraction[i]
        m = 1.0 - _minimum(1.0, norm[i] + 0.1)
        den = 1.0 + 3.0 * m * m * m + (1.0 - sigma[i])
        run_n2 = _seek_one(n2[i], idle_n2 + tp * n2_factor, d2u, d2d, dt_s, den)
        run_n1 = _seek_one(n1[i], idle_n1 + tp * n1_factor, d1u, d1d, dt_s, den)
        n2norm = (run_n2 - idle_n2) / n2_factor
        thrust = idle + mil * n2norm * n2norm
        rest = 1.0 - n2norm
        tsfc = c[_C_TSFC] * math.sqrt(t_r[i] / 389.7) * (0.84 + rest * rest)
        want = thrust * tsfc  # _seek without a divisor
        flow = pph[i]
        if flow > want:
            flow = _maximum(flow + pph_down, want)
        else:
            flow = _minimum(flow + pph_up, want)
        flow = _maximum(flow, c[_C_IDLE_FF])
        if bleed != 1.0:
            thrust = thrust * bleed
        if reverser[i] != 0.0:  # cos(0) x thrust is thrust
            thrust = math.cos(reverser[i]) * thrust
        n1_out[i], n2_out[i], norm_out[i], tsfc_out[i] = run_n1, run_n2, n2norm, tsfc
        pph_out[i], thrust_out[i] = flow, thrust
        # _burn with one feed tank (its priority usable: fed)
        frozen = freeze[i] != 0.0
        fuel = contents[i]
        has = fuel > unusable
        starving = not (has and fed)
        starved_out[i] = starved[i] if frozen else (1.0 if starving else 0.0)
        live = not frozen and not starving
        phase_out[i] = phase[i] if live or frozen else _OFF
        rate = flow / 3600.0
        burned = rate * dt_s
        ff_out[i] = rate if live else ff[i]
        used_out[i] = used[i] + burned if live else used[i]
        if live:  # feeding: it has fuel and the best priority
            left = fuel - burned
            fuel = left if left >= unusable else _minimum(fuel, unusable)
        contents_out[i] = fuel
        # FGForce, as _engine: a zero of the transform gives no term
        fx, fy, fz = thrust * ax, thrust * ay, thrust * az
        arm_x = IN_TO_FT * (cg_x[i] - x[i])
        arm_y = IN_TO_FT * (y[i] - cg_y[i])
        arm_z = IN_TO_FT * (cg_z[i] - z[i])
        force_x[i] = _sum(h_fx, px, force_x[i], fx)
        force_y[i] = _sum(h_fy, py, force_y[i], fy)
        force_z[i] = _sum(h_fz, pz, force_z[i], fz)
        moment_l[i] = _sum(h_l, py or pz, moment_l[i], _moment(pz, py, arm_y * fz, arm_z * fy))
        moment_m[i] = _sum(h_m, px or pz, moment_m[i], _moment(px, pz, arm_z * fx, arm_x * fz))
        moment_n[i] = _sum(h_n, px or py, moment_n[i], _moment(py, px, arm_x * fy, arm_y * fx))


@dataclass(frozen=True)
class Turbine:
    """One turbine engine and its direct thruster, compiled."""

    index: int
    name: str
    milthrust_lbs: float
    idle_n1: float
    idle_n2: float
    n1_factor: float
    n2_factor: float
    tsfc: float
    one_minus_bleed: float
    idle_ff_pph: float
    #: FGSpoolUp's delays: N2 up, N2 down, N1 up, N1 down
    delays: tuple[float, float, float, float]
    #: the phases off, spin-up and start: N1's and N2's spin-down divisors,
    #: spin-up rates, ignition and start rates, and whether the engine windmills
    spindown: tuple[float, float]
    spinup: tuple[float, float]
    ignition: tuple[float, float]
    start_rate: tuple[float, float]
    windmill: bool
    idle_thrust: Compiled
    mil_thrust: Compiled
    feeds: tuple[int, ...]
    location_in: tuple[float, float, float]
    #: the thruster's first column of FGForce's custom transform
    axis: tuple[float, float, float]

    def key(self, leaf: str) -> str:
        return indexed(f"propulsion/engine/#/{leaf}", self.index)

    @property
    def throttle_key(self) -> str:
        return indexed("fcs/throttle-pos-norm/#", self.index)

    @property
    def rolls_and_yaws(self) -> bool:
        """A direct thruster along its axis: no torque rolls the airframe."""
        return False

    @property
    def inputs(self) -> frozenset[str]:
        return self.idle_thrust.inputs | self.mil_thrust.inputs | {self.throttle_key}

    @property
    def outputs(self) -> frozenset[str]:
        k = self.key
        return frozenset({k(x) for x in ("thrust-lbs", "n1", "n2", "fuel-flow-rate-pps",
                                         "fuel-used-lbs", "tsfc", "IdleThrust", "MilThrust")}
                         | {"_" + k(x) for x in ("fuel-flow-pph", "n2norm", "phase", "running",
                                                 "starved")})

    def init(self, props: dict[str, np.ndarray], n: int) -> None:
        """Running at full throttle's N1 and N2, the fuel flow at its steady
        value when the flight inputs are in ``props`` (else the idle flow)."""
        zeros = np.zeros(n)
        props[self.key("n1")] = np.full(n, self.idle_n1 + 1.0 * self.n1_factor)
        props[self.key("n2")] = np.full(n, self.idle_n2 + 1.0 * self.n2_factor)
        props["_" + self.key("n2norm")] = (props[self.key("n2")] - self.idle_n2) / self.n2_factor
        props["_" + self.key("phase")] = np.full(n, _RUN)
        props["_" + self.key("running")] = np.ones(n)
        props["_" + self.key("starved")] = zeros.copy()
        for k in ("thrust-lbs", "fuel-flow-rate-pps", "fuel-used-lbs", "tsfc",
                  "IdleThrust", "MilThrust"):
            props[self.key(k)] = zeros.copy()
        props[self.key("reverser-angle-rad")] = zeros.copy()
        for k, x in zip(POSITION, self.location_in):
            props[self.key(k)] = np.full(n, x)
        props["_" + self.key("fuel-flow-pph")] = self._steady_flow(props, n)

    def set_running(self, props: dict[str, np.ndarray], current: np.ndarray, source: str,
                    engines: int) -> np.ndarray:
        """``propulsion/set-running`` = -1 written after the initial
        conditions' frame (``place``), as JSBSim 1.3 does it, for this engine:
        ``FGTurbine::InitRunning`` (no longer cut off; running unless starved;
        N1 and N2 at the last frame's throttle; its frame without time moves
        nothing; the phase left running), then ``FGPropulsion::GetSteadyState``:
        the engine stepped at 0.5 s with the throttle at 1 and no fuel burned
        until its thrust has moved by less than 1e-4 lbf 121 steps running
        (at most 6,000 steps). A running engine so ends at its full-throttle
        N1, N2 and fuel flow, from which the next frame spools it down to the
        throttle's; a starved one winds down, off. The thrust is left at its
        steady value; the accelerations stay those of the initial conditions'
        frame (JSBSim runs no other model; it also sums the steady thrust into
        ``forces/fbx-prop-lbs``, which the next frame writes before reading)."""
        n = len(current)
        full = np.ones(n)
        starved = props["_" + self.key("starved")] != 0.0
        tp = _position(props[self.throttle_key])
        props[self.key("n2")] = self.idle_n2 + tp * self.n2_factor
        props[self.key("n1")] = self.idle_n1 + tp * self.n1_factor
        props["_" + self.key("running")] = np.where(starved, 0.0, 1.0)
        props["_" + self.key("phase")] = np.where(starved, _OFF, _RUN)
        _, _, idle, mil = self._thrusts(props)
        keys = [self.key(k) for k in ("n1", "n2", "tsfc")] + [
            "_" + self.key(k) for k in ("n2norm", "fuel-flow-pph", "phase", "running")] + [
            STARTER]
        count = np.zeros(n, dtype=np.int64)
        done = np.zeros(n, dtype=bool)
        for _ in range(6000):
            if bool(done.all()):
                break
            before = [props[k].copy() for k in keys]
            thrust = self._calculate(props, 0.5, full, idle, mil, source, engines)[0]
            reverser = props[self.key("reverser-angle-rad")]
            if bool(reverser.any()):
                thrust = np.cos(reverser) * thrust
            for k, b in zip(keys, before, strict=True):  # a steady aircraft stopped
                props[k] = np.where(done, b, props[k])
            last, current = current, np.where(done, current, thrust)
            count = np.where(done, count, np.where(np.abs(last - current) < 1e-4,
                                                   count + 1, 0))
            done = done | (count > 120)
        props[self.key("thrust-lbs")] = current
        return current

    def frame(self, props: dict[str, np.ndarray], dt_s: float, cg: list[np.ndarray],
              source: str, engines: int) -> tuple[np.ndarray, Terms, Terms]:
        """A frame of the turbine (its trim when ``dt_s`` is 0) and its
        thruster: the fuel flow it burns (pounds a second), the body forces
        and the moments about the CG."""
        tp = _position(props[self.throttle_key])
        props[self.key("IdleThrust")], props[self.key("MilThrust")], idle, mil = \
            self._thrusts(props)
        pph_key = "_" + self.key("fuel-flow-pph")
        if dt_s == 0.0:
            thrust = self._trim(props, tp, idle, mil)
            pph = props[pph_key]
        else:
            thrust, pph = self._calculate(props, dt_s, tp, idle, mil, source, engines)
        reverser = props[self.key("reverser-angle-rad")]
        if bool(reverser.any()):  # cos(0) x thrust is thrust
            thrust = np.cos(reverser) * thrust
        props[self.key("thrust-lbs")] = thrust
        # FGForce: the body force and the moment about the CG, the arm from
        # the structural frame to body axes in feet. A zero of the transform
        # (known when compiled) gives no force (None), as JSBSim's zero
        # products add nothing, and no term of the moment
        fb = [None if a == 0.0 else thrust * a for a in self.axis]
        need = [any(fb[j] is not None for j in range(3) if j != k) for k in range(3)]
        x, y, z = (props[self.key(k)] for k in POSITION)
        arms = [IN_TO_FT * (cg[0] - x) if need[0] else None,
                IN_TO_FT * (y - cg[1]) if need[1] else None,
                IN_TO_FT * (cg[2] - z) if need[2] else None]
        mb = [_minus(_times(arms[1], fb[2]), _times(arms[2], fb[1])),
              _minus(_times(arms[2], fb[0]), _times(arms[0], fb[2])),
              _minus(_times(arms[0], fb[1]), _times(arms[1], fb[0]))]
        return pph / 3600.0, fb, mb

    def starve(self, props: dict[str, np.ndarray], fed: np.ndarray) -> None:
        """A starved turbine's next frame begins off."""
        phase_key = "_" + self.key("phase")
        props[phase_key] = np.where(fed, props[phase_key], _OFF)

    def loop(self, tank: Tank, tanks: int) -> TurbineLoop:
        """Its running frame as ``_turbine``, fed by ``tank`` alone."""
        return TurbineLoop(self, tank, tanks)

    def _thrusts(self, props: dict[str, np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The ``IdleThrust`` and ``MilThrust`` functions' fractions, the
        idle thrust and the military thrust above it (lbs)."""
        idle_fraction = self.idle_thrust.evaluate(props)
        mil_fraction = self.mil_thrust.evaluate(props)
        idle = self.milthrust_lbs * idle_fraction
        return idle_fraction, mil_fraction, idle, (self.milthrust_lbs - idle) * mil_fraction

    def _steady_flow(self, props: dict[str, np.ndarray], n: int) -> np.ndarray:
        """The fuel flow JSBSim's steady state at full throttle leaves: the
        target thrust x TSFC at N2norm 1, never below the idle flow."""
        needed = self.idle_thrust.inputs | self.mil_thrust.inputs | {"atmosphere/T-R"}
        if not needed <= set(props):
            return np.full(n, self.idle_ff_pph)
        n2norm = (self.idle_n2 + 1.0 * self.n2_factor - self.idle_n2) / self.n2_factor
        _, _, idle, mil = self._thrusts(props)
        thrust = idle + mil * n2norm * n2norm
        tsfc = self.tsfc * np.sqrt(props["atmosphere/T-R"] / 389.7) * (
            0.84 + (1 - n2norm) * (1 - n2norm))
        return np.maximum(thrust * tsfc, self.idle_ff_pph)

    def _calculate(self, props: dict[str, np.ndarray], dt_s: float,
                   tp: np.ndarray, idle: np.ndarray, mil: np.ndarray, source: str,
                   engines: int) -> tuple[np.ndarray, np.ndarray]:
        """A frame of ``FGTurbine::Calculate`` (dt > 0): leaves N1, N2, the
        N2 fraction, TSFC and fuel flow in props, returns the thrust (before
        the thruster) and the fuel flow."""
        phase_key, cutoff, starter = "_" + self.key("phase"), props[CUTOFF], props[STARTER]
        slow = bool(cutoff.any()) or bool(starter.any()) or bool(
            (props[phase_key] != _RUN).any())
        if slow:
            self._leave_trim(props, tp, source, engines)
        norm_key, pph_key = "_" + self.key("n2norm"), "_" + self.key("fuel-flow-pph")
        n1, n2 = props[self.key("n1")], props[self.key("n2")]
        # FGSpoolUp with the N2norm of the previous frame, the same for N1 and N2
        m = 1.0 - np.minimum(1.0, props[norm_key] + 0.1)
        den = 1 + 3 * m * m * m + (1 - props["atmosphere/sigma"])
        d2u, d2d, d1u, d1d = self.delays
        run_n2 = _seek(n2, self.idle_n2 + tp * self.n2_factor, d2u, d2d, dt_s, den)
        run_n1 = _seek(n1, self.idle_n1 + tp * self.n1_factor, d1u, d1d, dt_s, den)
        n2norm = (run_n2 - self.idle_n2) / self.n2_factor
        thrust = idle + mil * n2norm * n2norm
        rest = 1 - n2norm
        tsfc = self.tsfc * np.sqrt(props["atmosphere/T-R"] / 389.7) * (0.84 + rest * rest)
        pph = np.maximum(_seek(props[pph_key], thrust * tsfc, 1000.0, 10000.0, dt_s),
                         self.idle_ff_pph)
        if self.one_minus_bleed != 1.0:
            thrust = thrust * self.one_minus_bleed
        if slow:
            ran = self._phases(props, dt_s, source, engines)
            run_n1, run_n2, pph = (np.where(ran, a, b) for a, b in (
                (run_n1, props[self.key("n1")]), (run_n2, props[self.key("n2")]),
                (pph, props[pph_key])))
            n2norm = np.where(ran, n2norm, props[norm_key])
            tsfc = np.where(ran, tsfc, props[self.key("tsfc")])
            thrust = np.where(ran, thrust, 0.0)
        props[self.key("n1")], props[self.key("n2")], props[norm_key] = run_n1, run_n2, n2norm
        props[self.key("tsfc")] = tsfc
        props[pph_key] = pph
        return thrust, pph

    def _trim(self, props: dict[str, np.ndarray], tp: np.ndarray,
              idle: np.ndarray, mil: np.ndarray) -> np.ndarray:
        """A frame without time (``FGTurbine::Trim``): the thrust of the
        throttle's N2 at once, N1, N2 and the fuel flow left as they are; a
        starved engine is off."""
        n2 = self.idle_n2 + tp * self.n2_factor
        n2norm = (n2 - self.idle_n2) / self.n2_factor
        thrust = (idle + mil * n2norm * n2norm) * self.one_minus_bleed
        starved = props["_" + self.key("starved")] != 0.0
        props["_" + self.key("phase")] = np.where(starved, _OFF, _TRIM)
        if bool(starved.any()):
            running_key = "_" + self.key("running")
            props[running_key] = np.where(starved, 0.0, props[running_key])
            thrust = np.where(starved, 0.0, thrust)
        return thrust

    def _leave_trim(self, props: dict[str, np.ndarray], tp: np.ndarray, source: str,
                    engines: int) -> None:
        """The first frame with time after a trim: a running engine that is
        not starved runs from the throttle's N1 and N2, no longer cut off;
        any other is off and cut off (JSBSim's Calculate)."""
        phase_key = "_" + self.key("phase")
        phase = props[phase_key]
        trim = phase == _TRIM
        if not bool(trim.any()):
            return
        go = trim & (props["_" + self.key("running")] != 0.0) & (
            props["_" + self.key("starved")] == 0.0)
        if engines > 1 and bool((trim & ~go).any() or (trim & (
                props[CUTOFF] != 0.0)).any()):
            raise PropulsionError(f"{source}: an engine of an aircraft with "
                                  f"{engines} engines leaving a trim cut off or "
                                  f"cutting off is not compiled (JSBSim keeps a cut-off per "
                                  f"engine behind the one command)")
        for n_key, idle_n, factor in (("n2", self.idle_n2, self.n2_factor),
                                      ("n1", self.idle_n1, self.n1_factor)):
            props[self.key(n_key)] = np.where(go, idle_n + tp * factor, props[self.key(n_key)])
        props[phase_key] = np.where(go, _RUN, np.where(trim, _OFF, phase))
        props[CUTOFF] = np.where(go, 0.0, np.where(trim, 1.0, props[CUTOFF]))

    def _phases(self, props: dict[str, np.ndarray], dt_s: float, source: str,
                engines: int) -> np.ndarray:
        """The turbine's phases other than running (``FGTurbine::Calculate``,
        ``Off``, ``SpinUp``, ``Start``) for every aircraft: leaves N1, N2 and
        the fuel flow of the rows not running in ``props`` and returns the
        rows that ran (whose values the caller keeps from ``run_*``)."""
        if engines > 1 and bool(props[STARTER].any()):
            raise PropulsionError(f"{source}: the starter of an aircraft with "
                                  f"{engines} engines is not compiled (JSBSim keeps "
                                  f"one per engine behind propulsion/starter_cmd)")
        phase_key, running_key = "_" + self.key("phase"), "_" + self.key("running")
        phase, running = props[phase_key], props[running_key] != 0.0
        starved = props["_" + self.key("starved")] != 0.0
        cutoff, starter = props[CUTOFF] != 0.0, props[STARTER] != 0.0
        qbar = props["aero/qbar-psf"]
        n1, n2 = props[self.key("n1")], props[self.key("n2")]
        pph_key = "_" + self.key("fuel-flow-pph")
        # the transitions, in JSBSim's order
        phase = np.where(~running & cutoff & starter & (phase == _OFF), _SPINUP, phase)
        phase = np.where((starter | (qbar > 30.0)) & ~running & ~cutoff & (n2 > 15.0),
                         _START, phase)
        phase = np.where((cutoff & (phase != _SPINUP)) | starved, _OFF, phase)
        off, spin, start = phase == _OFF, phase == _SPINUP, phase == _START
        ran = phase == _RUN
        # Off: spooling down to the windmilling speed, the fuel flow to none
        (i1, i2), (s1, s2) = self.ignition, self.spindown
        if self.windmill:
            off_n1 = _seek(n1, qbar / 10.0, n1 / 2.0 + 0.1, n1 / s1, dt_s)
            off_n2 = _seek(n2, qbar / 15.0, n2 / 2.0 + 0.1, n2 / s2, dt_s)
        else:
            off_n1 = _seek(n1, 0.0, n1 / 2.0, n1 / s1, dt_s)
            off_n2 = _seek(n2, 0.0, n2 / 2.0, n2 / s2, dt_s)
        off_pph = _seek(props[pph_key], 0.0, 1000.0, 10000.0, dt_s)
        # SpinUp: the starter turns it to the ignition speeds, no fuel
        spin_n2 = _seek(n2, i2, self.spinup[1], n2 / 2.0, dt_s)
        spin_n1 = _seek(n1, i1, self.spinup[0], n1 / 2.0, dt_s)
        # Start: lit above 15 % N2 with fuel, to idle; at idle it runs
        lit = start & (n2 > 15.0) & ~starved
        cranking = lit & (n2 < self.idle_n2)
        start_n2 = _seek(n2, self.idle_n2, self.start_rate[1], n2 / 2.0, dt_s)
        start_n1 = _seek(n1, self.idle_n1, self.start_rate[0], n1 / 2.0, dt_s)
        start_pph = self.idle_ff_pph * start_n2 / self.idle_n2
        props[self.key("n1")] = np.where(off, off_n1, np.where(spin, spin_n1, np.where(
            cranking, start_n1, n1)))
        props[self.key("n2")] = np.where(off, off_n2, np.where(spin, spin_n2, np.where(
            cranking, start_n2, n2)))
        props[pph_key] = np.where(off, off_pph, np.where(spin, 0.0, np.where(
            cranking, start_pph, props[pph_key])))
        # the phase and flags the frame leaves
        to_run = start & lit & ~cranking
        aborted = cranking & ~starter & (qbar < 30.0)
        phase = np.where((ran & cutoff) | (spin & ~starter) | (start & ~lit) | aborted, _OFF,
                         np.where(to_run, _RUN, phase))
        props[phase_key] = phase
        props[running_key] = (ran | to_run | (running & ~off & ~spin)).astype(np.float64)
        props[STARTER] = np.where(ran | to_run | (start & ~lit), 0.0, props[STARTER])
        return ran


class TurbineLoop:
    """A turbine's running frame as ``_turbine``, fed by one tank: its
    constants, the keys it reads and writes, and which of the six sums
    (forces, then moments) it adds a term to."""

    def __init__(self, engine: Turbine, tank: Tank, tanks: int) -> None:
        e = self.engine = engine
        self.constants = np.array([e.milthrust_lbs, e.idle_n1, e.idle_n2, e.n1_factor,
                                   e.n2_factor, e.tsfc, e.one_minus_bleed, e.idle_ff_pph,
                                   *e.delays, tank.unusable_lbs,
                                   float(1 <= tank.priority <= tanks), *e.axis])
        self.ins = (e.key("n1"), e.key("n2"), "_" + e.key("n2norm"),
                    "_" + e.key("fuel-flow-pph"), *FLIGHT, e.key("reverser-angle-rad"), FREEZE,
                    "_" + e.key("starved"), "_" + e.key("phase"), e.key("fuel-flow-rate-pps"),
                    e.key("fuel-used-lbs"), tank.contents_key, *CG,
                    *(e.key(k) for k in POSITION))
        self.outs = (e.key("n1"), e.key("n2"), "_" + e.key("n2norm"), e.key("tsfc"),
                     "_" + e.key("fuel-flow-pph"), e.key("thrust-lbs"), "_" + e.key("starved"),
                     "_" + e.key("phase"), e.key("fuel-flow-rate-pps"), e.key("fuel-used-lbs"),
                     tank.contents_key)
        x, y, z = (a != 0.0 for a in e.axis)
        self.terms = np.array([x, y, z, y or z, x or z, x or y])

    def ready(self, props: dict[str, np.ndarray]) -> bool:
        """Whether every aircraft's engine is running (the phase)."""
        return bool((props["_" + self.engine.key("phase")] == _RUN).all())

    def run(self, props: dict[str, np.ndarray], dt_s: float, have: np.ndarray,
            acc: tuple[np.ndarray, ...]) -> None:
        """The frame of every aircraft: ``_turbine``, new arrays for what it
        writes, its terms added to ``acc`` (``have``: which sums an engine
        before it gave a term)."""
        e, n = self.engine, len(acc[0])
        idle_fraction = e.idle_thrust.evaluate(props)
        mil_fraction = e.mil_thrust.evaluate(props)
        props[e.key("IdleThrust")] = idle_fraction
        props[e.key("MilThrust")] = mil_fraction
        arrays = tuple(np.empty(n) for _ in self.outs)
        _turbine(dt_s, self.constants, have, (props[e.throttle_key], idle_fraction,
                                              mil_fraction, *(props[k] for k in self.ins)),
                 arrays, acc)
        props.update(zip(self.outs, arrays))
