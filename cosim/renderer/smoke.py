"""A fire's smoke in camera frames: its puffs lit by the sun, and their
shadows on the ground.

Each puff (``targets.smoke_puffs``: a sphere of radius ``r`` and opacity
``alpha``) is drawn as a disc over the frame, mixed with what is behind it by
``alpha``. Lit by the sun as a Lambertian sphere: seen at phase angle ``a``
(between the directions from the puff to the camera and to the sun) its
disc's mean direct light is ``(2/3) (sin a + (pi - a) cos a) / pi`` of the
sun's, so its colour is ``SMOKE_BGR`` times ``(AMBIENT + (1 - AMBIENT) m(a)) /
(AMBIENT + (1 - AMBIENT) m(0))``: as given with the sun behind the camera,
darker toward the sun. With shadows on, a puff's shadow on the ground is the
sphere's: an ellipse centred ``hc / tan(elevation)`` away from the sun from the
puff's foot (``hc`` the centre's height), ``r`` across and ``r /
sin(elevation)`` along the sun's azimuth, darkening the ground toward its shade
(``shadows.shade_table``) by the puff's ``alpha``; overlapping puffs combine as
``1 - prod(1 - alpha)``.

The frame module calls ``draw_smoke`` and ``draw_smoke_shadows``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from cosim.core.camera import NEAR_M, SHIFT, Pose, fixed, project, to_camera
from cosim.renderer.haze import Haze
from cosim.renderer.targets import AMBIENT, smoke_puffs, to_local
from cosim.world.targets import TargetSpec

SMOKE_BGR = np.array([150.0, 150.0, 155.0])
#: points on a puff shadow's outline
OUTLINE = 24


def lit_sphere(phase_rad: float) -> float:
    """The mean direct light (times the sun's) over the visible disc of a
    Lambertian sphere seen at ``phase_rad`` from the sun."""
    a = min(max(phase_rad, 0.0), math.pi)
    return (2.0 / 3.0) * (math.sin(a) + (math.pi - a) * math.cos(a)) / math.pi


def smoke_gain(pose: Pose, centre_l: np.ndarray, sun_l: np.ndarray) -> float:
    """A puff's brightness relative to its colour with the sun behind the camera."""
    to_cam = pose.c_l - centre_l
    cos_a = float(np.dot(to_cam, sun_l) / max(float(np.linalg.norm(to_cam)), 1e-9))
    lit = AMBIENT + (1.0 - AMBIENT) * lit_sphere(math.acos(max(-1.0, min(1.0, cos_a))))
    return lit / (AMBIENT + (1.0 - AMBIENT) * lit_sphere(0.0))


def draw_smoke(K: np.ndarray, pose: Pose, t: TargetSpec, origin_l: np.ndarray, time_s: float,
               seed: int, img: np.ndarray, sun_l: np.ndarray, haze: Haze | None = None) -> None:
    """Draw fire ``t``'s smoke puffs over ``img`` (BGRA; alpha stays opaque)."""
    h_img, w_img = img.shape[:2]
    for centre_t, radius, alpha in smoke_puffs(t, time_s, seed):
        centre_l = to_local(t, origin_l, centre_t[None, :])
        c_c = to_camera(pose, centre_l)[0]
        if c_c[2] < NEAR_M + radius:
            continue
        uv = project(K, c_c[None, :])[0]
        r_px = K[0, 0] * radius / c_c[2]
        x0, y0 = int(max(0, uv[0] - r_px - 1)), int(max(0, uv[1] - r_px - 1))
        x1, y1 = int(min(w_img, uv[0] + r_px + 2)), int(min(h_img, uv[1] + r_px + 2))
        if x1 <= x0 or y1 <= y0:
            continue
        roi = img[y0:y1, x0:x1]
        disc = np.zeros(roi.shape[:2], dtype=np.uint8)
        (cx, cy), (r,) = fixed(uv - (x0, y0)), fixed(np.array([r_px]))
        cv2.circle(disc, (int(cx), int(cy)), int(r), 1, -1, cv2.LINE_8, SHIFT)
        m = disc.astype(bool)
        bgr = roi[..., :3]
        smoke = np.minimum(SMOKE_BGR * smoke_gain(pose, centre_l[0], sun_l), 255.0)
        if haze is not None:
            smoke = haze.colour(smoke, float(np.linalg.norm(c_c)))
        bgr[m] = (bgr[m] * (1.0 - alpha) + smoke * alpha).astype(np.uint8)


def shadow_outlines(t: TargetSpec, origin_l: np.ndarray, sun_l: np.ndarray, time_s: float,
                    seed: int) -> list[tuple[np.ndarray, float]]:
    """Each puff's shadow on the ground plane through the fire's foot: its
    outline (OUTLINE x 3, L) and opacity."""
    if sun_l[2] >= 0:
        return []
    sin_el = -float(sun_l[2])
    horiz = np.array([sun_l[0], sun_l[1]]) / max(math.hypot(sun_l[0], sun_l[1]), 1e-12)
    across = np.array([-horiz[1], horiz[0]])
    away = -sun_l[:2] / sin_el  # ground shift per metre of height
    ang = np.linspace(0.0, 2.0 * math.pi, OUTLINE, endpoint=False)
    out = []
    for centre_t, radius, alpha in smoke_puffs(t, time_s, seed):
        c_l = to_local(t, origin_l, centre_t[None, :])[0]
        height = origin_l[2] - c_l[2]
        foot = c_l[:2] + height * away
        ne = (foot + np.outer(np.cos(ang) * radius / sin_el, horiz)
              + np.outer(np.sin(ang) * radius, across))
        out.append((np.column_stack([ne, np.full(OUTLINE, origin_l[2])]), alpha))
    return out


def draw_smoke_shadows(K: np.ndarray, pose: Pose, specs: Sequence[TargetSpec],
                       origins: np.ndarray, sun_l: np.ndarray, time_s: float, seed: int,
                       img: np.ndarray, table: np.ndarray) -> None:
    """Darken the ground under every fire's smoke shadows in ``img`` (BGRA)."""
    h_img, w_img = img.shape[:2]
    polys: list[tuple[np.ndarray, float]] = []
    for k, t in enumerate(specs):
        if t.kind != "fire":
            continue
        for poly_l, alpha in shadow_outlines(t, origins[k], sun_l, time_s, seed + k):
            v_c = (poly_l - pose.c_l) @ pose.R_cl.T
            if v_c[:, 2].min() < NEAR_M:  # a puff's shadow reaching behind the camera
                continue
            uv = project(K, v_c)
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            if hi[0] >= 0 and hi[1] >= 0 and lo[0] < w_img and lo[1] < h_img:
                polys.append((uv, alpha))
    if not polys:
        return
    every = np.concatenate([uv for uv, _ in polys])
    x0, y0 = (max(0, int(v)) for v in every.min(axis=0))
    x1, y1 = min(w_img, int(every[:, 0].max()) + 2), min(h_img, int(every[:, 1].max()) + 2)
    if x1 <= x0 or y1 <= y0:
        return
    clear = np.ones((y1 - y0, x1 - x0), np.float32)  # the light let through
    disc = np.zeros((y1 - y0, x1 - x0), np.uint8)
    for uv, alpha in polys:
        disc[:] = 0
        cv2.fillConvexPoly(disc, fixed(uv - (x0, y0)), 1, cv2.LINE_8, SHIFT)
        clear[disc.astype(bool)] *= 1.0 - alpha
    roi = img[y0:y1, x0:x1]
    shade = (1.0 - clear)[..., None]
    dark = cv2.LUT(roi, table).astype(np.float32)
    mixed = roi.astype(np.float32)
    mixed += (dark - mixed) * shade
    np.copyto(roi, np.rint(mixed).astype(np.uint8))
