"""The ground vehicle's model: a kinematic bicycle, every vehicle of a worker
advanced together.

State per vehicle: position ``(n, e)`` of the rear axle in the scenario
frame (metres), heading ``psi``, speed ``v`` (forward only) and steering
angle ``delta``. Per substep ``dt`` (explicit Euler)::

    delta += clip(delta_cmd - delta, +-steer_rate * dt),  |delta| <= max_steer
    v     += clip(v_cmd - v, -brake * dt, accel * dt),      0 <= v <= max_speed
    n     += v cos(psi) dt;   e += v sin(psi) dt;   psi += v / L tan(delta) dt

so with the steering held the vehicle drives a circle of radius
``L / tan(delta)``. A kinematic model is enough for what the simulator
asks of a ground vehicle: low speeds (at most ``max_speed``, 15 m/s by
default) on firm ground, where the tyres do not slip and the lateral
acceleration ``v^2 tan(delta) / L`` stays small; the purpose is routing,
obstacle avoidance and being seen by cameras, not handling at the limit.

Obstacles are a hard rule here, not only in the guidance: a substep that
would put a vehicle inside an obstacle leaves it where it was, stopped
(``blocked`` = 1). Every operation is elementwise (trigonometry per vehicle
through ``math``), so a vehicle's state never depends on how many share
its batch. It drives on flat ground at its start's terrain height.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.world.obstacles import inside

SPEED_CMD = "ground/speed-cmd-mps"
STEER_CMD = "ground/steer-cmd-deg"
_S = STATE_INDEX


def _cos(a: np.ndarray) -> np.ndarray:
    return np.array([math.cos(x) for x in a.tolist()])


def _sin(a: np.ndarray) -> np.ndarray:
    return np.array([math.sin(x) for x in a.tolist()])


def _tan(a: np.ndarray) -> np.ndarray:
    return np.array([math.tan(x) for x in a.tolist()])


class BicycleModel:
    """Every ground vehicle of one worker (see the module docstring)."""

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                 columns: Sequence[str]) -> None:
        self.dt = dt_s
        cols = list(columns)
        self.c_steer, self.c_blocked = cols.index("steer_deg"), cols.index("blocked")
        ch = list(channels)
        self.i_speed = ch.index(SPEED_CMD) if SPEED_CMD in ch else None
        self.i_steer = ch.index(STEER_CMD) if STEER_CMD in ch else None
        p = [s.class_params for s in specs]
        o = p[0]["origin"] if p else (0.0, 0.0, 0.0)
        self.frame = LocalFrame(*o)
        self.alt = np.array([s.terrain_alt_m for s in specs])
        self.wheelbase = np.array([q["wheelbase_m"] for q in p])
        self.max_speed = np.array([q["max_speed_mps"] for q in p])
        self.accel = np.array([q["accel_mps2"] for q in p])
        self.brake = np.array([q["brake_mps2"] for q in p])
        self.max_steer = np.radians(np.array([q["max_steer_deg"] for q in p]))
        self.steer_rate = np.radians(np.array([q["steer_rate_dps"] for q in p]))
        self.obstacles = [np.array(poly) for poly in (p[0]["obstacles"] if p else ())]
        start = np.array([q["start_ne"] for q in p]).reshape(len(specs), 2)
        self.n, self.e = start[:, 0].copy(), start[:, 1].copy()
        self.psi = np.radians(np.array([s.heading_deg for s in specs]))
        self.v = np.clip(np.array([s.airspeed_mps for s in specs]), 0.0, self.max_speed)
        self.delta = np.zeros(len(specs))
        self.v_cmd = self.v.copy()
        self.delta_cmd = np.zeros(len(specs))
        self.blocked = np.zeros(len(specs))

    def apply(self, setpoints: np.ndarray) -> None:
        if self.i_speed is not None:
            s = setpoints[:, self.i_speed]
            self.v_cmd = np.where(np.isnan(s), self.v_cmd, s)
        if self.i_steer is not None:
            d = setpoints[:, self.i_steer]
            self.delta_cmd = np.where(np.isnan(d), self.delta_cmd, np.radians(d))

    def step(self, nsub: int) -> None:
        dt = self.dt
        for _ in range(nsub):
            target = np.clip(self.delta_cmd, -self.max_steer, self.max_steer)
            self.delta = self.delta + np.clip(target - self.delta, -self.steer_rate * dt,
                                              self.steer_rate * dt)
            v = self.v + np.clip(np.clip(self.v_cmd, 0.0, self.max_speed) - self.v,
                                 -self.brake * dt, self.accel * dt)
            n = self.n + v * _cos(self.psi) * dt
            e = self.e + v * _sin(self.psi) * dt
            psi = self.psi + v / self.wheelbase * _tan(self.delta) * dt
            hit = np.zeros(len(n), dtype=bool)
            if self.obstacles:
                pts = np.stack([n, e], axis=1)
                for poly in self.obstacles:
                    hit |= inside(poly, pts)
            self.n = np.where(hit, self.n, n)
            self.e = np.where(hit, self.e, e)
            self.psi = np.where(hit, self.psi, psi)
            self.v = np.where(hit, 0.0, v)
            self.blocked = hit.astype(float)

    def write_states(self, out: np.ndarray) -> None:
        out[:] = 0.0
        for j in range(len(self.n)):
            lat, lon = self.frame.place(float(self.n[j]), float(self.e[j]), float(self.alt[j]))
            out[j, _S["lat_deg"]], out[j, _S["lon_deg"]] = float(lat), float(lon)
        out[:, _S["alt_msl_m"]] = self.alt
        out[:, _S["yaw_deg"]] = np.degrees(self.psi) % 360.0
        c, s = _cos(self.psi), _sin(self.psi)
        out[:, _S["vn_mps"]] = self.v * c
        out[:, _S["ve_mps"]] = self.v * s
        out[:, _S["airspeed_mps"]] = self.v
        out[:, _S["status"]] = VehicleStatus.ACTIVE
        out[:, self.c_steer] = np.degrees(self.delta)
        out[:, self.c_blocked] = self.blocked
