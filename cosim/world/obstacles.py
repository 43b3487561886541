"""Obstacles: polygons on the ground that vehicles keep out of.

The scenario's ``obstacles:`` section lists them in the scenario's local
frame (north/east metres from the origin)::

    obstacles:
      - {id: barn, height_m: 6, polygon: [[40, -10], [40, 10], [60, 10], [60, -10]]}

A polygon is simple (its edges do not cross), 3 to ``MAX_VERTICES`` corners
in either winding, at most ``MAX_OBSTACLES`` of them, each within
``MAX_DISTANCE_M`` of the origin. Cameras see them as buildings: walls of
``color`` (concrete grey) and a ``roof`` (``flat``, the default, or, over a
convex polygon of 4 corners, ``gable`` or ``hip``, ``roof_height_m`` high
with ``height_m`` its top, so what vehicles keep out of does not depend on
the look) of ``roof_color`` (the walls' unless given). Vehicle classes that keep out of them read
them from the world through ``VehicleClass.with_world``; everything here is plain
geometry on ``(n, 2)`` arrays, elementwise, so results never depend on how
many points are tested together.
"""

from __future__ import annotations

import functools
import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.core.geo import MAX_DISTANCE_M
from cosim.core.section import SectionContext
from cosim.world.targets import rgb

MAX_OBSTACLES = 1000
MAX_VERTICES = 64
MAX_HEIGHT_M = 500.0
#: the roofs a building may have (gable and hip: over a convex polygon of 4 corners)
ROOFS = ("flat", "gable", "hip")
#: walls' (and, unless given, roofs') colour (RGB): concrete grey
WALL_RGB = (150, 148, 140)


@dataclass(frozen=True)
class Obstacle:
    id: str
    polygon: tuple[tuple[float, float], ...]  # (north_m, east_m) corners in order
    height_m: float  # its top: the roof's ridge, or its flat roof
    roof: str = "flat"
    roof_height_m: float = 0.0  # ridge above the walls' top (0: flat)
    color_rgb: tuple[int, int, int] = WALL_RGB  # walls (and gable ends)
    roof_rgb: tuple[int, int, int] = WALL_RGB

    @property
    def array(self) -> np.ndarray:
        return np.array(self.polygon, dtype=float)


def parse_obstacles(info: SectionContext, node: Any, path: tuple[Any, ...]
                    ) -> tuple[Obstacle, ...]:
    """The ``obstacles:`` section (see the module docstring); problems go to ``info``."""
    if not isinstance(node, list):
        info.err(path, f"expected a list of obstacles, got {node!r}")
        return ()
    if len(node) > MAX_OBSTACLES:
        info.err(path, f"{len(node)} obstacles; at most {MAX_OBSTACLES}")
        return ()
    out: list[Obstacle] = []
    seen: set[str] = set()
    for i, d in enumerate(node):
        p = path + (i,)
        r = info.reader(d, p, ("id", "polygon", "height_m", "roof", "roof_height_m", "color",
                               "roof_color"))
        oid = r.string("id", f"obstacle{i}")
        if oid in seen:
            info.err(p + ("id",), f"id {oid!r} repeats an earlier obstacle's")
        seen.add(oid)
        height = r.num("height_m", 3.0, lo=0.0, lo_open=True, hi=MAX_HEIGHT_M)
        poly = _polygon(info, r.d.get("polygon"), p + ("polygon",))
        roof = r.string("roof", "flat", choices=ROOFS)
        roof_h = _roof_height(info, r, p, roof, height)
        if roof in ("gable", "hip") and poly is not None and not _convex_quad(np.array(poly)):
            info.err(p + ("roof",), f"a {roof} roof needs a convex polygon of 4 corners, got "
                                    f"{len(poly)} corners{'' if len(poly) != 4 else ' not convex'}"
                                    "; give roof: flat")
            roof = None
        wall = rgb(info, r.d["color"], p + ("color",)) if r.has("color") else WALL_RGB
        top = rgb(info, r.d["roof_color"], p + ("roof_color",)) if r.has("roof_color") else wall
        if (oid is not None and height is not None and poly is not None and roof is not None
                and roof_h is not None and wall is not None and top is not None):
            out.append(Obstacle(oid, poly, height, roof, roof_h, wall, top))
    return tuple(out)


