"""A camera's sensor and lens, applied to each rendered frame (``SensorSpec``).

``render_frame`` draws what an ideal pinhole camera sees; ``Sensor.apply``
turns it into what the camera records, in this order:

1. lens distortion: Brown radial distortion, ``x_d = x (1 + k1 r^2 + k2 r^4)``
   in normalised coordinates (``x = (u - cx) / f``, ``r^2 = x^2 + y^2``): each
   recorded pixel is read, bilinearly, from the render at the undistorted
   point (float32 maps made once per stream, the radius found by Newton's method).
   Beyond the image's corner radius, where the polynomial is no lens's (it
   may fold back), the lens goes on at its rate at the corner. A barrel lens
   (``k1 < 0``) sees beyond the pinhole's field at the frame's edges and
   corners, so its stream renders a larger frame (``Sensor.source``: the same
   focal length and centre, ``margin_px`` more on each side, at most half the
   frame's size), nothing black unless the lens sees further still.
   The ground truth's geometry in pixels is distorted the same way and given
   in the recorded frame (``distort_truth``);
2. motion blur: an exposure of ``T`` = ``exposure_ms`` ending at the frame's
   tick sees the scene move; the pose one exposure earlier is the vehicle's
   position less velocity x ``T`` and its attitude less its rates x ``T``
   (``smear_px``). One kernel blurs the whole frame: the segment from where
   the ground point at the image centre was at the shutter's opening to where
   it is now (for a nadir camera in level flight ``v T / GSD`` pixels along
   the flight, plus about ``f`` x angular rate x ``T`` from pitch and roll;
   a rotation about the optical axis, which leaves the centre in place, is not
   modelled). The blur averages 8-bit values;
3. vignetting: linear light times ``cos^(4 s)(theta)``, ``theta`` the angle off
   the optical axis of the ray a pixel sees (``s = 1``: natural cos^4 falloff
   for the camera's own field of view); after the blur, as on a sensor, whose
   pixels keep their place while the scene's image moves over them;
4. noise: in linear light ``L`` (0 black, 1 full scale), a shot noise of
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
one random byte: the bytes of a splitmix64 stream keyed by the first raw word
of numpy's PCG64 seeded by (scenario seed, vehicle row, camera name, frame
number): the same frame for any backend or number of render workers.
Vignetting and noise are one compiled pass over the frame (``sensor_pass``).
The 256 levels are the means of 256 equal-probability bins of the normal
distribution, scaled to unit variance (the largest 3.0 sigma); the table
gives exactly what adding ``sigma z`` in floating point and rounding would.
The ground truth is measured on the clean render (``contrast``,
``pixels_on_target``).

Owns the sensor's pixels only: what is drawn is ``frame``'s, where frames go
``outputs``'.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from typing import Any

import cv2
import numpy as np
from scipy.special import ndtri

from cosim.core.camera import (
    GAMMA,
    CameraSpec,
    Pose,
    SensorSpec,
    camera_pose,
    ground_homography,
    intrinsics,
    project,
    to_camera,
)

#: how far along the image centre's ray motion blur looks when it meets no
#: ground nearer (a forward camera at the horizon)
SMEAR_RANGE_M = 5000.0
#: kernels of fewer cells cv2.filter2D applies tap by tap (8-bit in and out)
_DIRECT_CELLS = 130
#: the linear signal at which ``snr_db`` is given (18 % grey)
MID_GREY = 0.18
#: the linear signal at which read noise equals shot noise
READ_SIGNAL = 0.01
#: ``iso`` -> ``snr_db``: 40 dB at ISO 100, 3 dB less (half the light) per doubling
ISO_REF, SNR_AT_ISO_REF_DB = 100.0, 40.0

#: the 12 edges of a box as pairs of its corners (``targets.UNIT_CORNERS``' order:
#: corner 4 x + 2 y + z, so an edge joins corners one bit apart)
_EDGES = np.array([(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit])


def snr_of_iso(iso: float) -> float:
    """The signal-to-noise ratio at mid-grey (dB) of a sensor set to ``iso``."""
    return SNR_AT_ISO_REF_DB - 10.0 * math.log10(iso / ISO_REF)


def noise_model(snr_db: float) -> tuple[float, float]:
    """``(a, b)`` of the noise variance ``a + b L`` in linear light ``L`` for a
    signal-to-noise ratio ``snr_db`` at mid-grey."""
    snr = 10.0 ** (snr_db / 20.0)
    b = MID_GREY ** 2 / (snr ** 2 * (MID_GREY + READ_SIGNAL))
    return b * READ_SIGNAL, b


def _normalised(cam: CameraSpec) -> tuple[np.ndarray, np.ndarray]:
    """(h, w) normalised coordinates x, y of the pixel centres."""
    f = cam.fx_px
    x = (np.arange(cam.width_px) - (cam.width_px - 1) / 2.0) / f
    y = (np.arange(cam.height_px) - (cam.height_px - 1) / 2.0) / f
    return np.broadcast_to(x[None, :], (cam.height_px, cam.width_px)), \
        np.broadcast_to(y[:, None], (cam.height_px, cam.width_px))


def corner_radius(cam: CameraSpec) -> float:
    """The image corner's distance from the centre in normalised coordinates."""
    return math.hypot(math.tan(math.radians(cam.hfov_deg) / 2),
                      math.tan(math.radians(cam.vfov_deg) / 2))


