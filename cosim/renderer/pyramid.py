"""A pyramid of ground tiles by level, made on demand and kept in memory: the
tiles most recently used (``MAX_TILES``, an LRU) and, per camera stream, the
patch of whole tiles it last drew from (``patch``, at most ``PATCH_MB``).

Level ``l`` has ``base_m_per_px * 2**l`` metres per pixel; its pixel
``(row, col)`` is centred at ``east = (col + 0.5) * mpp``,
``north = -(row + 0.5) * mpp`` in the scenario frame (the image grid of
``cosim.world.image_grid`` with its corner at the origin). A frame picks the level
from its ground sample distance (``level_for``: no blur low, no aliasing high).

Owns the tiles in memory only: a subclass makes them (``_make_tile``; the
ground's: ``cosim.renderer.ground``), and what they show is not its concern.
"""

from __future__ import annotations

import math
import mmap
from collections import OrderedDict
from collections.abc import Hashable

import numpy as np

from cosim.world.image_grid import ne_to_px

MAX_TILES = 384  # LRU size per process (256 px BGRA tiles: ~100 MB)
PATCH_MB = 256  # assembled patches kept per process (TilePyramid.patch)
_CHUNK = 2 << 20  # new tiles are carved from 2 MB blocks of memory mapped in one call


def _fresh_memory(nbytes: int) -> np.ndarray:
    """``nbytes`` of memory (uint8, contents undefined) whose pages are present: an
    anonymous mapping made present in one call (MAP_POPULATE). Not transparent
    huge pages: where the kernel must compact memory to find one (``defrag:
    madvise``, as on the benchmark's VM) a 2 MB block took 4 to 8 ms against 0.8 ms
    in 4 kB pages."""
    flags = mmap.MAP_PRIVATE | getattr(mmap, "MAP_ANONYMOUS", 0) | \
        getattr(mmap, "MAP_POPULATE", 0)
    try:
        return np.frombuffer(mmap.mmap(-1, nbytes, flags=flags), np.uint8)
    except (OSError, TypeError, ValueError):  # no such mapping here
        return np.empty(nbytes, np.uint8)


class TilePyramid:
    """Tiles (``tile_px`` a side, BGRA uint8) by level, level 0 at ``base_m_per_px``,
    made by ``_make_tile`` on demand and kept in an LRU cache."""

    def __init__(self, base_m_per_px: float, tile_px: int) -> None:
        self.base_mpp = base_m_per_px
        self.tile_px = tile_px
        T = tile_px
        self._tiles: OrderedDict[tuple[int, int, int], np.ndarray] = OrderedDict()
        # assembled patches by (slot, level): the tile range held and its buffer
        self._patches: OrderedDict[tuple[Hashable, int],
                                   tuple[tuple[int, int, int, int], np.ndarray]] = OrderedDict()
        self._ne_to_px: dict[int, np.ndarray] = {}
        self._chunk = np.empty((0, T, T, 4), np.uint8)  # fresh tile memory (_new_tile)
        self._chunk_used = 0

    def _new_tile(self) -> np.ndarray:
        """Memory for one tile (T x T x 4 uint8, contents undefined): the next slot of
        a 2 MB block of fresh memory (``_fresh_memory``) rather than pages faulted in
        one by one as the tile is first written (~3 us each on the benchmark's VM:
        about 0.1 ms a tile); the block is released with the last of its tiles
        (views keep it alive)."""
        if self._chunk_used == len(self._chunk):
            T = self.tile_px
            per = max(1, _CHUNK // (T * T * 4))
            self._chunk = _fresh_memory(per * T * T * 4).reshape(per, T, T, 4)
            self._chunk_used = 0
        out: np.ndarray = self._chunk[self._chunk_used]
        self._chunk_used += 1
        return out

    def mpp(self, level: int) -> float:
        return float(self.base_mpp * 2 ** level)

    def level_for(self, gsd_m: float) -> int:
        """The finest level not much finer than the ground sample distance."""
        return max(0, math.floor(math.log2(max(gsd_m, 1e-9) / self.base_mpp) + 0.5))

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> global pixel (col, row, 1) of ``level``
        (read-only)."""
        P = self._ne_to_px.get(level)
        if P is None:  # the grid whose top-left corner is the origin
            P = self._ne_to_px[level] = ne_to_px(0.0, 0.0, self.mpp(level))
            P.flags.writeable = False
        return P

    def tile(self, level: int, ti: int, tj: int) -> np.ndarray:
        """Tile (ti, tj) of ``level`` (BGRA uint8; not to be written)."""
        key = (level, ti, tj)
        t = self._tiles.get(key)
        if t is not None:
            self._tiles.move_to_end(key)
            return t
        t = self._make_tile(level, ti, tj)
        self._tiles[key] = t
        if len(self._tiles) > MAX_TILES:
            self._tiles.popitem(last=False)
        return t

    def _make_tile(self, level: int, ti: int, tj: int) -> np.ndarray:
        """Tile (ti, tj) of ``level`` (BGRA uint8), in memory from ``_new_tile``."""
        raise NotImplementedError

    def patch(self, level: int, r0: int, r1: int, c0: int, c1: int,
              slot: Hashable = None) -> np.ndarray:
        """Global pixels rows [r0, r1) x cols [c0, c1) of ``level`` (BGRA uint8,
        alpha 255): a view into the whole tiles covering it, assembled when the
        set of tiles changes (not every frame) and valid until the next call for
        the same ``slot`` and level. A render process gives each camera stream its
        own slot: streams looking at different ground would otherwise take turns
        reassembling one buffer every frame. At most ``PATCH_MB`` of buffers are
        kept (least recently used dropped)."""
        T = self.tile_px
        key = (r0 // T, (r1 - 1) // T + 1, c0 // T, (c1 - 1) // T + 1)
        held = self._patches.get((slot, level))
        if held is None or held[0] != key:
            ta, tb, tc, td = key
            h, w = (tb - ta) * T, (td - tc) * T
            buf = held[1] if held is not None else np.empty((0, 0, 4), np.uint8)
            if buf.shape[0] < h or buf.shape[1] < w:
                buf = np.empty((max(h, buf.shape[0]), max(w, buf.shape[1]), 4), np.uint8)
            for ti in range(ta, tb):
                for tj in range(tc, td):
                    buf[(ti - ta) * T:(ti - ta + 1) * T, (tj - tc) * T:(tj - tc + 1) * T] = \
                        self.tile(level, ti, tj)
            held = self._patches[(slot, level)] = (key, buf)
            self._patches.move_to_end((slot, level))  # never the one dropped below
            total = sum(b.nbytes for _, b in self._patches.values())
            while total > PATCH_MB * 2**20 and len(self._patches) > 1:
                _, (_, old) = self._patches.popitem(last=False)
                total -= old.nbytes
        else:
            self._patches.move_to_end((slot, level))
        y, x = r0 - key[0] * T, c0 - key[2] * T
        out: np.ndarray = held[1][y:y + r1 - r0, x:x + c1 - c0]
        return out