def _roof_height(info: SectionContext, r: Any, p: tuple[Any, ...], roof: str | None,
                 height_m: float | None) -> float | None:
    """``roof_height_m``: 0 for a flat roof (refused if given), else below
    ``height_m`` (the walls keep some height), half of it by default."""
    if roof != "flat":
        h = r.num("roof_height_m", None, lo=0.0, lo_open=True, hi=MAX_HEIGHT_M)
        if height_m is None or roof is None:
            return h
        if h is None:
            return None if r.has("roof_height_m") else height_m / 2
        if h >= height_m:
            info.err(p + ("roof_height_m",), f"must be below height_m ({height_m:g}, the "
                                             f"roof's top: the walls end at height_m - "
                                             f"roof_height_m), got {h:g}")
            return None
        return float(h)
    if r.has("roof_height_m"):
        info.err(p + ("roof_height_m",), "a flat roof has no height: give roof: gable or hip")
        return None
    return 0.0


def _convex_quad(a: np.ndarray) -> bool:
    """Whether ``a`` has 4 corners and turns the same way at each."""
    if len(a) != 4:
        return False
    turns = [_orient(a[i - 1], a[i], a[(i + 1) % 4]) for i in range(4)]
    return all(t > 0 for t in turns) or all(t < 0 for t in turns)


def _polygon(info: Any, raw: Any, p: tuple[Any, ...]) -> tuple[tuple[float, float], ...] | None:
    if not isinstance(raw, list) or not 3 <= len(raw) <= MAX_VERTICES:
        info.err(p, f"expected a list of 3 to {MAX_VERTICES} [north_m, east_m] corners, "
                    f"got {raw!r}"[:300])
        return None
    pts = []
    for j, c in enumerate(raw):
        ok = (isinstance(c, list) and len(c) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                      and math.isfinite(x) and abs(x) <= MAX_DISTANCE_M for x in c))
        if not ok:
            info.err(p + (j,), f"expected [north_m, east_m] within {MAX_DISTANCE_M:g} m of the "
                               f"origin, got {c!r}"[:300])
            return None
        pts.append((float(c[0]), float(c[1])))
    a = np.array(pts)
    if _self_crossing(a):
        info.err(p, "the polygon's edges cross each other")
        return None
    if abs(signed_area(a)) < 1e-6:
        info.err(p, "the polygon has no area")
        return None
    return tuple(pts)


def signed_area(a: np.ndarray) -> float:
    """The shoelace area of polygon ``a`` ((k, 2)): positive counter-clockwise in
    (north, east), i.e. clockwise seen from above."""
    x, y = a[:, 0], a[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _self_crossing(a: np.ndarray) -> bool:
    """Whether two edges of polygon ``a`` that are not neighbours cross
    (``segments_cross``'s rule and arithmetic, every pair at once: the 1,952
    pairs of a 64-corner polygon in one pass, not one Python call each)."""
    i, j = _edge_pairs(len(a))
    x, y = a[:, 0], a[:, 1]
    xq, yq = np.roll(x, -1), np.roll(y, -1)  # edge k runs from (x, y)[k] to (xq, yq)[k]
    dx, dy = xq - x, yq - y
    xi, yi, xj, yj = x[i], y[i], x[j], y[j]
    xqi, yqi, xqj, yqj = xq[i], yq[i], xq[j], yq[j]
    dxi, dyi, dxj, dyj = dx[i], dy[i], dx[j], dy[j]
    # _orient(p, q, c) = (q - p) x (c - p), term for term
    o1 = dxi * (yj - yi) - dyi * (xj - xi)
    o2 = dxi * (yqj - yi) - dyi * (xqj - xi)
    o3 = dxj * (yi - yj) - dyj * (xi - xj)
    o4 = dxj * (yqi - yj) - dyj * (xqi - xj)
    return bool(((o1 * o2 < 0) & (o3 * o4 < 0)).any())


@functools.lru_cache(maxsize=MAX_VERTICES)
def _edge_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j) of an n-gon's edges that are not neighbours, i < j."""
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))  # the closing edge and the first
    i, j = i[keep], j[keep]
    i.flags.writeable = j.flags.writeable = False  # shared by every polygon of n corners
    return i, j


def inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Whether each of ``pts`` ((n, 2) north/east) lies inside ``poly`` (even-odd
    rule; a point on an edge may go either way). Elementwise over ``pts``."""
    x, y = pts[:, 0], pts[:, 1]
    out = np.zeros(len(pts), dtype=bool)
    k = len(poly)
    for i in range(k):
        (x1, y1), (x2, y2) = poly[i], poly[(i + 1) % k]
        if y1 == y2:
            continue
        crosses = (y1 > y) != (y2 > y)
        xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        out ^= crosses & (x < xc)
    return out


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
    """Whether segments ab and cd cross at a point inside both (touching ends do not)."""
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    return (o1 * o2 < 0) and (o3 * o4 < 0)


def inflate(poly: np.ndarray, margin_m: float) -> np.ndarray:
    """The polygon grown by ``margin_m``: each corner pushed out along the
    bisector of its edges' outward normals, far enough that every edge moves
    out by ``margin_m`` (a mitre; convex and concave corners alike)."""
    a = poly if signed_area(poly) > 0 else poly[::-1]  # counter-clockwise in (north, east)
    n = len(a)
    out = np.empty_like(a)
    for i in range(n):
        p, c, q = a[i - 1], a[i], a[(i + 1) % n]
        n1 = _normal(p, c)
        n2 = _normal(c, q)
        b = n1 + n2
        cosh = float(np.dot(b / np.linalg.norm(b), n1)) if np.linalg.norm(b) > 1e-12 else 1.0
        out[i] = c + b / np.linalg.norm(b) * margin_m / max(cosh, 0.2)
    return out


def _normal(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The outward unit normal of edge pq of a counter-clockwise polygon."""
    d = q - p
    return np.array([d[1], -d[0]]) / math.hypot(d[0], d[1])


def segment_clear(a: np.ndarray, b: np.ndarray, polys: Sequence[np.ndarray]) -> bool:
    """Whether segment ab stays out of every polygon (crossing no edge, and
    its midpoint outside: a segment between two corners of one polygon may
    run through it)."""
    mid = (a + b)[None, :] / 2
    for poly in polys:
        k = len(poly)
        for i in range(k):
            if segments_cross(a, b, poly[i], poly[(i + 1) % k]):
                return False
        if inside(poly, mid)[0]:
            return False
    return True


def plan_route(start: np.ndarray, goal: np.ndarray, polys: Sequence[np.ndarray]
               ) -> list[np.ndarray] | None:
    """The shortest path from ``start`` to ``goal`` that keeps out of ``polys``
    (already grown by the vehicle's margin), through their corners: a
    visibility graph and Dijkstra. ``None`` if there is none (the goal inside
    one, or enclosed). The start is not in the path; the goal is its last point."""
    # a start inside a grown polygon (within the margin of an obstacle just
    # learnt of) may leave it: those polygons do not block its first leg
    around = [p for p in polys if not inside(p, start[None, :])[0]]
    if segment_clear(start, goal, around):
        return [goal]
    if any(inside(p, goal[None, :])[0] for p in polys):
        return None
    nodes = [start, goal] + [c for p in polys for c in p
                             if not any(inside(q, c[None, :])[0] for q in polys)]
    dist = {0: 0.0}
    prev: dict[int, int] = {}
    heap = [(0.0, 0)]
    done: set[int] = set()
    while heap:
        d, i = heapq.heappop(heap)
        if i in done:
            continue
        done.add(i)
        if i == 1:
            break
        for j in range(1, len(nodes)):
            if j in done:
                continue
            nd = d + float(np.hypot(*(nodes[j] - nodes[i])))
            if nd < dist.get(j, math.inf) and segment_clear(nodes[i], nodes[j],
                                                            around if i == 0 else polys):
                dist[j] = nd
                prev[j] = i
                heapq.heappush(heap, (nd, j))
    if 1 not in done:
        return None
    path = [1]
    while path[-1] != 0:
        path.append(prev[path[-1]])
    return [nodes[k] for k in reversed(path[:-1])]
