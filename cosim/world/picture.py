"""A ground picture placed by hand: a north-up PNG, JPEG or TIFF whose top-left
corner is at the scenario's ``ground.origin`` (north/east metres, or
latitude/longitude) with ``ground.m_per_px``.

``Picture`` checks what it may read first (``imagery.check_picture``: the
declared size within what a render worker may hold), then decodes it whole
(OpenCV), places it on the scenario frame's grid (``image_grid``) and halves
it level by level while a level is at least 8 px a side (BGRA uint8,
opaque). A georeferenced file is ``geotiff``'s ``GeoRaster`` instead.

Owns reading and placing the picture; drawing it is the renderer's.
"""

from __future__ import annotations

import cv2
import numpy as np

from cosim.core.geo import LocalFrame
from cosim.world.image_grid import ImageGrid
from cosim.world.imagery import ImageRefused, check_picture


class Picture(ImageGrid):
    """The picture at ``path`` (read from the folders ``roots``), its top-left
    corner at ``origin_ne_m`` or ``origin_latlon_deg`` (else the origin),
    ``m_per_px``: ``levels[k]`` is level ``k``. ImageRefused if it may not be
    read or does not decode."""

    def __init__(self, path: str, roots: tuple[str, ...], frame: LocalFrame, m_per_px: float,
                 origin_ne_m: tuple[float, float] | None = None,
                 origin_latlon_deg: tuple[float, float] | None = None) -> None:
        check_picture(path, roots)  # its declared size, before decoding
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        if bgr is None:
            raise ImageRefused(f"cannot read {path} as an image")
        img = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
        if origin_latlon_deg is not None:
            la, lo = origin_latlon_deg
            n, e, _ = frame.geodetic_to_ned(la, lo, frame.alt_m)
            self.n0, self.e0 = float(n), float(e)
        else:
            self.n0, self.e0 = origin_ne_m or (0.0, 0.0)
        self.m_per_px = m_per_px
        self.levels: list[np.ndarray] = [img]
        while min(self.levels[-1].shape[:2]) >= 8:
            self.levels.append(cv2.resize(self.levels[-1], None, fx=0.5, fy=0.5,
                                          interpolation=cv2.INTER_AREA))
        self.n_levels = len(self.levels)
        h, w = img.shape[:2]
        self.bounds_ne = (self.n0 - h * self.m_per_px, self.n0, self.e0,
                          self.e0 + w * self.m_per_px)
