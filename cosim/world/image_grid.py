"""The north-up pixel grid a ground image lies on in the scenario's frame.

Level ``k`` of an image has square pixels of ``m = m_per_px * 2**k`` metres;
its pixel ``(row, col)`` is centred at ``north = n0 - (row + 1/2) m``,
``east = e0 + (col + 1/2) m``, ``(n0, e0)`` being the image's top-left
corner (scenario metres). A picture placed by hand (``picture``) and a
georeferenced file (``geotiff``) each lie on one; the procedural ground's
tiles on the one whose corner is the origin.

Owns this convention (``ne_to_px`` and ``ImageGrid``): nothing is read or
drawn here.
"""

from __future__ import annotations

import math

import numpy as np


def ne_to_px(n0: float, e0: float, m: float, row0: int = 0, col0: int = 0) -> np.ndarray:
    """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of the grid of ``m``
    metres per pixel whose top-left corner is at (``n0``, ``e0``), counted from
    its pixel (``row0``, ``col0``)."""
    return np.array([[0.0, 1.0 / m, -e0 / m - 0.5 - col0],
                     [-1.0 / m, 0.0, n0 / m - 0.5 - row0],
                     [0.0, 0.0, 1.0]])


class ImageGrid:
    """An image's levels on the grid: level 0 of ``m_per_px``, ``n_levels``
    levels, top-left corner (``n0``, ``e0``); set by the image that is one."""

    n0: float
    e0: float
    m_per_px: float
    n_levels: int

    def mpp(self, level: int) -> float:
        """Metres per pixel of ``level``."""
        return float(self.m_per_px * 2 ** level)

    def level_for(self, gsd_m: float) -> int:
        """The level to draw a ground sample distance of ``gsd_m`` from: the
        coarsest whose pixels are not much larger than it, within the levels."""
        k = math.floor(math.log2(max(gsd_m, 1e-9) / self.m_per_px) + 0.3)
        return min(max(k, 0), self.n_levels - 1)

    def ne_to_px(self, level: int, row0: int = 0, col0: int = 0) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of ``level``,
        counted from its pixel (``row0``, ``col0``)."""
        return ne_to_px(self.n0, self.e0, self.mpp(level), row0, col0)
