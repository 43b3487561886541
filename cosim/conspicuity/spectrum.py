"""The spectral exponent of an image's luminance: how a picture's contrast is
spread over spatial frequencies, the statistic natural scenes share (their
power falls as ``P(f) ~ f**-a`` with ``a`` about 2: Field 1987; van der Schaaf
and van Hateren 1996, 1.88 +- 0.43 over 276 scenes).

The estimator (``spectral_exponent``):

1. luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` (Rec. 709) of the
   linearised sRGB values (``luminance``);
2. its mean removed, then a 2-D Hann window (the outer product of two) against
   the leakage of the image's edges, which would otherwise add a spectrum of
   their own (a straight edge's power falls as ``f**-2`` whatever the scene);
3. the power ``|FFT|**2``, radially averaged in ``BINS`` bins equally spaced in
   log frequency between ``lo_cpi`` cycles per image (of the shorter side) and
   ``hi_nyquist`` times the Nyquist frequency (0.5 cycles per pixel); each bin
   is the mean power of the frequencies in it, at their mean radius;
4. ``log P`` against ``log f`` fitted by least squares over the bins: ``a`` is
   minus the slope.

The default band, 4 cycles per image to a quarter of Nyquist, leaves out the
lowest frequencies (a handful of samples each, and the window's own width)
and the top three quarters of the band, where a rendered frame's bilinear
interpolation and a video codec take power away and aliasing adds it back:
neither is the scene's. Log-spaced bins weigh every octave of the band alike.

Pure numpy: no files, nothing of the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.errors import ConfigError

#: bins of the radial average, equally spaced in log frequency over the band
BINS = 16
#: the default band: from this many cycles per image (the shorter side) ...
LO_CPI = 4.0
#: ... to this fraction of the Nyquist frequency (0.5 cycles per pixel)
HI_NYQUIST = 0.25
#: the natural-scene range the rendered ground is measured against
GOAL = (1.6, 2.6)
#: the largest image measured (pixels): an FFT's memory and time are bounded
MAX_PX = 4096 * 4096


@dataclass(frozen=True)
class Spectrum:
    """The radially averaged power spectrum over the band and its fit: ``freq_cpp``
    (cycles per pixel, each bin's mean radius), ``power`` (mean power per bin),
    ``exponent`` (``a`` of ``P ~ f**-a``) and ``r2`` (of the log-log fit)."""

    freq_cpp: np.ndarray
    power: np.ndarray
    exponent: float
    r2: float


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Relative luminance (float64, 0..1) of an (H, W, 3) sRGB image (uint8, or
    float in 0..1): Rec. 709 weights on the linearised values."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ConfigError(f"expected an (H, W, 3) RGB image, got shape {rgb.shape}")
    c = rgb.astype(np.float64)
    if rgb.dtype == np.uint8:
        c /= 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    out: np.ndarray = lin @ np.array([0.2126, 0.7152, 0.0722])
    return out


def spectral_exponent(lum: np.ndarray, lo_cpi: float = LO_CPI,
                      hi_nyquist: float = HI_NYQUIST) -> Spectrum:
    """The spectrum of a 2-D luminance image over the band ``lo_cpi`` cycles per
    image (of its shorter side) to ``hi_nyquist`` x Nyquist, and ``a`` fitted to
    it (module docstring)."""
    if lum.ndim != 2:
        raise ConfigError(f"expected a 2-D luminance image, got shape {lum.shape}")
    h, w = lum.shape
    if h * w > MAX_PX:
        raise ConfigError(f"image of {w}x{h} px: at most {MAX_PX} px")
    lo_cpp, hi_cpp = lo_cpi / min(h, w), 0.5 * hi_nyquist
    if not 0 < lo_cpp * 2 ** 1.5 <= hi_cpp <= 0.5:
        raise ConfigError(f"band {lo_cpi:g} cycles per image to {hi_nyquist:g} x Nyquist on "
                          f"a {w}x{h} image: the band must span at least 1.5 octaves below "
                          f"Nyquist (a larger image or a wider band)")
    y = lum.astype(np.float64) - float(lum.mean())
    y *= np.hanning(h)[:, None] * np.hanning(w)[None, :]
    p = np.abs(np.fft.rfft2(y)) ** 2
    fr = np.hypot(np.fft.fftfreq(h)[:, None], np.fft.rfftfreq(w)[None, :])
    # the rfft holds columns 1 .. w/2 - 1 once for two: weigh them twice, as the
    # full spectrum would, so the radial means are those of the full plane
    weight = np.full(fr.shape, 2.0)
    weight[:, 0] = 1.0
    if w % 2 == 0:
        weight[:, -1] = 1.0
    edges = np.geomspace(lo_cpp, hi_cpp, BINS + 1)
    k = np.digitize(fr.ravel(), edges) - 1
    inside = (k >= 0) & (k < BINS)
    k, wt = k[inside], weight.ravel()[inside]
    n = np.bincount(k, wt, BINS)
    if (n == 0).any():
        raise ConfigError(f"a {w}x{h} image has no frequency in some of the band's "
                          f"{BINS} bins: a larger image or a wider band")
    freq = np.bincount(k, wt * fr.ravel()[inside], BINS) / n
    power = np.bincount(k, wt * p.ravel()[inside], BINS) / n
    if not (power > 0).all() or lum.min() == lum.max():  # a flat image: no slope to fit
        return Spectrum(freq, power, float("nan"), float("nan"))
    lx, ly = np.log(freq), np.log(power)
    slope, icept = np.polyfit(lx, ly, 1)
    resid = ly - (slope * lx + icept)
    r2 = 1.0 - float(resid @ resid) / float(((ly - ly.mean()) ** 2).sum())
    return Spectrum(freq, power, float(-slope), r2)


def noise_image(shape: tuple[int, int], exponent: float, seed: int) -> np.ndarray:
    """Random-phase noise (float64, zero mean, unit variance) whose power spectrum
    is ``f**-exponent``: white Gaussian noise with its amplitudes scaled by
    ``f**(-exponent / 2)`` (the reference the estimator is tested against)."""
    h, w = shape
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft2(rng.standard_normal((h, w)))
    fr = np.hypot(np.fft.fftfreq(h)[:, None], np.fft.rfftfreq(w)[None, :])
    fr[0, 0] = 1.0
    spec *= fr ** (-exponent / 2)
    spec[0, 0] = 0.0
    out: np.ndarray = np.fft.irfft2(spec, s=(h, w))
    return out / out.std()
