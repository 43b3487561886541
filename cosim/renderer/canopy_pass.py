"""The trees' outlines filled, compiled: a run of convex polygons painted in
order into the frame, clearing the target-id image under those that hide
what is behind them (``fill_polygons``).

A pixel (centred on whole numbers) is filled when the polygon reaches into
its square: on each row, the span the polygon covers within the row's band
of height one, widened to the pixels it reaches into. Like OpenCV's fill of
a convex polygon, which adds the pixels its outline crosses, this draws a
polygon thinner than a pixel (a far trunk) as a line, not as nothing, and
does it without a call per polygon. Compiled by numba on first use in a
process (kept in numba's cache beside this file after that). Owns nothing
but the arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, boundscheck=False)
def _fill(img: np.ndarray, ids: np.ndarray, polys: np.ndarray, counts: np.ndarray,
          bgr: np.ndarray, clear: np.ndarray, lo: int, hi: int
          ) -> None:  # pragma: no cover (compiled)
    h, w = ids.shape
    for m in range(lo, hi):
        n = counts[m]
        if n < 3:
            continue
        y_lo, y_hi = polys[m, 0, 1], polys[m, 0, 1]
        for k in range(1, n):
            y_lo = min(y_lo, polys[m, k, 1])
            y_hi = max(y_hi, polys[m, k, 1])
        # the rows and columns of the pixels whose square the polygon overlaps
        r0, r1 = int(math.floor(y_lo - 0.5)) + 1, int(math.ceil(y_hi + 0.5)) - 1
        b, g, r = bgr[m, 0], bgr[m, 1], bgr[m, 2]
        for y in range(max(0, r0), min(h - 1, r1) + 1):
            top, bottom = max(y - 0.5, y_lo), min(y + 0.5, y_hi)  # the row's band
            x_lo, x_hi = np.inf, -np.inf
            for k in range(n):
                ax, ay = polys[m, k, 0], polys[m, k, 1]
                bx, by = polys[m, (k + 1) % n, 0], polys[m, (k + 1) % n, 1]
                if top <= ay <= bottom:
                    x_lo, x_hi = min(x_lo, ax), max(x_hi, ax)
                if ay != by:  # where the edge crosses the band's top and bottom
                    for yc in (top, bottom):
                        if min(ay, by) <= yc <= max(ay, by):
                            x = ax + (yc - ay) * (bx - ax) / (by - ay)
                            x_lo, x_hi = min(x_lo, x), max(x_hi, x)
            if x_hi < x_lo:
                continue
            c0 = max(0, int(math.floor(x_lo - 0.5)) + 1)
            c1 = min(w - 1, int(math.ceil(x_hi + 0.5)) - 1)
            for x in range(c0, c1 + 1):
                img[y, x, 0] = b
                img[y, x, 1] = g
                img[y, x, 2] = r
                if clear[m]:
                    ids[y, x] = 0


def fill_polygons(img: np.ndarray, ids: np.ndarray, polys: np.ndarray, counts: np.ndarray,
                  bgr: np.ndarray, clear: np.ndarray, lo: int, hi: int) -> None:
    """Fill polygons ``lo .. hi - 1`` in order into ``img`` (h x w x 4 BGRA uint8;
    alpha left as it is): polygon ``m`` is the convex ``polys[m, :counts[m]]``
    (pixels, x and y; float64), in colour ``bgr[m]`` (uint8), and where
    ``clear[m]`` it sets ``ids`` (h x w uint16) to 0 under it."""
    if not (polys.ndim == 3 and polys.shape[2] == 2 and len(counts) == len(bgr) == len(clear)
            == len(polys) and img.shape[:2] == ids.shape and 0 <= lo <= hi <= len(polys)):
        raise ValueError(f"fill_polygons: polygons {polys.shape}, {len(counts)} counts, "
                         f"{len(bgr)} colours, {len(clear)} flags, image {img.shape}, ids "
                         f"{ids.shape}, range {lo}..{hi}")
    _fill(img, ids, polys, counts, bgr, clear, lo, hi)
