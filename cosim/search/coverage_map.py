"""The coverage map: when each cell of the search area was first under a camera.

A grid of square cells over the area's bounding box (the area's and the
zones' outlines filled by OpenCV); a cell counts as searched at the first
frame whose swept footprint covers its centre. The
swept footprint of an aircraft between two consecutive frames is the convex
hull of its footprints at both (exact for straight flight, a little
generous on the outside of a turn), so a camera that moves farther than its
footprint's length between frames leaves no gaps. Cells inside a no-fly
zone are not part of the area.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

SHIFT = 4  # sub-cell bits of the polygon fill
_ONE = 1 << SHIFT
NEVER = -1


class CoverageMap:
    def __init__(self, area_ne: Sequence[tuple[float, float]],
                 no_fly_ne: Sequence[Sequence[tuple[float, float]]], cell_m: float) -> None:
        a = np.asarray(area_ne, dtype=float)
        self.cell = float(cell_m)
        self.n0, self.e0 = float(a[:, 0].min()), float(a[:, 1].min())
        self.rows = int(math.ceil((a[:, 0].max() - self.n0) / cell_m)) + 1
        self.cols = int(math.ceil((a[:, 1].max() - self.e0) / cell_m)) + 1
        self.inside = np.zeros((self.rows, self.cols), np.uint8)
        cv2.fillPoly(self.inside, [self._px(a)], 1, cv2.LINE_8, SHIFT)
        for z in no_fly_ne:
            cv2.fillPoly(self.inside, [self._px(np.asarray(z, dtype=float))], 0, cv2.LINE_8,
                         SHIFT)
        self.cells = int(self.inside.sum())
        self.open = self.inside.astype(bool)  # inside the area, outside every zone
        self._xs = np.arange(self.cols, dtype=np.float32)
        self._ys = np.arange(self.rows, dtype=np.float32)
        if not self.cells:
            raise ValueError("the search area covers no cell of the coverage map")
        #: the frame at which each cell was first covered (NEVER: not yet)
        self.first = np.full((self.rows, self.cols), NEVER, np.int32)
        self.covered = 0

    def _px(self, ne: np.ndarray) -> np.ndarray:
        """(k, 2) north/east -> fixed-point (x = column, y = row) cell coordinates,
        cell centres at whole numbers."""
        x = (ne[..., 1] - self.e0) / self.cell
        y = (ne[..., 0] - self.n0) / self.cell
        return np.round(np.stack([x, y], axis=-1) * _ONE).astype(np.int32)

    def add(self, frame: int, polygons_ne: Sequence[np.ndarray]) -> int:
        """Mark the cells whose centres lie in each polygon's convex hull
        ((k, 2) north/east) as covered at ``frame`` (if not already); the
        cells newly covered. (An exact centre test, edge by edge: OpenCV's
        fill would also take the cells the outline only grazes.)"""
        new = 0
        for poly in polygons_ne:
            xy = np.empty((len(poly), 2), np.float32)
            xy[:, 0] = (poly[:, 1] - self.e0) / self.cell
            xy[:, 1] = (poly[:, 0] - self.n0) / self.cell
            hull = cv2.convexHull(xy)[:, 0, :]
            if len(hull) < 3:
                continue
            x, y = hull[:, 0], hull[:, 1]
            if float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) < 0:
                hull = hull[::-1]  # counter-clockwise (x east, y north)
            x0 = max(0, math.ceil(float(hull[:, 0].min())))
            y0 = max(0, math.ceil(float(hull[:, 1].min())))
            x1 = min(self.cols, math.floor(float(hull[:, 0].max())) + 1)
            y1 = min(self.rows, math.floor(float(hull[:, 1].max())) + 1)
            if x1 <= x0 or y1 <= y0:
                continue
            first = self.first[y0:y1, x0:x1]
            fresh = self.open[y0:y1, x0:x1] & (first == NEVER)
            if not fresh.any():
                continue
            xs = self._xs[x0:x1][None, :]
            ys = self._ys[y0:y1][:, None]
            nxt = np.roll(hull, -1, axis=0)
            for (ax, ay), (bx, by) in zip(hull.tolist(), nxt.tolist()):
                fresh &= (bx - ax) * (ys - ay) >= (by - ay) * (xs - ax)
            k = int(np.count_nonzero(fresh))
            if k:
                first[fresh] = frame
                new += k
        self.covered += new
        return new

    @property
    def fraction(self) -> float:
        return self.covered / self.cells

    def extent_ne(self) -> tuple[float, float, float, float]:
        """(east0, east1, north0, north1) of the grid's cell edges, for imshow."""
        h = self.cell / 2
        return (self.e0 - h, self.e0 + (self.cols - 0.5) * self.cell,
                self.n0 - h, self.n0 + (self.rows - 0.5) * self.cell)
