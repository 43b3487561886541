"""Buildings: the scenario's obstacles as walls and roofs, and their shadows.

An obstacle (``cosim.world.obstacles.Obstacle``) stands on the ground plane
of the scenario frame: walls up to ``height_m - roof_height_m`` and a roof
whose top is ``height_m``. A flat roof is the polygon itself (it may be
concave); a gable roof over a convex quadrilateral runs its ridge between
the midpoints of the two shorter opposite edges (the gable ends, wall
triangles, take the walls' colour); a hip roof's ridge is that line cut
short by half the mean short edge at each end, so that every slope rises
``roof_height_m`` over the same run on a rectangle (a square's ridge is a
point: a pyramid). A roof slope that is not planar (a quadrilateral not a
rectangle) is drawn as two triangles. Every face carries its outward normal
for the sun's shading.

A building's shadow on the ground is the convex hull of its base and of its
points above the ground moved ``h / tan(elevation)`` away from the sun: exact
for a convex building on flat ground, which a gable or hip house is; the hull
of a concave flat-roofed one covers its courtyards too.

Buildings are made in the scenario frame (north, east, down metres), once;
``BuildingSet`` moves those in view into each frame's axes (the rotation and
shift the frame module gives) as faces for the frame's painter. Nothing here
draws.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from cosim.core.camera import NEAR_M, Pose, clip_near, project
from cosim.renderer.targets import lambert
from cosim.world.obstacles import Obstacle, inside, signed_area

#: a face for the frame's painter: (painter's depth, depth, camera-axis
#: polygon, BGRA, target id: 0, a building being no target)
Face = tuple[float, float, np.ndarray, tuple[int, int, int, int], int]


@dataclass(frozen=True)
class Building:
    """An obstacle's points (m x 3, scenario NED: its base's corners counter-
    clockwise in (north, east), the walls' tops, then the roof's own points)
    and its faces: (indices into the points, outward unit normal, RGB)."""

    points: np.ndarray
    faces: tuple[tuple[np.ndarray, np.ndarray, tuple[int, int, int]], ...]

    @property
    def normals(self) -> np.ndarray:
        """The faces' outward unit normals (F x 3)."""
        return np.array([n for _, n, _ in self.faces])

    @property
    def centres(self) -> np.ndarray:
        """The faces' centres, the mean of their corners (F x 3)."""
        return np.array([self.points[idx].mean(axis=0) for idx, _, _ in self.faces])


def building(o: Obstacle) -> Building:
    """The walls and roof of obstacle ``o`` (see the module docstring). A flat
    roof comes first, then the walls in order: the faces the renderer drew
    before roofs had kinds, in the same order."""
    poly = np.array(o.polygon, dtype=float)
    ccw = poly if signed_area(poly) > 0 else poly[::-1]
    k = len(ccw)
    wall_top_m = o.height_m - o.roof_height_m
    pts = [np.column_stack([ccw, np.zeros(k)]), np.column_stack([ccw, np.full(k, -wall_top_m)])]
    faces: list[tuple[tuple[int, ...], np.ndarray, tuple[int, int, int]]] = []
    if o.roof == "flat":
        faces.append((tuple(range(k, 2 * k)), np.array([0.0, 0.0, -1.0]), o.roof_rgb))
    walls = []
    for i in range(k):
        j = (i + 1) % k
        walls.append(((i, j, k + j, k + i), _wall_normal(ccw[i], ccw[j]), o.color_rgb))
    faces.extend(walls)
    if o.roof != "flat":
        ridge, roof_faces = _pitched(o, ccw, k)
        pts.append(ridge)
        every = np.concatenate(pts)
        for idx, rgb_, wall in roof_faces:
            if wall >= 0:  # a gable end: upright, facing as its wall
                faces.append((idx, walls[wall][1], rgb_))
            else:
                faces.extend(_planar_pieces(every, idx, rgb_))
        pts = [every]
    points = np.concatenate(pts)
    points.flags.writeable = False
    return Building(points, tuple((np.array(idx, dtype=np.intp), n, c) for idx, n, c in faces))


