"""Georeferenced ground images, read with rasterio (GDAL): GeoTIFFs and
Cloud-Optimized GeoTIFFs, VRT mosaics, any raster GDAL reads that carries a
coordinate system and a pixel-to-map transform (or ground control points), in
any coordinate system PROJ can relate to WGS-84 (longitude/latitude, UTM,
national grids, other datums). Only what a view needs is ever read.

``read_georef(path)`` opens the file and reads its metadata only: coordinate
system, transform, size and overviews. ``check_crs(ref)`` says why positions
cannot be converted to its coordinate system, if they cannot; ``probe(path)``
why its pixels cannot be read, if they cannot.

``GeoRaster(path, frame)`` is the file on the scenario frame's north-up grid
(``image_grid``): square pixels of ``m_per_px`` (the file's own pixel size at
its centre) whose top-left corner is at (``n0``, ``e0``); level ``k`` has
pixels ``2**k`` times larger. A level is cut into ``TILE_PX`` tiles, each made when first asked for:
the window of the file under the tile is read (``DatasetReader.read`` with a
window) from the overview whose pixels are the coarsest not coarser than the
tile's, decimated further by GDAL where the file has no overview that coarse
(averaging up to ``MAX_AVERAGE``, nearest beyond: averaging would read every
pixel of the full resolution), and warped onto the tile. Each tile pixel centre
is placed on the ground exactly (``LocalFrame.place`` at the ground altitude,
then the file's coordinate system through PROJ, then its raster) on a grid of
one point in 16 pixels each way, bilinear in between (the map is smooth: the
error is far below a pixel); the colours are taken by OpenCV's bilinear
``remap``, the coverage (the file's mask: alpha band, nodata or internal mask)
by nearest neighbour. Tiles are kept in an LRU of at most ``CACHE_MB``, and
GDAL's own block cache is held to ``GDAL_CACHE_MB`` while reading: memory is
bounded by the tiles in use, not by the file's size.

``resample(path, ref, frame)`` is the whole file at level 0 in one image (for
small files and tests; at most ``MAX_PX`` pixels).
"""

from __future__ import annotations

import logging
import math
import os
import re
import warnings
from collections import Counter, OrderedDict
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cosim.core.geo import LocalFrame
from cosim.world.image_grid import ImageGrid
from cosim.world.imagery import GDAL_OPTIONS, ImageRefused, gdal_driver

log = logging.getLogger(__name__)

WGS84 = 4326
#: GeoTIFF's tags (ModelPixelScale, ModelTiepoint, ModelTransformation,
#: GeoKeyDirectory), for writing a GeoTIFF without GDAL (GDAL reads them here)
TAG_PIXEL_SCALE, TAG_TIEPOINT, TAG_TRANSFORM, TAG_GEOKEYS = 33550, 33922, 34264, 34735
TILE_PX = 256  # a tile's side (a multiple of STEP_PX)
STEP_PX = 16  # one exactly placed point in this many output pixels each way
CACHE_MB = 96  # decoded tiles kept per file and process (BGRA + mask: 320 kB a tile)
GDAL_CACHE_MB = 64  # GDAL's block cache while this module reads
#: decimation by averaging at most this much (more: nearest), where the file has no
#: overview as coarse as a level (gdaladdo, or a COG, has them)
MAX_AVERAGE = 4.0
#: a file larger than this (a side) without overviews is logged as slow to view coarsely
BIG_PX = 8192
MAX_PX = 64 << 20  # resample's image's pixels at most (256 MB in BGRA)
_EMPTY_BYTES = 64  # what a tile with no data is counted as in the cache


class GeoTiffError(ValueError):
    """A georeferenced image that cannot be placed (the message says why and what
    to do)."""


