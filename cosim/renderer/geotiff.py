"""GeoTIFF ground images: the georeference from the file's own tags, the pixels
resampled onto the scenario frame's north/east grid.

``read_georef(path)`` reads the GeoTIFF tags (with Pillow, which matplotlib
already brings): ModelTiepoint + ModelPixelScale or ModelTransformation, the
raster type (pixel is area or point) and the coordinate system's EPSG code.
WGS-84 longitude/latitude (EPSG:4326) needs nothing more; any other EPSG
system (UTM zones, national grids, other datums) goes through pyproj when it is
installed (``pip install pyproj``).

``resample(path, georef, frame)`` returns the image in the scenario frame: north
up, square pixels about as fine as the file's, its top-left corner's north/east,
and a mask of the pixels the file covers. Each output pixel centre is placed on
the ground exactly (``LocalFrame.place`` at the ground altitude, then the file's
coordinate system, then its raster) on a grid of one point in 16 pixels each
way, bilinear in between (the map is smooth: the error is far below a pixel),
and the colours are taken by OpenCV's bilinear ``remap``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cosim.geo import LocalFrame

TAG_PIXEL_SCALE, TAG_TIEPOINT, TAG_TRANSFORM, TAG_GEOKEYS = 33550, 33922, 34264, 34735
KEY_MODEL_TYPE, KEY_RASTER_TYPE, KEY_GEOGRAPHIC, KEY_PROJECTED = 1024, 1025, 2048, 3072
MODEL_PROJECTED, MODEL_GEOGRAPHIC = 1, 2
RASTER_PIXEL_IS_POINT = 2
USER_DEFINED = 32767
WGS84 = 4326
MAX_PX = 64 << 20  # the resampled image's pixels at most (256 MB in BGRA)
STEP_PX = 16  # one exactly placed point in this many output pixels each way
CHUNK_ROWS = 64  # grid rows per remap (1024 output rows)


class GeoTiffError(ValueError):
    """A GeoTIFF that cannot be placed (the message says why and what to do)."""


@dataclass(frozen=True)
class GeoRef:
    """Raster corner coordinates (i right, j down; (0, 0) the first pixel's
    top-left corner) -> the coordinate system's (x, y):
    ``x = a i + b j + c``, ``y = d i + e j + f``; x is longitude and y latitude
    (degrees) in a geographic system, easting and northing in a projected one."""

    affine: tuple[float, float, float, float, float, float]
    epsg: int
    width_px: int
    height_px: int

    def to_raster(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c, d, e, f = self.affine
        det = a * e - b * d
        x, y = x - c, y - f
        return (e * x - b * y) / det, (a * y - d * x) / det

    def to_model(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c, d, e, f = self.affine
        return a * i + b * j + c, d * i + e * j + f


def _geokeys(raw: Any) -> dict[int, int]:
    """The GeoKeyDirectory's keys held in the directory itself (shorts: the model
    and raster types and EPSG codes; those stored elsewhere are not needed)."""
    v = [int(k) for k in raw]
    if len(v) < 4:
        return {}
    out = {}
    for n in range(v[3]):
        key, where, count, value = v[4 + 4 * n:8 + 4 * n]
        if where == 0 and count == 1:
            out[key] = value
    return out


def read_georef(path: str) -> GeoRef:
    """The georeference of the GeoTIFF at ``path``; GeoTiffError if it has none
    or one this cannot use."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            tags = dict(getattr(im, "tag_v2", {}))
            w, h = im.size
    except (OSError, UnidentifiedImageError, Image.DecompressionBombError) as err:
        raise GeoTiffError(f"{path}: cannot read it as a TIFF: {err}") from err
    if TAG_GEOKEYS not in tags or not (TAG_TRANSFORM in tags
                                       or (TAG_TIEPOINT in tags and TAG_PIXEL_SCALE in tags)):
        raise GeoTiffError(f"{path}: no GeoTIFF georeference (GeoKeyDirectory with "
                           "ModelTiepoint + ModelPixelScale, or ModelTransformation); "
                           "for a plain image give origin and m_per_px")
    keys = _geokeys(tags[TAG_GEOKEYS])
    model = keys.get(KEY_MODEL_TYPE)
    if model == MODEL_GEOGRAPHIC:
        epsg = keys.get(KEY_GEOGRAPHIC, WGS84)
    elif model == MODEL_PROJECTED:
        epsg = keys.get(KEY_PROJECTED, USER_DEFINED)
    else:
        raise GeoTiffError(f"{path}: GeoTIFF model type {model} is neither projected (1) nor "
                           "geographic (2)")
    if epsg == USER_DEFINED or epsg <= 0:
        raise GeoTiffError(f"{path}: its coordinate system has no EPSG code (user-defined); "
                           "reproject it, e.g. gdalwarp -t_srs EPSG:4326 IN.tif OUT.tif")
    if TAG_TRANSFORM in tags:
        m = [float(v) for v in tags[TAG_TRANSFORM]]
        if len(m) != 16:
            raise GeoTiffError(f"{path}: ModelTransformation has {len(m)} values, not 16")
        affine = (m[0], m[1], m[3], m[4], m[5], m[7])
    else:
        tp = [float(v) for v in tags[TAG_TIEPOINT]]
        sc = [float(v) for v in tags[TAG_PIXEL_SCALE]]
        if len(tp) < 6 or len(sc) < 2 or sc[0] <= 0 or sc[1] <= 0:
            raise GeoTiffError(f"{path}: ModelTiepoint {tp} / ModelPixelScale {sc} unusable")
        i0, j0, x0, y0 = tp[0], tp[1], tp[3], tp[4]
        affine = (sc[0], 0.0, x0 - i0 * sc[0], 0.0, -sc[1], y0 + j0 * sc[1])
    a, b, c, d, e, f = affine
    if abs(a * e - b * d) < 1e-300:
        raise GeoTiffError(f"{path}: its raster-to-model transform is singular")
    if keys.get(KEY_RASTER_TYPE) == RASTER_PIXEL_IS_POINT:  # raster (0, 0): the first centre
        c, f = c - 0.5 * (a + b), f - 0.5 * (d + e)
    return GeoRef((a, b, c, d, e, f), int(epsg), int(w), int(h))


