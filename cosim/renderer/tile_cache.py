"""The procedural ground's tiles on disk, so that the first run over a piece of
ground pays for them and later runs, and the other runs of a sweep, read them
(0.05 ms a tile against 1 to 2 ms to make one).

``ground_cache_dir`` is the folder of one seed's tiles, keyed by everything
their pixels depend on; ``TileCache`` reads and writes them there: one raw BGR
file of 192 kB per 256 px tile, written once (parallel render workers and
sweep runs race for it), read only whole. No more tiles are written once the
folder holds ``CACHE_MB`` (``COSIM_GROUND_CACHE_MB``); a cache that cannot be
written is skipped. ``COSIM_GROUND_CACHE=off`` turns it off.

Owns the files only: it neither makes tiles (``texture``) nor keeps them in
memory (``pyramid``).
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import cv2
import numpy as np

from cosim.core.cache import cache_folder
from cosim.renderer.texture import TEXTURE_VERSION
from cosim.world.ground import GroundSpec

log = logging.getLogger(__name__)

CACHE_ENV = "COSIM_GROUND_CACHE"  # "off": no tile cache (its folder: cosim.core.cache)
CACHE_MB_ENV, CACHE_MB = "COSIM_GROUND_CACHE_MB", 2048  # no more tiles written past this


def ground_cache_dir(spec: GroundSpec, seed: int) -> Path | None:
    """The disk cache folder for the procedural tiles of ``seed`` and ``spec``, or
    None if caching is off (``COSIM_GROUND_CACHE=off``): ``ground/`` in the cache
    folder (``cosim.core.cache``), one subfolder per
    texture version, seed, base resolution, tile size, trees (flat, 3d or none)
    and the numpy/OpenCV versions (their float maths makes the pixels), so a
    cached tile is the very tile this process would generate."""
    if os.environ.get(CACHE_ENV, "").lower() in ("off", "0", "no", "false"):
        return None
    root = cache_folder("ground")
    key = f"{TEXTURE_VERSION}|{seed}|{spec.base_m_per_px!r}|{spec.tile_px}|{np.__version__}|" \
          f"{cv2.__version__}"
    if spec.trees != "flat":  # its finer levels show the ground under the trees, or none
        key += f"|trees={spec.trees}"
    return root / f"v{TEXTURE_VERSION}-{hashlib.sha1(key.encode()).hexdigest()[:16]}"


def _folder_bytes(folder: Path) -> int:
    total = 0
    for sub in (folder.iterdir() if folder.is_dir() else ()):
        for f in (os.scandir(sub) if sub.is_dir() else ()):
            total += f.stat().st_size
    return total


class TileCache:
    """The tiles of one folder (``ground_cache_dir``; None: no cache), ``tile_px``
    a side: ``L<level>/<ti>_<tj>.bgr``."""

    def __init__(self, folder: Path | None, tile_px: int) -> None:
        self.folder = folder
        self.tile_px = tile_px
        T = tile_px
        self._buf = np.empty((T, T, 3), np.uint8)  # a tile read, or the BGR of one written
        self._room = 0  # bytes this process may still add to the cache
        self._dirs_made: set[str] = set()
        self._level_dirs: dict[int, str] = {}  # a level's cache folder, "/" at the end
        if folder is not None:
            mb = float(os.environ.get(CACHE_MB_ENV) or CACHE_MB)
            self._room = int(mb * 2**20) - _folder_bytes(folder)

    def path(self, level: int, ti: int, tj: int) -> str | None:
        """The tile's file (a string: a ``Path`` costs ~8 us to build), or None."""
        if self.folder is None:
            return None
        folder = self._level_dirs.get(level)
        if folder is None:
            folder = self._level_dirs[level] = os.path.join(self.folder, f"L{level}", "")
        return f"{folder}{ti}_{tj}.bgr"

    def read(self, path: str) -> np.ndarray | None:
        """The tile at ``path`` (BGR, in a buffer reused by the next call), or None
        if it is not cached (one cut short, by a crash or being written, is
        removed: it is made anew)."""
        try:
            with open(path, "rb") as f:
                bgr = self._buf
                if f.readinto(bgr.data.cast("B")) == bgr.nbytes and not f.read(1):
                    return bgr
            os.unlink(path)
        except OSError:
            pass  # not cached yet
        return None

    def write(self, level: int, path: str, bgra: np.ndarray) -> None:
        """Keep the tile ``bgra`` of ``level`` at ``path`` while there is room."""
        if self._room > 0:
            self._store(level, path, cv2.cvtColor(bgra, cv2.COLOR_BGRA2BGR, dst=self._buf))

    def _store(self, level: int, path: str, bgr: np.ndarray) -> None:
        """Write a tile's raw BGR bytes. A tile is written once (O_EXCL: parallel
        render workers and sweep runs race for it) in one call; a reader takes
        only a file of the full size. A cache that cannot be written is skipped."""
        try:
            folder = self._level_dirs[level]
            if folder not in self._dirs_made:  # a mkdir call costs as much as 0.04 ms
                os.makedirs(folder, exist_ok=True)
                self._dirs_made.add(folder)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            return
        except OSError as e:
            if isinstance(e, FileNotFoundError) and folder in self._dirs_made:
                self._dirs_made.discard(folder)  # removed meanwhile: made anew next time
                return
            log.debug("ground tile cache: cannot write %s: %s", path, e)
            self._room = 0
            return
        try:
            os.write(fd, bgr.data)
            self._room -= bgr.nbytes
        except OSError as e:
            log.debug("ground tile cache: cannot write %s: %s", path, e)
            self._room = 0
        finally:
            os.close(fd)
