"""Smooth value noise for the procedural ground, as a pure function of the seed
and the position: hashed lattice values, smoothstep-interpolated, evaluated on
a grid as two small matrix products (``noise_on_grid``); and the per-cell
tables kept across tiles (``TABLES``), each a pure function of its key, so
that a tile gathering from one gets the values it would compute itself.

Owns the hash and the noise only; what the ground looks like is
``texture``'s. Numbers only: no files, no tiles, nothing of the scenario.
"""

from __future__ import annotations

import itertools
from collections import OrderedDict
from collections.abc import Callable, Iterator

import numpy as np


def uniform_hash(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
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


def derive(h: np.ndarray, *k: float) -> Iterator[np.ndarray]:
    """Other uniform [0, 1) values from one hash (cheaper than hashing again), one
    per factor in ``k``: for a small ``h`` all in one pass (fewer calls), else one
    by one as they are taken (no large temporaries)."""
    h64 = h.astype(np.float64)
    n = len(k) if h.size * len(k) <= 1 << 14 else 1
    for i in range(0, len(k), n):
        x = h64 * np.reshape(k[i:i + n], (-1,) + (1,) * h.ndim)
        x -= np.floor(x)
        yield from x.astype(np.float32)


def value_noise(x: np.ndarray, y: np.ndarray, seed: int, period: int = 0) -> np.ndarray:
    """Smooth value noise in [0, 1) on the unit lattice (periodic if ``period``)."""
    xi, yi, fx, fy = _cells(x, y)
    xi, yi = xi.astype(np.int64), yi.astype(np.int64)
    x1, y1 = xi + 1, yi + 1
    if period:
        xi, yi, x1, y1 = xi % period, yi % period, x1 % period, y1 % period
    a, b = uniform_hash(xi, yi, seed), uniform_hash(x1, yi, seed)
    c, d = uniform_hash(xi, y1, seed), uniform_hash(x1, y1, seed)
    return _blend(a, b, c, d, fx, fy)


def value_noise_at(x: np.ndarray, y: np.ndarray, *seeds: int) -> list[np.ndarray]:
    """``value_noise`` (not periodic) of each seed at scattered points, the same
    values: their lattice corners hashed once over the corners' span and gathered
    (points many to a corner cost a gather instead of four hashes)."""
    xi, yi, fx, fy = _cells(x, y)
    out = []
    for seed in seeds:
        k, tab, nj = hash_table(xi, yi, seed, 1)
        out.append(_blend(tab.take(k), tab.take(k + nj), tab.take(k + 1),
                          tab.take(k + nj + 1), fx, fy))
    return out


def hash_table(i: np.ndarray, j: np.ndarray, seed: int, more: int = 0
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """``uniform_hash`` over the lattice corners ``i.min() .. i.max() + more`` x
    ``j.min() .. j.max() + more`` (whole numbers, as floats or ints): ``(k, table,
    nj)``, the flat ``table`` with rows of ``nj`` and the index ``k`` of each
    ``(i, j)`` in it (``k + nj``: the next ``i``, ``k + 1``: the next ``j``)."""
    i0, j0 = int(i.min()), int(j.min())
    ni, nj = int(i.max()) - i0 + 1 + more, int(j.max()) - j0 + 1 + more
    tab = uniform_hash(np.arange(i0, i0 + ni)[:, None], np.arange(j0, j0 + nj)[None, :],
                       seed).ravel()
    k = (i - i0).astype(np.intp)
    k *= nj
    k += (j - j0).astype(np.intp)
    return k, tab, nj


def _cells(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
    """The lattice cell of each point and its smoothstepped place in it."""
    xi, yi = np.floor(x), np.floor(y)
    fx, fy = (x - xi).astype(np.float32), (y - yi).astype(np.float32)
    return xi, yi, fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)


def _blend(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, fx: np.ndarray,
           fy: np.ndarray) -> np.ndarray:
    """Corner values ``a`` (x, y), ``b`` (x + 1, y), ``c`` (x, y + 1), ``d`` interpolated."""
    top = a + (b - a) * fx
    out: np.ndarray = top + ((c + (d - c) * fx) - top) * fy
    return out


WEIGHTS: OrderedDict[bytes, list[tuple[int, np.ndarray]]] = OrderedDict()


def noise_weights(x: np.ndarray, wavelengths_m: list[float]) -> list[tuple[int, np.ndarray]]:
    """``_make_noise_weights``, remembered for the last few sample rows and columns
    (tiles side by side share them; the arrays returned are not to be written)."""
    key = x.tobytes() + np.asarray(wavelengths_m, np.float64).tobytes()
    out = WEIGHTS.get(key)
    if out is None:
        out = WEIGHTS[key] = _make_noise_weights(x, wavelengths_m)
        if len(WEIGHTS) > 16:
            WEIGHTS.popitem(last=False)
    else:
        WEIGHTS.move_to_end(key)
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


def product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
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


class Tables:
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


TABLES = Tables(16 << 20)


def lattice(wn: tuple[int, np.ndarray], we: tuple[int, np.ndarray], seed: int,
            offset: float, scale: float) -> np.ndarray:
    """The hashed lattice values ``scale * (hash + offset)`` (float32, contiguous) of
    the corners under the weights ``wn`` (north) and ``we`` (east), cut from a kept
    table of whole 32 x 32 blocks of corners (a large grid's: made for it)."""
    (i0, w_n), (j0, w_e) = wn, we
    ni, nj = w_n.shape[1], w_e.shape[1]

    def make(a0: int, a1: int, b0: int, b1: int) -> tuple[np.ndarray, ...]:
        h = uniform_hash(np.arange(a0, a1)[:, None], np.arange(b0, b1)[None, :], seed)
        if offset or scale != 1.0:
            h = ((h + np.float32(offset)) * np.float32(scale)).astype(np.float32)
        return (h,)

    got = TABLES.cover(("lattice", seed, offset, scale), i0, i0 + ni - 1, j0, j0 + nj - 1,
                       32, make)
    assert got is not None
    a0, _, b0, _, (tab,) = got
    return np.ascontiguousarray(tab[i0 - a0:i0 - a0 + ni, j0 - b0:j0 - b0 + nj])


def noise_on_grid(wn: tuple[int, np.ndarray], we: tuple[int, np.ndarray], seed: int,
                  scale: float = 1.0, offset: float = 0.0) -> np.ndarray:
    """``scale * (value noise + offset)`` at a grid (R, C) from its weights along
    north ``wn`` and east ``we`` (``noise_weights``): the same smoothstep
    interpolation of hashed lattice values as ``value_noise``, as two small matrix
    products (a pure function of position: neighbouring tiles agree)."""
    return product(wn[1] @ lattice(wn, we, seed, offset, scale), we[1].T)
