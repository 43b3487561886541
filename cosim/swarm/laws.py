"""The consensus laws of docs/physics.md ("Swarm consensus behaviours"), pure
numpy, vectorised over vehicles.

Positions are horizontal ``(n, 2)`` arrays of (north, east) metres in one
local tangent frame (``cosim.core.geo.LocalFrame``: exact WGS-84, no flat-earth
shortcut). Distances are **horizontal**: the swarm is altitude-layered (each
vehicle holds its own layer altitude, ``SwarmGroup.layer_spacing_m``), so a
vehicle "at" the centroid is above or below the others, and the consensus
acts in the horizontal plane where fixed-wing aircraft manoeuvre.

Speeds are true airspeeds (m/s). ``stall_speed_mps`` gives the stall speed
in the current bank; ``clip_speed_mps`` keeps every commanded speed inside
the vehicle's envelope but never below that stall speed (where the envelope
minimum is the lower of the two, the stall speed wins).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def centroid(p_ne_m: ArrayLike) -> Array:
    """c = (1/|N|) sum_j p_j, shape (2,)."""
    p = np.asarray(p_ne_m, dtype=np.float64)
    return np.asarray(p.mean(axis=0), dtype=np.float64)


def distances_to_centroid_m(p_ne_m: ArrayLike) -> Array:
    """||p_i - c|| for every vehicle, shape (n,)."""
    p = np.asarray(p_ne_m, dtype=np.float64)
    d = p - centroid(p)
    return np.asarray(np.hypot(d[:, 0], d[:, 1]), dtype=np.float64)


def stall_speed_mps(stall_constant_mps: ArrayLike, roll_rad: ArrayLike) -> Array:
    """s_s,i = stall_constant_i / sqrt(cos(phi_i)). |phi| >= 90 deg: infinite."""
    k = np.asarray(stall_constant_mps, dtype=np.float64)
    c = np.cos(np.asarray(roll_rad, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(c > 0, k / np.sqrt(np.maximum(c, 1e-300)), np.inf)
    return np.asarray(out, dtype=np.float64)


def rendezvous(p_ne_m: ArrayLike, mu: float, k_s: float, stall_mps: ArrayLike
               ) -> tuple[Array, Array]:
    """Goals ``g_i = mu (c - p_i) + p_i`` and speeds ``max(s_s,i, k_s ||p_i - c||)``."""
    p = np.asarray(p_ne_m, dtype=np.float64)
    c = centroid(p)
    goal = mu * (c - p) + p
    d = np.hypot(*(p - c).T)
    return goal, np.maximum(np.asarray(stall_mps, dtype=np.float64), k_s * d)


def anti_rendezvous(p_ne_m: ArrayLike, mu: float, k_s: float, stall_mps: ArrayLike
                    ) -> tuple[Array, Array]:
    """Goals ``g_i = mu (c - p_i) + p_i`` (mu < 0: away from the centroid) and
    speeds ``max(s_s,i, k_s (max_j ||p_j - c|| - ||p_i - c||))``.

    ``k_s`` (1/s) multiplies the whole difference, for the result to be a
    speed:
    the vehicles nearest the centre fly fastest, the outermost at stall.
    """
    p = np.asarray(p_ne_m, dtype=np.float64)
    c = centroid(p)
    goal = mu * (c - p) + p
    d = np.hypot(*(p - c).T)
    return goal, np.maximum(np.asarray(stall_mps, dtype=np.float64), k_s * (d.max() - d))


def flocking(p_ne_m: ArrayLike, mu: float, k_s: float, q_ne_m: ArrayLike, stall_mps: ArrayLike
             ) -> tuple[Array, Array]:
    """Goals ``g_i = mu (c - p_i) + p_i + q`` and speeds ``max(s_s,i, k_s ||p_i - g_i||)``."""
    p = np.asarray(p_ne_m, dtype=np.float64)
    c = centroid(p)
    goal = mu * (c - p) + p + np.asarray(q_ne_m, dtype=np.float64).reshape(1, 2)
    d = np.hypot(*(p - goal).T)
    return goal, np.maximum(np.asarray(stall_mps, dtype=np.float64), k_s * d)


def clip_speed_mps(speed_mps: ArrayLike, stall_mps: ArrayLike, min_mps: ArrayLike,
                   max_mps: ArrayLike) -> Array:
    """Speeds inside ``[max(min_i, s_s,i), max_i]``; where the stall speed is above
    the envelope maximum the maximum is returned (the vehicle cannot fly
    faster) -- callers should report that case."""
    lo = np.maximum(np.asarray(min_mps, dtype=np.float64), np.asarray(stall_mps, dtype=np.float64))
    hi = np.asarray(max_mps, dtype=np.float64)
    return np.asarray(np.minimum(np.maximum(np.asarray(speed_mps, dtype=np.float64), lo), hi),
                      dtype=np.float64)


def q_vector_ne_m(bearing_deg: float, distance_m: float) -> Array:
    """The flocking bias q as (north, east) metres from a bearing and a length."""
    b = math.radians(bearing_deg)
    return np.array([distance_m * math.cos(b), distance_m * math.sin(b)])


def float32_at_least(x: ArrayLike) -> NDArray[np.float32]:
    """The float32 nearest ``x`` that is not below it (MAVLink params are float32:
    a speed rounded down could land below the stall speed it was clipped to)."""
    a = np.asarray(x, dtype=np.float64)
    f = a.astype(np.float32)
    low = f.astype(np.float64) < a
    return np.where(low, np.nextafter(f, np.float32(np.inf)), f).astype(np.float32)


def level_stall_constant_mps(mass_kg: float, wing_area_m2: float, clmax: float,
                             alt_msl_m: ArrayLike) -> Array:
    """The level-flight stall true airspeed ``sqrt(2 m g / (rho(h) S CL_max))``
    at altitude (ISA density), from the model's own numbers."""
    from cosim.analysis.flight import isa_density
    from cosim.core.units import G_MPS2

    rho = np.asarray(isa_density(alt_msl_m), dtype=np.float64)
    return np.asarray(np.sqrt(2.0 * mass_kg * G_MPS2 / (rho * wing_area_m2 * clmax)),
                      dtype=np.float64)