def check_crs(epsg: int) -> str | None:
    """None if positions can be converted to EPSG ``epsg`` here, else why not."""
    if epsg == WGS84:
        return None
    try:
        import pyproj
    except ImportError:
        return (f"its coordinate system EPSG:{epsg} needs pyproj (pip install pyproj), or "
                "reproject it to EPSG:4326 (gdalwarp -t_srs EPSG:4326 IN.tif OUT.tif)")
    try:
        pyproj.CRS.from_epsg(epsg)
    except pyproj.exceptions.CRSError as err:
        return f"EPSG:{epsg} is not a coordinate system pyproj knows: {err}"
    return None


class _Crs:
    """WGS-84 latitude/longitude <-> the file's coordinate system (x, y)."""

    def __init__(self, epsg: int) -> None:
        self.fwd = self.inv = None
        if epsg != WGS84:
            import pyproj

            self.fwd = pyproj.Transformer.from_crs(WGS84, epsg, always_xy=True)
            self.inv = pyproj.Transformer.from_crs(epsg, WGS84, always_xy=True)

    def from_latlon(self, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.fwd is None:
            return lon, lat
        x, y = self.fwd.transform(lon, lat)
        return np.asarray(x), np.asarray(y)

    def to_latlon(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.inv is None:
            return y, x
        lon, lat = self.inv.transform(x, y)
        return np.asarray(lat), np.asarray(lon)


def resample(path: str, ref: GeoRef, frame: LocalFrame
             ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """``(bgra, mask, north_m, east_m, m_per_px)``: the file's pixels on the
    scenario frame's north-up grid of square ``m_per_px`` pixels whose top-left
    corner is at (``north_m``, ``east_m``), and ``mask`` (uint8) 255 where the
    file (and its alpha, if any) covers the pixel."""
    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)  # libtiff warns of every GeoTIFF tag it does not know
    try:
        src = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    finally:
        log.setLogLevel(level)
    if src is None:
        raise GeoTiffError(f"{path}: OpenCV cannot read its pixels")
    if src.dtype != np.uint8:  # 16-bit or float bands: scaled to their own range
        lo, hi = float(np.nanmin(src)), float(np.nanmax(src))
        src = np.nan_to_num((src - lo) * (255.0 / max(hi - lo, 1e-12))).astype(np.uint8)
    if src.ndim == 2:
        src = cv2.cvtColor(src, cv2.COLOR_GRAY2BGR)
    alpha = src[..., 3] if src.shape[2] == 4 else None
    bgra = cv2.cvtColor(src[..., :3], cv2.COLOR_BGR2BGRA)
    crs = _Crs(ref.epsg)
    h, w = src.shape[:2]

    def ne_of(i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lat, lon = crs.to_latlon(*ref.to_model(i, j))
        n, e, _ = frame.geodetic_to_ned(lat, lon, frame.alt_m)
        return n, e

    # the pixel size: the geometric mean of a pixel's sides at the image centre
    n, e = ne_of(np.array([w / 2, w / 2 + 1, w / 2]), np.array([h / 2, h / 2, h / 2 + 1]))
    mpp = math.sqrt(math.hypot(n[1] - n[0], e[1] - e[0]) * math.hypot(n[2] - n[0], e[2] - e[0]))
    # the extent: the file's outline, 65 points a side
    t = np.linspace(0.0, 1.0, 65)
    i = np.concatenate([t * w, np.full_like(t, w), t * w, np.zeros_like(t)])
    j = np.concatenate([np.zeros_like(t), t * h, np.full_like(t, h), t * h])
    n, e = ne_of(i, j)
    n0, e0 = float(n.max()), float(e.min())
    rows = max(1, math.ceil((n0 - float(n.min())) / mpp))
    cols = max(1, math.ceil((float(e.max()) - e0) / mpp))
    if rows * cols > MAX_PX:
        raise GeoTiffError(f"{path}: {cols} x {rows} px on the scenario's grid at "
                           f"{mpp:.3g} m/px is more than {MAX_PX >> 20} Mpx; give a smaller "
                           "or coarser file (e.g. gdal_translate -outsize 50% 50%)")
    # exact source positions at the centres of 16 x 16 blocks, one block beyond
    # each side: cv2.resize by 16 then puts grid point k at output pixel 16 k + 7.5,
    # the centre of its block, and interpolates in between
    gr, gc = np.arange(-1, rows // STEP_PX + 2), np.arange(-1, cols // STEP_PX + 2)
    gn = n0 - ((gr + 0.5) * STEP_PX) * mpp
    ge = e0 + ((gc + 0.5) * STEP_PX) * mpp
    lat, lon = frame.place(gn[:, None], ge[None, :], frame.alt_m)
    x, y = crs.from_latlon(lat, lon)
    si, sj = ref.to_raster(x, y)
    si, sj = (si - 0.5).astype(np.float32), (sj - 0.5).astype(np.float32)  # OpenCV's centres
    out = np.empty((rows, cols, 4), np.uint8)
    mask = np.empty((rows, cols), np.uint8)
    cover = np.full((h, w), 255, np.uint8) if alpha is None else alpha
    for k0 in range(0, rows // STEP_PX + 1, CHUNK_ROWS):
        k1 = min(k0 + CHUNK_ROWS, rows // STEP_PX + 1)
        g = slice(k0, k1 + 2)  # grid rows k0 - 1 .. k1: this chunk's blocks and one beyond
        size = (len(gc) * STEP_PX, (k1 - k0 + 2) * STEP_PX)
        mx = cv2.resize(si[g], size, interpolation=cv2.INTER_LINEAR)
        my = cv2.resize(sj[g], size, interpolation=cv2.INTER_LINEAR)
        r0, r1 = k0 * STEP_PX, min(rows, k1 * STEP_PX)
        mx = mx[STEP_PX:STEP_PX + r1 - r0, STEP_PX:STEP_PX + cols]
        my = my[STEP_PX:STEP_PX + r1 - r0, STEP_PX:STEP_PX + cols]
        cv2.remap(bgra, mx, my, cv2.INTER_LINEAR, dst=out[r0:r1],
                  borderMode=cv2.BORDER_REPLICATE)
        cv2.remap(cover, mx, my, cv2.INTER_NEAREST, dst=mask[r0:r1],
                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    out[..., 3] = 255
    return out, mask, n0, e0, mpp