@dataclass(frozen=True)
class GeoRef:
    """Raster corner coordinates (i right, j down; (0, 0) the first pixel's
    top-left corner) -> the coordinate system's (x, y):
    ``x = a i + b j + c``, ``y = d i + e j + f``; x is longitude and y latitude
    (degrees) in a geographic system, easting and northing in a projected one.
    ``crs_wkt`` the coordinate system, ``epsg`` its EPSG code if it has one;
    ``overviews`` the file's overview decimation factors (band 1)."""

    affine: tuple[float, float, float, float, float, float]
    epsg: int | None
    width_px: int
    height_px: int
    crs_wkt: str = ""
    overviews: tuple[int, ...] = ()

    def to_raster(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c, d, e, f = self.affine
        det = a * e - b * d
        x, y = x - c, y - f
        return (e * x - b * y) / det, (a * y - d * x) / det

    def to_model(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c, d, e, f = self.affine
        return a * i + b * j + c, d * i + e * j + f


def _env() -> Any:
    """The GDAL settings every read runs under: its block cache bounded, and
    cosim.world.imagery's ``GDAL_OPTIONS`` (no network, no side files that
    name other paths, no Python or raw VRT bands)."""
    import rasterio

    return rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB << 20, **GDAL_OPTIONS)


def _open(path: str, overview: int | None = None) -> Any:
    """The rasterio dataset at ``path`` (its overview ``overview``: 0 the first),
    quietly (a file without georeference is reported by the caller), by the one
    GDAL driver its content calls for (GTiff or VRT: no other driver gets to
    guess at it)."""
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    kw = {} if overview is None else {"overview_level": overview}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        try:
            return rasterio.open(path, driver=gdal_driver(path), **kw)
        except (RasterioIOError, OSError, ImageRefused) as err:
            raise GeoTiffError(f"{path}: cannot read it as a raster image: {err}") from err


def _georef(path: str, ds: Any) -> GeoRef:
    from rasterio.transform import from_gcps

    crs, t = ds.crs, ds.transform
    gcps, gcp_crs = ds.gcps
    if (crs is None or t.is_identity) and gcps and gcp_crs is not None:
        crs, t = gcp_crs, from_gcps(gcps)  # an affine fit to its control points
    if crs is None or t.is_identity:
        raise GeoTiffError(f"{path}: no GeoTIFF georeference (a coordinate system and a "
                           "pixel-to-map transform, or ground control points); for a plain "
                           "image give origin and m_per_px")
    affine = (t.a, t.b, t.c, t.d, t.e, t.f)
    if abs(t.a * t.e - t.b * t.d) < 1e-300:
        raise GeoTiffError(f"{path}: its raster-to-model transform is singular")
    overviews = tuple(int(f) for f in ds.overviews(1))
    if any(f < 2 for f in overviews):  # GDAL's factor of an overview as large as the image
        raise GeoTiffError(f"{path}: its overviews (factors {list(overviews)}) are not smaller "
                           "than the image; make them again (gdaladdo -r average FILE)")
    return GeoRef(affine, crs.to_epsg(), int(ds.width), int(ds.height), crs.to_wkt(),
                  overviews)


def read_georef(path: str) -> GeoRef:
    """The georeference of the raster at ``path`` (its metadata only: no pixels
    are read); GeoTiffError if it is unreadable or has none."""
    with _env(), _open(path) as ds:
        return _georef(path, ds)


def check_crs(ref: GeoRef) -> str | None:
    """None if positions can be converted to ``ref``'s coordinate system here (its
    centre taken to WGS-84 and back), else why not."""
    why = "its centre does not convert to longitude/latitude"
    try:
        crs = _Crs(ref.crs_wkt)
        x, y = ref.to_model(np.array([ref.width_px / 2]), np.array([ref.height_px / 2]))
        lat, lon = crs.to_latlon(x, y)
        x2, y2 = crs.from_latlon(lat, lon)
        if np.isfinite([lat, lon, x2, y2]).all() and abs(float(lat[0])) <= 90.0:
            return None
    except Exception as err:  # PROJ's own errors (CRSError, CPLE_*Error) say what failed
        msg = str(err)
        why = msg if "{" not in msg and len(msg) < 200 else \
            "PROJ knows no conversion between it and longitude/latitude"
    m = re.match(r'\s*(\w+)\["([^"]*)"', ref.crs_wkt)
    kind, name = (m.group(1), m.group(2)) if m else ("", "")
    code = f"EPSG:{ref.epsg}" if ref.epsg else f"'{name}' ({kind}, no EPSG code)"
    return (f"its coordinate system {code} cannot be placed on the Earth: {why}; "
            "reproject it, e.g. gdalwarp -t_srs EPSG:4326 IN.tif OUT.tif")


def probe(path: str) -> str | None:
    """None if GDAL reads a pixel of the file at ``path`` (the whole file decimated
    to one: its coarsest overview, or one block), else why not."""
    from rasterio.errors import RasterioError

    try:
        with _env(), _open(path) as ds:
            ds.read(1, out_shape=(1, 1))
    except (GeoTiffError, RasterioError) as err:
        return f"cannot read its pixels: {err.__cause__ or err}"
    return None


class _Crs:
    """WGS-84 latitude/longitude <-> the file's coordinate system (x, y), by PROJ
    (the one rasterio bundles)."""

    def __init__(self, wkt: str) -> None:
        from rasterio.crs import CRS

        self.crs = CRS.from_wkt(wkt)
        self.wgs84 = CRS.from_epsg(WGS84)
        self.same = self.crs.to_epsg() == WGS84

    def from_latlon(self, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.same:
            return np.asarray(lon, np.float64), np.asarray(lat, np.float64)
        return self._run(self.wgs84, self.crs, lon, lat)

    def to_latlon(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.same:
            return np.asarray(y, np.float64), np.asarray(x, np.float64)
        lon, lat = self._run(self.crs, self.wgs84, x, y)
        return lat, lon

    @staticmethod
    def _run(src: Any, dst: Any, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from rasterio.warp import transform

        a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
        xs, ys = transform(src, dst, a.ravel(), b.ravel())
        return np.asarray(xs).reshape(a.shape), np.asarray(ys).reshape(a.shape)


Tile = tuple[np.ndarray, np.ndarray]  # (BGRA uint8 opaque, mask uint8 0/255)


class GeoRaster(ImageGrid):
    """A georeferenced raster on the scenario frame's north-up grid, read a tile at
    a time (see the module docstring). Level ``k``'s pixel ``(row, col)`` is centred
    at ``north = n0 - (row + 1/2) m``, ``east = e0 + (col + 1/2) m`` with
    ``m = m_per_px * 2**k`` (``ImageGrid``); it has ``shape(k)`` pixels. Opening reads metadata
    only; GeoTiffError if the file cannot be placed."""

    def __init__(self, path: str, frame: LocalFrame, cache_mb: float = CACHE_MB,
                 tile_px: int = TILE_PX) -> None:
        from rasterio.enums import MaskFlags

        if tile_px % STEP_PX:
            raise ValueError(f"tile_px {tile_px} is not a multiple of {STEP_PX}")
        self.path, self.frame, self.tile_px = path, frame, int(tile_px)
        self.max_bytes = int(cache_mb * 2**20)
        self._pid = os.getpid()
        self._ds: dict[int, Any] = {}  # open datasets by overview (0: full resolution)
        with _env():
            ds = self._dataset(0)
            try:
                self.ref = ref = _georef(path, ds)
                why = check_crs(ref)
            except GeoTiffError:
                self.close()
                raise
            if why is not None:
                self.close()
                raise GeoTiffError(f"{path}: {why}")
            self._crs = _Crs(ref.crs_wkt)
            self._bands, self._lut = self._colour_bands(ds)
            self._masked = any(MaskFlags.all_valid not in ds.mask_flag_enums[i - 1]
                               for i in set(self._bands))
            self.dtype = np.dtype(ds.dtypes[self._bands[0] - 1])
            # overview factors with their exact scale (file pixels per overview pixel)
            self._overviews = [(1, 1.0, 1.0, 0)]
            for k, f in enumerate(ref.overviews):
                ow, oh = math.ceil(ref.width_px / f), math.ceil(ref.height_px / f)
                self._overviews.append((f, ref.width_px / ow, ref.height_px / oh, k + 1))
            if not ref.overviews and max(ref.width_px, ref.height_px) > BIG_PX \
                    and ds.driver != "VRT":
                log.warning("%s: %d x %d px without overviews: views of much of it read it at "
                            "full resolution, decimated without averaging (aliased); add "
                            "overviews (gdaladdo -r average FILE) or make it a COG",
                            path, ref.width_px, ref.height_px)
        self._range: tuple[float, float] | None = None  # non-uint8: scaled from this range
        self._place_grid(ref)
        self._tiles: OrderedDict[tuple[int, int, int], Tile | None] = OrderedDict()
        self.cache_bytes = self.peak_cache_bytes = 0
        self.reads: Counter[int] = Counter()  # windows read, by overview factor
        self.read_px = 0  # pixels (per band) read: the windows as delivered by GDAL
        self.tiles_made = 0

    # -- metadata ------------------------------------------------------------------
    def _dataset(self, overview: int) -> Any:
        if os.getpid() != self._pid:  # a forked copy: its own handles (file offsets)
            self._ds, self._pid = {}, os.getpid()
        ds = self._ds.get(overview)
        if ds is None:
            ds = self._ds[overview] = _open(self.path, overview - 1 if overview else None)
        return ds

    def close(self) -> None:
        for ds in self._ds.values():
            ds.close()
        self._ds.clear()

    def _colour_bands(self, ds: Any) -> tuple[tuple[int, int, int], np.ndarray | None]:
        """The bands (1-based) read as blue, green, red, and a palette's lookup
        table (256 x 3 BGR) if the file has one."""
        from rasterio.enums import ColorInterp

        ci = list(ds.colorinterp)
        if ds.count >= 3:
            by = {c: i + 1 for i, c in reversed(list(enumerate(ci)))}
            want = (ColorInterp.red, ColorInterp.green, ColorInterp.blue)
            r, g, b = [by[c] for c in want] if all(c in by for c in want) else [1, 2, 3]
            return (b, g, r), None
        lut = None
        if ci[0] == ColorInterp.palette:
            try:
                cmap = ds.colormap(1)
            except ValueError:
                cmap = {}
            lut = np.zeros((256, 3), np.uint8)
            for k, c in cmap.items():
                if 0 <= k < 256:
                    lut[k] = (c[2], c[1], c[0])
        return (1, 1, 1), lut

    def _place_grid(self, ref: GeoRef) -> None:
        """``m_per_px``, ``n0``, ``e0`` and the levels' shapes from the file's
        outline (65 points a side) placed in the scenario frame."""
        w, h = ref.width_px, ref.height_px
        n, e = self._ne_of(np.array([w / 2, w / 2 + 1, w / 2]),
                           np.array([h / 2, h / 2, h / 2 + 1]))
        # the pixel size: the geometric mean of a pixel's sides at the image centre
        self.m_per_px = math.sqrt(math.hypot(n[1] - n[0], e[1] - e[0])
                                  * math.hypot(n[2] - n[0], e[2] - e[0]))
        t = np.linspace(0.0, 1.0, 65)
        i = np.concatenate([t * w, np.full_like(t, w), t * w, np.zeros_like(t)])
        j = np.concatenate([np.zeros_like(t), t * h, np.full_like(t, h), t * h])
        n, e = self._ne_of(i, j)
        if not (np.isfinite(n).all() and np.isfinite(e).all()):
            raise GeoTiffError(f"{self.path}: its outline does not convert to longitude/"
                               "latitude (a file reaching beyond its projection's domain?)")
        mpp = self.m_per_px
        self.n0, self.e0 = float(n.max()), float(e.min())
        self.rows = max(1, math.ceil((self.n0 - float(n.min())) / mpp))
        self.cols = max(1, math.ceil((float(e.max()) - self.e0) / mpp))
        self.n_levels = 1
        while min(self.shape(self.n_levels - 1)) >= 8:
            self.n_levels += 1
        self.bounds_ne = (self.n0 - self.rows * mpp, self.n0, self.e0,
                          self.e0 + self.cols * mpp)

    def _ne_of(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lat, lon = self._crs.to_latlon(*self.ref.to_model(i, j))
        n, e, _ = self.frame.geodetic_to_ned(lat, lon, self.frame.alt_m)
        return np.asarray(n), np.asarray(e)

    def shape(self, level: int) -> tuple[int, int]:
        """(rows, cols) of ``level``."""
        k = 1 << level
        return -(-self.rows // k), -(-self.cols // k)

    # -- tiles ---------------------------------------------------------------------
    def tile(self, level: int, ti: int, tj: int) -> Tile | None:
        """Tile (ti, tj) of ``level``: (BGRA, mask) of tile_px x tile_px, or None
        where the file has no data."""
        key = (level, ti, tj)
        if key in self._tiles:
            self._tiles.move_to_end(key)
            return self._tiles[key]
        t = self._make_tile(level, ti, tj)
        self._tiles[key] = t
        self.cache_bytes += _EMPTY_BYTES if t is None else t[0].nbytes + t[1].nbytes
        self.peak_cache_bytes = max(self.peak_cache_bytes, self.cache_bytes)
        while self.cache_bytes > self.max_bytes and len(self._tiles) > 1:
            _, old = self._tiles.popitem(last=False)
            self.cache_bytes -= _EMPTY_BYTES if old is None else old[0].nbytes + old[1].nbytes
        return t

    def window(self, level: int, r0: int, r1: int, c0: int, c1: int,
               out: tuple[np.ndarray, np.ndarray] | None = None) -> Tile:
        """Pixels rows [r0, r1) x cols [c0, c1) of ``level``: (BGRA, mask), assembled
        from its tiles (into ``out`` if given, of at least that size)."""
        T = self.tile_px
        h, w = r1 - r0, c1 - c0
        if out is None:
            out = (np.empty((h, w, 4), np.uint8), np.empty((h, w), np.uint8))
        img, mask = out[0][:h, :w], out[1][:h, :w]
        for ti in range(r0 // T, (r1 - 1) // T + 1):
            for tj in range(c0 // T, (c1 - 1) // T + 1):
                ya, yb = max(r0, ti * T), min(r1, ti * T + T)
                xa, xb = max(c0, tj * T), min(c1, tj * T + T)
                dst = (slice(ya - r0, yb - r0), slice(xa - c0, xb - c0))
                src = (slice(ya - ti * T, yb - ti * T), slice(xa - tj * T, xb - tj * T))
                t = self.tile(level, ti, tj)
                if t is None:
                    img[dst] = (0, 0, 0, 255)
                    mask[dst] = 0
                else:
                    img[dst] = t[0][src]
                    mask[dst] = t[1][src]
        return img, mask

    def _make_tile(self, level: int, ti: int, tj: int) -> Tile | None:
        from rasterio.errors import RasterioError

        T = self.tile_px
        rows, cols = self.shape(level)
        if not (0 <= ti * T < rows and 0 <= tj * T < cols):
            return None
        m, r0, c0 = self.mpp(level), ti * T, tj * T
        # exact raster positions (file pixel corner coordinates) at the centres of
        # 16 x 16 blocks, one block beyond each side: cv2.resize by 16 then puts grid
        # point k at pixel 16 k + 7.5, the centre of its block, and interpolates
        g = np.arange(-1, T // STEP_PX + 2, dtype=np.float64)
        gn = self.n0 - (r0 + (g + 0.5) * STEP_PX) * m
        ge = self.e0 + (c0 + (g + 0.5) * STEP_PX) * m
        lat, lon = self.frame.place(gn[:, None], ge[None, :], self.frame.alt_m)
        u, v = self.ref.to_raster(*self._crs.from_latlon(lat, lon))
        # the overview: the coarsest whose pixels are no larger than this level's
        f, sx, sy, ov = max(o for o in self._overviews if o[0] <= 2 ** level * 1.01)
        with _env():
            ds = self._dataset(ov)
            u, v = u / sx, v / sy  # in the overview's pixels
            ca = max(0, math.floor(float(u.min())) - 1)
            cb = min(ds.width, math.ceil(float(u.max())) + 2)
            ra = max(0, math.floor(float(v.min())) - 1)
            rb = min(ds.height, math.ceil(float(v.max())) + 2)
            if ca >= cb or ra >= rb:
                return None
            try:
                got = self._read(ds, ca, ra, cb - ca, rb - ra, 2 ** level / f)
            except RasterioError as err:
                of = f"overview {f}" if f > 1 else "full resolution"
                raise GeoTiffError(f"{self.path}: cannot read its pixels (columns {ca}..{cb}, "
                                   f"rows {ra}..{rb}, {of}): {err.__cause__ or err}") from err
        self.reads[f] += 1
        self.tiles_made += 1
        bgra, cover, bx, by = got
        size = (len(g) * STEP_PX, len(g) * STEP_PX)
        inner = slice(STEP_PX, STEP_PX + T)
        mx = cv2.resize(((u - ca) * bx - 0.5).astype(np.float32),  # OpenCV's pixel centres
                        size, interpolation=cv2.INTER_LINEAR)[inner, inner]
        my = cv2.resize(((v - ra) * by - 0.5).astype(np.float32),
                        size, interpolation=cv2.INTER_LINEAR)[inner, inner]
        img = cv2.remap(bgra, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        mask = cv2.remap(cover, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)
        if cv2.countNonZero(mask) == 0:
            return None
        cv2.threshold(mask, 127, 255, cv2.THRESH_BINARY, dst=mask)
        img[..., 3] = 255
        return img, mask

    def _read(self, ds: Any, col: int, row: int, w: int, h: int, dec: float
              ) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The window (overview pixels) as BGRA and its mask, decimated by ``dec``
        where that is coarser than 1.5 (GDAL's average up to ``MAX_AVERAGE``, which
        reads every pixel; its nearest beyond: a file without overviews costs about
        as much to read coarsely as finely, and aliases); and the buffer pixels per
        window pixel (x, y)."""
        from rasterio.enums import Resampling
        from rasterio.windows import Window

        win = Window(col, row, w, h)
        if dec >= 1.5:
            ow, oh = max(1, round(w / dec)), max(1, round(h / dec))
            how = Resampling.average if dec <= MAX_AVERAGE else Resampling.nearest
        else:
            ow, oh, how = w, h, Resampling.nearest
        bands = list(dict.fromkeys(self._bands))
        data = ds.read(bands, window=win, out_shape=(len(bands), oh, ow), resampling=how)
        self.read_px += ow * oh
        if self.dtype != np.uint8:
            lo, hi = self._value_range()
            scaled = np.nan_to_num((data.astype(np.float32) - lo) * (255.0 / max(hi - lo, 1e-12)))
            data = np.clip(scaled, 0, 255).astype(np.uint8)
        bgra = np.empty((oh, ow, 4), np.uint8)
        if self._lut is not None:
            bgra[..., :3] = self._lut[data[0]]
        else:
            for k, b in enumerate(self._bands):
                bgra[..., k] = data[bands.index(b)]
        bgra[..., 3] = 255
        if self._masked:
            cover = ds.dataset_mask(window=win, out_shape=(oh, ow),
                                    resampling=Resampling.nearest).astype(np.uint8)
        else:
            cover = np.full((oh, ow), 255, np.uint8)
        return bgra, cover, ow / w, oh / h

    def _value_range(self) -> tuple[float, float]:
        """A 16-bit or float file's value range, from one read of the whole file at
        most 512 px a side (its coarsest overview, or decimated by GDAL)."""
        if self._range is None:
            from rasterio.enums import Resampling

            f, sx, sy, ov = self._overviews[-1]
            ds = self._dataset(ov)
            k = max(1.0, max(ds.width, ds.height) / 512)
            shape = (max(1, round(ds.height / k)), max(1, round(ds.width / k)))
            bands = list(dict.fromkeys(self._bands))
            a = ds.read(bands, out_shape=(len(bands), *shape), resampling=Resampling.nearest,
                        masked=True).astype(np.float64).filled(np.nan)
            lo, hi = (float(np.nanmin(a)), float(np.nanmax(a))) if np.isfinite(a).any() \
                else (0.0, 1.0)
            self._range = (lo, hi)
        return self._range


def resample(path: str, ref: GeoRef, frame: LocalFrame
             ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """``(bgra, mask, north_m, east_m, m_per_px)``: the whole file's pixels on the
    scenario frame's north-up grid of square ``m_per_px`` pixels whose top-left
    corner is at (``north_m``, ``east_m``), and ``mask`` (uint8) 255 where the
    file (and its mask or alpha, if any) covers the pixel. ``ref`` is the file's
    georeference (``read_georef``)."""
    src = GeoRaster(path, frame, cache_mb=0)
    try:
        if src.ref.affine != ref.affine:
            raise GeoTiffError(f"{path}: changed since its georeference was read")
        rows, cols = src.shape(0)
        if rows * cols > MAX_PX:
            raise GeoTiffError(f"{path}: {cols} x {rows} px on the scenario's grid at "
                               f"{src.m_per_px:.3g} m/px is more than {MAX_PX >> 20} Mpx in "
                               "one image; read it by tiles (GeoRaster)")
        img, mask = src.window(0, 0, rows, 0, cols)
        return img, mask, src.n0, src.e0, src.m_per_px
    finally:
        src.close()