def radial(k1: float, k2: float, r: np.ndarray) -> np.ndarray:
    """Brown's radial factor ``1 + k1 r^2 + k2 r^4``."""
    r2 = r * r
    out: np.ndarray = 1.0 + k1 * r2 + k2 * r2 * r2
    return out


def folds_at(k1: float, k2: float, r_max: float) -> float | None:
    """The smallest radius up to ``r_max`` where ``r (1 + k1 r^2 + k2 r^4)`` stops
    growing (its derivative ``1 + 3 k1 r^2 + 5 k2 r^4`` reaches 0), or None."""
    r = np.linspace(0.0, r_max, 2001)
    bad = np.flatnonzero(1.0 + 3 * k1 * r ** 2 + 5 * k2 * r ** 4 <= 0.0)
    return float(r[bad[0]]) if len(bad) else None


def undistort_radius(k1: float, k2: float, r_d: np.ndarray, r_max: float,
                     extend: bool = False) -> np.ndarray:
    """The undistorted radius ``r`` in [0, r_max] with ``r (1 + k1 r^2 + k2 r^4) =
    r_d`` (Newton's method; monotonic there); where ``r_d`` lies beyond the
    image of ``r_max``: NaN, or with ``extend`` the lens going on at its rate
    at ``r_max`` (as ``distort_px``)."""
    r = r_d.copy()
    for _ in range(30):
        r2 = r * r
        g = r * (1.0 + k1 * r2 + k2 * r2 * r2) - r_d
        before = r.copy()
        r -= g / (1.0 + 3 * k1 * r2 + 5 * k2 * r2 * r2)
        np.clip(r, 0.0, r_max, out=r)
        if not np.abs(r - before).max() > 1e-14:  # settled (quadratically: a few steps)
            break
    g_max = r_max * (1.0 + k1 * r_max ** 2 + k2 * r_max ** 4)
    past: float | np.ndarray = np.nan
    if extend:
        past = r_max + (r_d - g_max) / (1.0 + 3 * k1 * r_max ** 2 + 5 * k2 * r_max ** 4)
    out: np.ndarray = np.where(r_d <= g_max + 1e-12, r, past)
    return out


def distort_px(cam: CameraSpec, k1: float, k2: float, uv: np.ndarray) -> np.ndarray:
    """(..., 2) pixel coordinates of the ideal pinhole -> where the lens puts them.
    Beyond the image's corner radius, where the polynomial is no lens's (it may
    fold back), the radius goes on growing at its rate at the corner."""
    f = cam.fx_px
    c = np.array([(cam.width_px - 1) / 2.0, (cam.height_px - 1) / 2.0])
    x = (uv - c) / f
    r = np.hypot(x[..., 0], x[..., 1])
    r_max = corner_radius(cam)
    factor = radial(k1, k2, r)
    beyond = r > r_max
    if np.any(beyond):
        slope = 1.0 + 3 * k1 * r_max ** 2 + 5 * k2 * r_max ** 4
        g = r_max * float(radial(k1, k2, np.array(r_max))) + slope * (r - r_max)
        factor = np.where(beyond, g / np.where(beyond, r, 1.0), factor)
    out: np.ndarray = c + x * (f * factor)[..., None]
    return out


