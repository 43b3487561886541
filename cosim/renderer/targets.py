"""Targets: 3-D boxes on the ground, drawn with flat shading from the sun
(``cosim.world.sun``) in painter's order, and each target's ground truth.

A target is a set of boxes in its own frame (x along its heading, y right,
z down, origin on the ground under its centre). Its ground-truth box is the
box around all of them; a fire's is its burning patch up to the flame height
(the smoke is drawn but is not part of the target). Placement is exact: the
target's ground point is fixed geodetically once and converted into each
frame's local plane ``L`` (see ``camera``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from cosim.core.geo import LocalFrame, geodetic_to_ecef
from cosim.world.sun import DEFAULT as DEFAULT_SUN
from cosim.world.targets import TargetSpec

#: unit vector toward the sun without a ``sun:`` section (NED)
SUN_TO_L = DEFAULT_SUN.to_sun_ned()
AMBIENT = 0.45

# unit box corners (x, y, z in 0..1) and faces (outward, counter-clockwise seen from outside)
#: a unit box's 8 corners (x, y, z in 0/1), the order FACE_IDX refers to
UNIT_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
_FACES = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
FACE_IDX = np.array(_FACES)
FACE_NORMALS = np.array([[-1.0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]])


@dataclass(frozen=True)
class Part:
    lo: tuple[float, float, float]  # (x, y, z) min corner in the target frame (z down)
    hi: tuple[float, float, float]
    color_rgb: tuple[int, int, int]


def _shade(c: tuple[int, int, int], k: float) -> tuple[int, int, int]:
    return (int(min(255, c[0] * k)), int(min(255, c[1] * k)), int(min(255, c[2] * k)))


#: wheels and tyres (a vehicle's axles), a person's skin and hair
WHEEL_RGB = (28, 28, 30)
SKIN_RGB = (190, 150, 120)
HAIR_RGB = (60, 45, 35)


def _axles(L: float, W: float, clear_m: float, centres_x: tuple[float, ...],
           wheel_m: float) -> list[Part]:
    """One dark box per axle: its wheels' lower parts below the body (``clear_m``
    high, ``wheel_m`` long), across the width inset by 4 % a side."""
    hw = 0.46 * W
    return [Part((x - wheel_m / 2, -hw, -clear_m), (x + wheel_m / 2, hw, 0.0), WHEEL_RGB)
            for x in centres_x]


def parts_of(t: TargetSpec, time_s: float = 0.0, seed: int = 0) -> list[Part]:
    """The boxes of target ``t`` (a fire's flames depend on time and seed).

    Vehicles stand on their axles (dark boxes below the body, seen from the
    side and obliquely); a person has legs, torso, arms and a head. All lie
    inside ``bounding_part``."""
    L, W, H, c = t.length_m, t.width_m, t.height_m, t.color_rgb
    hl, hw = L / 2, W / 2
    if t.kind == "truck":  # cab ahead of a box load, three axles
        cab, clear = 0.2 * L, 0.25 * H
        return [*_axles(L, W, clear, (0.38 * L, -0.17 * L, -0.28 * L), 0.1 * L),
                Part((hl - cab, -hw, -0.8 * H), (hl, hw, -clear), _shade(c, 0.8)),
                Part((-hl, -hw, -H), (hl - cab - 0.02 * L, hw, -clear), c)]
    if t.kind == "fire_truck":  # red body on two axles, lime-yellow roof band, white ladder
        clear = 0.25 * H
        return [*_axles(L, W, clear, (0.33 * L, -0.25 * L), 0.1 * L),
                Part((-hl, -hw, -0.9 * H), (hl, hw, -clear), c),
                Part((-0.4 * L, -0.32 * W, -H), (0.3 * L, 0.32 * W, -0.9 * H), (200, 230, 20)),
                Part((-0.45 * L, -0.1 * W, -1.06 * H), (0.35 * L, 0.1 * W, -H),
                     (235, 235, 235))]
    if t.kind == "car":  # body on two axles, a darker cabin (its windows) on top
        clear = 0.22 * H
        return [*_axles(L, W, clear, (0.31 * L, -0.31 * L), 0.14 * L),
                Part((-hl, -hw, -0.58 * H), (hl, hw, -clear), c),
                Part((-0.25 * L, -0.42 * W, -H), (0.2 * L, 0.42 * W, -0.58 * H),
                     _shade(c, 0.7))]
    if t.kind == "person":  # trousers a darker shade of the clothing, skin and hair fixed
        legs, sleeves = _shade(c, 0.55), _shade(c, 0.9)
        return [Part((-0.2 * L, -0.3 * W, -0.47 * H), (0.2 * L, -0.04 * W, 0.0), legs),
                Part((-0.2 * L, 0.04 * W, -0.47 * H), (0.2 * L, 0.3 * W, 0.0), legs),
                Part((-0.25 * L, -0.32 * W, -0.82 * H), (0.25 * L, 0.32 * W, -0.47 * H), c),
                Part((-0.15 * L, -hw, -0.81 * H), (0.15 * L, -0.34 * W, -0.45 * H), sleeves),
                Part((-0.15 * L, 0.34 * W, -0.81 * H), (0.15 * L, hw, -0.45 * H), sleeves),
                Part((-0.22 * L, -0.22 * W, -0.95 * H), (0.22 * L, 0.22 * W, -0.82 * H),
                     SKIN_RGB),
                Part((-0.24 * L, -0.24 * W, -H), (0.22 * L, 0.24 * W, -0.95 * H), HAIR_RGB)]
    # fire: a charred patch and flickering flames (deterministic from seed and time)
    char = min(0.05, 0.1 * H)  # the patch's thickness (5 cm, less for a fire under 0.5 m)
    out = [Part((-hl, -hw, -char), (hl, hw, 0.0), (35, 30, 28))]
    rng = np.random.default_rng([seed, 4242])
    n = 6
    xs, ys = rng.uniform(-0.35, 0.35, n) * L, rng.uniform(-0.35, 0.35, n) * W
    ph, fr = rng.uniform(0, 2 * np.pi, n), rng.uniform(2.0, 5.0, n)
    for i in range(n):
        h = H * (0.45 + 0.55 * abs(math.sin(fr[i] * time_s + ph[i])))
        s = 0.12 * min(L, W) * (1.0 + 0.3 * math.sin(1.7 * fr[i] * time_s + ph[i]))
        col = (255, 200, 40) if i % 2 else c
        out.append(Part((max(-hl, xs[i] - s), max(-hw, ys[i] - s), -h),
                        (min(hl, xs[i] + s), min(hw, ys[i] + s), -char), col))  # inside the patch
    return out


@functools.lru_cache(maxsize=256)
def hidden_faces(parts: tuple[Part, ...]) -> np.ndarray:
    """(P, 6) bool, in ``FACE_IDX`` order: the faces of ``parts`` that lie flat
    against another part's opposite face and inside it (an axle's top under
    the body, a leg's under the torso). Never seen, they are not drawn: the
    painter's order, by each face's centre, could otherwise put one over the
    part it touches."""
    lo = np.array([p.lo for p in parts])
    hi = np.array([p.hi for p in parts])
    out = np.zeros((len(parts), 6), dtype=bool)
    for f in range(6):
        axis, outward = f // 2, f % 2  # FACE_NORMALS: -x, +x, -y, +y, -z, +z
        plane = (hi if outward else lo)[:, axis]
        other_plane = (lo if outward else hi)[:, axis]
        across = [a for a in range(3) if a != axis]
        for p in range(len(parts)):
            touching = np.isclose(other_plane, plane[p], rtol=0.0, atol=1e-9)
            touching[p] = False
            covers = (touching & (lo[:, across] <= lo[p, across] + 1e-9).all(axis=1)
                      & (hi[:, across] >= hi[p, across] - 1e-9).all(axis=1))
            out[p, f] = bool(covers.any())
    out.flags.writeable = False
    return out


def smoke_puffs(t: TargetSpec, time_s: float, seed: int) -> list[tuple[np.ndarray, float, float]]:
    """A fire's smoke puffs at ``time_s``: (centre in the target frame, radius_m, alpha)."""
    if t.kind != "fire":
        return []
    rng = np.random.default_rng([seed, 777])
    wind = rng.uniform(-1, 1, 2) * 1.5  # drift, m/s
    period, life = 0.6, 8.0
    out = []
    k_last = math.floor(time_s / period)
    for k in range(k_last - int(life / period), k_last + 1):
        age = time_s - k * period
        if age < 0 or age > life:
            continue
        j = np.random.default_rng([seed, 778, k & 0xFFFFFFFF]).uniform(-0.3, 0.3, 2)
        centre = np.array([j[0] * t.length_m + wind[0] * age, j[1] * t.width_m + wind[1] * age,
                           -(t.height_m + 2.0 * age)])
        out.append((centre, 0.3 * max(t.length_m, t.width_m) + 0.6 * age,
                    0.55 * (1.0 - age / life)))
    return out


def box_corners(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> np.ndarray:
    lo_a, hi_a = np.array(lo), np.array(hi)
    out: np.ndarray = lo_a + UNIT_CORNERS * (hi_a - lo_a)
    return out


def bounding_part(t: TargetSpec) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The target's ground-truth box (lo, hi) in its own frame."""
    hl, hw = t.length_m / 2, t.width_m / 2
    top = -t.height_m * (1.06 if t.kind == "fire_truck" else 1.0)
    return (-hl, -hw, top), (hl, hw, 0.0)


class TargetSet:
    """All targets, their ground points fixed geodetically at start."""

    def __init__(self, targets: tuple[TargetSpec, ...], frame: LocalFrame, ground_alt_m: float
                 ) -> None:
        self.specs = targets
        lat, lon = [], []
        for t in targets:
            if t.lat_deg is not None and t.lon_deg is not None:
                la, lo = t.lat_deg, t.lon_deg
            else:
                la_a, lo_a = frame.place(t.north_m or 0.0, t.east_m or 0.0, ground_alt_m)
                la, lo = float(la_a), float(lo_a)
            lat.append(la)
            lon.append(lo)
        self.lat_deg = np.array(lat)
        self.lon_deg = np.array(lon)
        self.ground_alt_m = ground_alt_m
        ne = frame.geodetic_to_ned(self.lat_deg, self.lon_deg, np.full(len(lat), ground_alt_m))
        self.north_m, self.east_m = ne[0], ne[1]  # in the scenario frame (for maps)
        self.ecef_m = geodetic_to_ecef(self.lat_deg, self.lon_deg,
                                       np.full(len(lat), ground_alt_m))

    def origins_in(self, local: LocalFrame, local_ecef_m: np.ndarray) -> np.ndarray:
        """(n, 3) each target's ground point in the frame ``local`` (whose origin
        in ECEF is ``local_ecef_m``)."""
        if not self.specs:
            return np.zeros((0, 3))
        # LocalFrame.geodetic_to_ned's arithmetic, from the ECEF points kept at start
        x, y, z = self.ecef_m
        ox, oy, oz = local_ecef_m
        dx, dy, dz = x - ox, y - oy, z - oz
        lat, lon = np.radians(local.lat_deg), np.radians(local.lon_deg)
        sl, cl, so, co = (float(np.sin(lat)), float(np.cos(lat)), float(np.sin(lon)),
                          float(np.cos(lon)))
        out = np.empty((len(self.specs), 3))
        out[:, 0] = (-sl * co) * dx + (-sl * so) * dy + cl * dz
        out[:, 1] = -so * dx + co * dy
        out[:, 2] = (-cl * co) * dx + (-cl * so) * dy - sl * dz
        return out


def heading_rotation(t: TargetSpec) -> np.ndarray:
    a = math.radians(t.heading_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def to_local(t: TargetSpec, origin_l: np.ndarray, pts_t: np.ndarray) -> np.ndarray:
    """Target-frame points -> L (rotation by the heading; the target's own north
    differs from L's by far less than a millimetre over a target's size)."""
    out: np.ndarray = origin_l + pts_t @ heading_rotation(t).T
    return out


def lambert(normal_l: np.ndarray, sun_l: np.ndarray = SUN_TO_L) -> float:
    """A face's brightness (0..1 of its colour): the ambient share plus the
    direct share times the cosine of the sun's angle to the face's normal."""
    return AMBIENT + (1.0 - AMBIENT) * max(0.0, float(np.dot(normal_l, sun_l)))
