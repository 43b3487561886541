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
costs about 1 to 2 ms to make, so tiles are also kept on disk (``ground_cache_dir``:
one raw BGR file of 192 kB per 256 px tile, keyed by everything its pixels
depend on; no more written once a seed's folder holds ``CACHE_MB``): the
first run over a piece of ground pays for it, later runs and the other runs
of a sweep read it (0.05 ms a tile). A user picture (PNG/JPG/TIFF, north up,
``m_per_px``, top-left corner ``origin``) gets its own pyramid; a georeferenced
file (GeoTIFF, COG, VRT) is read a tile at a time, only under the ground being
drawn, from its overviews (cosim/renderer/geotiff.py). Where neither covers the
ground, the procedural ground shows.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import logging
import math
import mmap
import os
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from pathlib import Path

import cv2
import numpy as np

from cosim.core.cache import cache_folder
from cosim.core.geo import LocalFrame
from cosim.world.ground import GroundSpec

log = logging.getLogger(__name__)

MACRO_STEP_M = 0.5  # macro features (fields, roads, trees) sampled at least this fine
DETAIL_PX = 512  # the tileable detail texture's size at the base level
MAX_TILES = 384  # LRU size per process (256 px BGRA tiles: ~100 MB)
PATCH_MB = 256  # assembled patches kept per process (GroundTexture.patch)
MAX_WINDOW_PX = 4096  # a georeferenced file's window a band draws, at most (a side)
WINDOW_MB = 96  # a georeferenced file's assembled windows kept per process
MACRO_OVERSAMPLE = 2.0  # macro features sampled at most every this many pixels, then upsampled
#: bump whenever a tile's pixels change for the same seed and ground parameters
#: (old cache folders are then ignored; delete ~/.cache/cosim/ground to reclaim the space)
TEXTURE_VERSION = 6
CACHE_ENV = "COSIM_GROUND_CACHE"  # "off": no tile cache (its folder: cosim.core.cache)
CACHE_MB_ENV, CACHE_MB = "COSIM_GROUND_CACHE_MB", 2048  # no more tiles written past this
_CHUNK = 2 << 20  # new tiles are carved from 2 MB blocks of memory mapped in one call
FIELD_N_M, FIELD_E_M = 160.0, 220.0  # field size
TREE_M = 7.0  # one tree at most per cell of this size, at a random place in its middle half

# field palette, RGB: crops, pasture, wheat, ploughed soil, dry grass, dark crop
_FIELDS = np.array([[96, 128, 58], [118, 140, 72], [176, 160, 96], [122, 98, 72],
                    [150, 146, 98], [74, 104, 50]], dtype=np.float32)
_TREE = np.array([46, 70, 38], dtype=np.float32)
_ROAD = np.array([118, 116, 112], dtype=np.float32)


def _hash(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """Uniform [0, 1) from integer lattice coordinates (vectorised, stateless;
    uint32 arithmetic wraps by design: numpy does not check array overflow)."""
    h = i.astype(np.int64, copy=False).astype(np.uint32)
    h *= np.uint32(374761393)
    hj = j.astype(np.int64, copy=False).astype(np.uint32)
    hj *= np.uint32(668265263)
    hj += np.uint32((seed * 2246822519 + 0x9E3779B9) & 0xFFFFFFFF)
    h = h + hj
    h ^= h >> np.uint32(13)
    h *= np.uint32(1274126177)
    h ^= h >> np.uint32(16)
    h >>= np.uint32(8)
    out: np.ndarray = h.astype(np.float32)
    out *= np.float32(1.0 / 0x1000000)
    return out


def _derive(h: np.ndarray, *k: float) -> Iterator[np.ndarray]:
    """Other uniform [0, 1) values from one hash (cheaper than hashing again), one
    per factor in ``k``: for a small ``h`` all in one pass (fewer calls), else one
    by one as they are taken (no large temporaries)."""
    h64 = h.astype(np.float64)
    n = len(k) if h.size * len(k) <= 1 << 14 else 1
    for i in range(0, len(k), n):
        x = h64 * np.reshape(k[i:i + n], (-1,) + (1,) * h.ndim)
        x -= np.floor(x)
        yield from x.astype(np.float32)


def _vnoise(x: np.ndarray, y: np.ndarray, seed: int, period: int = 0) -> np.ndarray:
    """Smooth value noise in [0, 1) on the unit lattice (periodic if ``period``)."""
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


def _coverage(signed_dist_m: np.ndarray, step_m: float) -> np.ndarray:
    """Pixel coverage of a shape from the signed distance to its edge (inside > 0)."""
    out: np.ndarray = signed_dist_m / max(step_m, 1e-6)
    out += 0.5
    return np.clip(out, 0.0, 1.0, out=out).astype(np.float32)


_WEIGHTS: OrderedDict[bytes, list[tuple[int, np.ndarray]]] = OrderedDict()


def _noise_weights(x: np.ndarray, wavelengths_m: list[float]) -> list[tuple[int, np.ndarray]]:
    """``_make_noise_weights``, remembered for the last few sample rows and columns
    (tiles side by side share them; the arrays returned are not to be written)."""
    key = x.tobytes() + np.asarray(wavelengths_m, np.float64).tobytes()
    out = _WEIGHTS.get(key)
    if out is None:
        out = _WEIGHTS[key] = _make_noise_weights(x, wavelengths_m)
        if len(_WEIGHTS) > 16:
            _WEIGHTS.popitem(last=False)
    else:
        _WEIGHTS.move_to_end(key)
    return out


def _make_noise_weights(x: np.ndarray, wavelengths_m: list[float]) -> list[tuple[int, np.ndarray]]:
    """Value noise of each wavelength along one axis: ``(k0, W)``, the smoothstep
    weights ``W`` (len(x) x K, float32, two non-zero per row summing to 1) of the
    lattice corners ``k0 .. k0 + K - 1`` at the positions ``x`` (metres); all
    wavelengths at once (one weight matrix, sliced)."""
    u = x[None, :] / np.asarray(wavelengths_m, np.float64)[:, None]
    k = np.floor(u)
    f = (u - k).astype(np.float32)
    s = f * f * (3 - 2 * f)
    ki = k.astype(np.int64)
    k0, k1 = ki.min(axis=1).tolist(), ki.max(axis=1).tolist()
    width = [b - a + 2 for a, b in zip(k0, k1)]
    start = [0, *itertools.accumulate(width[:-1])]
    n, total = len(x), sum(width)
    w = np.zeros((n, total), np.float32)
    at = ki - np.array([a - b for a, b in zip(k0, start)])[:, None]  # column, then flat
    at += np.arange(0, n * total, total)
    flat = w.reshape(-1)
    flat[at] = 1 - s
    at += 1
    flat[at] = s
    return [(a, w[:, b:b + c]) for a, b, c in zip(k0, start, width)]


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` (float32) in row blocks small enough that OpenBLAS keeps each on
    the calling thread (it spreads a product of more than 2**18 multiply-adds over
    its thread pool, whose idle threads then spin: more CPU for these sizes)."""
    rows = max(1, (1 << 17) // max(1, b.shape[0] * b.shape[1]))
    if a.shape[0] <= rows:
        out: np.ndarray = a @ b
        return out
    out = np.empty((a.shape[0], b.shape[1]), np.float32)
    for r in range(0, a.shape[0], rows):
        np.matmul(a[r:r + rows], b, out=out[r:r + rows])
    return out


class _Tables:
    """Per-cell tables kept across tiles (an LRU of at most ``max_bytes``). Each is
    a pure function of its key (seed, cells, parameters), so a tile gathering from
    one gets the values it would compute itself, whichever tiles came before."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes, self.nbytes = max_bytes, 0
        self._held: OrderedDict[tuple[object, ...], tuple[np.ndarray, ...]] = OrderedDict()

    def cover(self, key: tuple[object, ...], i0: int, i1: int, j0: int, j1: int, size: int,
              make: Callable[[int, int, int, int], tuple[np.ndarray, ...]], own: bool = True
              ) -> tuple[int, int, int, int, tuple[np.ndarray, ...]] | None:
        """``(a0, a1, b0, b1, make(a0, a1, b0, b1))``: the tables of the cells
        ``[a0, a1) x [b0, b1)``, the whole blocks of ``size`` x ``size`` cells that hold
        ``i0 .. i1`` x ``j0 .. j1``, kept (the tiles over the same blocks share them).
        If those span more than ``size / 2`` cells either way (a tile's blocks would
        then be mostly its own, and up to 4x its cells): the tables of exactly
        ``i0 .. i1`` x ``j0 .. j1``, not kept, or None if not ``own``."""
        if i1 - i0 >= size // 2 or j1 - j0 >= size // 2:
            return (i0, i1 + 1, j0, j1 + 1, make(i0, i1 + 1, j0, j1 + 1)) if own else None
        a0, a1 = i0 - i0 % size, i1 - i1 % size + size
        b0, b1 = j0 - j0 % size, j1 - j1 % size + size
        key = (*key, a0, a1, b0, b1)
        out = self._held.get(key)
        if out is None:
            out = self._held[key] = make(a0, a1, b0, b1)
            self.nbytes += sum(a.nbytes for a in out)
            while self.nbytes > self.max_bytes and len(self._held) > 1:
                self.nbytes -= sum(a.nbytes for a in self._held.popitem(last=False)[1])
        else:
            self._held.move_to_end(key)
        return a0, a1, b0, b1, out


_TABLES = _Tables(16 << 20)


def _lattice(wn: tuple[int, np.ndarray], we: tuple[int, np.ndarray], seed: int,
             offset: float, scale: float) -> np.ndarray:
    """The hashed lattice values ``scale * (hash + offset)`` (float32, contiguous) of
    the corners under the weights ``wn`` (north) and ``we`` (east), cut from a kept
    table of whole 32 x 32 blocks of corners (a large grid's: made for it)."""
    (i0, w_n), (j0, w_e) = wn, we
    ni, nj = w_n.shape[1], w_e.shape[1]

    def make(a0: int, a1: int, b0: int, b1: int) -> tuple[np.ndarray, ...]:
        h = _hash(np.arange(a0, a1)[:, None], np.arange(b0, b1)[None, :], seed)
        if offset or scale != 1.0:
            h = ((h + np.float32(offset)) * np.float32(scale)).astype(np.float32)
        return (h,)

    got = _TABLES.cover(("lattice", seed, offset, scale), i0, i0 + ni - 1, j0, j0 + nj - 1,
                        32, make)
    assert got is not None
    a0, _, b0, _, (tab,) = got
    return np.ascontiguousarray(tab[i0 - a0:i0 - a0 + ni, j0 - b0:j0 - b0 + nj])


def _noise_on_grid(wn: tuple[int, np.ndarray], we: tuple[int, np.ndarray], seed: int,
                   scale: float = 1.0, offset: float = 0.0) -> np.ndarray:
    """``scale * (value noise + offset)`` at a grid (R, C) from its weights along
    north ``wn`` and east ``we`` (``_noise_weights``): the same smoothstep
    interpolation of hashed lattice values as ``_vnoise``, as two small matrix
    products (a pure function of position: neighbouring tiles agree)."""
    return _product(wn[1] @ _lattice(wn, we, seed, offset, scale), we[1].T)


def _field_cells(seed: int, step_m: float, a0: int, a1: int, b0: int,
                 b1: int) -> tuple[np.ndarray, ...]:
    """What depends only on a field: for the cells ``[a0, a1) x [b0, b1)`` of the
    field grid (flat, row-major) its colour (3 x cells), crop-row amplitude and
    cycles per field unit along u and v, whether it has a hedgerow; and whether the
    grid lines ``a0 .. a1 - 1`` (north) and ``b0 .. b1 - 1`` (east) are roads (a
    road's half width, or -1000)."""
    ki = np.arange(a0, a1, dtype=np.float64)
    kj = np.arange(b0, b1, dtype=np.float64)
    hf = _hash(ki[:, None], kj[None, :], seed + 3).ravel()
    kind = np.minimum((hf * len(_FIELDS)).astype(np.int64), len(_FIELDS) - 1)
    shade, rows, across, hedge = _derive(hf, 613.37, 2713.91, 97.13, 31.77)
    colour = (_FIELDS[kind] * (0.88 + 0.24 * shade)[..., None]).T.copy()
    # crop rows: 2.5-4 m apart, along or across the field, only where resolvable
    period = 2.5 + 1.5 * rows
    along = across < 0.5
    fade = np.clip((period / step_m - 4.0) / 4.0, 0.0, 1.0).astype(np.float32)
    amp = (0.10 * fade * (kind != 1)).astype(np.float32)  # pasture has none
    cu = np.where(along, FIELD_N_M / period, 0.0).astype(np.float32)  # cycles per field unit
    cv = np.where(along, 0.0, FIELD_E_M / period).astype(np.float32)
    road_n = np.where(_hash(ki, np.zeros_like(ki), seed + 8) < 0.3, 3.0, -1e3).astype(np.float32)
    road_e = np.where(_hash(np.zeros_like(kj), kj, seed + 9) < 0.3, 3.0, -1e3).astype(np.float32)
    return colour, amp, cu, cv, hedge < 0.5, road_n, road_e


def _tree_cells(kn: np.ndarray, ke: np.ndarray, seed: int) -> tuple[np.ndarray, ...]:
    """What depends only on a tree cell (``TREE_M`` square; ``kn``, ``ke`` its
    row and column, broadcast together), flat: whether a tree stands there in a
    wood, or on a hedgerow; its centre north and east; its radius and shade."""
    ht = _hash(kn, ke, seed + 12)
    d = _derive(ht, 43.9, 71.3, 577.31, 1291.7, 3343.1)  # taken in this order
    return ((next(d) < 0.9).ravel(), (next(d) < 0.7).ravel(),
            ((kn + 0.25 + 0.5 * ht) * TREE_M).ravel(),
            ((ke + 0.25 + 0.5 * next(d)) * TREE_M).ravel(), (1.6 + 1.2 * next(d)).ravel(),
            (0.75 + 0.5 * next(d)).ravel())


def macro_rgb(n: np.ndarray, e: np.ndarray, step_m: float, seed: int) -> np.ndarray:
    """The procedural ground's colour as float32 planes (3, R, C), RGB about 0..255
    (not clipped), at the scenario-frame grid ``n`` (R x 1) x ``e`` (1 x C), drawn
    for a sample spacing of ``step_m``. Smooth fields (field-grid warp, woods,
    brightness) are value noise evaluated as small matrix products; what depends
    only on a field, a grid line, a tree cell or a noise lattice corner is computed
    once per cell, kept across calls (``_TABLES``) and gathered; trees are drawn
    only where some may stand."""
    nv, ev = n.ravel().astype(np.float64), e.ravel().astype(np.float64)
    R, C = len(nv), len(ev)
    f32 = np.float32
    fn, fe = FIELD_N_M, FIELD_E_M
    warp = 15.0  # the field grid's warp, at most this many metres
    # value noise weights: field-grid warp, woods, brightness octaves (finer than
    # two samples left out)
    octaves = [wl for wl in (60.0, 30.0, 15.0, 7.5) if wl >= 2 * step_m]
    wts_n = _noise_weights(nv, [230.0, 500.0] + octaves)
    wts_e = _noise_weights(ev, [230.0, 500.0] + octaves)
    # warped coordinates in field units: u = (north + warp) / fn, v = (east + warp) / fe
    u = _noise_on_grid(wts_n[0], wts_e[0], seed + 1, 2 * warp / fn, -0.5)
    u += (nv / fn).astype(np.float32)[:, None]
    v = _noise_on_grid(wts_n[0], wts_e[0], seed + 2, 2 * warp / fe, -0.5)
    v += (ev / fe).astype(np.float32)[None, :]
    # fields: the (ci, cj) cells of the warped field grid here are ci0..ci1 x cj0..cj1;
    # their tables (_field_cells) are kept for whole blocks of 8 x 8 cells (a large
    # grid's: made for it)
    ci0 = math.floor((nv.min() - warp) / fn) - 1
    ci1 = math.floor((nv.max() + warp) / fn) + 1
    cj0 = math.floor((ev.min() - warp) / fe) - 1
    cj1 = math.floor((ev.max() + warp) / fe) + 1
    got = _TABLES.cover(("field", seed, step_m), ci0, ci1, cj0, cj1, 8,
                        functools.partial(_field_cells, seed, step_m))
    assert got is not None
    a0, a1, b0, b1, (colour, amp, cu, cv, hedge_cell, road_n, road_e) = got
    nj = b1 - b0
    here = (slice(ci0 - a0, ci1 + 1 - a0), slice(cj0 - b0, cj1 + 1 - b0))  # of a table
    fu, fv = np.floor(u), np.floor(v)
    iu = fu.astype(np.intp)  # field-grid row and column in the tables
    iu -= a0
    iv = fv.astype(np.intp)
    iv -= b0
    cell = iu * nj
    cell += iv
    # crop rows: 2.5-4 m apart, along or across the field, only where resolvable
    if amp.reshape(-1, nj)[here].any():
        phase = u * cu.take(cell)
        phase += v * cv.take(cell)
        phase -= np.floor(phase)  # sin in float32 of the phase in [0, 1)
        phase *= f32(2 * np.pi)
        factor = np.sin(phase, out=phase)
        factor *= amp.take(cell)
        factor += f32(1.0)
    else:
        factor = np.ones((R, C), np.float32)
    # brightness variation within fields (soil moisture, growth)
    if octaves:
        left = [wts_n[2 + k][1] @ _lattice(wts_n[2 + k], wts_e[2 + k], seed + 7 + 17 * k,
                                           -0.5, 0.35 * 0.5**k) for k in range(len(octaves))]
        bright = _product(np.hstack(left), np.hstack([w for _, w in wts_e[2:]]).T)
        bright += f32(1.0)
    else:
        bright = np.ones((R, C), np.float32)
    factor *= bright
    # distances to the nearest grid lines (roads, hedgerows), in metres
    du = u - fu
    dv = v - fv
    near_u = du > 0.5  # the nearest line is the next one
    near_v = dv > 0.5
    np.abs(du - near_u, out=du)
    du *= f32(fn)
    np.abs(dv - near_v, out=dv)
    dv *= f32(fe)
    # roads along some warped grid lines (a road's half width, or none)
    road: np.ndarray | None = None
    for d, i, near, half, lines in ((du, iu, near_u, road_n, here[0]),
                                    (dv, iv, near_v, road_e, here[1])):
        if half[lines].max() < 0:
            continue
        line = half.take(i + near)
        line -= d
        line *= f32(1.0 / max(step_m, 1e-6))
        line += f32(0.5)
        np.clip(line, 0.0, 1.0, out=line)
        road = line if road is None else np.maximum(road, line, out=road)
    # trees: woods where low-frequency noise is high, hedgerows on field edges
    woods = _noise_on_grid(wts_n[1], wts_e[1], seed + 10) > 0.76
    edge = np.minimum(du, dv)
    edge -= f32(6.5)  # exact here (Sterbenz): |edge - 6.5| < 2.5 is 4 < edge < 9
    band = np.abs(edge, out=edge) < f32(2.5)  # hedgerows where the field has one
    maybe = np.flatnonzero(woods | band)
    # a tree's coverage and shade: over the whole grid (tree, tone) where most of it
    # may have trees, else at the flat indices ``at`` only (cov, shade; zero elsewhere)
    tree: np.ndarray | None = None
    at: np.ndarray | None = None
    if len(maybe):
        # the tree cells' tables (_tree_cells): kept for whole blocks of 32 x 32 cells,
        # made for this grid's cells, or (more cells than samples) for the candidates'
        cn, ce = np.floor(nv / TREE_M), np.floor(ev / TREE_M)
        kn0, kn1 = int(min(cn[0], cn[-1])), int(max(cn[0], cn[-1]))
        ke0, ke1 = int(min(ce[0], ce[-1])), int(max(ce[0], ce[-1]))

        def trees(a0: int, a1: int, b0: int, b1: int) -> tuple[np.ndarray, ...]:
            return _tree_cells(np.arange(a0, a1, dtype=np.float64)[:, None],
                               np.arange(b0, b1, dtype=np.float64)[None, :], seed)

        got = _TABLES.cover(("tree", seed), kn0, kn1, ke0, ke1, 32, trees,
                            own=(kn1 - kn0 + 1) * (ke1 - ke0 + 1) <= R * C)
        if got is None:
            r, c = np.divmod(maybe, C)
            cells = _tree_cells(cn.take(r), ce.take(c), seed)
            tc = np.arange(len(maybe))
        else:
            a0, _, b0, b1, cells = got
            tc_row = (cn - a0).astype(np.intp) * (b1 - b0)
            tc_col = (ce - b0).astype(np.intp)
            if len(maybe) > R * C // 4:  # the same values, in fewer whole-grid passes
                tc = tc_row[:, None] + tc_col[None, :]
            else:
                r, c = np.divmod(maybe, C)
                tc = tc_row.take(r) + tc_col.take(c)
        in_wood, on_hedge, tn_cell, te_cell, radius_cell, tone_cell = cells
        if tc.ndim == 2:
            present = woods & in_wood.take(tc)
            present |= band & hedge_cell.take(cell) & on_hedge.take(tc)
            dist = tn_cell.take(tc)  # in place: fewer large float64 temporaries
            np.subtract(nv[:, None], dist, out=dist)
            dist *= dist
            dte = te_cell.take(tc)
            np.subtract(ev[None, :], dte, out=dte)
            dte *= dte
            dist += dte
            np.sqrt(dist, out=dist)
            cov = _coverage(np.subtract(radius_cell.take(tc), dist, out=dist), step_m)
            tree = np.where(present, cov, f32(0.0))
            tone = tree * tone_cell.take(tc)
        else:
            hedge = band.ravel().take(maybe) & hedge_cell.take(cell.ravel().take(maybe))
            present = ((woods.ravel().take(maybe) & in_wood.take(tc))
                       | (hedge & on_hedge.take(tc)))
            at, r, c, tc = maybe[present], r[present], c[present], tc[present]
            dtn, dte = nv.take(r) - tn_cell.take(tc), ev.take(c) - te_cell.take(tc)
            cov = _coverage(radius_cell.take(tc) - np.sqrt(dtn * dtn + dte * dte), step_m)
            shade = cov * tone_cell.take(tc)
    # blend: field colour x factor, then road, then tree over it (where a tree's
    # coverage is zero, x 1 and + 0 leave the values as they are)
    keep = factor
    if road is not None:
        keep *= 1.0 - road
    if tree is not None:
        keep *= 1.0 - tree
        if road is not None:
            road *= 1.0 - tree
    elif at is not None:
        clear = 1.0 - cov
        keep.reshape(-1)[at] *= clear
        if road is not None:
            road.reshape(-1)[at] *= clear
    rgb = np.take(colour, cell, axis=1, out=np.empty((3, R, C), np.float32),
                  mode="clip")  # in range: "clip" only spares take's copy of out
    for p, road_ch, tree_ch in zip(rgb, _ROAD, _TREE):  # planes: smaller temporaries
        p *= keep
        if road is not None:
            p += road_ch * road
        if tree is not None:
            p += tree_ch * tone
        elif at is not None:
            p.reshape(-1)[at] += tree_ch * shade
    return rgb


def _bgra(rgb: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Planar float32 RGB (3, R, C) -> interleaved BGRA (R, C, 4), alpha 1 (into
    ``out`` if given and of that shape)."""
    ones = np.ones(rgb.shape[1:], np.float32)
    if out is not None and out.shape == (*rgb.shape[1:], 4):
        res: np.ndarray = cv2.merge([rgb[2], rgb[1], rgb[0], ones], dst=out)
    else:
        res = cv2.merge([rgb[2], rgb[1], rgb[0], ones])
    return res


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


def _resize_plan(k: float, p0: int, T: int) -> tuple[int, int, int] | None:
    """How a bilinear resize by ``1 / k`` of lattice samples makes the pixels
    ``p0 .. p0 + T - 1`` along one axis (``k`` = lattice points per pixel, lattice
    point ``K`` at ``(K + 1/2) / k`` pixels): ``(x0, K0, n)``: resize the ``n``
    points from ``K0`` on and the pixels are the resize's ``x0 .. x0 + T - 1``
    (OpenCV maps output ``x`` to input ``k (x + 1/2) - 1/2``: ``K0 = k (p0 - x0)``
    must be whole, and ``x0`` large enough that no pixel needs a point before
    ``K0``). None if ``k`` is no fraction with a small denominator."""
    lo = max(0, math.ceil(0.5 / k - 0.5 - 1e-9))
    for x0 in range(lo, lo + 64):
        k0 = k * (p0 - x0)
        if abs(k0 - round(k0)) < 1e-6:
            return x0, round(k0), math.floor(k * (x0 + T - 0.5) - 0.5) + 2
    return None


def ground_cache_dir(spec: GroundSpec, seed: int) -> Path | None:
    """The disk cache folder for the procedural tiles of ``seed`` and ``spec``, or
    None if caching is off (``COSIM_GROUND_CACHE=off``): ``ground/`` in the cache
    folder (``cosim.core.cache``), one subfolder per
    texture version, seed, base resolution, tile size and the numpy/OpenCV
    versions (their float maths makes the pixels), so a cached tile is the very
    tile this process would generate."""
    if os.environ.get(CACHE_ENV, "").lower() in ("off", "0", "no", "false"):
        return None
    root = cache_folder("ground")
    key = f"{TEXTURE_VERSION}|{seed}|{spec.base_m_per_px!r}|{spec.tile_px}|{np.__version__}|" \
          f"{cv2.__version__}"
    return root / f"v{TEXTURE_VERSION}-{hashlib.sha1(key.encode()).hexdigest()[:16]}"


def _folder_bytes(folder: Path) -> int:
    total = 0
    for sub in (folder.iterdir() if folder.is_dir() else ()):
        for f in (os.scandir(sub) if sub.is_dir() else ()):
            total += f.stat().st_size
    return total


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


class _ImageLayer:
    """A user's north-up picture placed by ``origin`` and ``m_per_px``, with its
    pyramid (BGRA uint8, opaque, like the frames). A georeferenced file is a
    ``_GeoRasterLayer`` instead (the same four calls: ``level_for``, ``levels[k]``,
    ``ne_to_px(k)``, ``coverage(k)``)."""

    def __init__(self, spec: GroundSpec, frame: LocalFrame) -> None:
        from cosim.errors import ConfigError
        from cosim.world.imagery import ImageRefused, check_picture

        assert spec.image is not None
        try:  # its declared size within what a render worker may hold, before decoding
            check_picture(spec.image, spec.image_roots())
        except ImageRefused as err:
            raise ConfigError(f"ground.image: {err}") from None
        bgr = cv2.imread(spec.image, cv2.IMREAD_COLOR)
        if bgr is None:
            raise ConfigError(f"ground.image: cannot read {spec.image} as an image")
        img = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
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
        self._coverage: dict[int, np.ndarray] = {}

    def focus(self, n_lo: float, n_hi: float, e_lo: float, e_hi: float,
              slot: Hashable = None) -> None:
        """The ground about to be drawn (nothing to do: the picture is all in memory)."""

    def level_for(self, gsd_m: float) -> int:
        k = math.floor(math.log2(max(gsd_m, 1e-9) / self.mpp) + 0.3)
        return min(max(k, 0), len(self.levels) - 1)

    def coverage(self, level: int) -> np.ndarray:
        """255 where ``level`` has data, else 0: all of it; made once per level."""
        if level not in self._coverage:
            self._coverage[level] = np.full(self.levels[level].shape[:2], 255, np.uint8)
        return self._coverage[level]

    def ne_to_px(self, level: int) -> np.ndarray:
        """3x3: scenario (north, east, 1) -> pixel (col, row, 1) of ``level``."""
        m = self.mpp * 2 ** level
        return np.array([[0.0, 1.0 / m, -self.e0 / m - 0.5],
                         [-1.0 / m, 0.0, self.n0 / m - 0.5],
                         [0.0, 0.0, 1.0]])


class _FocusedLevels:
    """``levels[k]`` of a ``_GeoRasterLayer``: level ``k``'s pixels over the ground in
    focus (BGRA uint8)."""

    def __init__(self, layer: _GeoRasterLayer) -> None:
        self._layer = layer

    def __len__(self) -> int:
        return self._layer.src.n_levels

    def __getitem__(self, level: int) -> np.ndarray:
        return self._layer.held(level)[1]


class _GeoRasterLayer:
    """A georeferenced file (GeoTIFF, COG, VRT, ...; cosim/renderer/geotiff.py's
    ``GeoRaster``) read a tile at a time, with ``_ImageLayer``'s four calls. The
    renderer asks for a band's ground patch (``GroundTexture.patch``) before its
    image, and the patch focuses this layer on that ground (``focus``): then
    ``levels[k]``, ``ne_to_px(k)`` and ``coverage(k)`` are of a window of level ``k``
    over just that ground (its whole tiles, within the file), at most
    ``MAX_WINDOW_PX`` a side: ``level_for`` goes coarser where the window would be
    larger. Windows are kept per slot (a camera stream) and level, at most
    ``WINDOW_MB`` of them; tiles in the raster's own LRU."""

    def __init__(self, spec: GroundSpec, frame: LocalFrame) -> None:
        from cosim.errors import ConfigError
        from cosim.world import geotiff
        from cosim.world.imagery import ImageRefused, check_georeferenced

        assert spec.image is not None
        try:  # what validation checked, again where it is opened
            check_georeferenced(spec.image, spec.image_roots())
            self.src = geotiff.GeoRaster(spec.image, frame)
        except (geotiff.GeoTiffError, ImageRefused) as err:
            raise ConfigError(f"ground.image: {err}") from err
        self.mpp, self.n0, self.e0 = self.src.m_per_px, self.src.n0, self.src.e0
        self.bounds_ne = self.src.bounds_ne
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
            r0, r1 = math.floor((self.n0 - n_hi) / m) - 1, math.ceil((self.n0 - n_lo) / m) + 1
            c0, c1 = math.floor((e_lo - self.e0) / m) - 1, math.ceil((e_hi - self.e0) / m) + 1
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
        m, T = self.src.mpp(level), self.src.tile_px
        return np.array([[0.0, 1.0 / m, -self.e0 / m - 0.5 - tc * T],
                         [-1.0 / m, 0.0, self.n0 / m - 0.5 - ta * T],
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
        self.image: _ImageLayer | _GeoRasterLayer | None = None
        if spec.kind == "image":
            self.image = _GeoRasterLayer(spec, frame) if spec.geotiff else \
                _ImageLayer(spec, frame)
        self.tiles_made = 0
        self.tiles_loaded = 0
        self._slabs: dict[tuple[int, int, int], np.ndarray] = {}
        T = self.tile_px
        self._read_buf = np.empty((T, T, 3), np.uint8)  # also the BGR of a tile written
        # reused float buffers of a tile being made (no fresh ~1 MB temporaries, whose
        # pages the kernel would fault in again for every tile)
        self._warp_buf = np.empty((T, T, 4), np.float32)
        self._coarse_buf = np.empty((0, 0, 4), np.float32)
        self._big_bufs: dict[int, np.ndarray] = {}  # resized lattice, by level
        self._cache_dir = ground_cache_dir(spec, self.seed)
        self._cache_room = 0  # bytes this process may still add to the cache
        self._dirs_made: set[str] = set()
        self._level_dirs: dict[int, str] = {}  # a level's cache folder, "/" at the end
        if self._cache_dir is not None:
            mb = float(os.environ.get(CACHE_MB_ENV) or CACHE_MB)
            self._cache_room = int(mb * 2**20) - _folder_bytes(self._cache_dir)
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
        if P is None:
            m = self.mpp(level)
            P = self._ne_to_px[level] = np.array([[0.0, 1.0 / m, -0.5], [-1.0 / m, 0.0, -0.5],
                                                  [0.0, 0.0, 1.0]])
            P.flags.writeable = False
        return P

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
                        out: np.ndarray = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA,
                                                       dst=self._new_tile())
                        return out
                os.unlink(path)  # cut short (a crash, or being written): make it anew
            except OSError:
                pass  # not cached yet
        bgra = self._generate_tile(level, ti, tj)
        self.tiles_made += 1
        if path is not None and self._cache_room > 0:
            self._store(level, path, cv2.cvtColor(bgra, cv2.COLOR_BGRA2BGR, dst=self._read_buf))
        return bgra

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

    def _cache_path(self, level: int, ti: int, tj: int) -> str | None:
        """The tile's file (a string: a ``Path`` costs ~8 us to build), or None."""
        if self._cache_dir is None:
            return None
        folder = self._level_dirs.get(level)
        if folder is None:
            folder = self._level_dirs[level] = os.path.join(self._cache_dir, f"L{level}", "")
        return f"{folder}{ti}_{tj}.bgr"

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

    def _coarse(self, rows: int, cols: int) -> np.ndarray:
        """The reused (rows, cols, 4) float32 buffer of a tile's coarse lattice
        (contiguous: cv2.merge is 7x slower into a strided view)."""
        if self._coarse_buf.shape[:2] != (rows, cols):
            self._coarse_buf = np.empty((rows, cols, 4), np.float32)
        return self._coarse_buf

    def _big_buf(self, level: int, rows: int, cols: int) -> np.ndarray:
        """A (rows, cols, 4) float32 view of a buffer kept for ``level`` and grown as
        needed: the coarse lattice's size varies by a point or two from tile to tile,
        and a new ~1 MB array for its resize would have its pages faulted in again
        (cv2.resize writes into the strided view at the same speed)."""
        buf = self._big_bufs.get(level, np.empty((0, 0, 4), np.float32))
        if buf.shape[0] < rows or buf.shape[1] < cols:
            buf = self._big_bufs[level] = np.empty((max(rows, buf.shape[0]) + 2,
                                                    max(cols, buf.shape[1]) + 2, 4), np.float32)
        return buf[:rows, :cols]

    def _generate_tile(self, level: int, ti: int, tj: int) -> np.ndarray:
        T, m = self.tile_px, self.mpp(level)
        rows = np.arange(ti * T, ti * T + T, dtype=np.float64)
        cols = np.arange(tj * T, tj * T + T, dtype=np.float64)
        step = max(m * MACRO_OVERSAMPLE, MACRO_STEP_M)
        if step <= m * 1.0001:
            n = -(rows[:, None] + 0.5) * m
            e = (cols[None, :] + 0.5) * m
            bgra = _bgra(macro_rgb(n, e, m, self.seed), self._warp_buf)
        elif (pr := _resize_plan(m / step, ti * T, T)) and \
                (pc := _resize_plan(m / step, tj * T, T)):
            # the macro colour on the coarser global lattice of points at (K + 1/2) step
            # south and east, scaled up by OpenCV's bilinear resize (4x cheaper than
            # the equivalent warpAffine), of which the tile is a crop
            (y0, ka, na), (x0, kb, nb) = pr, pc
            gn = -(np.arange(ka, ka + na, dtype=np.float64) + 0.5) * step
            ge = (np.arange(kb, kb + nb, dtype=np.float64) + 0.5) * step
            coarse = macro_rgb(gn[:, None], ge[None, :], step, self.seed)
            up = step / m  # the resize's size is its own rounding of na x up, nb x up
            big = cv2.resize(_bgra(coarse, self._coarse(na, nb)), None, fx=up, fy=up,
                             dst=self._big_buf(level, round(na * up), round(nb * up)),
                             interpolation=cv2.INTER_LINEAR)
            bgra = big[y0:y0 + T, x0:x0 + T]
        else:  # sample the macro colour on a coarser global lattice, warp
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
            bgra = cv2.warpAffine(_bgra(coarse, self._coarse(*coarse.shape[1:])), M, (T, T),
                                  dst=self._warp_buf,
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REPLICATE)
        # BGRA uint8 (alpha 255): OpenCV's bilinear warp is ~2.5x faster on four channels
        if level < len(self.detail) - 1:
            out: np.ndarray = cv2.multiply(bgra, self._detail_slab(level, ti * T, tj * T),
                                           dst=self._new_tile(), dtype=cv2.CV_8U)  # rounded
        else:
            out = cv2.convertScaleAbs(bgra, dst=self._new_tile())
            out[..., 3] = 255
        return out

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
        if self.image is not None:  # the user's image is drawn over this ground next
            m = self.mpp(level)
            self.image.focus(-r1 * m, -r0 * m, c0 * m, c1 * m, slot)
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