def source_camera(cam: CameraSpec, margin_px: tuple[int, int]) -> CameraSpec:
    """``cam`` widened by ``margin_px`` (x, y) pixels on each side, its focal
    length and centre kept; its sensor notes the margin (``distort_truth``)."""
    mx, my = margin_px
    f = cam.fx_px
    w, h = cam.width_px + 2 * mx, cam.height_px + 2 * my
    assert cam.sensor is not None
    return dataclasses.replace(cam, width_px=w, height_px=h,
                               hfov_deg=math.degrees(2 * math.atan(w / 2.0 / f)),
                               vfov_deg=math.degrees(2 * math.atan(h / 2.0 / f)),
                               sensor=dataclasses.replace(cam.sensor, margin_px=margin_px))


def recorded_camera(cam: CameraSpec) -> CameraSpec:
    """The camera whose frames a ``source_camera`` renders for (itself if none)."""
    s = cam.sensor
    if s is None or s.margin_px == (0, 0):
        return cam
    mx, my = s.margin_px
    return source_camera(cam, (-mx, -my))


def off_axis_cos(cam: CameraSpec, k1: float = 0.0, k2: float = 0.0) -> np.ndarray:
    """(h, w) cosine of the off-axis angle of the ray each pixel centre sees
    (through a lens of distortion ``k1``, ``k2``, going on past the image's
    corner radius at its rate there)."""
    x, y = _normalised(cam)
    r = np.hypot(x, y)
    if k1 or k2:
        r = undistort_radius(k1, k2, r, corner_radius(cam), extend=True)
    out: np.ndarray = 1.0 / np.sqrt(1.0 + r * r)
    return out


