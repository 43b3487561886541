"""The piston engine and its fixed-pitch propeller of ``cosim.rigid.propulsion``'s
plan: JSBSim 1.3's ``FGPiston::Calculate`` and ``FGPropeller::Calculate``
for every aircraft at once, in numpy, their state in the caller's ``props``
(what they compute, refuse and leave out is said in ``cosim.rigid.propulsion``).
This module holds no XML; the fuel they burn is ``Propulsion``'s (the
``Engine`` protocol of ``cosim.rigid.propulsion_base``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.rigid import kernels
from cosim.rigid.propulsion_base import CG, POSITION, STARTER, Tank, Terms, indexed
from cosim.rigid.units import IN_TO_FT

#: FGJSBBase's and FGPiston's constants, as JSBSim holds them
PSFTOPA = 47.88
INHGTOPA = 3386.38
HPTOFTLBSSEC = 550.0
FTTOM = 0.3048
#: a cubic inch in cubic metres: FGJSBBase's, from the exact inch (not the
#: truncated one of the structural frame)
IN3TOM3 = IN_TO_FT * IN_TO_FT * IN_TO_FT / (1.0 / (FTTOM * FTTOM * FTTOM))
R_AIR = 287.3
STANDARD_PRESSURE = 101320.73
#: FGPiston's default mixture efficiency (fuel/air ratio -> efficiency)
MIXTURE_TABLE = ((0.05000, 0.05137, 0.05179, 0.05430, 0.05842, 0.06312, 0.06942, 0.07786,
                  0.08845, 0.09270, 0.10120, 0.11455, 0.12158, 0.12435, 0.12500),
                 (0.00000, 0.00862, 0.21552, 0.48276, 0.70690, 0.83621, 0.93103, 1.00000,
                  1.00000, 0.98276, 0.93103, 0.72414, 0.45690, 0.23276, 0.00000))

Table = tuple[tuple[float, ...], tuple[float, ...]]
#: an engine's properties a frame writes (``propulsion/engine[i]/...``) and
#: its private state (``_propulsion/engine[i]/...``)
_PUBLIC = ("map-pa", "map-inhg", "power-hp", "fuel-flow-rate-pps", "fuel-used-lbs",
           "engine-rpm", "propeller-rpm", "thrust-lbs", "advance-ratio", "thrust-coefficient",
           "helical-tip-Mach", "prop-induced-velocity_fps", "propeller-power-ftlbps",
           "propeller-torque-ftlb", "x-position", "y-position", "z-position")
_PRIVATE = ("running", "magnetos", "starved")


def lookup(table: Table, key: np.ndarray) -> np.ndarray:
    """A table of one dimension (``FGTable::GetValue``, clamped at its ends)."""
    return kernels.table1(np.asarray(table[0]), np.asarray(table[1]),
                          np.ascontiguousarray(key, dtype=np.float64))


@dataclass(frozen=True)
class Propeller:
    """A fixed-pitch propeller (``FGPropeller``), compiled."""

    diameter_ft: float
    ixx_slugft2: float
    gear_ratio: float
    ct: Table
    cp: Table
    ct_mach: Table | None
    cp_mach: Table | None
    ct_factor: float
    cp_factor: float
    sense: float
    #: -1 for a propeller file of version above 1.0 (the gyroscopic sense)
    sense_multiplier: float
    p_factor: float
    #: the thruster's reference location (in, structural frame)
    location_in: tuple[float, float, float]


@dataclass(frozen=True)
class Piston:
    """One piston engine (``FGPiston``, unboosted) and its propeller, compiled."""

    index: int
    name: str
    min_throttle: float
    max_throttle: float
    idle_rpm: float
    max_rpm: float
    stroke_in: float
    cycles: float
    displacement_m3: float
    isfc: float
    volumetric_efficiency: float
    compression_ratio: float
    peak_piston_speed_fps: float
    z_airbox: float
    z_throttle: float
    man_press_lag_s: float
    ram_air_factor: float
    fmep_dynamic_pa: float
    fmep_static_pa: float
    static_friction_hp: float
    spark_fail_drop: float
    starter_rpm: float
    starter_torque: float
    mixture: Table
    feeds: tuple[int, ...]
    propeller: Propeller

    def key(self, leaf: str) -> str:
        return indexed(f"propulsion/engine/#/{leaf}", self.index)

    @property
    def throttle_key(self) -> str:
        return indexed("fcs/throttle-pos-norm/#", self.index)

    @property
    def mixture_key(self) -> str:
        return indexed("fcs/mixture-pos-norm/#", self.index)

    @property
    def inputs(self) -> frozenset[str]:
        return frozenset({"atmosphere/P-psf", "atmosphere/delta", "velocities/mach",
                          "atmosphere/T-R", "atmosphere/rho-slugs_ft3", "atmosphere/a-fps",
                          self.throttle_key, self.mixture_key,
                          *(f"velocities/{a}-aero-fps" for a in "uvw"),
                          *(f"velocities/{a}-aero-rad_sec" for a in "pqr")})

    @property
    def rolls_and_yaws(self) -> bool:
        """A propeller's reaction torque and P-factor roll and yaw the
        airframe in level flight."""
        return True

    @property
    def outputs(self) -> frozenset[str]:
        return frozenset(self.state)

    @property
    def state(self) -> tuple[str, ...]:
        """The keys of the engine's state: what a frame writes, then its
        private flags (running, magnetos, starved)."""
        k = self.key
        return (*(k(x) for x in _PUBLIC), *("_" + k(x) for x in _PRIVATE))

    def init(self, props: dict[str, np.ndarray], n: int) -> None:
        """The engine as ``FGPiston::InitRunning`` leaves it before the
        steady state: magnetos on both, running at twice the idle speed, the
        manifold at the ambient pressure, no fuel flowing yet; the mixture
        command and position at 1 (``FGPropulsion::InitRunning``'s)."""
        k = self.key
        for x in _PUBLIC:
            props[k(x)] = np.zeros(n)
        for i, x in enumerate(POSITION):
            props[k(x)] = np.full(n, self.propeller.location_in[i])
        p_psf = props.get("atmosphere/P-psf")
        props[k("map-pa")] = np.full(n, 2116.228) * PSFTOPA if p_psf is None else p_psf * PSFTOPA
        props[k("map-inhg")] = props[k("map-pa")] / INHGTOPA
        props[k("propeller-rpm")] = np.full(n, 2.0 * self.idle_rpm / self.propeller.gear_ratio)
        props[k("engine-rpm")] = props[k("propeller-rpm")] * self.propeller.gear_ratio
        props["_" + k("running")] = np.ones(n)
        props["_" + k("magnetos")] = np.full(n, 3.0)
        props["_" + k("starved")] = np.zeros(n)
        self._full_mixture(props, n)

    def _full_mixture(self, props: dict[str, np.ndarray], n: int) -> None:
        """``FGPropulsion::InitRunning``'s mixture: command and position at 1."""
        for c in ("cmd", "pos"):
            props[indexed(f"fcs/mixture-{c}-norm/#", self.index)] = np.ones(n)

    def set_running(self, props: dict[str, np.ndarray], current: np.ndarray, source: str,
                    engines: int) -> np.ndarray:
        """``propulsion/set-running`` = -1 for this engine: the mixture at 1,
        then its steady state (``steady``); returns its thrust."""
        self._full_mixture(props, len(current))
        return self.steady(props, props[STARTER], current)

    def frame(self, props: dict[str, np.ndarray], dt_s: float, cg: list[np.ndarray],
              source: str, engines: int) -> tuple[np.ndarray, Terms, Terms]:
        """A frame of the engine and its propeller (``FGPiston::Calculate``):
        the fuel flow it burns (pounds a second), its body forces and
        moments."""
        fb, mb = self.thrust(props, dt_s, self.power(props, dt_s, props[STARTER]))
        return props[self.key("fuel-flow-rate-pps")], fb, mb

    def starve(self, props: dict[str, np.ndarray], fed: np.ndarray) -> None:
        """Starved, its next frame gets no fuel (``_starved``): nothing else."""

    def loop(self, tank: Tank, tanks: int) -> None:
        """No loop: every frame runs the numpy steps."""
        return None

    def steady(self, props: dict[str, np.ndarray], starter: np.ndarray,
               current: np.ndarray) -> np.ndarray:
        """``FGPiston::InitRunning`` then ``FGPropulsion::GetSteadyState``
        for this engine: at full throttle and the mixture at 1.3 x the
        pressure ratio, stepped at 0.5 s without burning fuel until its
        thrust has moved by less than 1e-4 lbf 121 steps running (at most
        6,000); an aircraft that got there stops moving. ``current``: the
        last engine's thrust, which JSBSim compares the first step's with;
        returns this one's."""
        n = len(current)
        k = self.key
        props["_" + k("magnetos")] = np.full(n, 3.0)
        props[k("propeller-rpm")] = np.full(n, 2.0 * self.idle_rpm / self.propeller.gear_ratio)
        props[k("engine-rpm")] = props[k("propeller-rpm")] * self.propeller.gear_ratio
        props["_" + k("running")] = np.ones(n)
        props[k("fuel-flow-rate-pps")] = np.zeros(n)  # as the initial frame at rest leaves it
        mixture, full = props["atmosphere/delta"] * 1.3, np.ones(n)
        count = np.zeros(n, dtype=np.int64)
        done = np.zeros(n, dtype=bool)
        keys = self.state
        for _ in range(6000):
            if bool(done.all()):
                break
            before = [props[x].copy() for x in keys]
            self.thrust(props, 0.5, self.power(props, 0.5, starter, mixture, full))
            thrust = props[k("thrust-lbs")]
            for x, b in zip(keys, before, strict=True):  # a steady aircraft stopped
                props[x] = np.where(done, b, props[x])
            last, current = current, np.where(done, current, thrust)
            count = np.where(done, count, np.where(np.abs(last - current) < 0.0001,
                                                   count + 1, 0))
            done = done | (count > 120)
        return current

    # -------------------------------------------------------- the engine --

    def power(self, props: dict[str, np.ndarray], dt_s: float, starter: np.ndarray,
              mixture: np.ndarray | None = None, throttle: np.ndarray | None = None
              ) -> np.ndarray:
        """``FGPiston::Calculate`` up to the thruster: the engine's state
        (running, the manifold pressure, the fuel flow, the power) moved a
        frame at the engine speed the propeller left, in ``props``; returns
        the power the propeller gets (ft-lbf/s). ``mixture`` and ``throttle``
        replace the flight controls' (the steady state's)."""
        k = self.key
        p_amb = props["atmosphere/P-psf"] * PSFTOPA
        p = kernels.pitot_total_arrays(props["velocities/mach"],
                                       props["atmosphere/P-psf"]) * PSFTOPA
        p_ram = (p - p_amb) * self.ram_air_factor + p_amb
        t_amb = props["atmosphere/T-R"] / 1.8
        rpm = props[k("engine-rpm")]
        mps = (rpm * self.stroke_in) / 360.0
        # doEngineStartup: the previous frame's fuel flow is the fuel
        magnetos = props["_" + k("magnetos")]
        spark = magnetos != 0.0
        fuel = props[k("fuel-flow-rate-pps")] > 0.0
        was = props["_" + k("running")] != 0.0
        slow = rpm < self.idle_rpm * 0.8
        fast = rpm > self.idle_rpm * 0.8
        running = np.where(was, spark & fuel & ~slow, spark & fuel & fast)
        cranking = starter != 0.0
        # doMAP: the manifold pressure lags towards the throttle's
        tp = props[self.throttle_key] if throttle is None else throttle
        zt = (1.0 - tp) * (1.0 - tp) * self.z_throttle
        with np.errstate(divide="ignore"):
            ze = np.where(mps > 0.0, self.peak_piston_speed_fps / mps, 999999.0)
        coefficient = ze / (ze + self.z_airbox + zt)
        d_map = props[k("map-pa")] - p_ram * coefficient
        if self.man_press_lag_s > dt_s:
            d_map = d_map * (dt_s / self.man_press_lag_s)
        tmap = props[k("map-pa")] - d_map
        pmep = (tmap - p_amb) * self.volumetric_efficiency
        # doAirFlow
        gamma = 1.3
        with np.errstate(divide="ignore", invalid="ignore"):
            mratio = np.where(tmap < 1.0, self.compression_ratio, p_amb / tmap)
        mratio = np.where(mratio > self.compression_ratio, self.compression_ratio, mratio)
        ve = ((gamma - 1.0) / gamma) + (self.compression_ratio - mratio) / (
            gamma * (self.compression_ratio - 1.0))
        swept = (self.displacement_m3 * (rpm / 60.0)) / 2.0
        v_dot_air = swept * (self.volumetric_efficiency * ve)
        m_dot_air = v_dot_air * (tmap / (R_AIR * t_amb))
        # doFuelFlow
        mix = props[self.mixture_key] if mixture is None else mixture
        equivalence = (1.3 * mix) * 101325.0 / p_amb
        m_dot_fuel = (m_dot_air * equivalence) / 14.7
        starved = props["_" + k("starved")] != 0.0
        if bool(starved.any()):
            m_dot_fuel = np.where(starved, 0.0, m_dot_fuel)
        rate_pps = m_dot_fuel * 2.2046
        pph = rate_pps * 3600.0
        # doEnginePower
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = m_dot_fuel / m_dot_air
        me = lookup(self.mixture, np.where(running, ratio, 0.0))  # a stopped engine's is unused
        fmep = np.where(running, -self.fmep_dynamic_pa * mps * FTTOM - self.fmep_static_pa, 0.0)
        spark_power = np.where(magnetos != 3.0, self.spark_fail_drop, 1.0)
        on_hp = (pph / self.isfc) * me * spark_power - self.static_friction_hp
        k_torque = np.where(rpm < self.starter_rpm, 1.0 - rpm / self.starter_rpm, 0.0)
        crank_hp = self.starter_torque * k_torque * 1.0 * np.where(rpm < 1.0, 1.0, rpm) / 5252.0
        ihp = np.where(running, on_hp, np.where(cranking, crank_hp, -self.static_friction_hp))
        pumping_hp = ((pmep + fmep) * self.displacement_m3 * rpm) / (self.cycles * 22371.0)
        hp = ihp + pumping_hp - 0.0
        running = running & ~(ihp < 0.1250)
        props[k("map-pa")] = tmap
        props[k("map-inhg")] = tmap / INHGTOPA
        props[k("fuel-flow-rate-pps")] = rate_pps
        props[k("power-hp")] = hp
        props["_" + k("running")] = running.astype(np.float64)
        power = hp * HPTOFTLBSSEC
        return np.where(rpm <= 0.1, np.maximum(power, 0.0), power)

    # ----------------------------------------------------- the propeller --

    def thrust(self, props: dict[str, np.ndarray], dt_s: float, power: np.ndarray
               ) -> tuple[list[np.ndarray | None], list[np.ndarray | None]]:
        """``FGPropeller::Calculate`` and ``FGForce::GetBodyForces`` of a
        propeller along the body's x axis: the thrust of the frame's engine
        speed, the speed moved by the excess torque, the P-factor's shift of
        the acting location; returns the body forces and the moments about
        the CG (the propeller's reaction torque, its gyroscopic moment and
        the thrust's)."""
        pr, k = self.propeller, self.key
        cg = [props[c] for c in CG]
        dx, dy, dz = (IN_TO_FT * (cg[0] - pr.location_in[0]),
                      IN_TO_FT * (pr.location_in[1] - cg[1]),
                      IN_TO_FT * (cg[2] - pr.location_in[2]))
        p, q, r = (props[f"velocities/{a}-aero-rad_sec"] for a in "pqr")
        u = props["velocities/u-aero-fps"] + (q * dz - r * dy)
        v = props["velocities/v-aero-fps"] + (r * dx - p * dz)
        w = props["velocities/w-aero-fps"] + (p * dy - q * dx)
        rho = props["atmosphere/rho-slugs_ft3"]
        rpm = props[k("propeller-rpm")]
        rps = rpm / 60.0
        d = pr.diameter_ft
        area = 0.25 * d * d * math.pi
        vtip = rps * d * math.pi
        tip_mach = np.sqrt(vtip * vtip + u * u) / props["atmosphere/a-fps"]
        with np.errstate(divide="ignore", invalid="ignore"):
            j = np.where(rps > 0.01, u / (d * rps), u / d)
        # GetPowerRequired
        cp = lookup(pr.cp, j) * pr.cp_factor
        if pr.cp_mach is not None:
            cp = cp * lookup(pr.cp_mach, tip_mach)
        local_rps = np.where(rps < 0.01, 0.01, rps)
        required = cp * local_rps * local_rps * local_rps * (d * d * d * d * d) * rho
        available = power - required
        ct = lookup(pr.ct, j) * pr.ct_factor
        if pr.ct_mach is not None:
            ct = ct * lookup(pr.ct_mach, tip_mach)
        thrust = ct * rps * rps * (d * d * d * d) * rho
        vel2sum = u * np.abs(u) + 2.0 * thrust / (rho * area)
        induced = np.where(vel2sum > 0.0, 0.5 * (-u + np.sqrt(np.abs(vel2sum))),
                           0.5 * (-u - np.sqrt(np.abs(vel2sum))))
        if pr.p_factor > 0.0001:
            tangential = np.sqrt(v * v + w * w)
            shift = tangential > 0.0001
            with np.errstate(divide="ignore", invalid="ignore"):
                angle = kernels.atan2_arrays(tangential, u + induced)
                factor = pr.sense * pr.p_factor * angle / tangential
            props[k("y-position")] = np.where(shift, pr.location_in[1] + factor * w,
                                              props[k("y-position")])
            props[k("z-position")] = np.where(shift, pr.location_in[2] + factor * v,
                                              props[k("z-position")])
        omega = rps * 2.0 * math.pi
        torque = -pr.sense * power / np.maximum(0.01, omega)
        h = pr.ixx_slugft2 * omega * pr.sense * pr.sense_multiplier
        excess = np.where(omega > 0.01, available / omega, available / 1.0)
        new_rpm = (rps + ((excess / pr.ixx_slugft2) / (2.0 * math.pi)) * dt_s) * 60.0
        new_rpm = np.where(new_rpm < 0.0, 0.0, new_rpm)
        props[k("propeller-rpm")] = new_rpm
        props[k("engine-rpm")] = new_rpm * pr.gear_ratio
        props[k("advance-ratio")] = j
        props[k("thrust-coefficient")] = ct
        props[k("helical-tip-Mach")] = tip_mach
        props[k("prop-induced-velocity_fps")] = induced
        props[k("propeller-power-ftlbps")] = required
        props[k("propeller-torque-ftlb")] = torque
        props[k("thrust-lbs")] = thrust
        # FGForce: the thrust at the acting location, the moment about the CG
        ax = IN_TO_FT * (cg[0] - props[k("x-position")])
        ay = IN_TO_FT * (props[k("y-position")] - cg[1])
        az = IN_TO_FT * (cg[2] - props[k("z-position")])
        pi, qi, ri = (props[f"_eom/{a}i"] for a in "pqr")
        zero = np.zeros_like(thrust)
        moments: list[np.ndarray | None] = [(qi * 0.0 - ri * 0.0 + torque) + (ay * 0.0 - az * 0.0),
                   (ri * h - pi * 0.0 + 0.0) + (az * thrust - ax * 0.0),
                   (pi * 0.0 - qi * h + 0.0) + (ax * 0.0 - ay * thrust)]
        forces: list[np.ndarray | None] = [thrust, zero, zero.copy()]
        return forces, moments
