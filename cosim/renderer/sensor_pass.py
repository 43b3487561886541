"""The sensor's per-pixel pass, compiled: vignetting's gain and the noise's
table look-up in one sweep over a BGRA frame (``gain_noise``), and the noise's
random levels (``fill_levels``).

``Sensor.apply`` runs it last, after distortion's remap and motion blur: each
colour value ``v`` becomes ``v g`` rounded half up and clipped to 255 (``g``
the pixel's vignetting gain on 8-bit values, in steps of 2^-16), then the noise
table's entry for that value and its random level (``table[v * 256 + level]``,
``sensor.noise_table``), the levels one byte a colour value in the frame's
order (pixel by pixel, B, G, R); alpha is left as it is. One pass instead of
five (the gain's multiply, a colour conversion each way, the index merge, the
look-up).

The levels are the bytes of splitmix64's stream (Steele, Lea and Flood 2014:
the 64-bit golden-ratio counter through a two-multiply finaliser) from a
64-bit key: a pure function of the key, whatever the process.

Compiled by numba on first use in a process (about a second; kept in numba's
cache beside this file after that, so later processes load it). Owns nothing
but the arithmetic; what the gain, table and key are is ``sensor``'s.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: fixed-point bits of the vignetting gain (``gain_fixed``)
GAIN_BITS = 16


@njit(cache=True, nogil=True, boundscheck=False)
def _fill(words: np.ndarray, key: np.uint64) -> None:  # pragma: no cover (compiled)
    z = key
    for j in range(words.shape[0]):
        z += np.uint64(0x9E3779B97F4A7C15)
        x = z
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        words[j] = x ^ (x >> np.uint64(31))


@njit(cache=True, nogil=True, boundscheck=False)
def _gain_noise(px: np.ndarray, gain: np.ndarray, table: np.ndarray, levels: np.ndarray,
                use_gain: bool, use_noise: bool) -> None:  # pragma: no cover (compiled)
    half = np.uint32(1 << (GAIN_BITS - 1))
    k = 0
    for i in range(px.shape[0]):
        g = gain[i] if use_gain else np.uint32(0)
        for c in range(3):
            v = np.uint32(px[i, c])
            if use_gain:
                v = min((v * g + half) >> np.uint32(GAIN_BITS), np.uint32(255))
            if use_noise:
                v = np.uint32(table[(v << np.uint32(8)) | np.uint32(levels[k])])
                k += 1
            px[i, c] = v


def gain_fixed(gain: np.ndarray) -> np.ndarray:
    """(h, w) float gains -> the pass's (h * w,) uint32 fixed-point ones."""
    out: np.ndarray = np.rint(np.asarray(gain, np.float64).reshape(-1)
                              * (1 << GAIN_BITS)).astype(np.uint32)
    return out


def fill_levels(words: np.ndarray, key: int) -> np.ndarray:
    """Fill ``words`` (uint64) with splitmix64's stream from ``key``; its bytes
    (``words.view(np.uint8)``, returned) are the noise's levels."""
    _fill(words, np.uint64(key & 0xFFFF_FFFF_FFFF_FFFF))
    out: np.ndarray = words.view(np.uint8)
    return out


def gain_noise(img: np.ndarray, gain: np.ndarray | None, table: np.ndarray | None,
               levels: np.ndarray | None) -> np.ndarray:
    """``img`` (h x w x 4 BGRA uint8, C-contiguous; changed in place and
    returned) times ``gain`` (``gain_fixed``; None: none), then through the
    noise ``table`` (65536 uint8; None: no noise) at each value's level in
    ``levels`` (at least h * w * 3 uint8)."""
    px = img.reshape(-1, 4)
    if table is not None:
        if levels is None or levels.size < px.shape[0] * 3:
            raise ValueError("gain_noise: the noise needs a level for each colour value")
    if gain is not None and gain.size != px.shape[0]:
        raise ValueError(f"gain_noise: {gain.size} gains for {px.shape[0]} pixels")
    _gain_noise(px, gain if gain is not None else _NO_GAIN,
                table if table is not None else _NO_TABLE,
                levels if levels is not None else _NO_TABLE, gain is not None,
                table is not None)
    return img


_NO_GAIN = np.zeros(1, np.uint32)
_NO_TABLE = np.zeros(1, np.uint8)


def _warm() -> None:
    """Compile (or load) the passes for the types frames have, on import: a
    render worker pays for it while it starts, not on its first frame."""
    img = np.zeros((2, 2, 4), np.uint8)
    words = np.zeros(2, np.uint64)
    gain_noise(img, gain_fixed(np.ones((2, 2))), np.zeros(65536, np.uint8),
               fill_levels(words, 1))


_warm()
