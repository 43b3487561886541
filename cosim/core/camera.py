"""The camera model: a camera's spec (``CameraSpec``), pinhole intrinsics,
mounts, the pose at a frame tick, projection (and clipping to the near plane)
and the ground footprint. Kernel geometry: the renderer draws with it, the
ground vehicles' guidance and the search reason with it.

Frames (all right-handed):

- ``L``: the local NED tangent frame at the point on the ground (height
  ``ground_alt_m``) directly below the vehicle. The ground near the vehicle
  is the plane ``down = 0`` of ``L``; JSBSim's roll/pitch/yaw are relative
  to this same north, so no convergence correction is needed.
- body: x nose, y right wing, z down; ``R_nb = Rz(yaw) Ry(pitch) Rx(roll)``.
- camera (OpenCV): x image right, y image down, z along the optical axis.

A ``nadir`` camera looks along body z with the image top toward the nose
(so ``vfov`` is the along-track field of view); on a banked aircraft it
therefore looks sideways. ``forward`` looks along the nose; a gimbal at
``(pitch p, yaw y)`` is the forward camera turned by ``y`` about the body z
axis (positive to the right), then pitched by ``p`` about its own y axis
(-90 is nadir): ``R_bc = Rz(y) Ry(p) R_forward``. ``stabilised: true``
removes the body's roll and pitch (a stabilised gimbal keeps only the
heading).

Pixel coordinates put pixel centres at integers: the image spans
``[-0.5, W - 0.5] x [-0.5, H - 0.5]`` and the principal point is its centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from cosim.core.geo import LocalFrame, geodetic_to_ecef


@dataclass(frozen=True)
class SensorSpec:
    """A camera's sensor and lens (``cosim.renderer.sensor`` applies it):
    vignetting ``cos^(4 vignetting)`` of the off-axis angle (0: none), the
    signal-to-noise ratio at mid-grey ``snr_db`` (None: no noise), Brown's
    radial distortion ``k1``, ``k2`` (normalised coordinates; 0: none) and the
    exposure time ``exposure_ms`` (motion blur; 0: none). ``margin_px`` is not
    a scenario key: the pixels (x, y) a barrel lens's render reaches beyond the
    recorded frame on each side (``sensor.source_camera``)."""

    vignetting: float = 0.0
    snr_db: float | None = None
    k1: float = 0.0
    k2: float = 0.0
    exposure_ms: float = 0.0
    margin_px: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class DatalinkSpec:
    """What a camera's downlink delivers (``cosim.renderer.datalink`` encodes
    it): ``codec`` at ``bitrate_kbps`` (constant bit rate), ``rate_hz`` frames
    a second (every ``every``-th rendered frame), a key frame every ``gop``
    delivered frames, each delivered ``latency_ms`` after it was rendered."""

    codec: str
    bitrate_kbps: float
    rate_hz: float
    every: int
    gop: int
    latency_ms: float


@dataclass(frozen=True)
class CameraSpec:
    name: str
    vehicles: tuple[int, ...]  # rows of Scenario.vehicles carrying this camera
    mount: str  # nadir | forward | gimbal (only a gimbal follows gimbal commands)
    pitch_deg: float  # the mount's pitch (nadir -90, forward 0); a gimbal's at the start
    stabilised: bool  # roll and pitch of the body removed (a stabilised gimbal)
    hfov_deg: float
    vfov_deg: float
    width_px: int
    height_px: int
    rate_hz: float
    frame_every: int  # physics ticks per frame
    yaw_deg: float = 0.0  # the mount's yaw from the nose (positive: right); a gimbal's at start
    #: the sensor and lens effects applied to its frames (None: the ideal pinhole's pixels)
    sensor: SensorSpec | None = None
    #: the downlink its video is delivered through (None: the rendered frames as they are)
    datalink: DatalinkSpec | None = None

    @property
    def fx_px(self) -> float:
        return self.width_px / 2.0 / math.tan(math.radians(self.hfov_deg) / 2.0)


NEAR_M = 0.05  # points closer than this along the optical axis are clipped
#: the power law between a frame's 8-bit values and linear light (``(v / 255) **
#: GAMMA``): the ground truth's contrast, the haze, the shade and the sensor use it
GAMMA = 2.2

# camera axes (columns) in body axes for the forward mount
_R_BC_FORWARD = np.array([[0.0, 0.0, 1.0],
                          [1.0, 0.0, 0.0],
                          [0.0, 1.0, 0.0]])


def rot_x(a_rad: float) -> np.ndarray:
    c, s = math.cos(a_rad), math.sin(a_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a_rad: float) -> np.ndarray:
    c, s = math.cos(a_rad), math.sin(a_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a_rad: float) -> np.ndarray:
    c, s = math.cos(a_rad), math.sin(a_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def intrinsics(cam: CameraSpec) -> np.ndarray:
    """The 3x3 pinhole matrix K (square pixels, principal point at the image centre)."""
    f = cam.fx_px
    return np.array([[f, 0.0, (cam.width_px - 1) / 2.0],
                     [0.0, f, (cam.height_px - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def frustum_planes(K: np.ndarray, w_px: int, h_px: int) -> np.ndarray:
    """(5, 3) the view frustum's planes through the camera of intrinsics ``K``
    and a ``w_px`` x ``h_px`` image (near, left, right, top, bottom; the
    image's outer pixel edges): a point ``p`` (camera axes) is inside a plane
    ``n`` where ``n . p >= 0`` (the near plane: ``z >= 0``)."""
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    return np.array([[0.0, 0.0, 1.0], [f, 0.0, cx + 0.5], [-f, 0.0, w_px - 0.5 - cx],
                     [0.0, f, cy + 0.5], [0.0, -f, h_px - 0.5 - cy]])


def mount_rotation(cam: CameraSpec, gimbal: tuple[float, float] | None = None) -> np.ndarray:
    """R_bc: camera axes -> body axes, for the mount's angles or a gimbal's
    current ``(pitch_deg, yaw_deg)``: yaw about the body's down axis (positive
    to the right), then pitch (nadir -90)."""
    pitch, yaw = gimbal if gimbal is not None else (cam.pitch_deg, cam.yaw_deg)
    return _mount_rotation(float(pitch), float(yaw))


@lru_cache(maxsize=256)
def _mount_rotation(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    out: np.ndarray = rot_z(math.radians(yaw_deg)) @ rot_y(math.radians(pitch_deg)) \
        @ _R_BC_FORWARD
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Pose:
    """A camera at one frame: ``R_cl`` maps L vectors to camera vectors; ``c_l``
    is the camera position in L; ``local`` is L itself and ``local_ecef_m`` its
    origin in ECEF (what the ground and target placement need, computed once)."""

    R_cl: np.ndarray
    c_l: np.ndarray
    local: LocalFrame
    height_m: float  # above the ground plane
    local_ecef_m: np.ndarray


def camera_pose(cam: CameraSpec, lat_deg: float, lon_deg: float, alt_msl_m: float,
                roll_deg: float, pitch_deg: float, yaw_deg: float, ground_alt_m: float,
                gimbal: tuple[float, float] | None = None) -> Pose:
    """The camera's pose for the vehicle's; ``gimbal``: a gimbal's current
    ``(pitch_deg, yaw_deg)`` instead of the mount's."""
    local = LocalFrame(float(lat_deg), float(lon_deg), float(ground_alt_m))
    r_lc = _mount_base(cam, roll_deg, pitch_deg, yaw_deg) @ mount_rotation(cam, gimbal)
    h = float(alt_msl_m) - float(ground_alt_m)
    return Pose(R_cl=r_lc.T.copy(), c_l=np.array([0.0, 0.0, -h]), local=local, height_m=h,
                local_ecef_m=np.array(geodetic_to_ecef(local.lat_deg, local.lon_deg,
                                                       local.alt_m)))


