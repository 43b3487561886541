"""The procedural ground's trees in 3-D (``ground: {trees: 3d}``).

Each tree of the texture (``texture._tree_cells``: where it stands, its crown's
radius and tone, the height of its crown's lowest point and of its top) is a
trunk under an ellipsoid crown: semi-axes the crown's radius across and half
its depth up, centred halfway between its lowest point and its top. Drawn in
perspective, exactly: the outline of an ellipsoid seen from a point is the
image of a circle on it (in the coordinates where the crown is the unit
sphere, seen from ``c``: the circle ``x . c = 1``), so a crown top ``h`` up
at off-nadir angle ``t`` lands ``h tan t`` from its foot, as it should. The
sun side is lighter: over the crown (in shade, the ambient light's share of
its colour) lies the outline of its sunlit cap (the unit sphere shrunk by
``LIT`` and moved that far toward the sun, in full light). The trunk is a
dark upright strip from the ground to the crown's centre, facing the camera.

A crown's shadow on the ground is exact too: the ellipsoid's outline along
the sun's rays (a great circle of the unit sphere) moved onto the ground, a
point ``h`` up landing ``h / tan(elevation)`` away from the sun.

Trees are 3-D where the ground is drawn finer than ``FLAT_FROM_LEVEL`` (the
tiles there show the ground under them); coarser levels keep their flat
crowns. Owns the trees' geometry and colours; the frame draws them in its
painter's order with the targets (``render_frame``), their shadows with the
targets' (``shadows.draw_shadows``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from cosim.core.camera import NEAR_M, Pose, clip_near, project
from cosim.renderer.haze import Haze
from cosim.renderer.targets import AMBIENT
from cosim.renderer.texture import _TREE, TREE_M, TREE_R_M, WOOD_TOP_M, tree_tables

#: ground levels this coarse (level 4: 0.8 m a pixel at the default 5 cm base,
#: which a frame draws where a pixel covers 0.57 m or more) or coarser keep their
#: flat crowns; finer ones show the ground under the trees
FLAT_FROM_LEVEL = 4
MAX_TREES = 4000  # trees drawn in 3-D a frame at most, the nearest
REACH_M = 600.0  # trees drawn in 3-D at most this far from the camera's ground point
SIDES = 20  # an outline's vertices
LIT = 0.35  # the sunlit cap: the unit sphere shrunk by this, moved this far sunward
TRUNK_M = 0.35  # a trunk's width
TRUNK_RGB = np.array([62, 50, 40], np.float32)
_BLOCK = 32  # tree cells a table block holds (texture.tree_tables)

_ANGLES = np.linspace(0.0, 2.0 * math.pi, SIDES, endpoint=False)
_COS, _SIN = np.cos(_ANGLES), np.sin(_ANGLES)


@dataclass(frozen=True)
class Trees:
    """Trees (arrays, one entry a tree): the foot of each trunk (``north_m``,
    ``east_m``; in the scenario frame, or in a frame's L axes on its plane
    ``down = 0``), the crown's radius, the heights of its lowest point and of
    its top above the ground, and its tone (its colour's factor)."""

    north_m: np.ndarray
    east_m: np.ndarray
    radius_m: np.ndarray
    crown_m: np.ndarray
    top_m: np.ndarray
    tone: np.ndarray

    def take(self, k: np.ndarray) -> Trees:
        return Trees(*(a[k] for a in (self.north_m, self.east_m, self.radius_m, self.crown_m,
                                      self.top_m, self.tone)))

    def __len__(self) -> int:
        return len(self.north_m)


@functools.lru_cache(maxsize=256)
def _block(seed: int, bn: int, be: int) -> np.ndarray:
    """The trees standing in the block of tree cells from ``(bn, be)`` (``_BLOCK``
    a side): (6, n) float64, foot north and east, radius, crown, top, tone (at
    most 50 kB a block; not to be written)."""
    tab = tree_tables(seed, bn, bn, be, be)  # the block that holds the cell, kept
    assert tab is not None and tab[1] - tab[0] == _BLOCK
    wood, hedge, tn, te, radius, tone, crown, top = tab[4]
    k = np.flatnonzero(wood | hedge)
    out = np.stack([a.take(k).astype(np.float64) for a in (tn, te, radius, crown, top, tone)])
    out.flags.writeable = False
    return out


def standing(seed: int, n0: float, n1: float, e0: float, e1: float) -> Trees:
    """The trees (scenario frame) whose foot lies in north ``[n0, n1)`` x east
    ``[e0, e1)``: the texture's, from its tables (kept by whole blocks)."""
    kn0, kn1 = math.floor(n0 / TREE_M), math.floor(n1 / TREE_M)
    ke0, ke1 = math.floor(e0 / TREE_M), math.floor(e1 / TREE_M)
    blocks = [_block(seed, bn, be) for bn in range(kn0 - kn0 % _BLOCK, kn1 + 1, _BLOCK)
              for be in range(ke0 - ke0 % _BLOCK, ke1 + 1, _BLOCK)]
    if not blocks:
        return Trees(*np.zeros((6, 0)))
    every = blocks[0] if len(blocks) == 1 else np.concatenate(blocks, axis=1)
    tn, te = every[0], every[1]
    return Trees(*every[:, (tn >= n0) & (tn < n1) & (te >= e0) & (te < e1)])


def _circle(centre: np.ndarray, radius: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N, SIDES, 3): points of the circles of ``centre`` (N, 3) and ``radius``
    (N,) in the planes perpendicular to ``axis`` (N, 3)."""
    a = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    helper = np.where((np.abs(a[:, 2]) > 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    u = np.cross(a, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(a, u)
    ring = _COS[None, :, None] * u[:, None, :] + _SIN[None, :, None] * v[:, None, :]
    out: np.ndarray = centre[:, None, :] + radius[:, None, None] * ring
    return out


def _axes(trees: Trees) -> tuple[np.ndarray, np.ndarray]:
    """Each crown's centre (N, 3, L axes: down negative up) and semi-axes (N, 3)."""
    half = 0.5 * (trees.top_m - trees.crown_m)
    centre = np.column_stack([trees.north_m, trees.east_m, -(trees.crown_m + half)])
    return centre, np.column_stack([trees.radius_m, trees.radius_m, half])


def outlines(trees: Trees, camera_l: np.ndarray, sun_l: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """In L (trees in L axes; the camera at ``camera_l``): each crown's outline
    seen from the camera and its sunlit cap's (N, SIDES, 3), its trunk (N, 4, 3),
    and whether the camera is outside the crown (N,): else the outlines are
    meaningless."""
    centre, semi = _axes(trees)
    c = (camera_l[None, :] - centre) / semi  # the camera where the crown is the unit sphere
    d2 = np.einsum("ij,ij->i", c, c)
    outside = d2 > 1.0 + 1e-6
    d2 = np.maximum(d2, 1.0 + 1e-6)
    crown = centre[:, None, :] + semi[:, None, :] * _circle(c / d2[:, None],
                                                             np.sqrt(1.0 - 1.0 / d2), c)
    # the cap: radius 1 - LIT at LIT toward the sunniest point (its normal the sun's)
    s = semi * sun_l[None, :]
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    cc = (c - LIT * s) / (1.0 - LIT)  # the camera where the cap is the unit sphere
    e2 = np.maximum(np.einsum("ij,ij->i", cc, cc), 1.0 + 1e-6)
    unit = LIT * s[:, None, :] + (1.0 - LIT) * _circle(cc / e2[:, None],
                                                       np.sqrt(1.0 - 1.0 / e2), cc)
    cap = centre[:, None, :] + semi[:, None, :] * unit
    # the trunk: foot to the crown's centre, across the camera's horizontal line of sight
    look = np.column_stack([trees.north_m - camera_l[0], trees.east_m - camera_l[1]])
    norm = np.hypot(look[:, 0], look[:, 1])
    across = np.where((norm > 1e-6)[:, None],
                      np.column_stack([-look[:, 1], look[:, 0]]) / np.maximum(norm, 1e-6)[:, None],
                      [0.0, 1.0]) * (0.5 * TRUNK_M)
    foot = np.column_stack([trees.north_m, trees.east_m, np.zeros(len(trees))])
    side = np.column_stack([across, np.zeros(len(trees))])
    trunk = np.stack([foot - side, foot + side, centre + side, centre - side], axis=1)
    return crown, cap, trunk, outside


def shadow_outlines(trees: Trees, sun_l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In L (trees in L axes): each crown's shadow on the ground (N, SIDES, 2:
    north, east) and its trunk's (N, 4, 2), the sun toward ``sun_l`` (above the
    horizon)."""
    centre, semi = _axes(trees)
    w = sun_l[None, :] / semi  # the sun's rays where the crown is the unit sphere
    rim = centre[:, None, :] + semi[:, None, :] * _circle(np.zeros_like(centre),
                                                          np.ones(len(trees)), w)
    away = -sun_l[:2] / -sun_l[2]  # ground shift a metre of height
    crown = rim[..., :2] - rim[..., 2:3] * away  # height is -down
    foot = np.column_stack([trees.north_m, trees.east_m])
    top = foot - centre[:, 2:3] * away
    a = np.array([-away[1], away[0]])
    across = a / max(float(np.hypot(*a)), 1e-9) * (0.5 * TRUNK_M)
    trunk = np.stack([foot - across, foot + across, top + across, top - across], axis=1)
    return crown, trunk


def to_image(K: np.ndarray, pose: Pose, polys_l: np.ndarray
             ) -> tuple[list[np.ndarray | None], np.ndarray]:
    """Polygons (N, k, 3 in L) in pixels: a list of (k', 2) arrays (None: wholly
    behind the camera; a polygon across the near plane is clipped to it) and
    each one's depth to its vertices' mean (N,)."""
    pts_c = (polys_l - pose.c_l) @ pose.R_cl.T
    z = pts_c[..., 2]
    depth = np.linalg.norm(pts_c.mean(axis=1), axis=1)
    front = z.min(axis=1) >= NEAR_M
    out: list[np.ndarray | None] = [None] * len(pts_c)
    if front.any():
        uv = project(K, pts_c[front].reshape(-1, 3)).reshape(-1, pts_c.shape[1], 2)
        for i, p in zip(np.flatnonzero(front).tolist(), uv):
            out[i] = p
    for i in np.flatnonzero(~front & (z.max(axis=1) >= NEAR_M)).tolist():
        clipped = clip_near(pts_c[i])
        if len(clipped) >= 3:
            out[i] = project(K, clipped)
    return out, depth


def colours(trees: Trees) -> tuple[np.ndarray, np.ndarray]:
    """Each crown's colour (N, 3, RGB) in shade (the ambient light's share of
    the texture's tree colour times the tree's tone, brightened by
    ``1 / (AMBIENT + (1 - AMBIENT) / 2)`` so that a crown half in sun and half in
    shade averages the flat crown's colour) and in full sun."""
    lit = _TREE[None, :] * (trees.tone / (AMBIENT + (1.0 - AMBIENT) / 2.0))[:, None]
    return lit * AMBIENT, lit


def reach_m(height_m: float, far_m: float) -> float:
    """How far beyond the ground seen a tree's foot may lie and its crown still
    rise into view: the tallest top at the steepest slant seen (the camera
    ``height_m`` up, the ground seen ``far_m`` away), at most 100 m."""
    return min(100.0, WOOD_TOP_M[1] * far_m / max(height_m - WOOD_TOP_M[1], 1.0)) \
        + TREE_R_M[1]


def in_view(seed: int, K: np.ndarray, pose: Pose, A: np.ndarray, bounds: tuple[int, ...],
            levels: list[int], extents_l: list[np.ndarray], max_r: float) -> Trees:
    """The trees (in L axes) a frame draws in 3-D: those whose foot lies on
    ground drawn finer than ``FLAT_FROM_LEVEL`` (``levels``: each band of image
    rows' ground level, -1 none; ``bounds`` their first rows, then the height),
    within ``max_r`` and ``REACH_M`` of the camera, at most ``MAX_TREES`` (the
    nearest). ``extents_l``: L points (2, k) bounding the ground those bands see;
    ``A``: L (north, east, 1) -> the scenario frame's."""
    pts = np.concatenate(extents_l, axis=1)
    cam = pose.c_l[:2]
    far_m = float(np.hypot(pts[0] - cam[0], pts[1] - cam[1]).max())
    margin = reach_m(pose.height_m, far_m)
    ne = A[:2, :2] @ pts + A[:2, 2:3]
    cam_s = A[:2, :2] @ cam + A[:2, 2]
    reach = min(REACH_M, max_r)
    n0, n1 = max(ne[0].min() - margin, cam_s[0] - reach), min(ne[0].max() + margin,
                                                               cam_s[0] + reach)
    e0, e1 = max(ne[1].min() - margin, cam_s[1] - reach), min(ne[1].max() + margin,
                                                               cam_s[1] + reach)
    if n1 <= n0 or e1 <= e0:
        return standing(seed, 0.0, 0.0, 0.0, 0.0)
    trees = standing(seed, n0, n1, e0, e1)
    a_inv = np.linalg.inv(A)
    north, east = a_inv[:2, :2] @ np.stack([trees.north_m, trees.east_m]) + a_inv[:2, 2:3]
    dist = np.hypot(north - cam[0], east - cam[1])
    foot_c = (np.column_stack([north, east, np.zeros(len(north))]) - pose.c_l) @ pose.R_cl.T
    z = foot_c[:, 2]
    row = np.where(z >= NEAR_M, K[1, 1] * foot_c[:, 1] / np.maximum(z, NEAR_M) + K[1, 2],
                   bounds[-1] - 1)
    band = np.searchsorted(bounds, np.clip(row, 0, bounds[-1] - 1), "right") - 1
    level = np.asarray(levels)[np.minimum(band, len(levels) - 1)]
    keep = np.flatnonzero((dist <= reach) & (level >= 0) & (level < FLAT_FROM_LEVEL))
    if len(keep) > MAX_TREES:
        keep = keep[np.argsort(dist[keep], kind="stable")[:MAX_TREES]]
    return Trees(north[keep], east[keep], trees.radius_m[keep], trees.crown_m[keep],
                 trees.top_m[keep], trees.tone[keep])


@dataclass(frozen=True)
class Drawn:
    """The trees of a frame as outlines to fill (``canopy_pass``), the farthest
    first: tree ``i`` (crown centre ``depth_m[i]`` from the camera) is the
    polygons ``first[i] .. first[i + 1] - 1``: its trunk (unless its crown hides
    it), its crown and its sunlit cap, each ``polys[m, :counts[m]]`` in pixels,
    in colour ``bgr[m]``, hiding targets behind it where ``clear[m]``."""

    depth_m: np.ndarray
    first: np.ndarray
    polys: np.ndarray
    counts: np.ndarray
    bgr: np.ndarray
    clear: np.ndarray

    def draw_to(self, depth_m: float, done: int, img: np.ndarray, ids: np.ndarray) -> int:
        """Fill the trees from ``done`` on that lie farther than ``depth_m`` (all
        of them for -inf) into ``img`` and ``ids``; return the next tree to draw."""
        k = int(np.searchsorted(-self.depth_m, -depth_m, "left"))
        if k > done:
            from cosim.renderer.canopy_pass import fill_polygons  # numba: only when drawn

            fill_polygons(img, ids, self.polys, self.counts, self.bgr, self.clear,
                          int(self.first[done]), int(self.first[k]))
        return max(k, done)


def drawn(trees: Trees, K: np.ndarray, pose: Pose, sun_l: np.ndarray, w_img: int,
          h_img: int, planes: np.ndarray, haze: Haze | None = None) -> Drawn | None:
    """The trees seen (``outlines``), ready to fill; ``planes``: the view
    frustum's (x, y, z coefficients a row; a tree wholly outside one is left
    out); ``haze``: their colours seen through it at their crowns' centres'
    distance. None if none is seen."""
    if not len(trees):
        return None
    centre, semi = _axes(trees)  # each tree inside a sphere about its crown's centre
    ball = np.maximum(semi.max(axis=1), -centre[:, 2])  # the foot is this far below
    side = ((centre - pose.c_l) @ pose.R_cl.T) @ planes.T
    side /= np.linalg.norm(planes, axis=1)
    trees = trees.take(np.flatnonzero((side >= -ball[:, None]).all(axis=1)))
    if not len(trees):
        return None
    from cosim.renderer.canopy_pass import outline_pixels  # numba: only when drawn

    out, counts, depth, state = outline_pixels(*_axes(trees), sun_l, pose.c_l, pose.R_cl, K,
                                               _COS, _SIN, LIT, TRUNK_M, NEAR_M)
    across = np.flatnonzero(state == 1)
    if len(across):  # across the near plane: each outline clipped to it
        crown, cap, trunk, _ = outlines(trees.take(across), pose.c_l, sun_l)
        counts[across] = 0
        for j, i in enumerate(across.tolist()):
            for part, poly in enumerate((trunk[j], crown[j], cap[j])):
                uv_i = to_image(K, pose, poly[None])[0][0]
                if uv_i is not None:
                    out[i, part, :len(uv_i)], counts[i, part] = uv_i, len(uv_i)
    # the box of each tree's crown and trunk, from their own vertices
    used = np.arange(out.shape[2])[None, None, :] < counts[:, :2, None]
    lo = np.where(used[..., None], out[:, :2], np.inf).min(axis=(1, 2))
    hi = np.where(used[..., None], out[:, :2], -np.inf).max(axis=(1, 2))
    seen = (counts[:, 1] >= 3) & (hi[:, 0] >= -0.5) & (hi[:, 1] >= -0.5) \
        & (lo[:, 0] <= w_img - 0.5) & (lo[:, 1] <= h_img - 0.5)
    order = np.flatnonzero(seen)[np.argsort(-depth[seen], kind="stable")]
    if not len(order):
        return None
    shade, lit = colours(trees.take(order))
    bgr = np.stack([np.broadcast_to(TRUNK_RGB, shade.shape), shade, lit], axis=1)[..., ::-1]
    d = depth[order]
    if haze is not None:
        bgr = np.array([haze.colour(tree, float(di)) for tree, di in zip(bgr, d)])
    bgr = np.rint(np.clip(bgr, 0.0, 255.0)).astype(np.uint8)
    keep = counts[order] > 0
    clear = np.broadcast_to(np.array([True, True, False]), keep.shape)[keep]
    return Drawn(d, np.concatenate([[0], np.cumsum(keep.sum(axis=1))]), out[order][keep],
                 counts[order][keep], np.ascontiguousarray(bgr[keep]), clear)


def shadows_l(trees: Trees, sun_l: np.ndarray) -> list[np.ndarray]:
    """The trees' shadows on the ground (``shadow_outlines``), each crown's and
    each trunk's a convex polygon (k, 3) in L, for ``shadows.draw_shadows``."""
    if not len(trees) or sun_l[2] >= 0:
        return []
    crown, trunk = shadow_outlines(trees, sun_l)
    out: list[np.ndarray] = []
    for polys in (crown, trunk):
        pts = np.concatenate([polys, np.zeros((*polys.shape[:2], 1))], axis=2)
        out.extend(pts)
    return out
