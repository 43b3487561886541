"""The procedural ground's texture: a pure function of the seed and the
position, drawn a tile at a time (``ProceduralTiles.make``).

Fields in a gently warped grid (crop colours, crop rows, tramlines), hedgerows
and woods of individual tree crowns, roads (``macro_rgb``), and a tileable
fine-detail texture down to the base level (5 cm/px by default: clods, stones,
leaf litter and tufts, ``detail``). Every feature is band-limited to the level
it is drawn at (crop rows and noise octaves finer than two pixels are left out,
roads, tree crowns and tramlines' tracks are drawn with their pixel coverage). A
tile costs about 1 to 2 ms to make. Level ``l`` has
``base_m_per_px * 2**l`` metres per pixel; its pixel ``(row, col)`` is centred
at ``east = (col + 0.5) * mpp``, ``north = -(row + 0.5) * mpp`` (scenario
frame metres).

Owns what the ground looks like; its noise is ``noise``'s. It keeps no tiles
(``pyramid``), writes no files (``tile_cache``) and knows no imagery.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import cv2
import numpy as np

from cosim.renderer import noise
from cosim.renderer.detail import detail_pyramid
from cosim.renderer.noise import (
    derive,
    hash_table,
    lattice,
    noise_on_grid,
    noise_weights,
    product,
    uniform_hash,
    value_noise_at,
)

MACRO_STEP_M = 0.5  # macro features (fields, roads, trees) sampled at least this fine
MACRO_OVERSAMPLE = 2.0  # macro features sampled at most every this many pixels, then upsampled
#: bump whenever a tile's pixels change for the same seed and ground parameters
#: (old cache folders are then ignored; delete ~/.cache/cosim/ground to reclaim the space)
TEXTURE_VERSION = 12
FIELD_N_M, FIELD_E_M = 160.0, 220.0  # field size
WARP_M = 15.0  # the field grid's warp, at most this many metres
TREE_M = 7.0  # one tree at most per cell of this size, at a random place in its middle half
TREE_R_M = (1.6, 2.8)  # a tree crown's radius, from .. to
WOODS = 0.76  # woods where the 500 m value noise is above this
HEDGE_M = (4.0, 9.0)  # a hedgerow's trees stand this far inside a field that has one
#: brightness within fields (soil moisture, growth): value-noise octaves of these
#: wavelengths and amplitudes (equal from 30 m down: the f**-2 law natural ground
#: follows, continued below 3 m by the fine detail, ``detail``)
BRIGHT_M: tuple[float, ...] = (60.0, 30.0, 15.0, 7.5, 3.75)
BRIGHT_AMP: tuple[float, ...] = (0.35, 0.25, 0.25, 0.25, 0.25)
#: a wood's tree: its crown's lowest point from .. to, its top from .. to (metres
#: above the ground); a hedgerow's trees are lower
WOOD_CROWN_M, WOOD_TOP_M = (3.0, 5.0), (8.0, 16.0)
HEDGE_CROWN_M, HEDGE_TOP_M = (2.5, 4.0), (6.0, 10.0)

#: tramlines: in some crop fields (``TRAMLINE_SHARE`` of crops, wheat and dark crop)
#: a pair of wheel tracks ``TRACK_GAUGE_M`` apart, each ``TRACK_M`` wide, along the
#: crop rows every ``TRAMLINE_ROWS`` rows, darker by ``TRACK_DARK`` (bare soil)
TRAMLINE_SHARE, TRAMLINE_ROWS = 0.6, 8
TRACK_GAUGE_M, TRACK_M, TRACK_DARK = 1.8, 0.45, 0.35

# field palette, RGB: crops, pasture, wheat, ploughed soil, dry grass, dark crop
_FIELDS = np.array([[96, 128, 58], [118, 140, 72], [176, 160, 96], [122, 98, 72],
                    [150, 146, 98], [74, 104, 50]], dtype=np.float32)
_TREE = np.array([46, 70, 38], dtype=np.float32)
_ROAD = np.array([118, 116, 112], dtype=np.float32)


def _coverage(signed_dist_m: np.ndarray, step_m: float) -> np.ndarray:
    """Pixel coverage of a shape from the signed distance to its edge (inside > 0)."""
    out: np.ndarray = signed_dist_m / max(step_m, 1e-6)
    out += 0.5
    return np.clip(out, 0.0, 1.0, out=out).astype(np.float32)


def _field_cells(seed: int, step_m: float, a0: int, a1: int, b0: int,
                 b1: int) -> tuple[np.ndarray, ...]:
    """What depends only on a field: for the cells ``[a0, a1) x [b0, b1)`` of the
    field grid (flat, row-major) its colour (3 x cells), crop-row amplitude and
    cycles per field unit along u and v, its tramlines' strength (0: none) and
    spacing (metres); and
    whether the grid lines ``a0 .. a1 - 1`` (north) and ``b0 .. b1 - 1`` (east) are
    roads (a road's half width, or -1000)."""
    ki = np.arange(a0, a1, dtype=np.float64)
    kj = np.arange(b0, b1, dtype=np.float64)
    hf = uniform_hash(ki[:, None], kj[None, :], seed + 3).ravel()
    kind = np.minimum((hf * len(_FIELDS)).astype(np.int64), len(_FIELDS) - 1)
    shade, rows, across, _ = derive(hf, 613.37, 2713.91, 97.13, 31.77)  # _: _tree_cells' hedge
    colour = (_FIELDS[kind] * (0.88 + 0.24 * shade)[..., None]).T.copy()
    # crop rows: 2.5-4 m apart, along or across the field, only where resolvable
    period = 2.5 + 1.5 * rows
    along = across < 0.5
    fade = np.clip((period / step_m - 4.0) / 4.0, 0.0, 1.0).astype(np.float32)
    amp = (0.10 * fade * (kind != 1)).astype(np.float32)  # pasture has none
    cu = np.where(along, FIELD_N_M / period, 0.0).astype(np.float32)  # cycles per field unit
    cv = np.where(along, 0.0, FIELD_E_M / period).astype(np.float32)
    # tramlines, 20 m or more apart: faded out where a sample is 4 to 8 m
    tram = next(derive(hf, 4241.3)) < TRAMLINE_SHARE
    tram &= (kind == 0) | (kind == 2) | (kind == 5)
    tram_fade = float(np.clip((8.0 - step_m) / 4.0, 0.0, 1.0))
    tram_amp = (TRACK_DARK * tram_fade * tram).astype(np.float32)
    tram_m = (TRAMLINE_ROWS * period).astype(np.float32)
    road_n = np.where(uniform_hash(ki, np.zeros_like(ki), seed + 8) < 0.3, 3.0,
                      -1e3).astype(np.float32)
    road_e = np.where(uniform_hash(np.zeros_like(kj), kj, seed + 9) < 0.3, 3.0,
                      -1e3).astype(np.float32)
    return colour, amp, cu, cv, tram_amp, tram_m, road_n, road_e


def _tree_cells(kn: np.ndarray, ke: np.ndarray, seed: int) -> tuple[np.ndarray, ...]:
    """What depends only on a tree cell (``TREE_M`` square; ``kn``, ``ke`` its
    row and column, broadcast together), flat: whether a tree stands there in a
    wood, or on a hedgerow; its centre north and east; its radius and shade; the
    height of its crown's lowest point and of its top (``WOOD_CROWN_M`` ..).

    Whether it stands is decided at its centre, so a tree is drawn whole or not
    at all, across the edges of its wood, hedgerow band, field, cell and tile: in
    a wood where the woods' value noise there is above ``WOODS``; on a hedgerow
    where the centre is ``HEDGE_M`` inside a field that has one (the centre's
    field and distances to the field grid's lines, warped as ``macro_rgb``'s;
    the warp's noise at the centre itself, not on a grid)."""
    ht = uniform_hash(kn, ke, seed + 12)
    d = derive(ht, 43.9, 71.3, 577.31, 1291.7, 3343.1, 5003.7, 7919.3)  # in this order
    in_wood, on_hedge = (next(d) < 0.9).ravel(), (next(d) < 0.7).ravel()
    tn = ((kn + 0.25 + 0.5 * ht) * TREE_M).ravel()
    te = ((ke + 0.25 + 0.5 * next(d)) * TREE_M).ravel()
    lo, hi = TREE_R_M
    radius = (lo + (hi - lo) * next(d)).ravel()
    tone = (0.75 + 0.5 * next(d)).ravel()
    crown_u, top_u = next(d).ravel(), next(d).ravel()
    in_wood &= value_noise_at(tn / 500.0, te / 500.0, seed + 10)[0] > WOODS
    (c0, c1), (t0, t1) = WOOD_CROWN_M, WOOD_TOP_M
    (h0, h1), (s0, s1) = HEDGE_CROWN_M, HEDGE_TOP_M
    crown_m = np.where(in_wood, c0 + (c1 - c0) * crown_u, h0 + (h1 - h0) * crown_u)
    top_m = np.where(in_wood, t0 + (t1 - t0) * top_u, s0 + (s1 - s0) * top_u)
    u32, v32 = value_noise_at(tn / 230.0, te / 230.0, seed + 1, seed + 2)
    u = u32.astype(np.float64)
    u -= 0.5
    u *= 2 * WARP_M / FIELD_N_M
    u += tn / FIELD_N_M
    v = v32.astype(np.float64)
    v -= 0.5
    v *= 2 * WARP_M / FIELD_E_M
    v += te / FIELD_E_M
    fu, fv = np.floor(u), np.floor(v)
    k, fields, _ = hash_table(fu, fv, seed + 3)
    hedge = (next(derive(fields, 31.77)) < 0.5).take(k)  # _field_cells' hedgerow
    u -= fu
    v -= fv
    edge = np.minimum(np.minimum(u, 1.0 - u) * FIELD_N_M, np.minimum(v, 1.0 - v) * FIELD_E_M)
    on_hedge &= hedge & (edge > HEDGE_M[0]) & (edge < HEDGE_M[1])
    return in_wood, on_hedge, tn, te, radius, tone, crown_m, top_m


def tree_tables(seed: int, kn0: int, kn1: int, ke0: int, ke1: int, own: bool = True
                ) -> tuple[int, int, int, int, tuple[np.ndarray, ...]] | None:
    """``_tree_cells`` of the tree cells ``kn0 .. kn1`` x ``ke0 .. ke1`` (inclusive),
    kept by whole blocks (``noise.TABLES.cover``): ``(a0, a1, b0, b1, tables)``, the
    tables of the cells ``[a0, a1) x [b0, b1)`` (flat, rows of ``b1 - b0``)."""

    def make(a0: int, a1: int, b0: int, b1: int) -> tuple[np.ndarray, ...]:
        return _tree_cells(np.arange(a0, a1, dtype=np.float64)[:, None],
                           np.arange(b0, b1, dtype=np.float64)[None, :], seed)

    return noise.TABLES.cover(("tree", seed), kn0, kn1, ke0, ke1, 32, make, own=own)


#: how far a sample's woods noise and field-edge distance (metres) may be from
#: those at the centre of its cell's tree, at most 7.5 m away (the middle half of
#: a 7 m cell): the noise's slope is at most 1.5 per wavelength along each axis
#: (smoothstep), 0.032 over 5.25 m + 5.25 m at 500 m; the warp's is 30 m x 1.5 /
#: 230 m, so an edge distance moves by at most 5.25 m + 0.2 x 10.5 m, 7.3 m
_NEAR_WOODS = 0.05
_NEAR_EDGE_M = 10.0


def _trees(nv: np.ndarray, ev: np.ndarray, step_m: float, seed: int,
           edge_m: Callable[[], np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The trees over the grid ``nv`` x ``ev`` (monotonic, either way): the flat
    indices ``at`` of the samples they cover, their coverage ``cov`` and shade
    (coverage x tone), or None where no tree stands.

    A tree's disc reaches ``TREE_R_M[1] + step_m / 2`` past its centre, beyond its
    cell: every tree cell that reaches the grid is drawn, each tree over its own
    box of samples (a wood's edge, a hedgerow band, a field, a cell and a tile cut
    none). Overlapping crowns are laid one over another in a fixed order, the
    trees of cells ``q`` apart at a time (their boxes never overlap), so a sample's
    colour does not depend on which tile or call drew it. Where a grid spans more
    tree cells than it has samples (a tree is then smaller than a sample; the
    tables of every cell would cost more than the tile) each sample takes the
    tree of its own cell only, looked up where one may stand: near a wood (the
    woods' noise at the sample within ``_NEAR_WOODS`` of ``WOODS``) or a field's
    edge (``edge_m()``, the sample's distance to the nearest line of the warped
    field grid, within ``_NEAR_EDGE_M`` of a hedgerow band)."""
    R, C = len(nv), len(ev)
    reach = TREE_R_M[1] + 0.5 * step_m
    kn0, kn1 = math.floor((nv.min() - reach) / TREE_M), math.floor((nv.max() + reach) / TREE_M)
    ke0, ke1 = math.floor((ev.min() - reach) / TREE_M), math.floor((ev.max() + reach) / TREE_M)
    got = tree_tables(seed, kn0, kn1, ke0, ke1, own=(kn1 - kn0 + 1) * (ke1 - ke0 + 1) <= R * C)
    if got is None:  # each sample its own cell's tree, where one may stand
        woods = noise_on_grid(noise_weights(nv, [500.0])[0], noise_weights(ev, [500.0])[0],
                              seed + 10)
        maybe = np.flatnonzero((woods > WOODS - _NEAR_WOODS)
                               | (edge_m() < HEDGE_M[1] + _NEAR_EDGE_M))
        r, c = np.divmod(maybe, C)
        wood, hedge, tn, te, radius, tone, *_ = _tree_cells(np.floor(nv.take(r) / TREE_M),
                                                            np.floor(ev.take(c) / TREE_M), seed)
        stand = np.flatnonzero(wood | hedge)
        at, r, c = maybe.take(stand), r.take(stand), c.take(stand)
        dtn, dte = nv.take(r) - tn.take(stand), ev.take(c) - te.take(stand)
        cov = _coverage(radius.take(stand) - np.sqrt(dtn * dtn + dte * dte), step_m)
        return (at, cov, cov * tone.take(stand)) if len(at) else None
    a0, a1, b0, b1, (wood, hedge, tn, te, radius, tone, *_) = got
    nb = b1 - b0
    stands = (wood | hedge).reshape(-1, nb)[kn0 - a0:kn1 + 1 - a0, ke0 - b0:ke1 + 1 - b0]
    kn, ke = np.nonzero(stands)
    if not len(kn):
        return None
    kn += kn0
    ke += ke0
    t = (kn - a0) * nb + (ke - b0)  # in the tables
    tn, te, radius, tone = tn.take(t), te.take(t), radius.take(t), tone.take(t)
    # each tree's box of samples: |nv - tn| and |ev - te| < its reach
    ext = radius + 0.5 * step_m
    sn = 1.0 if nv[-1] >= nv[0] else -1.0  # nv * sn ascending
    se = 1.0 if ev[-1] >= ev[0] else -1.0
    i0 = np.searchsorted(nv * sn, tn * sn - ext, "right")
    i1 = np.searchsorted(nv * sn, tn * sn + ext, "left")
    j0 = np.searchsorted(ev * se, te * se - ext, "right")
    j1 = np.searchsorted(ev * se, te * se + ext, "left")
    rows, cols = np.maximum(i1 - i0, 0), np.maximum(j1 - j0, 0)
    # laid in order of the cells' (row mod q, column mod q): within one such class
    # trees are at least q TREE_M - TREE_M / 2 apart along a row or column, more
    # than two reaches
    q = math.floor((2 * reach + TREE_M / 2) / TREE_M) + 1
    order = np.argsort((kn % q) * q + ke % q, kind="stable")
    cls = ((kn % q) * q + ke % q)[order]
    count = (rows * cols)[order]
    tree = np.repeat(order, count)  # one entry per (tree, sample of its box)
    first = np.cumsum(count) - count
    k = np.arange(len(tree)) - np.repeat(first, count)
    wide = cols.take(tree)
    r = i0.take(tree) + k // wide
    c = j0.take(tree) + k % wide
    dtn, dte = nv.take(r) - tn.take(tree), ev.take(c) - te.take(tree)
    cov = _coverage(radius.take(tree) - np.sqrt(dtn * dtn + dte * dte), step_m)
    flat = r * C + c
    alpha = np.zeros(R * C, np.float32)
    shade = np.zeros(R * C, np.float32)
    ends = np.searchsorted(np.repeat(cls, count), np.arange(q * q + 1), "left")
    tone_of = tone.take(tree)
    for lo, hi in zip(ends[:-1], ends[1:]):  # a class's samples are each covered once
        at, a = flat[lo:hi], cov[lo:hi]
        shade[at] = shade[at] * (1.0 - a) + a * tone_of[lo:hi]
        alpha[at] = alpha[at] + a - alpha[at] * a
    at = np.flatnonzero(alpha)
    return at, alpha.take(at), shade.take(at)


def _tracks(rows: np.ndarray, tram_m: np.ndarray, step_m: float) -> np.ndarray:
    """A tramline's wheel tracks' coverage (0..1, float32) of each sample, box-filtered
    over ``step_m`` (a track narrower than a sample covers its share of it, both
    tracks a sample wider than them both), from the crop-row phase ``rows`` (rows
    across the field) and the tramlines' spacing ``tram_m`` (metres, every
    ``TRAMLINE_ROWS``-th row): its two tracks ``TRACK_GAUGE_M / 2`` to either side
    of each. A sample ``2 b`` wide at a distance ``d >= 0`` from a track ``2 h``
    wide overlaps it by ``clip(h + b - d, 0, 2 min(h, b))``."""
    f32 = np.float32
    half, box, gauge = f32(TRACK_M / 2), f32(max(step_m, 1e-6) / 2), f32(TRACK_GAUGE_M / 2)
    dist = rows / f32(TRAMLINE_ROWS)
    dist -= np.round(dist)
    np.abs(dist, out=dist)
    dist *= tram_m  # metres from the tramline's centre
    near = np.abs(dist - gauge)  # from the nearer track, then the farther one's overlap
    out = np.subtract(half + box - gauge, dist, out=dist)
    cap = f32(2 * min(half, box))
    np.clip(out, 0.0, cap, out=out)
    near -= half + box
    np.negative(near, out=near)
    np.clip(near, 0.0, cap, out=near)
    out += near
    out *= f32(1.0 / (2 * box))
    res: np.ndarray = np.minimum(out, 1.0, out=out)
    return res


def macro_rgb(n: np.ndarray, e: np.ndarray, step_m: float, seed: int,
              with_trees: bool = True) -> np.ndarray:
    """The procedural ground's colour as float32 planes (3, R, C), RGB about 0..255
    (not clipped), at the scenario-frame grid ``n`` (R x 1) x ``e`` (1 x C), drawn
    for a sample spacing of ``step_m``. Smooth fields (field-grid warp, woods,
    brightness) are value noise evaluated as small matrix products; what depends
    only on a field, a grid line, a tree cell or a noise lattice corner is computed
    once per cell, kept across calls (``noise.TABLES``) and gathered; trees are drawn
    only where some may stand (none without ``with_trees``: the ground under them)."""
    nv, ev = n.ravel().astype(np.float64), e.ravel().astype(np.float64)
    R, C = len(nv), len(ev)
    f32 = np.float32
    fn, fe, warp = FIELD_N_M, FIELD_E_M, WARP_M
    # value noise weights: field-grid warp, brightness octaves (finer than two
    # samples left out)
    octaves = [wl for wl in BRIGHT_M if wl >= 2 * step_m]
    wts_n = noise_weights(nv, [230.0] + octaves)
    wts_e = noise_weights(ev, [230.0] + octaves)
    # warped coordinates in field units: u = (north + warp) / fn, v = (east + warp) / fe
    u = noise_on_grid(wts_n[0], wts_e[0], seed + 1, 2 * warp / fn, -0.5)
    u += (nv / fn).astype(np.float32)[:, None]
    v = noise_on_grid(wts_n[0], wts_e[0], seed + 2, 2 * warp / fe, -0.5)
    v += (ev / fe).astype(np.float32)[None, :]
    # fields: the (ci, cj) cells of the warped field grid here are ci0..ci1 x cj0..cj1;
    # their tables (_field_cells) are kept for whole blocks of 8 x 8 cells (a large
    # grid's: made for it)
    ci0 = math.floor((nv.min() - warp) / fn) - 1
    ci1 = math.floor((nv.max() + warp) / fn) + 1
    cj0 = math.floor((ev.min() - warp) / fe) - 1
    cj1 = math.floor((ev.max() + warp) / fe) + 1
    got = noise.TABLES.cover(("field", seed, step_m), ci0, ci1, cj0, cj1, 8,
                        functools.partial(_field_cells, seed, step_m))
    assert got is not None
    a0, a1, b0, b1, (colour, amp, cu, cv, tram_amp, tram_m, road_n, road_e) = got
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
    rows_here, trams_here = amp.reshape(-1, nj)[here].any(), tram_amp.reshape(-1, nj)[here].any()
    if rows_here or trams_here:
        phase = u * cu.take(cell)
        phase += v * cv.take(cell)  # crop rows (cycles) across the field
        tracks = _tracks(phase, tram_m.take(cell), step_m) if trams_here else None
        phase -= np.floor(phase)  # sin in float32 of the phase in [0, 1)
        phase *= f32(2 * np.pi)
        factor = np.sin(phase, out=phase)
        factor *= amp.take(cell)
        factor += f32(1.0)
        if tracks is not None:
            tracks *= tram_amp.take(cell)
            factor *= f32(1.0) - tracks
    else:
        factor = np.ones((R, C), np.float32)
    # brightness variation within fields (soil moisture, growth)
    if octaves:
        left = [wts_n[1 + k][1] @ lattice(wts_n[1 + k], wts_e[1 + k], seed + 7 + 17 * k,
                                           -0.5, BRIGHT_AMP[k]) for k in range(len(octaves))]
        bright = product(np.hstack(left), np.hstack([w for _, w in wts_e[1:]]).T)
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
    # trees: whole discs over the fields and roads (_tree_cells, _trees)
    trees = _trees(nv, ev, step_m, seed, lambda: np.minimum(du, dv)) if with_trees else None
    # blend: field colour x factor, then road, then trees over it
    keep = factor
    if road is not None:
        keep *= 1.0 - road
    if trees is not None:
        at, cov, shade = trees
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
        if trees is not None:
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


class ProceduralTiles:
    """The tiles of the procedural ground for one seed, ``tile_px`` a side, level
    0 at ``base_m_per_px`` (``make``), flat trees from ``trees_from_level`` on;
    keeps the detail texture's levels and the float buffers a tile is made in (no
    fresh ~1 MB temporaries, whose pages the kernel would fault in again for every
    tile)."""

    def __init__(self, seed: int, base_m_per_px: float, tile_px: int,
                 trees_from_level: int = 0) -> None:
        self.seed, self.base_mpp, self.tile_px = int(seed), base_m_per_px, tile_px
        #: the finest level whose tiles show the trees (flat); finer ones show the
        #: ground under them (their trees are drawn in 3-D: ``canopy``)
        self.trees_from_level = trees_from_level
        #: the fine detail's levels (``detail.detail_pyramid``, about 0.5 s a seed):
        #: made here, at the start, not in the middle of a run at its first new tile
        self.detail = detail_pyramid(self.seed)
        T = tile_px
        self._slabs: dict[tuple[int, int, int], np.ndarray] = {}
        self._warp_buf = np.empty((T, T, 4), np.float32)
        self._coarse_buf = np.empty((0, 0, 4), np.float32)
        self._big_bufs: dict[int, np.ndarray] = {}  # resized lattice, by level

    def _detail_slab(self, level: int, r0: int, c0: int) -> np.ndarray:
        """The fine-detail multiplier over one tile's pixels (T x T x 4 float32: the
        factors for B, G, R and 255 for alpha, which the warp leaves at 1)."""
        d = self.detail[level]
        s = d.shape[0]
        key = (level, r0 % s, c0 % s)
        slab = self._slabs.get(key)
        if slab is None:
            T = self.tile_px
            ri, ci = (np.arange(r0, r0 + T) % s), (np.arange(c0, c0 + T) % s)
            slab = np.empty((T, T, 4), np.float32)
            slab[..., :3] = d[np.ix_(ri, ci)][..., ::-1]  # RGB to BGR
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

    def make(self, level: int, ti: int, tj: int, out: np.ndarray) -> np.ndarray:
        """Tile (ti, tj) of ``level`` (BGRA uint8, alpha 255), made in ``out`` (T x T x 4
        uint8, its contents undefined)."""
        T, m = self.tile_px, float(self.base_mpp * 2 ** level)
        rows = np.arange(ti * T, ti * T + T, dtype=np.float64)
        cols = np.arange(tj * T, tj * T + T, dtype=np.float64)
        step = max(m * MACRO_OVERSAMPLE, MACRO_STEP_M)
        macro = functools.partial(macro_rgb, seed=self.seed,
                                  with_trees=level >= self.trees_from_level)
        if step <= m * 1.0001:
            n = -(rows[:, None] + 0.5) * m
            e = (cols[None, :] + 0.5) * m
            bgra = _bgra(macro(n, e, m), self._warp_buf)
        elif (pr := _resize_plan(m / step, ti * T, T)) and \
                (pc := _resize_plan(m / step, tj * T, T)):
            # the macro colour on the coarser global lattice of points at (K + 1/2) step
            # south and east, scaled up by OpenCV's bilinear resize (4x cheaper than
            # the equivalent warpAffine), of which the tile is a crop
            (y0, ka, na), (x0, kb, nb) = pr, pc
            gn = -(np.arange(ka, ka + na, dtype=np.float64) + 0.5) * step
            ge = (np.arange(kb, kb + nb, dtype=np.float64) + 0.5) * step
            coarse = macro(gn[:, None], ge[None, :], step)
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
            coarse = macro(gn[:, None], ge[None, :], step)
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
            res: np.ndarray = cv2.multiply(bgra, self._detail_slab(level, ti * T, tj * T),
                                           dst=out, dtype=cv2.CV_8U)  # rounded
        else:
            res = cv2.convertScaleAbs(bgra, dst=out)
            res[..., 3] = 255
        return res
