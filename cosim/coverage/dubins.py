"""Shortest paths of bounded curvature between two poses (Dubins paths).

A fixed-wing cannot turn tighter than ``R = v^2 / (g tan(bank))``; the
shortest path from one pose to another with that bound is one of six words
of arcs of radius ``R`` (L: turning left, R: turning right) and straight
segments (S): LSL, RSR, LSR, RSL, RLR, LRL (Dubins, 1957; the closed forms
as in Shkel and Lumelsky, 2001). Poses are ``(x_m, y_m, heading_rad)`` in
a right-handed plane (x east, y north), the heading counter-clockwise from
+x; a left turn is counter-clockwise.

Each word's closed form is checked by flying it: a candidate whose end is
not the goal (a degenerate case of the formulas) is dropped, so a path this
module returns always ends where it was asked to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_TWO_PI = 2.0 * math.pi
_END_TOL_M = 1e-6  # relative to R: a word must end this close to the goal


def _mod(a: float) -> float:
    return a % _TWO_PI


@dataclass(frozen=True)
class DubinsPath:
    """``word`` (e.g. "LSR") with its three segment lengths in units of ``radius_m``."""

    start: tuple[float, float, float]
    word: str
    lengths: tuple[float, float, float]
    radius_m: float

    @property
    def length_m(self) -> float:
        return sum(self.lengths) * self.radius_m

    def sample(self, step_m: float) -> np.ndarray:
        """Points every ``step_m`` (at most) along the path, both ends
        included: ``(k, 3)`` of ``x_m, y_m, heading_rad``."""
        out = [self.start]
        x, y, h = self.start
        r = self.radius_m
        for kind, seg in zip(self.word, self.lengths):
            n = max(1, math.ceil(seg * r / step_m))
            for _ in range(n):
                x, y, h = _advance((x, y, h), kind, seg / n, r)
                out.append((x, y, h))
        return np.array(out)

    def end(self) -> tuple[float, float, float]:
        p = self.start
        for kind, seg in zip(self.word, self.lengths):
            p = _advance(p, kind, seg, self.radius_m)
        return p


@dataclass(frozen=True)
class DubinsChain:
    """Dubins paths flown one after another, each from the pose where the
    last one ends: a detour through waypoint poses. Same interface as a
    ``DubinsPath`` (``start``, ``length_m``, ``sample``, ``end``)."""

    paths: tuple[DubinsPath, ...]

    @property
    def start(self) -> tuple[float, float, float]:
        return self.paths[0].start

    @property
    def length_m(self) -> float:
        return sum(p.length_m for p in self.paths)

    def sample(self, step_m: float) -> np.ndarray:
        """As ``DubinsPath.sample``, the joints once each."""
        parts = [self.paths[0].sample(step_m)] + [p.sample(step_m)[1:] for p in self.paths[1:]]
        return np.vstack(parts)

    def end(self) -> tuple[float, float, float]:
        return self.paths[-1].end()


def _advance(p: tuple[float, float, float], kind: str, seg: float, r: float
             ) -> tuple[float, float, float]:
    """Fly ``seg`` (radians of arc, or radius-lengths of straight) of ``kind``."""
    x, y, h = p
    if kind == "S":
        return x + seg * r * math.cos(h), y + seg * r * math.sin(h), h
    turn = seg if kind == "L" else -seg
    # the centre is to the left (L) or right (R) of the heading
    side = 1.0 if kind == "L" else -1.0
    cx, cy = x - side * r * math.sin(h), y + side * r * math.cos(h)
    h2 = h + turn
    return cx + side * r * math.sin(h2), cy - side * r * math.cos(h2), h2


def _words(a: float, b: float, d: float) -> dict[str, tuple[float, float, float] | None]:
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    out: dict[str, tuple[float, float, float] | None] = {}
    p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
    if p2 >= 0:
        th = math.atan2(cb - ca, d + sa - sb)
        out["LSL"] = (_mod(-a + th), math.sqrt(p2), _mod(b - th))
    p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
    if p2 >= 0:
        th = math.atan2(ca - cb, d - sa + sb)
        out["RSR"] = (_mod(a - th), math.sqrt(p2), _mod(-b + th))
    p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        th = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        out["LSR"] = (_mod(-a + th), p, _mod(-_mod(b) + th))
    p2 = -2 + d * d + 2 * cab - 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        th = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        out["RSL"] = (_mod(a - th), p, _mod(b - th))
    tmp = (6.0 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8.0
    if abs(tmp) <= 1:
        p = _mod(_TWO_PI - math.acos(tmp))
        t = _mod(a - math.atan2(ca - cb, d - sa + sb) + p / 2.0)
        out["RLR"] = (t, p, _mod(a - b - t + p))
    tmp = (6.0 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8.0
    if abs(tmp) <= 1:
        p = _mod(_TWO_PI - math.acos(tmp))
        t = _mod(-a - math.atan2(ca - cb, d + sa - sb) + p / 2.0)
        out["LRL"] = (t, p, _mod(_mod(b) - a - t + p))
    return out


def shortest(start: tuple[float, float, float], goal: tuple[float, float, float],
             radius_m: float) -> DubinsPath:
    """The shortest path from ``start`` to ``goal`` turning no tighter than
    ``radius_m``."""
    return candidates(start, goal, radius_m)[0]


def candidates(start: tuple[float, float, float], goal: tuple[float, float, float],
               radius_m: float) -> list[DubinsPath]:
    """Every word's path from ``start`` to ``goal`` turning no tighter than
    ``radius_m``, shortest first (ties in the order LSL, RSR, LSR, RSL, RLR,
    LRL): the others are for when the shortest runs where it must not."""
    if not radius_m > 0:
        raise ValueError(f"radius_m must be > 0, got {radius_m}")
    dx, dy = goal[0] - start[0], goal[1] - start[1]
    d = math.hypot(dx, dy) / radius_m
    phi = math.atan2(dy, dx) if d > 0 else 0.0
    a, b = _mod(start[2] - phi), _mod(goal[2] - phi)
    out: list[DubinsPath] = []
    for word, lengths in _words(a, b, d).items():
        if lengths is None:
            continue
        path = DubinsPath(start, word, lengths, radius_m)
        ex, ey, eh = path.end()
        dh = abs(math.remainder(eh - goal[2], _TWO_PI))
        if math.hypot(ex - goal[0], ey - goal[1]) > _END_TOL_M * max(1.0, radius_m) or dh > 1e-6:
            continue  # a degenerate closed form: not a path to the goal
        out.append(path)
    if not out:  # cannot happen for a positive radius; say so if it does
        raise ValueError(f"no Dubins path from {start} to {goal} with radius {radius_m} m")
    out.sort(key=lambda p: p.length_m)  # stable: ties keep the words' order
    return out

#: a join between lanes, a transit: one Dubins path or a chain of them (a detour)
Flight = DubinsPath | DubinsChain
