"""Ground imagery drawn over the procedural ground: a user's picture placed by
hand, or a georeferenced file (GeoTIFF, COG, VRT), each as a layer with the
four calls a frame draws with: ``level_for``, ``levels[k]``, ``ne_to_px(k)``
and ``coverage(k)`` (255 where the layer has data); ``focus`` tells it the
ground about to be drawn first (``GroundTexture.patch``).

A picture is held whole with its pyramid; a georeferenced file is read a
tile at a time (``cosim.world.geotiff.GeoRaster``), only under the ground
being drawn, in windows of at most ``MAX_WINDOW_PX`` a side (``WINDOW_MB`` of
them kept). Where neither covers the ground, the procedural ground shows.

Owns how the imagery is drawn; reading and placing it is the world's
(``cosim.world``), and it never touches the procedural tiles.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Hashable

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.world.geotiff import GeoRaster
from cosim.world.ground import GroundSpec, open_image
from cosim.world.picture import Picture

MAX_WINDOW_PX = 4096  # a georeferenced file's window a band draws, at most (a side)
WINDOW_MB = 96  # a georeferenced file's assembled windows kept per process


class PictureLayer:
    """A picture placed by hand (``cosim.world.picture.Picture``), drawn from its
    whole levels (BGRA uint8, opaque, like the frames). A georeferenced file is a
    ``GeoRasterLayer`` instead (the same four calls: ``level_for``, ``levels[k]``,
    ``ne_to_px(k)``, ``coverage(k)``)."""

    def __init__(self, src: Picture) -> None:
        self.src = src
        self.levels = src.levels
        self.bounds_ne = src.bounds_ne
        self._coverage: dict[int, np.ndarray] = {}

    def focus(self, n_lo: float, n_hi: float, e_lo: float, e_hi: float,
              slot: Hashable = None) -> None:
        """The ground about to be drawn (nothing to do: the picture is all in memory)."""

    def level_for(self, gsd_m: float) -> int:
        return self.src.level_for(gsd_m)

    def coverage(self, level: int) -> np.ndarray:
        """255 where ``level`` has data, else 0: all of it; made once per level."""
        if level not in self._coverage:
            self._coverage[level] = np.full(self.levels[level].shape[:2], 255, np.uint8)
        return self._coverage[level]

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of ``level``."""
        return self.src.ne_to_px(level)


class _FocusedLevels:
    """``levels[k]`` of a ``GeoRasterLayer``: level ``k``'s pixels over the ground in
    focus (BGRA uint8)."""

    def __init__(self, layer: GeoRasterLayer) -> None:
        self._layer = layer

    def __len__(self) -> int:
        return self._layer.src.n_levels

    def __getitem__(self, level: int) -> np.ndarray:
        return self._layer.held(level)[1]


