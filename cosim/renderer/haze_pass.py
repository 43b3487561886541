"""The ground's haze, compiled: each tile of the frame through its own
transmittance's table, in one sweep (``haze_tiles``).

``Haze.ground`` gives the tiles' rows and levels (``haze.tile_levels``); each
pixel's B, G and R go through ``tables[level]`` (``Haze.tables``), alpha is
left as it is, and with a ground mask only the pixels it marks change: the
same bytes as a ``cv2.LUT`` per run of tiles of one level (``Haze.pieces``),
without the runs' bookkeeping or a masked copy.

Compiled by numba on first use in a process (kept in numba's cache beside
this file after that). Owns nothing but the arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, boundscheck=False)
def _haze_tiles(img: np.ndarray, rows: np.ndarray, levels: np.ndarray, tables: np.ndarray,
                tile_cols: int, mask: np.ndarray, use_mask: bool
                ) -> None:  # pragma: no cover (compiled)
    w = img.shape[1]
    for r in range(rows.shape[0]):
        for y in range(rows[r, 0], rows[r, 1]):
            for c in range(levels.shape[1]):
                t = tables[levels[r, c]]
                for x in range(c * tile_cols, min((c + 1) * tile_cols, w)):
                    if use_mask and mask[y, x] == 0:
                        continue
                    img[y, x, 0] = t[img[y, x, 0], 0]
                    img[y, x, 1] = t[img[y, x, 1], 1]
                    img[y, x, 2] = t[img[y, x, 2], 2]


def haze_tiles(img: np.ndarray, rows: np.ndarray, levels: np.ndarray, tables: np.ndarray,
               tile_cols: int, mask: np.ndarray | None = None) -> None:
    """Haze ``img`` (h x w x 4 BGRA uint8, in place): the rows ``[y0, y1)`` of
    ``rows`` (n x 2 int) cut into tiles ``tile_cols`` wide, tile ``(r, c)``
    through ``tables[levels[r, c]]`` (``tables``: L x 256 x 4 uint8; ``levels``
    n x tiles across); with ``mask`` (h x w uint8) only where it is not 0."""
    if levels.shape[0] != rows.shape[0] or levels.shape[1] * tile_cols < img.shape[1]:
        raise ValueError(f"haze_tiles: {levels.shape} levels for {rows.shape[0]} rows of "
                         f"{img.shape[1]} px in tiles of {tile_cols}")
    _haze_tiles(img, rows, levels, tables, tile_cols,
                mask if mask is not None else _NO_MASK, mask is not None)


_NO_MASK = np.zeros((1, 1), np.uint8)


def _warm() -> None:
    """Compile (or load) the pass for the types frames have, on import: a
    render worker pays for it while it starts, not on its first frame."""
    img = np.zeros((4, 4, 4), np.uint8)
    rows, levels = np.array([[0, 4]], np.int64), np.zeros((1, 1), np.int64)
    tables = np.zeros((1, 256, 4), np.uint8)
    haze_tiles(img, rows, levels, tables, 4)
    haze_tiles(img, rows, levels, tables, 4, np.zeros((4, 4), np.uint8))


_warm()
