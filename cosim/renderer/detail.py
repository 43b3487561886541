"""The ground's fine detail: a tileable multiplier (around 1) over what a
camera a few tens of metres up resolves, 5 cm to a few metres a feature, laid
on every tile of the procedural ground (``texture``).

Two layers, summed:

* litter: the clods, stones, leaf litter and tufts of grass that cover a
  field, as a "dead leaves" picture (Matheron 1968; Lee, Mumford and Huang
  2001): ellipses of random tone, size, elongation and heading laid one over
  another, their radii drawn with density ``r**-3`` from ``LITTER_R_PX``, each
  tinted as what it is (``LITTER_KINDS``: living leaves, dry straw, bare soil,
  stone; a tint changes the hue, not the luminance).
  Scale-invariant occlusion of that kind is what gives natural pictures their
  ``f**-2`` power spectrum; each is antialiased (drawn at ``SUPERSAMPLE`` x the
  base resolution and area-averaged), and none is narrower than two pixels;
* growth and moisture: value-noise octaves of equal amplitude (the same
  ``f**-2`` law over their span), ``GROWTH_CELLS`` cells across the texture.

Their sum is high-passed (a Gaussian in frequency, ``1 - exp(-(f L)**2 / 2)``
with ``L = HIGHPASS_PX``): the texture repeats every ``DETAIL_PX`` pixels, so
it carries only the scales well below its period; larger ones are the macro
brightness's (``texture.BRIGHT_M``), which does not repeat. The levels below
the base are 2x2 averages (no feature finer than a level's pixel).

A pure function of the seed (its hashes, OpenCV's rasteriser and numpy's FFT;
the tile cache's key holds both libraries' versions). Owns the detail only:
nothing of the tiles, the macro colour or the scenario.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from cosim.renderer.noise import uniform_hash, value_noise

DETAIL_PX = 512  # the tileable detail texture's size at the base level
#: litter: this many ellipses, radii (the geometric mean of the two semi-axes,
#: base pixels) from .. to, elongation (major / minor axis) 1 to this, or less:
#: no ellipse is narrower than two base pixels (its minor semi-axis at least 1)
LITTER_COUNT = 40000
LITTER_R_PX = (1.0, 12.0)
LITTER_ELONGATION = 4.0
LITTER_TONE_SD = 0.2  # an ellipse's tone: 1 + this x a standard normal
#: what an ellipse is: its share of them and its tint (R, G, B multipliers of
#: Rec. 709 luminance 1)
LITTER_KINDS = {"leaf": (0.55, (0.95, 1.02, 0.95)), "straw": (0.20, (1.06, 1.00, 0.87)),
                "soil": (0.20, (1.07, 0.98, 0.94)), "stone": (0.05, (0.99, 1.00, 1.02))}
SUPERSAMPLE = 2  # the litter drawn at this many times the base resolution
#: growth and moisture: value-noise octaves of this many cells across, each of
#: this amplitude
GROWTH_CELLS = (4, 8, 16, 32)
GROWTH_AMP = 0.5
HIGHPASS_PX = 64.0  # scales above about this many base pixels removed
_SHIFT = 4  # OpenCV's sub-pixel bits for the ellipses' centres and axes


def litter_ellipses(seed: int) -> tuple[np.ndarray, ...]:
    """The litter's ellipses, in the order they are laid: centre row and column,
    major and minor semi-axes (base pixels), heading (degrees) and colour (R, G, B
    on 0..255, 128 the ground's own)."""
    S = DETAIL_PX
    k = np.arange(LITTER_COUNT, dtype=np.float64)
    cy, cx, ur, ut, uphase, ue, uh, uk = (uniform_hash(k, np.full_like(k, j), seed).astype(
        np.float64) for j in range(8))
    lo, hi = LITTER_R_PX[0] ** -2.0, LITTER_R_PX[1] ** -2.0
    r = (lo - ur * (lo - hi)) ** -0.5  # inverse of the r**-3 density's distribution
    gauss = np.sqrt(-2.0 * np.log(np.maximum(ut, 1e-7))) * np.cos(2.0 * np.pi * uphase)
    share = np.cumsum([f for f, _ in LITTER_KINDS.values()])
    tint = np.array([t for _, t in LITTER_KINDS.values()])[
        np.minimum(np.searchsorted(share / share[-1], uk, "right"), len(share) - 1)]
    colour = np.clip(np.rint(128.0 * (1.0 + LITTER_TONE_SD * gauss)[:, None] * tint), 1,
                     255).astype(int)
    elong = 1.0 + (np.minimum(LITTER_ELONGATION, r * r) - 1.0) * ue
    return cy * S, cx * S, r * np.sqrt(elong), r / np.sqrt(elong), uh * 180.0, colour


def litter(seed: int) -> np.ndarray:
    """The litter layer (``DETAIL_PX`` square x RGB, float32, tones about 0,
    tileable): ``litter_ellipses`` in their order, each later one over the earlier
    ones, drawn again one period over where they cross the texture's edge."""
    S, ss = DETAIL_PX, SUPERSAMPLE
    y, x, major, minor, heading, colour = litter_ellipses(seed)
    pad = math.ceil(LITTER_R_PX[1] * math.sqrt(LITTER_ELONGATION)) + 2
    canvas = np.full(((S + 2 * pad) * ss,) * 2 + (3,), 128, np.uint8)
    # each ellipse where it is and, near an edge, one period over (its copies drawn
    # right after it): in the canvas's fixed point
    near_y = np.where(y < pad, S, np.where(y > S - pad, -S, 0))
    near_x = np.where(x < pad, S, np.where(x > S - pad, -S, 0))
    oy = np.stack([np.zeros_like(near_y), near_y, np.zeros_like(near_y), near_y])
    ox = np.stack([np.zeros_like(near_x), np.zeros_like(near_x), near_x, near_x])
    draw = np.ones(oy.shape, bool)
    draw[1:] = (oy[1:] != 0) | (ox[1:] != 0)
    draw[3] &= (near_y != 0) & (near_x != 0)
    which, copy = np.nonzero(draw.T)  # by ellipse, then copy
    unit = ss * (1 << _SHIFT)  # base pixels to the canvas's fixed point
    fixed = np.rint(np.stack([(x[which] + ox[copy, which] + pad) * unit,
                              (y[which] + oy[copy, which] + pad) * unit,
                              major[which] * unit, minor[which] * unit])).astype(np.int64)
    for (px, py, a, b), t, h in zip(fixed.T.tolist(), colour[which].tolist(),
                                    heading[which].tolist()):
        cv2.ellipse(canvas, (px, py), (a, b), h, 0, 360, t, -1, cv2.LINE_AA, _SHIFT)
    small = cv2.resize(canvas, None, fx=1 / ss, fy=1 / ss, interpolation=cv2.INTER_AREA)
    out: np.ndarray = small[pad:pad + S, pad:pad + S].astype(np.float32)
    out *= np.float32(1 / 128)
    out -= np.float32(1.0)
    return out


def growth(seed: int) -> np.ndarray:
    """The growth and moisture layer (``DETAIL_PX`` square, float32, about 0,
    tileable): ``GROWTH_CELLS`` octaves of periodic value noise."""
    S = DETAIL_PX
    y, x = np.mgrid[0:S, 0:S].astype(np.float64)
    out = np.zeros((S, S), np.float32)
    for k, cells in enumerate(GROWTH_CELLS):
        out += GROWTH_AMP * (value_noise(x * cells / S, y * cells / S, seed + 31 + k,
                                         period=cells) - 0.5)
    return out


def highpass(d: np.ndarray, scale_px: float) -> np.ndarray:
    """``d`` (square, periodic; any channels along a third axis) without its scales
    above about ``scale_px``: its spectrum times ``1 - exp(-(f scale_px)**2 / 2)``
    (float32)."""
    n = d.shape[0]
    f = np.hypot(np.fft.fftfreq(n)[:, None], np.fft.rfftfreq(n)[None, :])
    keep = -np.expm1(-0.5 * (f * scale_px) ** 2).reshape(f.shape + (1,) * (d.ndim - 2))
    out: np.ndarray = np.fft.irfft2(np.fft.rfft2(d, axes=(0, 1)) * keep, s=d.shape[:2],
                                    axes=(0, 1)).astype(np.float32)
    return out


@functools.lru_cache(maxsize=4)
def detail_pyramid(seed: int) -> tuple[np.ndarray, ...]:
    """The detail multiplier (around 1; R, G, B along the last axis) at the base
    level and its 2x2-averaged levels down to 1 px (float32; kept for the last
    few seeds: about half a second to make; the arrays are not to be written)."""
    d = highpass(litter(seed + 40) + growth(seed)[..., None], HIGHPASS_PX)
    d += np.float32(1.0)
    levels = [d]
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    for lv in levels:
        lv.flags.writeable = False
    return tuple(levels)
