"""A camera's sensor and lens, applied to each rendered frame (``SensorSpec``).

``render_frame`` draws what an ideal pinhole camera sees; ``Sensor.apply``
turns it into what the camera records, in this order:

1. vignetting: linear light times ``cos^(4 s)(theta)``, ``theta`` the pixel's
   off-axis angle (``s = 1``: natural cos^4 falloff for the camera's own field
   of view);
2. noise: in linear light ``L`` (0 black, 1 full scale), a shot noise of
   variance ``b L`` and a read noise of variance ``a = b L_r`` (``L_r`` =
   ``READ_SIGNAL``: read noise equals shot noise at 1 % of full scale), ``b``
   set by the signal-to-noise ratio ``snr_db`` at mid-grey ``L_m`` =
   ``MID_GREY``: ``SNR^2 = L_m^2 / (b (L_m + L_r))``; independent in each
   pixel and channel, clipped to black and full scale.

Linear light is the frame's 8-bit values through the 2.2 power law the
ground truth's contrast uses (``truth.py``); each step writes 8-bit values
(rounded). Under a power law, linear light times ``g`` is the 8-bit value
times ``g^(1/2.2)``: vignetting is one multiplication. Noise is one table
look-up per value (``noise_table``: for each 8-bit value and each of 256
equiprobable normal levels, ``normal_levels``, the value recorded), the level
drawn from numpy's PCG64 seeded by (scenario seed, vehicle row, camera name,
frame number): the same frame for any backend or number of render workers.
The 256 levels are the means of 256 equal-probability bins of the normal
distribution, scaled to unit variance (the largest 3.0 sigma); the table
gives exactly what adding ``sigma z`` in floating point and rounding would.
The ground truth is measured on the clean render (``contrast``,
``pixels_on_target``).

Owns the sensor's pixels only: what is drawn is ``frame``'s, where frames go
``outputs``'.
"""

from __future__ import annotations

import math
import sys
import zlib

import cv2
import numpy as np
from scipy.special import ndtri

from cosim.core.camera import CameraSpec, SensorSpec

#: the power law between a frame's 8-bit values and linear light
GAMMA = 2.2
#: the linear signal at which ``snr_db`` is given (18 % grey)
MID_GREY = 0.18
#: the linear signal at which read noise equals shot noise
READ_SIGNAL = 0.01
#: ``iso`` -> ``snr_db``: 40 dB at ISO 100, 3 dB less (half the light) per doubling
ISO_REF, SNR_AT_ISO_REF_DB = 100.0, 40.0

#: the byte of a uint16 that holds its high 8 bits
_HIGH = 1 if sys.byteorder == "little" else 0


def snr_of_iso(iso: float) -> float:
    """The signal-to-noise ratio at mid-grey (dB) of a sensor set to ``iso``."""
    return SNR_AT_ISO_REF_DB - 10.0 * math.log10(iso / ISO_REF)


def noise_model(snr_db: float) -> tuple[float, float]:
    """``(a, b)`` of the noise variance ``a + b L`` in linear light ``L`` for a
    signal-to-noise ratio ``snr_db`` at mid-grey."""
    snr = 10.0 ** (snr_db / 20.0)
    b = MID_GREY ** 2 / (snr ** 2 * (MID_GREY + READ_SIGNAL))
    return b * READ_SIGNAL, b


def off_axis_cos(cam: CameraSpec) -> np.ndarray:
    """(h, w) cosine of each pixel centre's angle off the optical axis."""
    f = cam.fx_px
    x = (np.arange(cam.width_px) - (cam.width_px - 1) / 2.0) / f
    y = (np.arange(cam.height_px) - (cam.height_px - 1) / 2.0) / f
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    out: np.ndarray = 1.0 / np.sqrt(1.0 + r2)
    return out


def frame_rng(seed: int, vehicle_row: int, camera: str, frame_no: int) -> np.random.Generator:
    """The generator of one frame's noise: a pure function of its arguments."""
    key = [seed & 0xFFFF_FFFF_FFFF_FFFF, vehicle_row, zlib.crc32(camera.encode()), frame_no]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(key)))


def normal_levels(n: int = 256) -> np.ndarray:
    """``n`` equiprobable values standing for a standard normal: the mean of each
    of ``n`` equal-probability bins, scaled to a variance of exactly 1."""
    edges = ndtri(np.linspace(0.0, 1.0, n + 1))
    pdf = np.exp(-0.5 * edges ** 2) / math.sqrt(2 * math.pi)  # 0 at the infinite ends
    z = (pdf[:-1] - pdf[1:]) * n
    out: np.ndarray = z / math.sqrt(float(np.mean(z ** 2)))
    return out


def noise_table(snr_db: float) -> np.ndarray:
    """(65536,) uint8: at ``v * 256 + k`` the 8-bit value recorded for a
    rendered value ``v`` and the ``k``-th of ``normal_levels()``: linear light
    plus ``sigma(L) z_k``, clipped to black and full scale, back to 8 bits."""
    a, b = noise_model(snr_db)
    lin = (np.arange(256) / 255.0) ** GAMMA
    sigma = np.sqrt(a + b * lin)
    noisy = np.clip(lin[:, None] + sigma[:, None] * normal_levels()[None, :], 0.0, 1.0)
    out: np.ndarray = np.rint(255.0 * noisy ** (1.0 / GAMMA)).astype(np.uint8).reshape(-1)
    return out


class Sensor:
    """One stream's sensor: what ``spec`` asks, precomputed for its camera."""

    def __init__(self, cam: CameraSpec, spec: SensorSpec, seed: int, vehicle_row: int) -> None:
        self.cam, self.spec = cam, spec
        self.seed, self.row = seed, vehicle_row
        h, w = cam.height_px, cam.width_px
        #: (h, w, 4) float32 factor of the 8-bit values (alpha 1): the power law
        #: makes linear light times g the 8-bit value times g^(1/GAMMA)
        self.gain: np.ndarray | None = None
        if spec.vignetting:
            v = (off_axis_cos(cam) ** (4.0 * spec.vignetting / GAMMA)).astype(np.float32)
            self.gain = np.dstack([v, v, v, np.ones_like(v)])
        self.table = noise_table(spec.snr_db) if spec.snr_db is not None else None
        self.bgr = np.empty((h, w, 3), np.uint8)

    def apply(self, img: np.ndarray, frame_no: int) -> np.ndarray:
        """The recorded frame from the render ``img`` (h x w x 4 BGRA uint8,
        changed in place and returned) of frame ``frame_no``."""
        if self.gain is not None:
            cv2.multiply(img, self.gain, dst=img, dtype=cv2.CV_8U)
        if self.table is not None:
            bgr = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR, dst=self.bgr)
            rng = frame_rng(self.seed, self.row, self.cam.name, frame_no)
            idx = rng.integers(0, 65536, bgr.size, dtype=np.uint16)  # low byte: k
            idx.view(np.uint8)[_HIGH::2] = bgr.reshape(-1)  # high byte: the value
            np.take(self.table, idx, out=bgr.reshape(-1))
            cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA, dst=img)
        return img
