"""Haze in camera frames: the atmosphere's law (``cosim.world.atmosphere``)
applied to each drawn pixel at its distance from the camera, in linear light.

A colour ``L0`` (sRGB linearised as the ground truth's contrast does it,
``(v / 255) ** 2.2``) seen at distance ``d`` becomes ``L = L0 t + A (1 - t)``,
``t = exp(-3.912 d / V)``, ``A`` the airlight. Targets' and obstacles' faces
are flat, so each face's colour is hazed once at its own distance (its
centre's, the one that orders the faces) before it is filled; smoke puffs
likewise at theirs. The ground is hazed where it is drawn, before anything
is drawn over it: the transmittance of the ray through each tile centre of a
grid ``TILE_ROWS x TILE_COLS`` pixels apart to the ground plane (a ray that
misses the ground, or meets it beyond the ground's range, counts at that
range), interpolated bilinearly to every pixel, in steps of ``1 / LEVELS``,
each hazed with its step's middle: one table look-up per value in one
compiled sweep (``haze_pass``). The tests hold the pixels' transmittance to
the exact per-pixel one. The sky is left as it is (its horizon is the
default airlight: ``cosim.renderer.sky``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.core.camera import GAMMA, Pose
from cosim.world.atmosphere import EXTINCTION, AtmosphereSpec

#: transmittance steps of the ground's tables: step k holds t from k / LEVELS
#: to (k + 1) / LEVELS and hazes with their middle, within 1 / (2 LEVELS)
LEVELS = 128
#: the ground's transmittance is computed this many pixels apart, interpolated between
TILE_ROWS, TILE_COLS = 4, 32


class Haze:
    """The per-process tables of one atmosphere (built once, about 20 ms);
    ``horizon_rgb`` is the airlight where the atmosphere gives no colour."""

    def __init__(self, spec: AtmosphereSpec, horizon_rgb: tuple[int, int, int]) -> None:
        self.spec = spec
        self.k_per_m = EXTINCTION / (1000.0 * spec.visibility_km)
        air = spec.color_rgb if spec.color_rgb is not None else horizon_rgb
        self.air_bgr = (np.array(air[::-1], dtype=float) / 255.0) ** GAMMA
        lin = (np.arange(256) / 255.0) ** GAMMA
        t = (np.arange(LEVELS) + 0.5) / LEVELS
        hazy = t[:, None, None] * lin[None, :, None] + (1.0 - t)[:, None, None] * self.air_bgr
        tables = np.empty((LEVELS, 1, 256, 4), np.uint8)
        tables[:, 0, :, :3] = np.rint(255.0 * hazy ** (1.0 / GAMMA))
        tables[..., 3] = np.arange(256)  # alpha stays as it is
        self.tables = tables
        self.tables3 = np.ascontiguousarray(tables[:, 0])  # (LEVELS, 256, 4): haze_pass's
        from cosim.renderer import haze_pass  # numba (0.3 s to import): only when hazy

        self.compiled: Any = haze_pass
        #: per (bands, width): the rows of tiles and their centres (``tile_centres``)
        self.grids: dict[tuple[tuple[tuple[int, int], ...], int],
                         tuple[np.ndarray, np.ndarray]] = {}

    def colour(self, bgr: tuple[float, ...] | np.ndarray, distance_m: float) -> np.ndarray:
        """A BGR colour (0-255, floats) seen through ``distance_m`` of haze."""
        t = math.exp(-self.k_per_m * distance_m)
        lin = (np.asarray(bgr[:3], dtype=float) / 255.0) ** GAMMA
        out: np.ndarray = 255.0 * (lin * t + self.air_bgr * (1.0 - t)) ** (1.0 / GAMMA)
        return out

    def bgra(self, bgra: tuple[int, int, int, int], distance_m: float
             ) -> tuple[int, int, int, int]:
        """A face's fill colour (BGRA) seen through ``distance_m`` of haze."""
        b, g, r = (int(c) for c in np.rint(self.colour(bgra, distance_m)))
        return b, g, r, bgra[3]

    def ground(self, img: np.ndarray, H: np.ndarray, pose: Pose, max_r_m: float,
               bands: list[tuple[int, int]], mask: np.ndarray | None = None) -> None:
        """Haze the ground drawn in ``img`` (BGRA) in the rows of ``bands``
        (``[y0, y1)`` each), in place; with ``mask`` (h x w uint8) only the
        pixels it marks. ``H``: image -> L ground (north, east)
        (``cosim.core.camera.ground_homography``), ``max_r_m`` the ground's range."""
        rows, yc, xc, t = self.tile_transmittance(H, pose, max_r_m, bands, img.shape[1])
        if len(rows):
            self.compiled.haze_smooth(img, rows, yc, xc, t, self.tables3, mask)

    def tile_transmittance(self, H: np.ndarray, pose: Pose, max_r_m: float,
                           bands: list[tuple[int, int]], w: int
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The ground's rows of tiles (n x 2: ``[y0, y1)``), their centres' rows
        (n) and columns (tiles across), and the transmittance there (n x tiles
        across): what ``haze_pass.haze_smooth`` interpolates."""
        key = (tuple(bands), w)
        grid = self.grids.get(key)
        if grid is None:  # the tiles of these bands, once (a frame's bands repeat)
            rows = np.array([(y, min(y + TILE_ROWS, y1)) for y0, y1 in bands
                             for y in range(y0, y1, TILE_ROWS)], np.int64).reshape(-1, 2)
            if len(self.grids) > 64:
                self.grids.clear()
            grid = self.grids[key] = (rows, tile_centres(rows.tolist(), w))
        rows, centres = grid
        n = len(rows)
        if not n:
            return rows, np.zeros(0), np.zeros(0), np.zeros((0, 0))
        t = transmittance_at(self.k_per_m, H, pose, max_r_m, centres).reshape(n, -1)
        return rows, centres[1, ::t.shape[1]], centres[0, :t.shape[1]], t


def tile_centres(rows: Sequence[Sequence[int]], w: int) -> np.ndarray:
    """(3, n) homogeneous pixel centres of the tiles of ``rows`` (row by row),
    ``TILE_COLS`` wide across an image ``w`` pixels wide."""
    xs = np.array([(x + min(x + TILE_COLS, w) - 1) / 2.0 for x in range(0, w, TILE_COLS)])
    ys = np.array([(y0 + y1 - 1) / 2.0 for y0, y1 in rows])
    gx, gy = np.meshgrid(xs, ys)
    out: np.ndarray = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    return out


def transmittance_at(k_per_m: float, H: np.ndarray, pose: Pose, max_r_m: float,
                     centres: np.ndarray) -> np.ndarray:
    """(n,) transmittance ``exp(-k d)`` of the ground seen through the pixels
    ``centres`` (3 x n, homogeneous)."""
    q = H @ centres
    with np.errstate(divide="ignore", invalid="ignore"):
        ne = q[:2] / q[2]
    far = (q[2] <= 1e-12) | ~(np.hypot(ne[0], ne[1]) <= max_r_m)
    c = pose.c_l
    rho = np.where(far, max_r_m, np.hypot(ne[0] - c[0], ne[1] - c[1]))
    d = np.sqrt(rho * rho + pose.height_m ** 2)
    out: np.ndarray = np.exp(-k_per_m * d)
    return out