def distortion_maps(cam: CameraSpec, k1: float, k2: float, fixed: bool = False,
                    margin_px: tuple[int, int] = (0, 0), extend: bool = False
                    ) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap's maps (x and y, float32; ``fixed``: OpenCV's fixed-point pair,
    which remaps a 640x480 BGRA frame about a quarter slower on one thread) from
    each recorded pixel to the pixel it sees of a render ``margin_px`` larger
    on each side; far outside the image where it sees past the image's corner
    radius (with ``extend``: the lens going on at its rate there)."""
    x, y = _normalised(cam)
    r_d = np.hypot(x, y)
    r = undistort_radius(k1, k2, r_d, corner_radius(cam), extend)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(r_d > 0, r / r_d, 1.0)
    f = cam.fx_px
    map_x = (x * scale * f + (cam.width_px - 1) / 2.0 + margin_px[0]).astype(np.float32)
    map_y = (y * scale * f + (cam.height_px - 1) / 2.0 + margin_px[1]).astype(np.float32)
    outside = ~np.isfinite(map_x) | ~np.isfinite(map_y)
    map_x[outside] = map_y[outside] = -1000.0
    if not fixed:
        return map_x, map_y
    m1, m2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
    return m1, m2


def distort_truth(rows: list[dict[str, Any]], cam: CameraSpec, box_uv: np.ndarray,
                  front: np.ndarray, image_quad: np.ndarray) -> None:
    """The ground truth's pixel geometry (``bbox``, ``center``,
    ``eccentricity_px``, ``in_view``, ``fully_in_view``) where the lens puts it:
    each box's edges (``box_uv``: T x 8 x 2, the ideal projection of its
    corners; ``front``: all corners in front of the camera) sampled at 17
    points and distorted, the bounding rectangle taken. A box crossing the
    near plane keeps its ideal geometry. ``pixels_on_target`` and ``contrast``
    stay those of the ideal render. ``cam`` may be a ``source_camera``: the
    geometry is then given in the recorded frame (the margin taken off), and a
    target the recorded frame does not show has no pixels or contrast."""
    s = cam.sensor
    assert s is not None
    mx, my = s.margin_px
    if (mx, my) != (0, 0):
        cam = recorded_camera(cam)
        box_uv = box_uv - np.array([mx, my], float)
        w, h = cam.width_px, cam.height_px
        image_quad = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5],
                               [-0.5, h - 0.5]], np.float32)
        for row in rows:
            for key, m in (("center_x_px", mx), ("center_y_px", my), ("bbox_x0_px", mx),
                           ("bbox_y0_px", my), ("bbox_x1_px", mx), ("bbox_y1_px", my)):
                if row[key] is not None:
                    row[key] -= m
    t = np.linspace(0.0, 1.0, 17)[:, None]
    a, b = _EDGES[:, 0], _EDGES[:, 1]
    cx, cy = (cam.width_px - 1) / 2.0, (cam.height_px - 1) / 2.0
    xmax, ymax = cam.width_px - 0.5, cam.height_px - 0.5
    # every centre and every box's edge points through the lens at once
    centred = [k for k, row in enumerate(rows) if row["center_x_px"] is not None]
    if centred:
        c_d = distort_px(cam, s.k1, s.k2, np.array([[rows[k]["center_x_px"],
                                                     rows[k]["center_y_px"]] for k in centred]))
        for k, (cu, cv_) in zip(centred, c_d.tolist()):
            rows[k].update(center_x_px=cu, center_y_px=cv_,
                           eccentricity_px=math.hypot(cu - cx, cv_ - cy))
    boxed = [k for k, row in enumerate(rows) if row["bbox_x0_px"] is not None and front[k]]
    edges: dict[int, np.ndarray] = {}
    if boxed:
        uv = box_uv[boxed]  # (n, 8, 2)
        pts = distort_px(cam, s.k1, s.k2, (uv[:, a][:, :, None, :] * (1 - t)
                                           + uv[:, b][:, :, None, :] * t
                                           ).reshape(len(boxed), -1, 2))
        edges = dict(zip(boxed, pts))
    for k, row in enumerate(rows):
        if row["bbox_x0_px"] is None:
            continue
        if not front[k]:  # its ideal geometry: in view if its box meets the frame
            if (mx, my) != (0, 0):
                row["in_view"] = int(row["in_view"] and row["bbox_x1_px"] >= -0.5
                                     and row["bbox_y1_px"] >= -0.5 and row["bbox_x0_px"] <= xmax
                                     and row["bbox_y0_px"] <= ymax)
                _unseen(row)
            continue
        box_pts = edges[k]
        x0, y0 = box_pts.min(axis=0).tolist()
        x1, y1 = box_pts.max(axis=0).tolist()
        row.update(bbox_x0_px=x0, bbox_y0_px=y0, bbox_x1_px=x1, bbox_y1_px=y1)
        inside = x0 >= -0.5 and y0 >= -0.5 and x1 <= xmax and y1 <= ymax
        if inside:
            row["in_view"] = 1
        elif x1 < -0.5 or y1 < -0.5 or x0 > xmax or y0 > ymax:
            row["in_view"] = 0
        else:
            hull = cv2.convexHull(box_pts.astype(np.float32))
            row["in_view"] = int(cv2.intersectConvexConvex(hull, image_quad)[0] > 0)
        row["fully_in_view"] = int(inside)
        if (mx, my) != (0, 0):
            _unseen(row)


def _unseen(row: dict[str, Any]) -> None:
    """A target out of the recorded frame has no pixels in it (its margin's
    pixels were measured on the larger render)."""
    if not row["in_view"]:
        row.update(pixels_on_target=0, contrast=None, visible_fraction=None)


def frame_rng(seed: int, vehicle_row: int, camera: str, frame_no: int) -> np.random.Generator:
    """The generator of one frame's noise: a pure function of its arguments."""
    key = [seed & 0xFFFF_FFFF_FFFF_FFFF, vehicle_row, zlib.crc32(camera.encode()), frame_no]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(key)))