class GeoRasterLayer:
    """A georeferenced file (GeoTIFF, COG, VRT, ...; cosim/world/geotiff.py's
    ``GeoRaster``) read a tile at a time, with ``PictureLayer``'s four calls. The
    renderer asks for a band's ground patch (``GroundTexture.patch``) before its
    image, and the patch focuses this layer on that ground (``focus``): then
    ``levels[k]``, ``ne_to_px(k)`` and ``coverage(k)`` are of a window of level ``k``
    over just that ground (its whole tiles, within the file), at most
    ``MAX_WINDOW_PX`` a side: ``level_for`` goes coarser where the window would be
    larger. Windows are kept per slot (a camera stream) and level, at most
    ``WINDOW_MB`` of them; tiles in the raster's own LRU."""

    def __init__(self, src: GeoRaster) -> None:
        self.src = src
        self.bounds_ne = src.bounds_ne
        self.levels = _FocusedLevels(self)
        self._focus: tuple[float, float, float, float] | None = None
        self._slot: Hashable = None
        # (slot, level) -> (tiles, bgra, mask, and the buffers these are views of)
        self._held: OrderedDict[tuple[Hashable, int], tuple[tuple[int, int, int, int],
                                                            np.ndarray, np.ndarray,
                                                            np.ndarray, np.ndarray]] = \
            OrderedDict()

    def focus(self, n_lo: float, n_hi: float, e_lo: float, e_hi: float,
              slot: Hashable = None) -> None:
        """The ground about to be drawn: north ``n_lo .. n_hi``, east ``e_lo .. e_hi``
        (scenario metres), for ``slot``."""
        self._focus, self._slot = (n_lo, n_hi, e_lo, e_hi), slot

    def _tiles(self, level: int) -> tuple[int, int, int, int]:
        """The tiles (rows ta .. tb - 1, cols tc .. td - 1) of ``level`` under the
        focus (with a pixel more each side), within the file; empty if none."""
        T, m = self.src.tile_px, self.src.mpp(level)
        rows, cols = self.src.shape(level)
        if self._focus is None:
            r0, r1, c0, c1 = 0, rows, 0, cols
        else:
            n_lo, n_hi, e_lo, e_hi = self._focus
            n0, e0 = self.src.n0, self.src.e0
            r0, r1 = math.floor((n0 - n_hi) / m) - 1, math.ceil((n0 - n_lo) / m) + 1
            c0, c1 = math.floor((e_lo - e0) / m) - 1, math.ceil((e_hi - e0) / m) + 1
            r0, r1, c0, c1 = max(r0, 0), min(r1, rows), max(c0, 0), min(c1, cols)
        if r0 >= r1 or c0 >= c1:
            return (0, 0, 0, 0)
        return r0 // T, (r1 - 1) // T + 1, c0 // T, (c1 - 1) // T + 1

    def level_for(self, gsd_m: float) -> int:
        k = self.src.level_for(gsd_m)
        T = self.src.tile_px
        while k < self.src.n_levels - 1:
            ta, tb, tc, td = self._tiles(k)
            if max(tb - ta, td - tc) * T <= MAX_WINDOW_PX:
                break
            k += 1
        return k

    def held(self, level: int) -> tuple[tuple[int, int, int, int], np.ndarray, np.ndarray]:
        """``(tiles, bgra, mask)``: the window of ``level`` under the focus, assembled
        when its tiles change (into the slot's buffers for the level, grown as needed)."""
        key = self._tiles(level)
        got = self._held.get((self._slot, level))
        if got is not None and got[0] == key:
            self._held.move_to_end((self._slot, level))
            return got[:3]
        ta, tb, tc, td = key
        T = self.src.tile_px
        h, w = max(1, (tb - ta) * T), max(1, (td - tc) * T)
        if max(h, w) > MAX_WINDOW_PX and self._focus is None:
            raise ValueError(f"{self.src.path}: level {level} is {w} x {h} px: focus on the "
                             "ground to draw first (GroundTexture.patch)")
        buf, bmask = (got[3], got[4]) if got is not None else \
            (np.empty((0, 0, 4), np.uint8), np.empty((0, 0), np.uint8))
        if buf.shape[0] < h or buf.shape[1] < w:
            buf = np.empty((max(h, buf.shape[0]), max(w, buf.shape[1]), 4), np.uint8)
            bmask = np.empty(buf.shape[:2], np.uint8)
        img, mask = buf[:h, :w], bmask[:h, :w]
        if tb > ta and td > tc:
            self.src.window(level, ta * T, tb * T, tc * T, td * T, (img, mask))
        else:  # nothing of the file here
            mask[:] = 0
        self._held[(self._slot, level)] = (key, img, mask, buf, bmask)
        self._held.move_to_end((self._slot, level))  # never the one dropped below
        total = sum(v[3].nbytes + v[4].nbytes for v in self._held.values())
        while total > WINDOW_MB * 2**20 and len(self._held) > 1:
            _, old = self._held.popitem(last=False)
            total -= old[3].nbytes + old[4].nbytes
        return key, img, mask

    def coverage(self, level: int) -> np.ndarray:
        """255 where ``levels[level]`` (the window in focus) has data, else 0."""
        return self.held(level)[2]

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of ``levels[level]``
        (the window in focus)."""
        (ta, _, tc, _), _, _ = self.held(level)
        T = self.src.tile_px
        return self.src.ne_to_px(level, ta * T, tc * T)


def image_layer(spec: GroundSpec, frame: LocalFrame) -> PictureLayer | GeoRasterLayer | None:
    """The layer of the ground's image, if it has one (``open_image``: ConfigError
    if it cannot be read)."""
    if spec.kind != "image":
        return None
    src = open_image(spec, frame)
    return GeoRasterLayer(src) if isinstance(src, GeoRaster) else PictureLayer(src)
