"""The batched fixed-wing model: every aircraft of a worker as a point mass
flying coordinated turns, advanced together with numpy.

It takes the same setpoints as the JSBSim autopilot (``cosim/ap/*``, written
by the fixed-wing guidance) and closes the same loops, on a point mass
instead of a rigid body:

- heading: ``phi_cmd = atan(V k_psi e_psi / g)`` within the bank limit,
  moving at most ``ROLL_RATE_DPS``; the bank follows it with the time
  constant ``TAU_PHI_S``; the turn is coordinated, ``psi' = g tan(phi) / V``;
- height: the climb rate asked for is ``k_h (h_cmd - h)`` within
  ``+-VS_MAX_MPS``, followed with ``TAU_H_S``; below the speed floor
  (``1.2 v_s / sqrt(cos phi)``, stall protection on) it trades height for
  speed as the autopilot does;
- speed: thrust ``T = p T_max`` (``p`` follows the throttle with the
  engine's lag ``TAU_ENGINE_S``) against drag ``D = T_max (V / V_max)^2``
  (so full throttle holds ``V_max`` level) and gravity along the path,
  ``V' = (T - D) / m - g h' / V``; the speed hold sets the throttle from the
  speed error with the level trim fed forward;
- stall: below the level stall speed at its bank ``v_s / sqrt(cos phi)``
  (``v_s`` from weight, wing area and CL_max at the density of its height)
  lift falls with ``(V / v_s)^2`` and the aircraft sinks until it has
  the speed again.

It is integrated (explicit Euler) in steps of at most ``MAX_STEP_S``, not at
the run's physics rate: at a 10 Hz exchange, two steps per exchange. The
ground is flat at each aircraft's start terrain; reaching it is a ground
impact, unless the autopilot's ``landing`` flag is set and the sink is
gentle: then it stays on the ground and slows to a stop.

It flies in the scenario's flat frame: headings are bearings there (within
a fraction of a degree of true north's over tens of kilometres), and its
position in that frame is a state column the guidance reads directly.

Every operation is elementwise, so an aircraft's state does not depend on
how many share its batch, and the results are the same on every backend.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.core.units import FT_TO_M, G_MPS2, KT_TO_MPS

#: the mean Earth radius (m), for the curvature drop of a point in the flat frame
R_EARTH_M = 6_371_008.8
#: the JSBSim autopilot's gains, in SI (``aircraft/systems/cosim_autopilot.xml``)
K_PSI = 0.35  # 1/s: heading error to turn rate
ROLL_RATE_DPS = 15.0  # the bank command's rate limit
K_H = 0.12  # 1/s: height error to climb rate
VS_MAX_MPS = 25.0 * FT_TO_M  # the climb and sink rate limit
TRADE = 3.0 * FT_TO_M / KT_TO_MPS  # (m/s of sink) per (m/s below the speed floor)
STALL_MARGIN = 1.2
#: time constants of the responses (s), measured on the uav700 under the
#: JSBSim autopilot (``benchmarks/batched_fidelity.py``)
TAU_PHI_S = 0.75
TAU_H_S = 0.5
#: the engine: thrust follows the throttle with this lag (a turbojet spooling)
TAU_ENGINE_S = 1.35
#: the longest integration step (s): a point mass with these time constants
#: needs no more, whatever the physics rate of the run's JSBSim aircraft
MAX_STEP_S = 0.05
#: the speed hold: throttle per m/s of error
K_V = 0.08
#: the sink a full stall settles at (m/s)
STALL_SINK_MPS = 15.0
#: a touchdown with the landing flag set and less sink than this is a landing
LANDING_SINK_MPS = 3.0
#: on the ground after a landing: braking (m/s^2)
ROLLOUT_DECEL = 2.0
_S = STATE_INDEX

#: the autopilot settings it takes (the setpoint channels the fixed-wing
#: guidance writes) -> the attribute holding each, in the property's units
INPUTS = {"cosim/ap/engage": "engaged", "cosim/ap/heading-hold": "hdg_hold",
          "cosim/ap/heading-cmd-deg": "hdg_cmd", "cosim/ap/bank-limit-deg": "bank_lim",
          "cosim/ap/alt-hold": "alt_hold", "cosim/ap/alt-cmd-ft": "alt_cmd_ft",
          "cosim/ap/alt-mode": "alt_mode", "cosim/ap/speed-hold": "spd_hold",
          "cosim/ap/speed-cmd-kt": "spd_cmd_kt", "cosim/ap/stall-protect": "protect",
          "fcs/throttle-cmd-norm": "throttle", "cosim/ap/landing": "landing"}


def isa_sigma(h_m: np.ndarray) -> np.ndarray:
    """Density ratio of the standard atmosphere (troposphere, clipped to 11 km)."""
    h = np.minimum(np.maximum(h_m, -500.0), 11000.0)
    return (1.0 - 2.25577e-5 * h) ** 4.2559


class PointMassModel:
    """Every batched fixed-wing of one worker (see the module docstring)."""

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                 columns: Sequence[str]) -> None:
        m = len(specs)
        self.dt = dt_s
        cols = list(columns)
        self.c_contact = cols.index("contact_force_n")
        self.c_fuel = cols.index("fuel_kg")  # not modelled: NaN (unknown)
        self.c_north, self.c_east = cols.index("frame_north_m"), cols.index("frame_east_m")
        ch = list(channels)
        self.idx = {c: ch.index(c) for c in INPUTS if c in ch}
        p = [s.class_params for s in specs]
        self.frame = LocalFrame(*(p[0]["origin"] if p else (0.0, 0.0, 0.0)))
        self.ground = np.array([s.terrain_alt_m for s in specs], dtype=np.float64)
        self.vs_sl = np.array([q["vs1g_sl_mps"] for q in p], dtype=np.float64)
        self.v_max = np.array([q["v_max_mps"] for q in p], dtype=np.float64)
        self.a_t = np.array([q["thrust_accel_mps2"] for q in p], dtype=np.float64)
        self.alpha_stall = np.array([q["alpha_stall_deg"] for q in p], dtype=np.float64)
        self.mass_n = np.array([q["weight_n"] for q in p], dtype=np.float64)
        self.h = np.array([s.alt_msl_m for s in specs], dtype=np.float64)
        n, e, _ = self.frame.geodetic_to_ned(np.array([s.lat_deg for s in specs]),
                                             np.array([s.lon_deg for s in specs]), self.h)
        self.n, self.e = np.array(n, dtype=np.float64), np.array(e, dtype=np.float64)
        self.psi = np.radians(np.array([s.heading_deg for s in specs], dtype=np.float64))
        self.v = np.array([s.airspeed_mps for s in specs], dtype=np.float64)
        self.phi = np.zeros(m)
        self.hdot = np.zeros(m)
        self.phi_cmd = np.zeros(m)
        self.throttle = self._trim(self.v, self.hdot)
        self.power = self.throttle.copy()  # the thrust, as a fraction of T_max
        self.status = np.full(m, float(VehicleStatus.ACTIVE))
        self.on_ground = np.zeros(m, dtype=bool)
        self.stalled = np.zeros(m, dtype=bool)
        self.protecting = np.zeros(m, dtype=bool)
        # the autopilot's settings (as its properties: degrees, feet, knots)
        self.engaged = np.zeros(m)
        self.hdg_hold = np.zeros(m)
        self.hdg_cmd = np.degrees(self.psi)
        self.bank_lim = np.full(m, 45.0)
        self.alt_hold = np.zeros(m)
        self.alt_cmd_ft = self.h / FT_TO_M
        self.alt_mode = np.zeros(m)
        self.spd_hold = np.zeros(m)
        self.spd_cmd_kt = self.v / KT_TO_MPS
        self.protect = np.ones(m)
        self.landing = np.zeros(m)

    def _trim(self, v: np.ndarray, hdot: np.ndarray) -> np.ndarray:
        """The throttle that holds speed ``v`` at climb rate ``hdot``."""
        return np.clip((v / self.v_max) ** 2 + G_MPS2 * hdot / np.maximum(v, 1.0) / self.a_t,
                       0.0, 1.0)

    def apply(self, setpoints: np.ndarray) -> None:
        for name, j in self.idx.items():
            col = setpoints[:, j]
            if np.isnan(col).all():
                continue
            attr = INPUTS[name]
            setattr(self, attr, np.where(np.isnan(col), getattr(self, attr), col))

    def step(self, nsub: int) -> None:
        """``nsub`` physics ticks, integrated in equal steps of at most
        ``MAX_STEP_S`` (the responses' time constants are 0.5 s and more)."""
        total = nsub * self.dt
        k = max(1, math.ceil(total / MAX_STEP_S - 1e-9))
        for _ in range(k):
            self._substep(total / k)

    def _substep(self, dt: float) -> None:
        live = self.status == VehicleStatus.ACTIVE
        air = live & ~self.on_ground
        v = np.maximum(self.v, 1.0)
        cosphi = np.cos(self.phi)
        vs = self.vs_sl / np.sqrt(isa_sigma(self.h)) / np.sqrt(np.maximum(cosphi, 0.2))
        floor = STALL_MARGIN * vs
        on = self.engaged > 0.5
        # heading -> bank command (rate limited) -> bank
        err = np.remainder(np.radians(self.hdg_cmd) - self.psi + np.pi, 2.0 * np.pi) - np.pi
        lim = np.radians(self.bank_lim)
        want = np.where(on & (self.hdg_hold > 0.5),
                        np.clip(np.arctan(v * K_PSI * err / G_MPS2), -lim, lim), 0.0)
        want = np.where(on, want, self.phi_cmd)
        rate = np.radians(ROLL_RATE_DPS) * dt
        self.phi_cmd = self.phi_cmd + np.clip(want - self.phi_cmd, -rate, rate)
        phi = self.phi + (self.phi_cmd - self.phi) * (dt / TAU_PHI_S)
        # height -> climb rate
        target_h = self.alt_cmd_ft * FT_TO_M + np.where(self.alt_mode > 0.5, self.ground, 0.0)
        vs_cmd = np.where(on & (self.alt_hold > 0.5),
                          np.clip(K_H * (target_h - self.h), -VS_MAX_MPS, VS_MAX_MPS), 0.0)
        self.protecting = on & (self.protect > 0.5) & (self.landing < 2) & (
            (v < floor) | ((self.spd_hold > 0.5) & (self.spd_cmd_kt * KT_TO_MPS < floor)))
        vs_cmd = np.where(on & (self.protect > 0.5) & (v < floor),
                          np.minimum(vs_cmd, -TRADE * (floor - v)), vs_cmd)
        self.stalled = air & (v < vs)
        lift = np.minimum((v / vs) ** 2, 1.0)
        vs_cmd = np.where(self.stalled, np.minimum(vs_cmd, -STALL_SINK_MPS * (1.0 - lift)),
                          vs_cmd)
        hdot = self.hdot + (vs_cmd - self.hdot) * (dt / TAU_H_S)
        # speed: the throttle from the speed hold, then thrust, drag and the climb
        spd = np.where(self.protect > 0.5, np.maximum(self.spd_cmd_kt * KT_TO_MPS, floor),
                       self.spd_cmd_kt * KT_TO_MPS)
        thr = np.where(on & (self.spd_hold > 0.5),
                       np.clip(self._trim(v, hdot) + K_V * (spd - v), 0.0, 1.0), self.throttle)
        power = self.power + (thr - self.power) * (dt / TAU_ENGINE_S)
        vdot = self.a_t * (power - (v / self.v_max) ** 2) - G_MPS2 * hdot / v
        vdot = np.where(self.on_ground, -ROLLOUT_DECEL, vdot)
        vnew = np.maximum(self.v + vdot * dt, 0.0)
        # move
        psi = self.psi + np.where(air, G_MPS2 * np.tan(phi) / v, 0.0) * dt
        gs = vnew * np.sqrt(np.maximum(1.0 - (hdot / np.maximum(vnew, 1.0)) ** 2, 0.0))
        n = self.n + gs * np.cos(self.psi) * dt
        e = self.e + gs * np.sin(self.psi) * dt
        h = self.h + np.where(self.on_ground, 0.0, hdot) * dt
        # the ground
        hit = air & (h <= self.ground)
        landed = hit & (self.landing >= 1.0) & (-hdot < LANDING_SINK_MPS)
        crashed = hit & ~landed
        keep = ~live | crashed
        self.n = np.where(keep, self.n, n)
        self.e = np.where(keep, self.e, e)
        self.h = np.where(keep, self.h, np.where(landed, self.ground, h))
        self.psi = np.where(keep, self.psi, psi)
        self.v = np.where(keep, self.v, vnew)
        self.phi = np.where(keep, self.phi, np.where(self.on_ground | landed, 0.0, phi))
        self.hdot = np.where(keep, self.hdot, np.where(self.on_ground | landed, 0.0, hdot))
        self.throttle = np.where(keep, self.throttle, thr)
        self.power = np.where(keep, self.power, power)
        self.on_ground = self.on_ground | landed
        self.status = np.where(crashed, float(VehicleStatus.GROUND_IMPACT), self.status)

    def write_states(self, out: np.ndarray) -> None:
        out[:] = 0.0
        out[:, self.c_fuel] = np.nan
        # down of the point at height h over (n, e): the flat-earth value less
        # the Earth's curvature drop (latitude and longitude within 5 mm of
        # the exact LocalFrame.place over 50 km; the height reported is h)
        down = -(self.h - self.frame.alt_m) + (self.n ** 2 + self.e ** 2) / (2.0 * R_EARTH_M)
        lat, lon, _ = self.frame.ned_to_geodetic(self.n, self.e, down)
        out[:, _S["lat_deg"]], out[:, _S["lon_deg"]] = lat, lon
        out[:, _S["alt_msl_m"]] = self.h
        out[:, _S["alt_agl_m"]] = self.h - self.ground
        v = np.maximum(self.v, 1e-9)
        gamma = np.arcsin(np.clip(self.hdot / np.maximum(v, 1.0), -1.0, 1.0))
        cosphi = np.cos(self.phi)
        vs = self.vs_sl / np.sqrt(isa_sigma(self.h)) / np.sqrt(np.maximum(cosphi, 0.2))
        alpha = np.where(self.on_ground, 0.0,
                         self.alpha_stall * np.minimum((vs / np.maximum(v, 1.0)) ** 2, 1.5))
        out[:, _S["roll_deg"]] = np.degrees(self.phi)
        out[:, _S["pitch_deg"]] = np.degrees(gamma) + alpha
        out[:, _S["yaw_deg"]] = np.degrees(self.psi) % 360.0
        gs = self.v * np.cos(gamma)
        out[:, _S["vn_mps"]] = gs * np.cos(self.psi)
        out[:, _S["ve_mps"]] = gs * np.sin(self.psi)
        out[:, _S["vd_mps"]] = -self.hdot
        out[:, _S["airspeed_mps"]] = self.v
        out[:, _S["alpha_deg"]] = alpha
        out[:, _S["throttle"]] = self.throttle
        out[:, _S["ap_engaged"]] = self.engaged
        out[:, _S["bank_limit_deg"]] = self.bank_lim
        out[:, _S["stalled"]] = self.stalled
        out[:, _S["stall_protection_active"]] = self.protecting
        out[:, _S["status"]] = self.status
        out[:, self.c_contact] = np.where(self.on_ground, self.mass_n, 0.0)
        out[:, self.c_north], out[:, self.c_east] = self.n, self.e
        out[:, _S["gear_force_lbs"]] = np.where(self.on_ground, -self.mass_n / 4.4482216152605,
                                                0.0)
