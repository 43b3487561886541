"""The ground's haze, compiled: every pixel through the table of its own
transmittance, interpolated from a coarse grid, in one sweep (``haze_smooth``).

``Haze.ground`` gives the transmittance at the centres of tiles of
``TILE_ROWS x TILE_COLS`` pixels (``Haze.tile_transmittance``); each pixel's
is the bilinear interpolation between the four tile centres around it
(extrapolated from the outermost two past the outermost), rounded down to a
step of ``1 / levels``, and its B, G and R go through ``tables[step]``
(``Haze.tables3``), a run of pixels of one step at a time; alpha is left as
it is, and with a ground mask only the pixels it marks change. The
transmittance is a smooth function of the pixel (a ray beyond the ground's
range counts at that range), so the interpolation holds it within a small
fraction of a step, and neighbouring pixels never differ by more than a
step or two: no tile edges to see.

Compiled by numba on first use in a process (kept in numba's cache beside
this file after that). Owns nothing but the arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, boundscheck=False)
def _haze_smooth(img: np.ndarray, rows: np.ndarray, yc: np.ndarray, xc: np.ndarray,
                 t_c: np.ndarray, tables: np.ndarray, mask: np.ndarray, use_mask: bool
                 ) -> None:  # pragma: no cover (compiled)
    n_r, n_c = t_c.shape
    w = img.shape[1]
    levels = tables.shape[0]
    top = levels - 1
    flat = tables.reshape(-1)  # step k, value v, channel ch at (k * 256 + v) * 4 + ch
    pix = img.reshape(-1)  # pixel (y, x), channel ch at (y * w + x) * 4 + ch
    n_seg = max(n_c - 1, 1)
    # each segment between tile centres: its first and end column (the first
    # and last reach the image's edges: the line through the outermost two)
    first = np.zeros(n_seg, np.int64)
    end = np.zeros(n_seg, np.int64)
    for c in range(n_seg):
        first[c] = 0 if c == 0 else int(math.ceil(xc[c]))
        end[c] = w if c == n_seg - 1 else int(math.ceil(xc[c + 1]))
    row_t = np.empty(n_c)
    for r in range(n_r):
        for y in range(rows[r, 0], rows[r, 1]):
            # along the line through the centre rows around y (past the first
            # and the last, the line through the nearest two)
            r2 = r - 1 if (y < yc[r] and r > 0) or r + 1 >= n_r else r + 1
            a = 0.0
            if r2 >= 0 and yc[r2] != yc[r]:
                a = (y - yc[r]) / (yc[r2] - yc[r])
            else:
                r2 = r
            for k in range(n_c):
                row_t[k] = (t_c[r, k] + (t_c[r2, k] - t_c[r, k]) * a) * levels
            row = y * w
            for c in range(n_seg):
                base = row_t[c]
                slope = (row_t[c + 1] - base) / (xc[c + 1] - xc[c]) if n_c > 1 else 0.0
                x, xb = first[c], end[c]
                while x < xb:
                    # a run of one step: to where the line crosses the next whole step
                    v = base + slope * (x - xc[c])
                    kk = math.floor(v)
                    if slope > 0.0:
                        xe = min(xb, int(math.ceil(xc[c] + (kk + 1 - base) / slope)))
                    elif slope < 0.0:
                        xe = min(xb, int(math.floor(xc[c] + (kk - base) / slope)) + 1)
                    else:
                        xe = xb
                    if xe <= x:
                        xe = x + 1
                    k = min(max(int(kk), 0), top)
                    tk = k * 1024
                    for xx in range(x, xe):
                        if use_mask and mask[y, xx] == 0:
                            continue
                        p = (row + xx) * 4
                        pix[p] = flat[tk + pix[p] * 4]
                        pix[p + 1] = flat[tk + pix[p + 1] * 4 + 1]
                        pix[p + 2] = flat[tk + pix[p + 2] * 4 + 2]
                    x = xe


def haze_smooth(img: np.ndarray, rows: np.ndarray, yc: np.ndarray, xc: np.ndarray,
                t_c: np.ndarray, tables: np.ndarray, mask: np.ndarray | None = None) -> None:
    """Haze ``img`` (h x w x 4 BGRA uint8, in place) in the rows ``[y0, y1)`` of
    ``rows`` (n x 2 int), row ``r`` of tiles having its centre at row ``yc[r]``
    and its tiles theirs at columns ``xc`` (increasing), with transmittances
    ``t_c`` (n x len(xc)) there; ``tables``: L x 256 x 4 uint8, step ``k``
    holding t from k / L to (k + 1) / L; with ``mask`` (h x w uint8) only where
    it is not 0."""
    if t_c.shape != (rows.shape[0], xc.shape[0]) or yc.shape[0] != rows.shape[0]:
        raise ValueError(f"haze_smooth: {t_c.shape} transmittances for {rows.shape[0]} rows "
                         f"and {xc.shape[0]} columns")
    if not img.flags.c_contiguous or not tables.flags.c_contiguous:
        raise ValueError("haze_smooth: the frame and the tables must be C-contiguous")
    _haze_smooth(img, rows, yc, xc, t_c, tables,
                 mask if mask is not None else _NO_MASK, mask is not None)


_NO_MASK = np.zeros((1, 1), np.uint8)


def _warm() -> None:
    """Compile (or load) the pass for the types frames have, on import: a
    render worker pays for it while it starts, not on its first frame."""
    img = np.zeros((4, 4, 4), np.uint8)
    rows = np.array([[0, 4]], np.int64)
    yc, xc, t_c = np.array([1.5]), np.array([1.5]), np.ones((1, 1))
    tables = np.zeros((1, 256, 4), np.uint8)
    haze_smooth(img, rows, yc, xc, t_c, tables)
    haze_smooth(img, rows, yc, xc, t_c, tables, np.zeros((4, 4), np.uint8))


_warm()