def _mount_base(cam: CameraSpec, roll_deg: float, pitch_deg: float, yaw_deg: float
                ) -> np.ndarray:
    """R_nb as the mount sees it: the body's attitude, or only its heading for
    a stabilised mount."""
    if cam.stabilised:
        return rot_z(math.radians(yaw_deg))
    return (rot_z(math.radians(yaw_deg)) @ rot_y(math.radians(pitch_deg))
            @ rot_x(math.radians(roll_deg)))


def look_at_angles(cam: CameraSpec, lat_deg: float, lon_deg: float, alt_msl_m: float,
                   roll_deg: float, pitch_deg: float, yaw_deg: float, ground_alt_m: float,
                   at_lat_deg: float, at_lon_deg: float, at_alt_msl_m: float
                   ) -> tuple[float, float]:
    """The gimbal's ``(pitch_deg, yaw_deg)`` (as ``mount_rotation`` takes
    them, not clamped) that put the point at (``at_lat_deg``, ``at_lon_deg``,
    ``at_alt_msl_m``) on the optical axis, the image's centre, of a camera at
    the vehicle's pose: the point in the frame's L, turned into the mount's
    base axes (the body's, or the heading's if stabilised); its azimuth there
    is the yaw, its elevation the pitch. Straight below gives yaw 0."""
    local = LocalFrame(float(lat_deg), float(lon_deg), float(ground_alt_m))
    n, e, d = local.geodetic_to_ned(at_lat_deg, at_lon_deg, at_alt_msl_m)
    v_l = np.array([float(n), float(e), float(d) + float(alt_msl_m) - float(ground_alt_m)])
    x, y, z = _mount_base(cam, roll_deg, pitch_deg, yaw_deg).T @ v_l
    return (-math.degrees(math.atan2(z, math.hypot(x, y))),
            math.degrees(math.atan2(y, x)) if x or y else 0.0)