def line_kernel(dx_px: float, dy_px: float, part: int = 0, parts: int = 1
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """cv2.filter2D's kernel (and anchor) averaging the image along the segment
    from each pixel to ``(dx, dy)`` away: a point now at ``p`` that was at
    ``p - (dx, dy)`` when the shutter opened is smeared back over that
    segment. Samples every quarter pixel, spread bilinearly; sums to 1. With
    ``parts``: the ``part``-th of that many pieces of the segment (its samples
    cut as evenly as they go; the pieces' kernels sum to the whole's), cropped
    to its own box (the anchor may lie outside it)."""
    r = math.ceil(max(abs(dx_px), abs(dy_px))) + 1
    k = np.zeros((2 * r + 1, 2 * r + 1), np.float32)
    n = max(2, math.ceil(4 * math.hypot(dx_px, dy_px)))
    lam = (np.arange(n)[part * n // parts:(part + 1) * n // parts] + 0.5) / n
    x, y = r + lam * dx_px, r + lam * dy_px
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    for ox, oy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                        (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + oy, x0 + ox), wgt / n)
    rows, cols = np.flatnonzero(k.any(axis=1)), np.flatnonzero(k.any(axis=0))
    y_lo, y_hi, x_lo, x_hi = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    # cropped to the segment's box: a smear along the image's rows or columns
    # costs filter2D a few columns or rows, not a square
    return np.ascontiguousarray(k[y_lo:y_hi, x_lo:x_hi]), (int(r - x_lo), int(r - y_lo))


def smear_frame(img: np.ndarray, dx_px: float, dy_px: float) -> np.ndarray:
    """``img`` (BGRA uint8, changed in place and returned) smeared by
    ``line_kernel(dx, dy)``, the image's edge pixels repeated beyond it.
    OpenCV filters a kernel of fewer than 130 cells tap by tap (its zeros
    skipped) but a larger one through a DFT, several times slower for a thin
    line: a diagonal line is therefore cut into the fewest equal pieces whose
    boxes hold fewer cells, each filtered, moved into place and summed (in
    1/64 steps, rounded once). Within a piece's reach of the image's edges the
    pieces repeat their own edge pixels, not the image's."""
    ax_px, ay_px = abs(dx_px), abs(dy_px)
    parts = 1
    while (ax_px / parts + 3) * (ay_px / parts + 3) >= _DIRECT_CELLS:
        parts += 1
    if parts == 1:
        kernel, anchor = line_kernel(dx_px, dy_px)
        cv2.filter2D(img, -1, kernel, dst=img, anchor=anchor, borderType=cv2.BORDER_REPLICATE)
        return img
    size = (img.shape[1], img.shape[0])
    acc: np.ndarray | None = None
    for i in range(parts):
        kernel, (ax, ay) = line_kernel(dx_px, dy_px, i, parts)
        piece = cv2.filter2D(img, cv2.CV_16S, kernel * 64.0, anchor=(0, 0),
                             borderType=cv2.BORDER_REPLICATE)
        move = np.array([[1, 0, -ax], [0, 1, -ay]], np.float32)  # out(p) = piece(p + move)
        piece = cv2.warpAffine(piece, move, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REPLICATE)
        acc = piece if acc is None else cv2.add(acc, piece)
    assert acc is not None
    cv2.convertScaleAbs(acc, dst=img, alpha=1 / 64)
    return img


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
        #: (h * w,) fixed-point factor of the 8-bit values (``sensor_pass.gain_fixed``):
        #: the power law makes linear light times g the 8-bit value times g^(1/GAMMA)
        self.gain: np.ndarray | None = None
        self.compiled: Any = None  # sensor_pass, imported (numba: 0.3 s) only when needed
        if spec.vignetting or spec.snr_db is not None:
            from cosim.renderer import sensor_pass

            self.compiled = sensor_pass
        if spec.vignetting:
            cos = np.nan_to_num(off_axis_cos(cam, spec.k1, spec.k2), nan=1.0)
            self.gain = self.compiled.gain_fixed(cos ** (4.0 * spec.vignetting / GAMMA))
        #: the camera to render (``cam`` widened where a barrel lens sees past it)
        self.source = cam
        self.maps: tuple[np.ndarray, np.ndarray] | None = None
        if spec.k1 or spec.k2:
            self.maps = distortion_maps(cam, spec.k1, spec.k2, extend=True)
            # at most half the frame on each side (a lens near folding at its
            # corner would ask for a render many times the frame's size)
            margin = tuple(min(n // 2, max(0, math.ceil(max(-float(v.min()),
                                                            float(v.max()) - (n - 1))) + 1))
                           for v, n in zip(self.maps, (w, h)))
            if margin != (0, 0):  # the same maps, into the larger render
                mx, my = margin
                self.source = source_camera(cam, (mx, my))
                self.maps = (self.maps[0] + np.float32(mx), self.maps[1] + np.float32(my))
        self.plain_maps: tuple[np.ndarray, np.ndarray] | None = None  # for a frame of cam's size
        self.warped = np.empty((h, w, 4), np.uint8)
        self.table = noise_table(spec.snr_db) if spec.snr_db is not None else None
        #: the noise's random words, 8 levels each (a buffer kept: a new one's pages cost)
        self.words = np.empty(-(-h * w * 3 // 8), np.uint64)

    def smear_px(self, pose6: tuple[float, ...], motion: tuple[float, ...] | None,
                 gimbal: tuple[float, float] | None, pose: Pose, ground_alt_m: float
                 ) -> tuple[float, float] | None:
        """How far (pixels, x and y) the ground point at the image centre moved
        during the exposure ending at the frame of vehicle pose ``pose6`` and
        camera ``pose``; ``motion`` the vehicle's velocity (north, east, down,
        m/s) and attitude rates (roll, pitch, yaw, deg/s). None: no exposure,
        or no motion given."""
        if not self.spec.exposure_ms or motion is None:
            return None
        t_s = self.spec.exposure_ms / 1000.0
        la, lo, alt, roll, pitch, yaw = pose6
        vn, ve, vd, roll_dps, pitch_dps, yaw_dps = motion
        before = camera_pose(self.cam, la, lo, alt, roll - roll_dps * t_s,
                             pitch - pitch_dps * t_s, yaw - yaw_dps * t_s, ground_alt_m, gimbal)
        moved = np.array([vn, ve, vd]) * t_s
        before = dataclasses.replace(before, c_l=pose.c_l - moved,
                                     height_m=pose.height_m + moved[2])
        K = intrinsics(self.cam)
        centre = np.array([K[0, 2], K[1, 2], 1.0])
        ray = pose.R_cl.T @ (np.linalg.inv(K) @ centre)  # in L
        ray /= np.linalg.norm(ray)
        hit = ground_homography(np.linalg.inv(K), pose) @ centre
        reach_m = SMEAR_RANGE_M
        if hit[2] > 1e-12:  # the ground, if it is nearer than that
            reach_m = min(reach_m, float(np.linalg.norm(np.append(hit[:2] / hit[2], 0.0)
                                                        - pose.c_l)))
        seen = to_camera(before, (pose.c_l + ray * reach_m)[None, :])
        if seen[0, 2] <= 0:
            return None
        u, v = project(K, seen)[0]
        return float(K[0, 2] - u), float(K[1, 2] - v)

    def apply(self, img: np.ndarray, frame_no: int,
              smear: tuple[float, float] | None = None) -> np.ndarray:
        """The recorded frame from the render ``img`` of ``source`` (h x w x 4
        BGRA uint8, changed in place and returned, or a buffer of the sensor's
        when distorted) of frame ``frame_no``, smeared by ``smear`` (``smear_px``;
        None: none). A render of the camera's own size is read as far as it
        goes (black beyond)."""
        if self.maps is not None:
            maps = self.maps
            if img.shape[:2] != (self.source.height_px, self.source.width_px):
                if self.plain_maps is None:
                    self.plain_maps = distortion_maps(self.cam, self.spec.k1, self.spec.k2)
                maps = self.plain_maps
            img = cv2.remap(img, *maps, cv2.INTER_LINEAR, dst=self.warped,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 255))
        if smear is not None:
            img = smear_frame(img, *smear)
        if self.compiled is None:
            return img
        levels = None
        if self.table is not None:
            key = int(frame_rng(self.seed, self.row, self.cam.name, frame_no)
                      .bit_generator.random_raw())
            levels = self.compiled.fill_levels(self.words, key)
        out: np.ndarray = self.compiled.gain_noise(np.ascontiguousarray(img), self.gain,
                                                   self.table, levels)
        return out
