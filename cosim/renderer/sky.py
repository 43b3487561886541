"""The sky in camera frames: a colour per ray, from the ray's elevation and
the sun.

A ray of elevation ``e`` above the horizon has the colour
``horizon + (zenith - horizon) (1 - exp(-e / E0_DEG))``: the bright band
along the horizon fades into the zenith's blue over the lowest ~15 deg,
wherever the horizon lies in the image (a rolled or pitched camera sees it
tilted or high). Rays below the horizon that meet no ground within its range
see the horizon's colour: the far ground fades into it, and the haze's
default airlight is that colour, so hazy ground meets the sky without a
seam. The sun sets the sky's brightness (``brightness``: full at 30 deg of
elevation and above, 60 % at the horizon) and, when it stands low, warms the
sky around it (``GLOW_RGB``, strongest toward the sun, none above 40 deg).

Owns the sky's colours; the frame's pose and intrinsics are the caller's.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from cosim.world.sun import SunSpec

#: the sky's colours (RGB) under a sun at 30 deg or more
ZENITH_RGB = (120, 170, 225)
HORIZON_RGB = (205, 220, 235)
#: the low sun's warm light (RGB)
GLOW_RGB = (255, 200, 150)
#: elevation (deg) over which the horizon's colour gives way to the zenith's (1 - 1/e)
E0_DEG = 12.0
#: the sun's glow: strength at the horizon, gone at GLOW_TOP_DEG of elevation;
#: its width (the power of the cosine of the angle to the sun)
GLOW_STRENGTH, GLOW_TOP_DEG, GLOW_POWER = 0.5, 40.0, 8
#: the sky is drawn from a grid this many pixels apart, interpolated between
STEP_PX = 8


def brightness(sun: SunSpec) -> float:
    """The sky's brightness under ``sun``: 1 at 30 deg of elevation and above,
    falling linearly in sin(elevation) to 0.6 at the horizon."""
    s = math.sin(math.radians(sun.elevation_deg)) / math.sin(math.radians(30.0))
    return 0.6 + 0.4 * min(1.0, max(0.0, s))


def horizon_rgb(sun: SunSpec) -> tuple[int, int, int]:
    """The horizon's colour under ``sun`` away from its glow: the haze's
    default airlight."""
    b = brightness(sun)
    r, g, bl = (int(round(c * b)) for c in HORIZON_RGB)
    return r, g, bl


class Sky:
    """The sky of one world's sun (colours in BGR floats, built once)."""

    def __init__(self, sun: SunSpec) -> None:
        b = brightness(sun)
        self.horizon_bgr = np.array(HORIZON_RGB[::-1], np.float32) * b
        self.zenith_bgr = np.array(ZENITH_RGB[::-1], np.float32) * b
        self.glow_bgr = np.array(GLOW_RGB[::-1], np.float32)
        self.glow = GLOW_STRENGTH * max(0.0, 1.0 - sun.elevation_deg / GLOW_TOP_DEG)
        self.sun_l = sun.to_sun_ned()
        #: per image size and intrinsics: the grid's rays in camera axes
        self._rays: dict[tuple[int, int, bytes], np.ndarray] = {}

    def colours(self, dirs_l: np.ndarray) -> np.ndarray:
        """(n, 3) BGR floats of rays of directions ``dirs_l`` (n, 3, north-east-down)."""
        d = np.ascontiguousarray(dirs_l.T)  # (3, n): per-axis rows, no broadcasting
        norm = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        up = np.clip(-d[2] / norm, 0.0, 1.0)  # below the horizon: as on it
        g = 1.0 - np.exp(np.arcsin(up) * (-1.0 / math.radians(E0_DEG)))
        glow = None
        if self.glow > 0.0:
            cos = (d[0] * self.sun_l[0] + d[1] * self.sun_l[1] + d[2] * self.sun_l[2]) / norm
            glow = self.glow * np.maximum(cos, 0.0) ** GLOW_POWER
        out = np.empty((3, d.shape[1]), np.float32)
        for c in range(3):
            hor, zen = float(self.horizon_bgr[c]), float(self.zenith_bgr[c])
            ch = hor + (zen - hor) * g
            if glow is not None:
                ch += (float(self.glow_bgr[c]) - ch) * glow
            out[c] = ch
        return out.T

    def draw(self, K_inv: np.ndarray, R_cl: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Fill ``out`` (h x w x 4 uint8, BGRA) with the sky seen through a camera of
        inverse intrinsics ``K_inv`` and attitude ``R_cl`` (L -> camera): the
        exact colours on a grid ``STEP_PX`` apart, bilinear between; alpha 255."""
        h, w = out.shape[:2]
        gh, gw = max(2, -(-h // STEP_PX)), max(2, -(-w // STEP_PX))
        key = (h, w, K_inv.tobytes())
        rays_c = self._rays.get(key)
        if rays_c is None:  # where cv2.resize's bilinear samples a (gh, gw) grid
            xs = (np.arange(gw) + 0.5) * w / gw - 0.5
            ys = (np.arange(gh) + 0.5) * h / gh - 0.5
            gx, gy = np.meshgrid(xs, ys)
            rays_c = self._rays[key] = K_inv @ np.stack([gx.ravel(), gy.ravel(),
                                                         np.ones(gx.size)])
        bgr = self.colours((R_cl.T @ rays_c).T).reshape(gh, gw, 3)
        small = np.empty((gh, gw, 4), np.uint8)
        small[..., :3] = np.rint(np.clip(bgr, 0.0, 255.0))
        small[..., 3] = 255
        cv2.resize(small, (w, h), dst=out, interpolation=cv2.INTER_LINEAR)
        return out