def _wall_normal(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The outward unit normal (NED) of the wall on edge pq of a counter-clockwise polygon."""
    d = q - p
    return np.array([d[1], -d[0], 0.0]) / math.hypot(d[0], d[1])


def _pitched(o: Obstacle, ccw: np.ndarray, k: int
             ) -> tuple[np.ndarray, list[tuple[tuple[int, ...], tuple[int, int, int], int]]]:
    """A gable or hip roof over 4 corners: its ridge's two points (2 x 3, NED)
    and its faces as (indices into base, wall tops, ridge; RGB; the wall a
    gable end stands on, else -1)."""
    lengths = np.hypot(*(np.roll(ccw, -1, axis=0) - ccw).T)
    s = 0 if lengths[0] + lengths[2] <= lengths[1] + lengths[3] else 1  # a short edge
    mid_a = (ccw[s] + ccw[s + 1]) / 2
    mid_b = (ccw[s + 2] + ccw[(s + 3) % 4]) / 2
    if o.roof == "hip":  # the ridge cut short by half the mean short edge at each end
        run = float(np.hypot(*(mid_b - mid_a)))
        t = 0.5 if run <= 0 else min(0.5, (lengths[s] + lengths[s + 2]) / 4 / run)
        mid_a, mid_b = mid_a + t * (mid_b - mid_a), mid_b + t * (mid_a - mid_b)
    ridge = np.array([[*mid_a, -o.height_m], [*mid_b, -o.height_m]])
    a, b = 2 * k, 2 * k + 1  # the ridge's points
    top = [k + (s + n) % 4 for n in range(4)]  # wall tops from the short edge s on
    ends: list[tuple[tuple[int, ...], tuple[int, int, int], int]]
    if o.roof == "hip":  # the ends are slopes too
        ends = [((top[0], top[1], a), o.roof_rgb, -1), ((top[2], top[3], b), o.roof_rgb, -1)]
    else:  # gable ends: upright triangles on the short edges' walls
        ends = [((top[0], top[1], a), o.color_rgb, s),
                ((top[2], top[3], b), o.color_rgb, (s + 2) % 4)]
    return ridge, ends + [((top[1], top[2], b, a), o.roof_rgb, -1),
                          ((top[3], top[0], a, b), o.roof_rgb, -1)]


def _planar_pieces(points: np.ndarray, idx: tuple[int, ...], rgb_: tuple[int, int, int]
                   ) -> list[tuple[tuple[int, ...], np.ndarray, tuple[int, int, int]]]:
    """A roof slope as planar faces with their upward unit normals: the face
    itself if its corners lie in one plane (within 1 mm), else two triangles;
    pieces without area are left out, corners repeated (a hip roof's ridge
    over a square, a point) taken once."""
    idx = tuple(i for n, i in enumerate(idx)
                if np.abs(points[i] - points[idx[n - 1]]).max() > 1e-9)
    v = points[list(idx)]
    if len(v) < 3:
        return []
    if len(v) == 4:
        n = _upward_normal(v[0], v[1], v[2])
        if n is None or abs(float(np.dot(v[3] - v[0], n))) > 1e-3:
            return (_planar_pieces(points, (idx[0], idx[1], idx[2]), rgb_)
                    + _planar_pieces(points, (idx[0], idx[2], idx[3]), rgb_))
        return [(idx, n, rgb_)]
    n = _upward_normal(v[0], v[1], v[2])
    return [] if n is None else [(idx, n, rgb_)]


def _upward_normal(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """The unit normal of the plane through p, q, r pointing up (down < 0), or
    None if they lie on a line."""
    n = np.cross(q - p, r - p)
    size = float(np.linalg.norm(n))
    if size < 1e-9:
        return None
    return n / size if n[2] < 0 else -n / size


def shadow_on_ground(b: Building, away_ne: np.ndarray) -> np.ndarray:
    """The building's shadow on the ground (k x 2, scenario north/east, convex):
    the hull of every point moved ``height * away_ne`` (``away_ne``: the
    ground shift per metre of height, away from the sun)."""
    ground = b.points[:, :2] - b.points[:, 2:3] * away_ne
    at = ground[0]  # float32 hull on offsets: metres from the origin lose centimetres
    hull = cv2.convexHull((ground - at).astype(np.float32)).reshape(-1, 2)
    out: np.ndarray = hull.astype(np.float64) + at
    return out


class BuildingSet:
    """The scenario's obstacles as buildings (``building``), their shadows on
    the ground if the sun casts them, and, for culling, a sphere around each
    building with its shadow."""

    def __init__(self, obstacles: Sequence[Obstacle], sun_ned: np.ndarray, shadows: bool) -> None:
        self.buildings = [building(o) for o in obstacles]
        away = -sun_ned[:2] / -sun_ned[2]
        #: each building's shadow on the ground (k x 3, scenario NED), if they cast them
        self.shadows = [np.column_stack([g, np.zeros(len(g))])
                        for g in (shadow_on_ground(b, away) for b in self.buildings)] \
            if shadows else []
        #: per building, its faces' normals and centres (F x 3 each)
        self.face_normals = [b.normals for b in self.buildings]
        #: per building, its faces' corners' indices (``_corner_table``)
        self.face_corners = [_corner_table(b) for b in self.buildings]
        self.face_centres = [b.centres for b in self.buildings]
        #: per building, its top's height and its box (north, east min; north, east max)
        self.tops_m = np.array([-float(b.points[:, 2].min()) for b in self.buildings])
        self.boxes = np.array([[*b.points[:, :2].min(axis=0), *b.points[:, :2].max(axis=0)]
                               for b in self.buildings]).reshape(-1, 4)
        self.centres = np.zeros((len(self.buildings), 3))
        self.radii = np.zeros(len(self.buildings))
        for i, b in enumerate(self.buildings):
            pts = np.concatenate([b.points, self.shadows[i]]) if shadows else b.points
            self.centres[i] = (pts.min(axis=0) + pts.max(axis=0)) / 2
            self.radii[i] = float(np.sqrt(((pts - self.centres[i]) ** 2).sum(axis=1)).max())

    def __len__(self) -> int:
        return len(self.buildings)

    def in_view(self, rot: np.ndarray, shift: np.ndarray, pose: Pose, planes: np.ndarray
                ) -> list[int]:
        """The buildings whose sphere (with their shadow) is not wholly outside
        one of the view frustum's ``planes`` (the frame's: near, left, right,
        top, bottom, through the camera); ``rot``, ``shift``: scenario NED -> L."""
        if not self.buildings:
            return []
        c_c = ((self.centres @ rot.T + shift) - pose.c_l) @ pose.R_cl.T
        side = c_c @ (planes / np.linalg.norm(planes, axis=1)[:, None]).T
        side[:, 0] -= NEAR_M
        out: list[int] = np.flatnonzero((side >= -self.radii[:, None]).all(axis=1)).tolist()
        return out

    def in_shadow(self, pts: np.ndarray, sun_ned: np.ndarray, which: Sequence[int]
                  ) -> np.ndarray:
        """Whether each of ``pts`` (n x 3, scenario NED) is in the shadow of one
        of buildings ``which``: its ray toward the sun (``sun_ned``, unit)
        enters one of their faces."""
        out = np.zeros(len(pts), dtype=bool)
        if not len(which) or not len(pts):
            return out
        up_s = -float(sun_ned[2])  # the sun's rise per metre along its ray
        tops_m = self.tops_m[which][:, None]  # (W, 1)
        box = self.boxes[which][:, None, :]  # (W, 1, 4)
        # where each ray rises past each building's top (W, n, 2): none reaches a
        # building unless its way there meets the building's box
        reach = pts[None, :, :2] + sun_ned[:2] * ((tops_m + pts[None, :, 2]) / up_s)[..., None]
        near = ((-pts[None, :, 2] < tops_m)
                & (np.minimum(pts[None, :, :2], reach) <= box[..., 2:]).all(axis=2)
                & (np.maximum(pts[None, :, :2], reach) >= box[..., :2]).all(axis=2))
        for w, k in np.argwhere(near).tolist():
            if not out[k]:
                b = self.buildings[which[w]]
                out[k] = any(_enters(b.points[idx], n, pts[k], sun_ned) for idx, n, _ in b.faces)
        return out

    def shadows_l(self, rot: np.ndarray, shift: np.ndarray, which: Sequence[int]
                  ) -> list[np.ndarray]:
        """The shadows of buildings ``which`` in L (k x 3 each; none without shadows)."""
        return [self.shadows[i] @ rot.T + shift for i in which] if self.shadows else []

    def faces(self, rot: np.ndarray, shift: np.ndarray, pose: Pose, sun_l: np.ndarray,
              which: Sequence[int], K: np.ndarray | None = None,
              boxes_c: np.ndarray | None = None, drawn: Sequence[Face] = ()) -> list[Face]:
        """The front faces of buildings ``which``, flat-shaded by the sun
        (``sun_l``, in L), clipped to the near plane, in painter's order with
        the targets' faces ``drawn`` (their boxes' corners ``boxes_c``, T x 8
        x 3 camera axes, target id k + 1 for row k; ``K`` the intrinsics):
        see ``_painter_depth``."""
        targets = _targets(K, boxes_c, drawn) \
            if K is not None and boxes_c is not None and drawn else None
        out: list[Face] = []
        for i in which:
            b = self.buildings[i]
            pts_c = (b.points @ rot.T + shift - pose.c_l) @ pose.R_cl.T
            normals = self.face_normals[i] @ rot.T
            # the camera on the outer side of a face's plane: the face is seen
            toward = ((self.face_centres[i] @ rot.T + shift - pose.c_l) * normals).sum(axis=1)
            # its order against the targets whose image boxes meet its own (none:
            # its faces keep their depths): every face at once (keys) if it lies
            # before the near plane, else face by face, each clipped and projected
            uv = keys = None
            if targets is not None and K is not None:
                if pts_c[:, 2].min() < NEAR_M:
                    uv = np.empty((0, 2))  # across the near plane: each face projected
                else:
                    uv = project(K, pts_c)
                    if not any(_meets(targets[2], uv)):
                        uv = None
                    else:  # every face's order against the targets at once
                        keys = _painter_bounds(uv[self.face_corners[i]],
                                               pts_c[self.face_corners[i][:, 0]],
                                               normals @ pose.R_cl.T, targets)
            for f in np.flatnonzero(toward < 0).tolist():
                idx, _, c = b.faces[f]
                v_c = pts_c[idx]
                if v_c[:, 2].min() < NEAR_M:
                    v_c = clip_near(v_c)
                    if len(v_c) < 3:
                        continue
                k = lambert(normals[f], sun_l)
                bgra = (min(255, int(c[2] * k)), min(255, int(c[1] * k)),
                        min(255, int(c[0] * k)), 255)
                depth_m = float(np.linalg.norm(v_c.mean(axis=0)))
                key = depth_m
                if keys is not None:
                    key = max(min(depth_m, keys[0][f]), keys[1][f])
                elif uv is not None and targets is not None and K is not None:
                    key = _painter_depth(depth_m, project(K, v_c), v_c[0],
                                         pose.R_cl @ normals[f], targets)
                out.append((key, depth_m, v_c, bgra, 0))
        return out


def _corner_table(b: Building) -> np.ndarray:
    """Building ``b``'s faces' corners' indices, a face a row (F x its most
    corners), the rows of faces with fewer corners padded with their first."""
    most = max(len(idx) for idx, _, _ in b.faces)
    return np.array([[*idx, *[idx[0]] * (most - len(idx))] for idx, _, _ in b.faces])


def _enters(v: np.ndarray, normal: np.ndarray, p: np.ndarray, d: np.ndarray) -> bool:
    """Whether the ray from ``p`` along ``d`` enters the planar face ``v``
    (k x 3) of outward ``normal``: it meets the face's plane ahead, going in,
    at a point inside the face (in the plane's projection onto the two axes
    the normal leans on least)."""
    into = float(np.dot(normal, d))
    if into > -1e-9:
        return False  # along the face or out of it
    t = float(np.dot(normal, v[0] - p)) / into
    if t <= 0:
        return False
    x = p + t * d
    keep = [a for a in range(3) if a != int(np.argmax(np.abs(normal)))]
    return bool(inside(v[:, keep], x[None, keep])[0])


#: the targets as the painter's order with buildings sees them: per target
#: its faces' nearest and farthest painter's depths, its image box (x0, y0,
#: x1, y1) and its box's centre (T x 3, camera axes). A handful of targets:
#: plain floats cost less than numpy's calls here.
_Targets = tuple[list[float], list[float], list[list[float]], np.ndarray]


def _targets(K: np.ndarray, boxes_c: np.ndarray, drawn: Sequence[Face]) -> _Targets | None:
    """The targets among ``drawn`` (faces with an id above 0), None if none."""
    keys: dict[int, tuple[float, float]] = {}
    for key, _, _, _, tid in drawn:
        if tid > 0:
            lo, hi = keys.get(tid, (math.inf, -math.inf))
            keys[tid] = (min(lo, key), max(hi, key))
    if not keys:
        return None
    tids = list(keys)
    boxes = boxes_c[[t - 1 for t in tids]]  # (T, 8, 3)
    rects = np.tile([-math.inf, -math.inf, math.inf, math.inf], (len(tids), 1))
    ahead = (boxes[:, :, 2] >= NEAR_M).all(axis=1)  # else across the near plane: anywhere
    if ahead.any():
        uv = project(K, boxes[ahead].reshape(-1, 3)).reshape(-1, 8, 2)
        rects[ahead] = np.concatenate([uv.min(axis=1), uv.max(axis=1)], axis=1)
    return ([keys[t][0] for t in tids], [keys[t][1] for t in tids], rects.tolist(),
            boxes.mean(axis=1))


def _meets(rects: list[list[float]], uv: np.ndarray) -> list[bool]:
    """Which of image boxes ``rects`` meet the box around points ``uv`` (n x 2)."""
    bx0, by0 = uv.min(axis=0).tolist()
    bx1, by1 = uv.max(axis=0).tolist()
    return [x1 >= bx0 and x0 <= bx1 and y1 >= by0 and y0 <= by1 for x0, y0, x1, y1 in rects]


def _painter_bounds(uv: np.ndarray, on_plane: np.ndarray, normals_c: np.ndarray,
                    targets: _Targets) -> tuple[list[float], list[float]]:
    """``_painter_depth``'s rule for F faces at once (``uv``: F x corners x 2,
    ``on_plane``, ``normals_c``: F x 3): the painter's depth each may have at
    most (before the targets behind it) and at least (after those in front)."""
    t_lo, t_hi, rects, centres = targets
    f_x0, f_y0 = uv.min(axis=1).T.tolist()
    f_x1, f_y1 = uv.max(axis=1).T.tolist()
    # the side of each face's plane each target's centre is on: c . n against p . n
    c_n = (normals_c @ centres.T).tolist()
    p_n = (on_plane * normals_c).sum(axis=1).tolist()
    most, least = [], []
    for f in range(len(p_n)):
        m, n = math.inf, -math.inf
        for t, (x0, y0, x1, y1) in enumerate(rects):
            if x1 >= f_x0[f] and x0 <= f_x1[f] and y1 >= f_y0[f] and y0 <= f_y1[f]:
                if c_n[f][t] < p_n[f]:
                    m = min(m, t_lo[t])
                else:
                    n = max(n, t_hi[t])
        most.append(m - 1e-3)
        least.append(n + 1e-3)
    return most, least


def _painter_depth(depth_m: float, uv: np.ndarray, on_plane: np.ndarray, normal_c: np.ndarray,
                   targets: _Targets) -> float:
    """A building face's painter's depth (its centre's distance ``depth_m``
    otherwise; ``uv`` its corners in the image, ``on_plane`` a point of its
    plane and ``normal_c`` its outward normal, camera axes): painted after
    every target whose image box meets its own and whose box centre lies
    behind the face's plane (seen from the camera), and before every such
    target in front of it, whatever their centres' distances (a long wall's
    centre may be farther than a car behind it). Should a target behind the
    face be nearer than one in front of it (rare), the one in front keeps
    its place and the one behind may show through."""
    most, least = _painter_bounds(uv[None], on_plane[None], normal_c[None], targets)
    return max(min(depth_m, most[0]), least[0])
