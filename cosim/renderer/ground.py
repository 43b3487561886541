"""The ground a frame draws: the procedural texture (``texture``) as a pyramid
of tiles (``pyramid``), kept on disk between runs (``tile_cache``), with the
scenario's imagery, if any, drawn over it (``image_layers``).

Texture coordinates are the scenario frame's ``(north_m, east_m)``: a ground
point is the ellipsoid point ``LocalFrame.place(north, east, ground_alt)``,
the same convention targets use. A tile is taken from memory, else from the
disk cache, else made (and stored there). A frame asks for the patch of
tiles under a band of its image (``GroundTexture.patch``), which also focuses
the image layer on that ground, then for the layer's pixels there.

Owns that composition only: what the tiles look like, where they are kept and
how imagery is read or drawn belong to the modules named above.
"""

from __future__ import annotations

from collections.abc import Hashable

import cv2
import numpy as np

from cosim.core.geo import LocalFrame
from cosim.renderer.canopy import FLAT_FROM_LEVEL
from cosim.renderer.image_layers import GeoRasterLayer, PictureLayer, image_layer
from cosim.renderer.pyramid import TilePyramid
from cosim.renderer.texture import ProceduralTiles
from cosim.renderer.tile_cache import TileCache, ground_cache_dir
from cosim.world.ground import GroundSpec


def trees_from_level(trees: str) -> int:
    """The finest ground level whose tiles show flat trees: every level for
    ``flat``, the coarse ones for ``3d`` (finer ones: drawn in 3-D), none for
    ``none``."""
    return {"flat": 0, "3d": FLAT_FROM_LEVEL}.get(trees, 1 << 20)


class GroundTexture(TilePyramid):
    """The scenario's ground by level: procedural tiles made on demand, kept in
    memory and on disk, and its image layer (``image``)."""

    def __init__(self, spec: GroundSpec, frame: LocalFrame, seed: int) -> None:
        super().__init__(spec.base_m_per_px, spec.tile_px)
        self.spec = spec
        self.seed = int(seed)
        self.procedural = ProceduralTiles(self.seed, spec.base_m_per_px, spec.tile_px,
                                          trees_from_level(spec.trees))
        self.image: PictureLayer | GeoRasterLayer | None = image_layer(spec, frame)
        self.tiles_made = 0
        self.tiles_loaded = 0
        self.cache = TileCache(ground_cache_dir(spec, self.seed), spec.tile_px)

    def _make_tile(self, level: int, ti: int, tj: int) -> np.ndarray:
        """Tile (ti, tj) of ``level`` (BGRA uint8): from the disk cache if there,
        else generated (and stored there)."""
        path = self.cache.path(level, ti, tj)
        if path is not None:
            bgr = self.cache.read(path)
            if bgr is not None:
                self.tiles_loaded += 1
                out: np.ndarray = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA, dst=self._new_tile())
                return out
        bgra = self.procedural.make(level, ti, tj, self._new_tile())
        self.tiles_made += 1
        if path is not None:
            self.cache.write(level, path, bgra)
        return bgra

    def patch(self, level: int, r0: int, r1: int, c0: int, c1: int,
              slot: Hashable = None) -> np.ndarray:
        """``TilePyramid.patch``, with the image layer focused on that ground (it is
        drawn over it next)."""
        if self.image is not None:
            m = self.mpp(level)
            self.image.focus(-r1 * m, -r0 * m, c0 * m, c1 * m, slot)
        return super().patch(level, r0, r1, c0, c1, slot)