def to_camera(pose: Pose, pts_l: np.ndarray) -> np.ndarray:
    """(n, 3) points in L -> (n, 3) in camera axes."""
    d = pts_l - pose.c_l
    out: np.ndarray = d @ pose.R_cl.T
    return out


def project(K: np.ndarray, pts_c: np.ndarray) -> np.ndarray:
    """(n, 3) camera-axis points (z > 0) -> (n, 2) pixel coordinates."""
    z = pts_c[:, 2]
    u = K[0, 0] * pts_c[:, 0] / z + K[0, 2]
    v = K[1, 1] * pts_c[:, 1] / z + K[1, 2]
    return np.stack([u, v], axis=1)


#: sub-pixel bits of the polygon vertices OpenCV fills (its ``shift`` argument)
SHIFT = 4


def fixed(uv: np.ndarray) -> np.ndarray:
    """(n, 2) pixel coordinates -> OpenCV's fixed-point vertices (``SHIFT`` bits)."""
    out: np.ndarray = np.round(uv * (1 << SHIFT)).astype(np.int32)
    return out


def clip_near(poly_c: np.ndarray) -> np.ndarray:
    """Clip a polygon (n x 3, camera axes) to z >= NEAR_M (Sutherland-Hodgman)."""
    out = []
    n = len(poly_c)
    for i in range(n):
        a, b = poly_c[i], poly_c[(i + 1) % n]
        ina, inb = a[2] >= NEAR_M, b[2] >= NEAR_M
        if ina:
            out.append(a)
        if ina != inb:
            t = (NEAR_M - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out) if out else np.zeros((0, 3))


def ground_homography(K_inv: np.ndarray, pose: Pose) -> np.ndarray:
    """3x3 H: image pixel (u, v, 1) -> ground point (north, east, 1) of L, up to
    scale, from the inverse of the intrinsics ``K_inv``; the third component of
    ``H @ p`` is the ray's downward component (<= 0: the ray does not reach the
    ground)."""
    h = pose.height_m
    c = pose.c_l
    g = np.array([[h, 0.0, c[0]], [0.0, h, c[1]], [0.0, 0.0, 1.0]])
    out: np.ndarray = g @ pose.R_cl.T @ K_inv
    return out


def footprint(cam: CameraSpec, pose: Pose, max_range_m: float = 5000.0) -> np.ndarray:
    """(4, 2) north/east in ``L`` of the image's corners on the ground (top
    left, top right, bottom right, bottom left): the ground the camera sees.
    A corner whose ray misses the ground (above the horizon) or meets it
    beyond ``max_range_m`` is cut back to that horizontal range along its
    direction."""
    K_inv = np.linalg.inv(intrinsics(cam))
    H = ground_homography(K_inv, pose)
    w, h = cam.width_px, cam.height_px
    corners = np.array([[-0.5, -0.5, 1.0], [w - 0.5, -0.5, 1.0], [w - 0.5, h - 0.5, 1.0],
                        [-0.5, h - 0.5, 1.0]])
    out = np.empty((4, 2))
    for i, p in enumerate(corners):
        q = H @ p
        c = pose.c_l[:2]
        if q[2] > 1e-12:
            ne = q[:2] / q[2]
            d = ne - c
            r = float(np.hypot(*d))
            out[i] = ne if r <= max_range_m else c + d * (max_range_m / r)
        else:  # the ray's horizontal direction, from the camera's own
            ray = pose.R_cl.T @ (K_inv @ p)
            d = ray[:2]
            n = float(np.hypot(*d))
            out[i] = c + (d / n * max_range_m if n > 0 else 0.0)
    return out
