"""Shadows on the ground: each target's boxes and each building cast along the sun.

A box point at height h above the ground lands ``h / tan(elevation)`` from its
foot, away from the sun's azimuth; a box's shadow is the convex hull of its
foot and its top corners so moved (exact for a box on flat ground). A
building's shadow is made the same way, once (``buildings.shadow_on_ground``).
A fire's flames give light, not shade, and cast none. Shadowed ground keeps only the
sky's ambient light: in linear light it is scaled by
``AMBIENT / (AMBIENT + (1 - AMBIENT) sin(elevation))``, the ratio of a
horizontal surface's shade to its sunlit brightness (``targets.lambert``).

Drawn onto the ground before the targets (which hide their own shadow's
foot); the ground-truth id buffer is untouched. The frame module calls
``draw_shadows``; nothing here knows how the ground is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from cosim.core.camera import (
    GAMMA,
    NEAR_M,
    SHIFT,
    Pose,
    clip_near,
    fixed,
    frustum_planes,
    project,
)
from cosim.renderer.targets import (
    AMBIENT,
    UNIT_CORNERS,
    bounding_part,
    heading_rotation,
    parts_of,
)
from cosim.world.targets import TargetSpec


def shade_table(elevation_deg: float) -> np.ndarray:
    """cv2.LUT's table (256 x 1 x 4, uint8) darkening sRGB ground to its shade
    (alpha kept): a value's linear light (gamma 2.2, as the ground truth's
    luminance) times the shade ratio."""
    s = float(np.sin(np.radians(elevation_deg)))
    ratio = AMBIENT / (AMBIENT + (1.0 - AMBIENT) * s)
    v = np.arange(256, dtype=np.float64)
    dark = np.clip(np.round(v * ratio ** (1 / GAMMA)), 0, 255).astype(np.uint8)
    table = np.repeat(dark[None, :, None], 4, axis=2)
    table[0, :, 3] = np.arange(256, dtype=np.uint8)
    return table


def hulls_on_ground(t: TargetSpec, origin_l: np.ndarray, sun_l: np.ndarray, time_s: float,
                    seed: int) -> list[np.ndarray]:
    """Each of target ``t``'s parts' shadow on the ground plane through its
    foot (``origin_l``, in L): a convex polygon (k x 3, L) per part."""
    if t.kind == "fire" or sun_l[2] >= 0:
        return []
    away = -sun_l[:2] / -sun_l[2]  # ground shift per metre of height
    parts = parts_of(t, time_s, seed)
    lo = np.array([p.lo for p in parts])[:, None, :]
    hi = np.array([p.hi for p in parts])[:, None, :]
    corners = origin_l + (lo + UNIT_CORNERS * (hi - lo)) @ heading_rotation(t).T  # (P, 8, 3)
    height = origin_l[2] - corners[..., 2]  # above the foot's ground level
    ground = (corners[..., :2] + height[..., None] * away).astype(np.float32)
    out = []
    for g in ground:
        hull = cv2.convexHull(g).reshape(-1, 2).astype(np.float64)
        out.append(np.column_stack([hull, np.full(len(hull), origin_l[2])]))
    return out


def draw_shadows(K: np.ndarray, pose: Pose, specs: Sequence[TargetSpec], origins: np.ndarray,
                 sun_l: np.ndarray, time_s: float, seed: int, img: np.ndarray,
                 table: np.ndarray, more_l: Sequence[np.ndarray] = ()) -> None:
    """Darken the ground under every target's shadow in ``img`` (BGRA), and
    under ``more_l``: other shadows on the ground (convex, k x 3, in L). A
    target whose shadow cannot reach the view (``may_reach_view``) is skipped."""
    h_img, w_img = img.shape[:2]
    polys = []
    hulls = [h for k, t in enumerate(specs)
             if may_reach_view(t, origins[k], sun_l, K, pose, w_img, h_img)
             for h in hulls_on_ground(t, origins[k], sun_l, time_s, seed + k)]
    for poly_l in (*hulls, *more_l):
        v_c = (poly_l - pose.c_l) @ pose.R_cl.T
        if v_c[:, 2].max() < NEAR_M:
            continue
        if v_c[:, 2].min() < NEAR_M:
            v_c = clip_near(v_c)
            if len(v_c) < 3:
                continue
        uv = project(K, v_c)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        if hi[0] >= 0 and hi[1] >= 0 and lo[0] < w_img and lo[1] < h_img:
            polys.append(uv)
    if not polys:
        return
    dark = np.ascontiguousarray(table[0, :, 0])  # B, G and R share it; alpha is left out
    for (x0, y0, x1, y1), group in _groups(polys, w_img, h_img):
        # a mask over the group's bounding box only, alpha left unset (cv2.LUT with one
        # table for all channels and a four-channel mask: 1.5x faster than a table per
        # channel; numpy's masked copy is 50x slower than cv2.copyTo)
        mask = np.zeros((y1 - y0, x1 - x0, 4), np.uint8)
        for uv in group:
            cv2.fillConvexPoly(mask, fixed(uv - (x0, y0)), (1, 1, 1, 0), cv2.LINE_8, SHIFT)
        roi = img[y0:y1, x0:x1]
        cv2.copyTo(cv2.LUT(roi, dark), mask, roi)


def may_reach_view(t: TargetSpec, origin_l: np.ndarray, sun_l: np.ndarray, K: np.ndarray,
                   pose: Pose, w_img: int, h_img: int) -> bool:
    """Whether target ``t``'s shadow (foot at ``origin_l``, in L) may fall in the
    view of a ``w_img`` x ``h_img`` image: a ball round its foot holding every
    shadow point (the box's half-diagonal on the ground plus its top's shift,
    ``height / tan(elevation)``) not wholly outside one of the view's planes."""
    if t.kind == "fire" or sun_l[2] >= 0:
        return False
    (lo_x, lo_y, lo_z), (hi_x, hi_y, _) = bounding_part(t)
    reach_m = (max(abs(lo_x), abs(hi_x)) ** 2 + max(abs(lo_y), abs(hi_y)) ** 2) ** 0.5 \
        + abs(lo_z) * float(np.hypot(sun_l[0], sun_l[1])) / -float(sun_l[2])
    c = pose.R_cl @ (origin_l - pose.c_l)
    planes = frustum_planes(K, w_img, h_img)
    return bool(((planes @ c) >= -reach_m * np.linalg.norm(planes, axis=1)).all())


