"""What the search cameras see, from geometry alone (no pixels rendered).

Every camera of the fleet, at every one of its frames, gets:

- its **footprint**: the image's four corners cast onto the flat ground
  (``footprints``, all aircraft at once), for the coverage map;
- for each fire near enough to be in it, the fire's **ground truth** as the
  renderer's ground-truth record has it (``fire_truth``): the same camera
  pose (``cosim.renderer.camera.camera_pose``), the same placement of the
  target's ground point (``TargetSet.origins_in``) and the same box
  (``cosim.renderer.frame.probe_offsets``), so ``in_view``,
  ``fully_in_view`` and the bounding box equal the rendered frame's;
  ``pixels_on_target`` is the area (px) of the projected box clipped to the
  image, what a rendered frame's count is up to the gaps between flames;
- a **report** of a detected fire (``report``): its position found the way
  an aircraft finds it, from the camera geometry: the ray through the
  centroid of the fire's image cast onto the ground from the aircraft's own
  estimate of its pose (with the navigation and pointing errors the
  scenario gives), and its size from its pixel extent at that range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from cosim.core.camera import NEAR_M, CameraSpec, Pose, camera_pose, intrinsics, mount_rotation

#: a footprint corner whose ray misses the ground, or meets it farther than
#: this, is cut back to this horizontal range (as the renderer draws haze)
MAX_RANGE_M = 5000.0


def _r_lb(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray, stabilised: bool
          ) -> np.ndarray:
    """(n, 3, 3) body -> local level axes (NED), all aircraft at once, the
    renderer's ``camera_pose`` rotation."""
    n = len(yaw)
    cy, sy = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
    rz = np.zeros((n, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = cy, -sy, sy, cy, 1.0
    if stabilised:
        return rz
    cp, sp = np.cos(np.radians(pitch)), np.sin(np.radians(pitch))
    cr, sr = np.cos(np.radians(roll)), np.sin(np.radians(roll))
    ry = np.zeros((n, 3, 3))
    ry[:, 0, 0], ry[:, 0, 2], ry[:, 1, 1], ry[:, 2, 0], ry[:, 2, 2] = cp, sp, 1.0, -sp, cp
    rx = np.zeros((n, 3, 3))
    rx[:, 0, 0], rx[:, 1, 1], rx[:, 1, 2], rx[:, 2, 1], rx[:, 2, 2] = 1.0, cr, -sr, sr, cr
    out: np.ndarray = rz @ ry @ rx
    return out


def footprints(cam: CameraSpec, height_m: np.ndarray, roll: np.ndarray, pitch: np.ndarray,
               yaw: np.ndarray) -> np.ndarray:
    """(n, 4, 2) north/east offsets from each aircraft's ground point of its
    image's corners on the ground (top left, top right, bottom right, bottom
    left), as ``cosim.renderer.camera.footprint`` gives them one at a time."""
    k_inv = np.linalg.inv(intrinsics(cam))
    w, h = cam.width_px, cam.height_px
    px = np.array([[-0.5, -0.5, 1.0], [w - 0.5, -0.5, 1.0], [w - 0.5, h - 0.5, 1.0],
                   [-0.5, h - 0.5, 1.0]])
    rays_c = px @ k_inv.T  # (4, 3)
    r_lc = _r_lb(roll, pitch, yaw, cam.stabilised) @ mount_rotation(cam)  # (n, 3, 3)
    rays = np.einsum("nij,kj->nki", r_lc, rays_c)  # (n, 4, 3) in L
    down = rays[:, :, 2]
    hz = np.hypot(rays[:, :, 0], rays[:, :, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(down > 1e-12, height_m[:, None] / down, np.inf)
        rng = np.where(np.isfinite(t), t * hz, np.inf)
        scale = np.where(rng <= MAX_RANGE_M, t, MAX_RANGE_M / np.maximum(hz, 1e-12))
    out: np.ndarray = rays[:, :, :2] * scale[:, :, None]
    return out


@dataclass
class Sighting:
    """One fire in one camera frame (the renderer's ground-truth fields)."""

    in_view: bool
    fully_in_view: bool
    bbox: tuple[float, float, float, float] | None  # x0, y0, x1, y1 (px)
    pixels: float  # area of the projected box inside the image (px)
    centroid_px: tuple[float, float] | None  # of that area
    range_m: float


def fire_truth(cam: CameraSpec, pose: Pose, corners_l: np.ndarray) -> Sighting:
    """A fire's box (8 corners in the pose's L frame) seen by ``cam`` at ``pose``."""
    k = intrinsics(cam)
    box_c = (corners_l - pose.c_l) @ pose.R_cl.T
    centre = box_c.mean(axis=0)
    rng = float(np.linalg.norm(centre))
    z = box_c[:, 2]
    if (z < NEAR_M).any():  # behind or crossing the camera plane: not a search view
        return Sighting(False, False, None, 0.0, None, rng)
    uv = box_c[:, :2] * k[0, 0] / z[:, None] + k[:2, 2]
    x0, y0 = (float(a) for a in uv.min(axis=0))
    x1, y1 = (float(a) for a in uv.max(axis=0))
    xmax, ymax = cam.width_px - 0.5, cam.height_px - 0.5
    if x1 < -0.5 or y1 < -0.5 or x0 > xmax or y0 > ymax:
        return Sighting(False, False, (x0, y0, x1, y1), 0.0, None, rng)
    inside = x0 >= -0.5 and y0 >= -0.5 and x1 <= xmax and y1 <= ymax
    hull = cv2.convexHull(uv.astype(np.float32))
    if inside:
        part = hull.reshape(-1, 2)
        area = float(cv2.contourArea(hull))
    else:
        quad = np.array([[-0.5, -0.5], [xmax, -0.5], [xmax, ymax], [-0.5, ymax]], np.float32)
        area, part = cv2.intersectConvexConvex(hull, quad)
        area = float(area)
        part = part.reshape(-1, 2) if part is not None else np.zeros((0, 2))
    if area <= 0.0:
        return Sighting(False, False, (x0, y0, x1, y1), 0.0, None, rng)
    m = cv2.moments(part.astype(np.float32))
    cen = (m["m10"] / m["m00"], m["m01"] / m["m00"]) if m["m00"] > 0 else \
        (float(part[:, 0].mean()), float(part[:, 1].mean()))
    return Sighting(True, inside, (x0, y0, x1, y1), area, cen, rng)


def pose_of(cam: CameraSpec, row: np.ndarray, idx: dict[str, int], ground_alt_m: float
            ) -> Pose:
    """The camera's pose for a state row (the renderer's)."""
    return camera_pose(cam, row[idx["lat_deg"]], row[idx["lon_deg"]], row[idx["alt_msl_m"]],
                       row[idx["roll_deg"]], row[idx["pitch_deg"]], row[idx["yaw_deg"]],
                       ground_alt_m)


def report(cam: CameraSpec, row: np.ndarray, idx: dict[str, int], ground_alt_m: float,
           centroid_px: tuple[float, float], pixels: float, rng: np.random.Generator,
           position_sigma_m: float, attitude_sigma_deg: float
           ) -> tuple[float, float, float]:
    """Where the aircraft at state ``row`` says the fire it sees at
    ``centroid_px`` is (lat_deg, lon_deg), and its size (m): the pixel's ray
    from the aircraft's estimated pose (its true one with the navigation and
    pointing errors drawn from ``rng``) cast onto the ground, and the side of
    a square of ``pixels`` at that range."""
    lat, lon = float(row[idx["lat_deg"]]), float(row[idx["lon_deg"]])
    alt = float(row[idx["alt_msl_m"]])
    roll, pitch, yaw = (float(row[idx[k]]) for k in ("roll_deg", "pitch_deg", "yaw_deg"))
    dn = de = dh = 0.0
    if position_sigma_m > 0:
        dn, de, dh = (float(x) for x in rng.normal(0.0, position_sigma_m, 3))
    if attitude_sigma_deg > 0:
        roll, pitch, yaw = (a + float(e) for a, e in
                            zip((roll, pitch, yaw), rng.normal(0.0, attitude_sigma_deg, 3)))
    pose = camera_pose(cam, lat, lon, alt + dh, roll, pitch, yaw, ground_alt_m)  # as it thinks
    k = intrinsics(cam)
    ray = pose.R_cl.T @ (np.linalg.inv(k) @ np.array([centroid_px[0], centroid_px[1], 1.0]))
    h = pose.height_m
    if ray[2] <= 1e-9 or h <= 0:  # (a frame that saw the fire looks down at it)
        return lat, lon, 0.0
    t = h / ray[2]
    n, e = dn + t * ray[0], de + t * ray[1]
    la, lo = pose.local.place(n, e, ground_alt_m)
    rng_m = t * float(np.linalg.norm(ray))
    size = math.sqrt(max(pixels, 0.0)) * rng_m / k[0, 0]
    return float(la), float(lo), size


def candidates(ne_air: np.ndarray, reach_m: np.ndarray, ne_fire: np.ndarray,
               fire_size_m: np.ndarray) -> np.ndarray:
    """(k, 2) (aircraft, fire) index pairs close enough that the fire may be in
    view: within each camera's reach on the ground (its footprint's farthest
    corner) plus the fire's size and a margin for its flames (a cheap cut
    before the exact ``fire_truth``)."""
    if not len(ne_fire) or not len(ne_air):
        return np.zeros((0, 2), dtype=np.int64)
    d = np.hypot(ne_air[:, None, 0] - ne_fire[None, :, 0],
                 ne_air[:, None, 1] - ne_fire[None, :, 1])
    near = d <= reach_m[:, None] + fire_size_m[None, :] + 50.0
    out: np.ndarray = np.argwhere(near)
    return out
