"""The ground texture: geo-referenced in the scenario's local frame, as a
pyramid of levels made of tiles generated on demand (LRU cache).

Texture coordinates are the scenario frame's ``(north_m, east_m)``: a ground
point is the ellipsoid point ``LocalFrame.place(north, east, ground_alt)``,
the same convention targets use. Level ``l`` has ``base_m_per_px * 2**l``
metres per pixel; its pixel ``(row, col)`` is centred at
``east = (col + 0.5) * mpp``, ``north = -(row + 0.5) * mpp``. A frame picks
the level from its ground sample distance (no blur low, no aliasing high).

The procedural texture is a pure function of the seed and the position:
fields in a gently warped grid (crop colours, crop rows), hedgerows and woods
of individual tree crowns, roads, and a tileable fine-detail texture down to
the base level (5 cm/px by default). Every feature is band-limited to the
level it is drawn at (crop rows and noise octaves finer than two pixels are
left out, roads and tree crowns are drawn with their pixel coverage). A tile
costs about 3 ms to make, so tiles are also kept on disk (``ground_cache_dir``:
one raw BGR file of 192 kB per 256 px tile, keyed by everything its pixels
depend on; no more written once a seed's folder holds ``CACHE_MB``): the
first run over a piece of ground pays for it, later runs and the other runs
of a sweep read it (0.05 ms a tile). A user image (PNG/JPG, north up, ``m_per_px``, top-left corner
``origin``) gets its own pyramid; outside it the procedural ground shows.
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from cosim.geo import LocalFrame
from cosim.renderer.config import GroundSpec

log = logging.getLogger(__name__)

MACRO_STEP_M = 0.5  # macro features (fields, roads, trees) sampled at least this fine
DETAIL_PX = 512  # the tileable detail texture's size at the base level
MAX_TILES = 384  # LRU size per process (256 px BGRA tiles: ~100 MB)
MACRO_OVERSAMPLE = 2.0  # macro features sampled at most every this many pixels, then upsampled
#: bump whenever a tile's pixels change for the same seed and ground parameters
#: (old cache folders are then ignored; delete ~/.cache/cosim/ground to reclaim the space)
TEXTURE_VERSION = 4
CACHE_ENV = "COSIM_GROUND_CACHE"  # a folder for the tile cache, or "off"
CACHE_MB_ENV, CACHE_MB = "COSIM_GROUND_CACHE_MB", 2048  # no more tiles written past this

# field palette, RGB: crops, pasture, wheat, ploughed soil, dry grass, dark crop
_FIELDS = np.array([[96, 128, 58], [118, 140, 72], [176, 160, 96], [122, 98, 72],
                    [150, 146, 98], [74, 104, 50]], dtype=np.float32)
_TREE = np.array([46, 70, 38], dtype=np.float32)
_ROAD = np.array([118, 116, 112], dtype=np.float32)


def _hash(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """Uniform [0, 1) from integer lattice coordinates (vectorised, stateless;
    uint32 arithmetic wraps by design)."""
    with np.errstate(over="ignore"):
        h = (i.astype(np.int64).astype(np.uint32) * np.uint32(374761393)
             + j.astype(np.int64).astype(np.uint32) * np.uint32(668265263)
             + np.uint32((seed * 2246822519 + 0x9E3779B9) & 0xFFFFFFFF))
        h = (h ^ (h >> np.uint32(13))) * np.uint32(1274126177)
        h = h ^ (h >> np.uint32(16))
    out: np.ndarray = (h >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 0x1000000)
    return out


def _derive(h: np.ndarray, k: float) -> np.ndarray:
    """Another uniform [0, 1) value from one hash (cheaper than hashing again)."""
    x = h.astype(np.float64) * k
    out: np.ndarray = (x - np.floor(x)).astype(np.float32)
    return out


def _vnoise(x: np.ndarray, y: np.ndarray, seed: int, period: int = 0) -> np.ndarray:
    """Smooth value noise in [0, 1) on the unit lattice (periodic if ``period``)."""
    if not period and x.ndim == 2 and y.ndim == 2 and x.shape[1] == 1 and y.shape[0] == 1:
        return _vnoise_grid(x[:, 0], y[0, :], seed)
    xi, yi = np.floor(x), np.floor(y)
    fx, fy = (x - xi).astype(np.float32), (y - yi).astype(np.float32)
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    xi, yi = xi.astype(np.int64), yi.astype(np.int64)
    x1, y1 = xi + 1, yi + 1
    if period:
        xi, yi, x1, y1 = xi % period, yi % period, x1 % period, y1 % period
    a, b = _hash(xi, yi, seed), _hash(x1, yi, seed)
    c, d = _hash(xi, y1, seed), _hash(x1, y1, seed)
    top = a + (b - a) * fx
    return top + ((c + (d - c) * fx) - top) * fy


def _vnoise_grid(x: np.ndarray, y: np.ndarray, seed: int) -> np.ndarray:
    """``_vnoise`` on the grid x (R) by y (C), the same values: the lattice
    corners it needs are hashed once each (a few) and gathered."""
    xi, yi = np.floor(x), np.floor(y)
    fx, fy = (x - xi).astype(np.float32), (y - yi).astype(np.float32)
    fx, fy = (fx * fx * (3 - 2 * fx))[:, None], (fy * fy * (3 - 2 * fy))[None, :]
    xi, yi = xi.astype(np.int64), yi.astype(np.int64)
    x0, y0 = int(xi.min()), int(yi.min())
    kx = np.arange(x0, int(xi.max()) + 2, dtype=np.int64)
    ky = np.arange(y0, int(yi.max()) + 2, dtype=np.int64)
    table = _hash(kx[:, None], ky[None, :], seed)  # (corner x, corner y)
    ny = len(ky)
    base = ((xi - x0) * ny)[:, None] + (yi - y0)[None, :]
    a, b = table.take(base), table.take(base + ny)
    c, d = table.take(base + 1), table.take(base + (ny + 1))
    top = a + (b - a) * fx
    out: np.ndarray = top + ((c + (d - c) * fx) - top) * fy
    return out


def _fbm(n: np.ndarray, e: np.ndarray, wavelength_m: float, octaves: int, step_m: float,
         seed: int) -> np.ndarray:
    """Fractal noise around 0 (about +-0.5), octaves finer than two samples left out."""
    out = np.zeros(np.broadcast_shapes(n.shape, e.shape), dtype=np.float32)
    amp, wl = 1.0, wavelength_m
    for k in range(octaves):
        if wl < 2 * step_m:
            break
        out += amp * (_vnoise(n / wl, e / wl, seed + 17 * k) - 0.5)
        amp *= 0.5
        wl *= 0.5
    return out


def _coverage(signed_dist_m: np.ndarray, step_m: float) -> np.ndarray:
    """Pixel coverage of a shape from the signed distance to its edge (inside > 0)."""
    out: np.ndarray = np.clip(signed_dist_m / max(step_m, 1e-6) + 0.5, 0.0, 1.0)
    return out.astype(np.float32)


def _smooth(n: np.ndarray, e: np.ndarray, spacing_m: float,
            field: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """``field`` (a smooth function of north, east) at the grid ``n`` (R x 1) x
    ``e`` (1 x C), evaluated on the global lattice of ``spacing_m`` that covers
    the grid and interpolated bilinearly (exact at lattice points; a pure
    function of position, so neighbouring tiles agree)."""
    nv, ev = n[:, 0], e[0, :]
    if len(nv) * len(ev) <= 64 or (len(nv) > 1 and abs(nv[1] - nv[0]) >= spacing_m):
        return field(n, e)
    kn0, kn1 = math.floor(nv.min() / spacing_m), math.floor(nv.max() / spacing_m) + 1
    ke0, ke1 = math.floor(ev.min() / spacing_m), math.floor(ev.max() / spacing_m) + 1
    gn = np.arange(kn0, kn1 + 1, dtype=np.float64) * spacing_m
    ge = np.arange(ke0, ke1 + 1, dtype=np.float64) * spacing_m
    coarse = field(gn[:, None], ge[None, :])
    fn = nv / spacing_m - kn0
    i = np.minimum(np.floor(fn).astype(np.int64), len(gn) - 2)
    wn = (fn - i).astype(np.float32)[:, None]
    rows = coarse[i] + (coarse[i + 1] - coarse[i]) * wn  # (R, lattice columns): small
    fe = ev / spacing_m - ke0
    j = np.minimum(np.floor(fe).astype(np.int64), len(ge) - 2)
    we = (fe - j).astype(np.float32)[None, :]
    left = rows.take(j, axis=1)
    out: np.ndarray = left + (rows.take(j + 1, axis=1) - left) * we
    return out


class _CellTable:
    """Per-cell values looked up at every sample: the cells of ``floor(a / size)``
    (a float array of any shape) are numbered from its smallest one, so a value
    computed once per cell (a few dozen) is gathered instead of evaluated per
    sample (thousands)."""

    def __init__(self, k: np.ndarray) -> None:
        self.k0 = float(k.min())
        self.keys = np.arange(self.k0, float(k.max()) + 1.0)  # the cells, as floats
        self.idx = (k - self.k0).astype(np.intp)


def macro_rgb(n: np.ndarray, e: np.ndarray, step_m: float, seed: int) -> np.ndarray:
    """The procedural ground's colour (float32 RGB 0..255, shape (R, C, 3)) at
    the scenario-frame grid ``n`` (R x 1) x ``e`` (1 x C), drawn for a sample
    spacing of ``step_m``. Low-frequency fields (field-grid warp, woods, the
    brightness noise) are evaluated on coarser lattices and interpolated; what
    depends only on a field or a tree cell is computed once per cell and
    gathered."""
    n = n.astype(np.float64)
    e = e.astype(np.float64)
    wn = n + _smooth(n, e, 8.0, lambda a, b: 30.0 * (_vnoise(a / 230.0, b / 230.0, seed + 1)
                                                    - 0.5))
    we = e + _smooth(n, e, 8.0, lambda a, b: 30.0 * (_vnoise(a / 230.0, b / 230.0, seed + 2)
                                                    - 0.5))
    fn, fe = 160.0, 220.0  # field size
    # fields: one row of the table per (ci, cj) cell of the warped field grid
    ti, tj = _CellTable(np.floor(wn / fn)), _CellTable(np.floor(we / fe))
    cell = ti.idx * len(tj.keys) + tj.idx
    hf = _hash(ti.keys[:, None], tj.keys[None, :], seed + 3).ravel()
    kind = np.minimum((hf * len(_FIELDS)).astype(np.int64), len(_FIELDS) - 1)
    colour = _FIELDS[kind] * (0.88 + 0.24 * _derive(hf, 613.37))[..., None]
    # colours are planar (3, R, C) until the end: numpy broadcasts an (R, C) factor
    # over a leading axis of 3 several times faster than over a trailing one
    rgb = colour.T.take(cell, axis=1)
    # crop rows: 2.5-4 m apart, along or across the field, only where resolvable
    period = 2.5 + 1.5 * _derive(hf, 2713.91)
    along = _derive(hf, 97.13) < 0.5
    fade = np.clip((period / step_m - 4.0) / 4.0, 0.0, 1.0).astype(np.float32)
    amp = 0.10 * fade * (kind != 1)  # pasture has none
    phase = np.where(along.take(cell), wn, we) / period.take(cell)
    phase -= np.floor(phase)  # sin in float32 of the phase in [0, 1): 6x faster than float64
    factor = 1.0 + amp.take(cell) * np.sin(np.float32(2 * np.pi) * phase.astype(np.float32))
    # brightness variation within fields (soil moisture, growth)
    factor *= 1.0 + 0.35 * _smooth(n, e, 2.0, lambda a, b: _fbm(a, b, 60.0, 4, step_m,
                                                                seed + 7))
    rgb *= factor
    # roads along some warped grid lines
    rn, re_ = _CellTable(np.round(wn / fn)), _CellTable(np.round(we / fe))
    dn = wn - fn * rn.keys.take(rn.idx)
    de = we - fe * re_.keys.take(re_.idx)
    road_n = (_hash(rn.keys, np.zeros_like(rn.keys), seed + 8) < 0.3).take(rn.idx)
    road_e = (_hash(np.zeros_like(re_.keys), re_.keys, seed + 9) < 0.3).take(re_.idx)
    road = np.maximum(_coverage(3.0 - np.abs(dn), step_m) * road_n,
                      _coverage(3.0 - np.abs(de), step_m) * road_e)
    # trees: woods where low-frequency noise is high, hedgerows on field edges
    woods = _smooth(n, e, 8.0, lambda a, b: _vnoise(a / 500.0, b / 500.0, seed + 10)) > 0.76
    edge = np.minimum(np.abs(dn), np.abs(de))
    hedge = (edge > 4.0) & (edge < 9.0) & (_derive(hf, 31.77) < 0.5).take(cell)
    size = 7.0  # one tree at most per 7 m cell, at a random place in its middle half
    cn, ce = _CellTable(np.floor(n / size)), _CellTable(np.floor(e / size))
    kn, ke = cn.keys[:, None], ce.keys[None, :]
    ht = _hash(kn, ke, seed + 12)
    tc = cn.idx * len(ce.keys) + ce.idx  # (R, 1) and (1, C) -> the (R, C) tree cell
    tn = ((kn + 0.25 + 0.5 * ht) * size).take(tc)
    te = ((ke + 0.25 + 0.5 * _derive(ht, 577.31)) * size).take(tc)
    radius = (1.6 + 1.2 * _derive(ht, 1291.7)).take(tc)
    present = ((woods & (_derive(ht, 43.9) < 0.9).take(tc))
               | (hedge & (_derive(ht, 71.3) < 0.7).take(tc)))
    dtn, dte = n - tn, e - te
    tree = _coverage(radius - np.sqrt(dtn * dtn + dte * dte), step_m) * present
    tree_rgb = (_TREE * (0.75 + 0.5 * _derive(ht, 3343.1))[..., None]).reshape(-1, 3).T.take(
        tc, axis=1)
    rgb += (_ROAD[:, None, None] - rgb) * road
    rgb += (tree_rgb - rgb) * tree
    out = np.empty(rgb.shape[1:] + (3,), np.float32)
    np.clip(np.moveaxis(rgb, 0, -1), 0, 255, out=out)
    return out


def _detail_pyramid(seed: int) -> list[np.ndarray]:
    """A tileable fine-detail multiplier (around 1) at the base level and its
    2x2-averaged levels down to 1 px."""
    y, x = np.mgrid[0:DETAIL_PX, 0:DETAIL_PX].astype(np.float64)
    d = np.zeros((DETAIL_PX, DETAIL_PX), dtype=np.float32)
    amp = 0.5
    for k, cells in enumerate((8, 32, 64, 128, 256)):
        d += amp * (_vnoise(x * cells / DETAIL_PX, y * cells / DETAIL_PX, seed + 31 + k,
                            period=cells) - 0.5)
        amp *= 0.8
    levels = [1.0 + 0.6 * d]
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    return [lv.astype(np.float32) for lv in levels]


def ground_cache_dir(spec: GroundSpec, seed: int) -> Path | None:
    """The disk cache folder for the procedural tiles of ``seed`` and ``spec``, or
    None if caching is off (``COSIM_GROUND_CACHE=off``). Default
    ``$XDG_CACHE_HOME/cosim/ground`` (``~/.cache/cosim/ground``); one subfolder per
    texture version, seed, base resolution, tile size and the numpy/OpenCV
    versions (their float maths makes the pixels), so a cached tile is the very
    tile this process would generate."""
    env = os.environ.get(CACHE_ENV, "")
    if env.lower() in ("off", "0", "no", "false"):
        return None
    root = Path(env) if env else Path(os.environ.get("XDG_CACHE_HOME") or
                                      Path.home() / ".cache") / "cosim" / "ground"
    key = f"{TEXTURE_VERSION}|{seed}|{spec.base_m_per_px!r}|{spec.tile_px}|{np.__version__}|" \
          f"{cv2.__version__}"
    return root / f"v{TEXTURE_VERSION}-{hashlib.sha1(key.encode()).hexdigest()[:16]}"


def _folder_bytes(folder: Path) -> int:
    total = 0
    for sub in (folder.iterdir() if folder.is_dir() else ()):
        for f in (os.scandir(sub) if sub.is_dir() else ()):
            total += f.stat().st_size
    return total


class _ImageLayer:
    """A user's north-up image with its pyramid (BGR uint8)."""

    def __init__(self, spec: GroundSpec, frame: LocalFrame) -> None:
        assert spec.image is not None
        img = cv2.imread(spec.image, cv2.IMREAD_COLOR)
        if img is None:
            from cosim.errors import ConfigError

            raise ConfigError(f"ground.image: cannot read {spec.image} as an image")
        if spec.origin_latlon_deg is not None:
            la, lo = spec.origin_latlon_deg
            n, e, _ = frame.geodetic_to_ned(la, lo, frame.alt_m)
            self.n0, self.e0 = float(n), float(e)
        else:
            self.n0, self.e0 = spec.origin_ne_m or (0.0, 0.0)
        self.mpp = spec.m_per_px
        self.levels = [img]
        while min(self.levels[-1].shape[:2]) >= 8:
            self.levels.append(cv2.resize(self.levels[-1], None, fx=0.5, fy=0.5,
                                          interpolation=cv2.INTER_AREA))
        h, w = img.shape[:2]
        self.bounds_ne = (self.n0 - h * self.mpp, self.n0, self.e0, self.e0 + w * self.mpp)

    def level_for(self, gsd_m: float) -> int:
        k = math.floor(math.log2(max(gsd_m, 1e-9) / self.mpp) + 0.3)
        return min(max(k, 0), len(self.levels) - 1)

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of ``level``."""
        m = self.mpp * 2 ** level
        return np.array([[0.0, 1.0 / m, -self.e0 / m - 0.5],
                         [-1.0 / m, 0.0, self.n0 / m - 0.5],
                         [0.0, 0.0, 1.0]])


class GroundTexture:
    """Tiles of the ground by level, generated on demand and kept in an LRU cache."""

    def __init__(self, spec: GroundSpec, frame: LocalFrame, seed: int) -> None:
        self.spec = spec
        self.seed = int(seed)
        self.base_mpp = spec.base_m_per_px
        self.tile_px = spec.tile_px
        self.detail = _detail_pyramid(self.seed)
        self._tiles: OrderedDict[tuple[int, int, int], np.ndarray] = OrderedDict()
        self.image = _ImageLayer(spec, frame) if spec.kind == "image" else None
        self.tiles_made = 0
        self.tiles_loaded = 0
        self._slabs: dict[tuple[int, int, int], np.ndarray] = {}
        self._read_buf = np.empty((self.tile_px, self.tile_px, 3), np.uint8)
        self._cache_dir = ground_cache_dir(spec, self.seed)
        self._cache_room = 0  # bytes this process may still add to the cache
        if self._cache_dir is not None:
            mb = float(os.environ.get(CACHE_MB_ENV) or CACHE_MB)
            self._cache_room = int(mb * 2**20) - _folder_bytes(self._cache_dir)
        self._patches: dict[int, tuple[tuple[int, int, int, int], np.ndarray]] = {}

    def mpp(self, level: int) -> float:
        return float(self.base_mpp * 2 ** level)

    def level_for(self, gsd_m: float) -> int:
        """The finest level not much finer than the ground sample distance."""
        return max(0, math.floor(math.log2(max(gsd_m, 1e-9) / self.base_mpp) + 0.5))

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> global pixel (col, row, 1) of ``level``."""
        m = self.mpp(level)
        return np.array([[0.0, 1.0 / m, -0.5], [-1.0 / m, 0.0, -0.5], [0.0, 0.0, 1.0]])

    def tile(self, level: int, ti: int, tj: int) -> np.ndarray:
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
        """Tile (ti, tj) of ``level`` (BGRA uint8): from the disk cache if there,
        else generated (and stored there)."""
        path = self._cache_path(level, ti, tj)
        if path is not None:
            try:
                with open(path, "rb") as f:
                    bgr = self._read_buf  # reused: the tile itself is a new BGRA array
                    if f.readinto(bgr.data.cast("B")) == bgr.nbytes and not f.read(1):
                        self.tiles_loaded += 1
                        out: np.ndarray = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
                        return out
                os.unlink(path)  # cut short (a crash, or being written): make it anew
            except OSError:
                pass  # not cached yet
        bgra = self._generate_tile(level, ti, tj)
        self.tiles_made += 1
        if path is not None and self._cache_room > 0:
            self._store(path, cv2.cvtColor(bgra, cv2.COLOR_BGRA2BGR))
        return bgra

    def _store(self, path: Path, bgr: np.ndarray) -> None:
        """Write a tile's raw BGR bytes. A tile is written once (O_EXCL: parallel
        render workers and sweep runs race for it) in one call; a reader takes
        only a file of the full size. A cache that cannot be written is skipped."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            return
        except OSError as e:
            log.debug("ground tile cache: cannot write %s: %s", path, e)
            self._cache_room = 0
            return
        try:
            os.write(fd, bgr.data)
            self._cache_room -= bgr.nbytes
        except OSError as e:
            log.debug("ground tile cache: cannot write %s: %s", path, e)
            self._cache_room = 0
        finally:
            os.close(fd)

    def _cache_path(self, level: int, ti: int, tj: int) -> Path | None:
        if self._cache_dir is None:
            return None
        return self._cache_dir / f"L{level}" / f"{ti}_{tj}.bgr"

    def _detail_slab(self, level: int, r0: int, c0: int) -> np.ndarray:
        """The fine-detail multiplier over one tile's pixels (T x T x 4 float32: the
        same factor for B, G, R and 255 for alpha, which the warp leaves at 1)."""
        d = self.detail[level]
        s = d.shape[0]
        key = (level, r0 % s, c0 % s)
        slab = self._slabs.get(key)
        if slab is None:
            T = self.tile_px
            ri, ci = (np.arange(r0, r0 + T) % s), (np.arange(c0, c0 + T) % s)
            slab = np.empty((T, T, 4), np.float32)
            slab[..., :3] = d[np.ix_(ri, ci)][..., None]
            slab[..., 3] = 255.0
            self._slabs[key] = slab
        return slab

    def _generate_tile(self, level: int, ti: int, tj: int) -> np.ndarray:
        T, m = self.tile_px, self.mpp(level)
        rows = np.arange(ti * T, ti * T + T, dtype=np.float64)
        cols = np.arange(tj * T, tj * T + T, dtype=np.float64)
        step = max(m * MACRO_OVERSAMPLE, MACRO_STEP_M)
        if step <= m * 1.0001:
            n = -(rows[:, None] + 0.5) * m
            e = (cols[None, :] + 0.5) * m
            bgra = cv2.cvtColor(macro_rgb(n, e, m, self.seed), cv2.COLOR_RGB2BGRA)
        else:  # sample the macro colour on a coarser global lattice, interpolate
            n0, n1 = -(rows[-1] + 0.5) * m, -(rows[0] + 0.5) * m
            e0, e1 = (cols[0] + 0.5) * m, (cols[-1] + 0.5) * m
            ka0, ka1 = math.floor(n0 / step), math.ceil(n1 / step)
            kb0, kb1 = math.floor(e0 / step), math.ceil(e1 / step)
            gn = np.arange(ka1, ka0 - 1, -1, dtype=np.float64) * step  # north descending
            ge = np.arange(kb0, kb1 + 1, dtype=np.float64) * step
            coarse = macro_rgb(gn[:, None], ge[None, :], step, self.seed)
            # lattice position of tile pixel (r, c): an axis-aligned affine map; four
            # float channels warp 2.7x faster than three
            k = m / step
            M = np.array([[k, 0.0, (tj * T + 0.5) * k - kb0],
                          [0.0, k, ka1 + (ti * T + 0.5) * k]])
            bgra = cv2.warpAffine(cv2.cvtColor(coarse, cv2.COLOR_RGB2BGRA), M, (T, T),
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REPLICATE)
        # BGRA uint8 (alpha 255): OpenCV's bilinear warp is ~2.5x faster on four channels
        if level < len(self.detail) - 1:
            out: np.ndarray = cv2.multiply(bgra, self._detail_slab(level, ti * T, tj * T),
                                           dtype=cv2.CV_8U)  # rounded, saturated
        else:
            out = cv2.convertScaleAbs(bgra)
            out[..., 3] = 255
        return out

    def patch(self, level: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Global pixels rows [r0, r1) x cols [c0, c1) of ``level`` (BGRA uint8,
        alpha 255): a view into the whole tiles covering it, assembled when the
        set of tiles changes (not every frame) and valid until the next call for
        the same level."""
        T = self.tile_px
        key = (r0 // T, (r1 - 1) // T + 1, c0 // T, (c1 - 1) // T + 1)
        held = self._patches.get(level)
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
            held = self._patches[level] = (key, buf)
        y, x = r0 - key[0] * T, c0 - key[2] * T
        out: np.ndarray = held[1][y:y + r1 - r0, x:x + c1 - c0]
        return out