def _groups(polys: list[np.ndarray], w_img: int, h_img: int
            ) -> list[tuple[tuple[int, int, int, int], list[np.ndarray]]]:
    """The polygons (image points) in groups whose bounding boxes (within the
    image, a pixel's margin) do not overlap, each with its group's box: each
    pixel is darkened once, and shadows apart do not make one box as large
    as the frame."""
    out: list[tuple[tuple[int, int, int, int], list[np.ndarray]]] = []
    for uv in polys:
        x0, y0 = (max(0, int(v)) for v in uv.min(axis=0))
        x1, y1 = min(w_img, int(uv[:, 0].max()) + 2), min(h_img, int(uv[:, 1].max()) + 2)
        if x1 <= x0 or y1 <= y0:
            continue
        box, group = (x0, y0, x1, y1), [uv]
        merged = True
        while merged:  # take in every group the box overlaps, until none does
            merged = False
            for g in out:
                b = g[0]
                if b[0] < box[2] and box[0] < b[2] and b[1] < box[3] and box[1] < b[3]:
                    out.remove(g)
                    box = (min(b[0], box[0]), min(b[1], box[1]), max(b[2], box[2]),
                           max(b[3], box[3]))
                    group = g[1] + group
                    merged = True
                    break
        out.append((box, group))
    return out
