"""One camera frame: ground, targets, sky.

``World`` holds everything a frame depends on besides the pose and the
tick (ground texture, targets, seed); a render worker builds it once from a
picklable ``WorldSpec``. ``render_frame`` is a pure function of
(world, camera, pose, tick): the same inputs give the same pixels in any
process. It draws the frame and its target-id image and hands them, with the
targets' boxes, to ``truth``, which owns the ground-truth columns and their
values.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cosim.core.camera import (
    NEAR_M,
    SHIFT,
    CameraSpec,
    Pose,
    clip_near,
    fixed,
    frustum_planes,
    ground_homography,
    intrinsics,
    project,
)
from cosim.core.geo import LocalFrame, geodetic_to_ecef
from cosim.renderer import canopy
from cosim.renderer.buildings import BuildingSet
from cosim.renderer.ground import GroundTexture
from cosim.renderer.haze import Haze
from cosim.renderer.shadows import draw_shadows, shade_table
from cosim.renderer.sky import Sky, horizon_rgb
from cosim.renderer.smoke import draw_smoke, draw_smoke_shadows
from cosim.renderer.targets import (
    FACE_IDX,
    FACE_NORMALS,
    UNIT_CORNERS,
    TargetSet,
    bounding_part,
    box_corners,
    heading_rotation,
    hidden_faces,
    lambert,
    parts_of,
)
from cosim.renderer.truth import ground_truth
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.ground import GroundSpec
from cosim.world.obstacles import WALL_RGB
from cosim.world.sun import DEFAULT as DEFAULT_SUN
from cosim.world.sun import SunSpec
from cosim.world.targets import TargetSpec

MAX_PATCH_PX = 3000
STRIPS = 8  # bands of rows, each drawn from one ground level
OPAQUE = 255  # the frame's alpha channel: frames are BGRA (see render_frame)
#: the sun of a target in a building's shadow: none (``targets.lambert`` gives ambient light)
_NO_SUN = np.zeros(3)


@dataclass(frozen=True)
class WorldSpec:
    """Picklable: what every render process builds its ``World`` from."""

    origin_lat_deg: float
    origin_lon_deg: float
    ground_alt_m: float
    seed: int
    physics_hz: float
    ground: GroundSpec
    targets: tuple[TargetSpec, ...]
    #: the scenario's obstacles (``cosim.obstacles.Obstacle``): drawn as prisms
    obstacles: tuple[Any, ...] = ()
    #: where the sun stands: it shades every target's and obstacle's faces
    sun: SunSpec = DEFAULT_SUN
    #: the haze between the camera and what it sees (None: clear air)
    atmosphere: AtmosphereSpec | None = None


#: obstacles' colour (RGB) unless the scenario gives theirs: concrete grey
OBSTACLE_RGB = WALL_RGB


def probe_offsets(targets: Sequence[TargetSpec]) -> np.ndarray:
    """(T, 9, 3) per target, in L axes from its ground point: the 8 corners of
    its ground-truth box and a ninth probe point for culling (a fire's smoke
    top, else a corner again)."""
    out = np.zeros((len(targets), 9, 3))
    for k, t in enumerate(targets):
        lo, hi = bounding_part(t)
        out[k, :8] = box_corners(lo, hi) @ heading_rotation(t).T
        top = np.array([[0.0, 0.0, -(t.height_m + 20.0)]]) @ heading_rotation(t).T \
            if t.kind == "fire" else out[k, :1]
        out[k, 8] = top[0]
    return out


class World:
    def __init__(self, spec: WorldSpec) -> None:
        self.spec = spec
        self.frame = LocalFrame(spec.origin_lat_deg, spec.origin_lon_deg, spec.ground_alt_m)
        self.ground = GroundTexture(spec.ground, self.frame, spec.seed)
        self.targets = TargetSet(spec.targets, self.frame, spec.ground_alt_m)
        # per target, in L axes from its ground point: the 8 ground-truth box corners
        # and a ninth probe point for culling (a fire's smoke top, else a corner again)
        self.probe_offsets = probe_offsets(spec.targets)
        #: the targets that change size (growing fires): their boxes per frame
        self.growing = [k for k, t in enumerate(spec.targets) if t.growth_m_per_s]
        #: the sky's colours under the scenario's sun
        self.sky = Sky(spec.sun)
        self.ecef_to_ned = _ecef_to_ned(self.frame)
        self.origin_ecef = np.array(geodetic_to_ecef(spec.origin_lat_deg, spec.origin_lon_deg,
                                                     spec.ground_alt_m))
        self._scratch: dict[tuple[str, int, int], np.ndarray] = {}
        self._grids: dict[tuple[int, int, int], np.ndarray] = {}
        self._ids: dict[tuple[int, int], tuple[np.ndarray, list[int]]] = {}
        self._zeros: dict[tuple[int, int], np.ndarray] = {}
        self._views: dict[CameraSpec, _View] = {}
        #: unit vector toward the sun, north-east-down (a frame's local axes turn
        #: against the origin's by 0.01 deg a km: far below a shade step)
        self.sun_l = spec.sun.to_sun_ned()
        self.haze = Haze(spec.atmosphere, horizon_rgb(spec.sun)) \
            if spec.atmosphere is not None else None
        #: the procedural ground's trees are drawn in 3-D (``canopy``)
        self.trees_3d = spec.ground.trees == "3d"
        #: the ground's darkening in shade (cv2.LUT), if the targets cast shadows
        self.shade_table = shade_table(spec.sun.elevation_deg) if spec.sun.shadows else None
        #: the obstacles as buildings, and their shadows if the sun casts them
        self.buildings = BuildingSet(spec.obstacles, self.sun_l, self.shade_table is not None)

    def view(self, cam: CameraSpec) -> _View:
        """What every frame of ``cam`` shares, built once."""
        v = self._views.get(cam)
        if v is None:
            v = self._views[cam] = _View.of(self, cam)
        return v

    def ids_buffer(self, h: int, w: int) -> tuple[np.ndarray, list[int]]:
        """The target-id image for h x w, all zero, and its dirty rectangle
        ``[x0, y0, x1, y1]`` (to be grown by whoever draws into it): only that
        rectangle is cleared for the next frame, not the whole image."""
        held = self._ids.get((h, w))
        if held is None:
            held = self._ids[(h, w)] = (np.zeros((h, w), np.uint16), [0, 0, 0, 0])
        ids, dirty = held
        x0, y0, x1, y1 = dirty
        if x1 > x0 and y1 > y0:
            ids[y0:y1, x0:x1] = 0
        dirty[:] = [w, h, 0, 0]
        return ids, dirty

    def zeros(self, h: int, w: int) -> np.ndarray:
        """An h x w uint8 buffer, all zero, for whoever leaves it so (reused across frames)."""
        buf = self._zeros.get((h, w))
        if buf is None:
            buf = self._zeros[(h, w)] = np.zeros((h, w), np.uint8)
        return buf

    def last_ids(self, h: int, w: int) -> np.ndarray:
        """The target-id image of the last h x w frame drawn (valid until the next)."""
        return self._ids[(h, w)][0]

    def pixel_grid(self, y0: int, y1: int, w: int, rows: int) -> np.ndarray:
        """3 x (rows * 9) homogeneous image points: 9 columns across the width
        and ``rows`` rows over the pixel rows [y0, y1), edges included
        (constant per camera: built once)."""
        key = (y0, y1, w * 16 + rows)
        p = self._grids.get(key)
        if p is None:
            xs = np.linspace(-0.5, w - 0.5, 9)
            ys = np.linspace(y0 - 0.5, y1 - 0.5, rows)
            gx, gy = np.meshgrid(xs, ys)
            p = self._grids[key] = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
        return p

    def scratch(self, name: str, h: int, w: int, channels: int, dtype: Any = np.uint8
                ) -> np.ndarray:
        """A per-process buffer reused across frames (no allocation, no page faults)."""
        key = (name, h, w)
        buf = self._scratch.get(key)
        if buf is None:
            shape = (h, w, channels) if channels > 1 else (h, w)
            buf = self._scratch[key] = np.empty(shape, dtype=dtype)
        return buf


@dataclass(frozen=True)
class _View:
    """A camera's per-frame constants: intrinsics, the sample grid that decides
    where the ground is and at which level, the row bands, the culling planes."""

    K: np.ndarray
    K_inv: np.ndarray
    grid: np.ndarray  # 3 x 243: a 9 x 9 pixel grid, then moved a pixel right, then down
    bounds: tuple[int, ...]  # first row of each band of rows, then the height
    planes: np.ndarray  # the view frustum's planes (x, y, z coefficients; _culled)
    image_quad: np.ndarray  # the image's outline (4 x 2, float32)

    @staticmethod
    def of(world: World, cam: CameraSpec) -> _View:
        K = intrinsics(cam)
        w, h = cam.width_px, cam.height_px
        p = world.pixel_grid(0, h, w, 9)
        grid = np.concatenate([p, p + np.array([[1.0], [0.0], [0.0]]),
                               p + np.array([[0.0], [1.0], [0.0]])], axis=1)
        planes = frustum_planes(K, w, h)
        quad = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]],
                        dtype=np.float32)
        bounds = tuple(int(b) for b in np.linspace(0, h, STRIPS + 1).round().astype(int))
        for a in (K, grid, planes, quad):
            a.flags.writeable = False
        return _View(K, np.linalg.inv(K), grid, bounds, planes, quad)


def _l_to_scenario_ne(world: World, pose: Pose) -> np.ndarray:
    """3x3 affine: L ground (north, east, 1) -> scenario frame (north, east, 1).

    Both frames are tangent frames, so L -> ECEF -> scenario NED is an exact
    rigid 3-D map; the affine is its north/east part on L's plane ``down = 0``.
    Leaving out the plane's own curvature (down offsets of ``r**2 / 2R``, under
    2 m at 5 km) moves a point by that offset times the angle between the two
    verticals: micrometres over a camera footprint, ~1 cm at 5 km range from a
    vehicle 30 km from the origin."""
    r_s = world.ecef_to_ned
    r_l = _ecef_to_ned(pose.local)
    o_l = pose.local_ecef_m
    r = r_s @ r_l.T
    t = r_s @ (o_l - world.origin_ecef)
    return np.array([[r[0, 0], r[0, 1], t[0]], [r[1, 0], r[1, 1], t[1]], [0.0, 0.0, 1.0]])


def _ecef_to_ned(frame: LocalFrame) -> np.ndarray:
    lat, lon = math.radians(frame.lat_deg), math.radians(frame.lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


def _draw_ground(world: World, cam: CameraSpec, pose: Pose, view: _View,
                 img: np.ndarray, slot: Hashable
                 ) -> tuple[np.ndarray, list[tuple[int, int]], np.ndarray | None, list[int]]:
    """Draw the sky and the ground into ``img`` (every pixel is written); return
    the image -> L ground homography, the bands of rows ``[y0, y1)`` holding
    ground and the ground mask (None: all of them ground) for the haze, and the
    ground level each of the ``STRIPS`` bands of ``view.bounds`` drew (-1: none)."""
    h_img, w_img = cam.height_px, cam.width_px
    H = ground_homography(view.K_inv, pose)
    max_r = world.spec.ground.max_range_m
    # visibility: a ray reaches the ground (w > 0) within max range
    q_all = H @ view.grid
    q = q_all[:, :81]
    wq = q[2]
    horiz = np.hypot(q[0], q[1])
    near_ok = (wq > 1e-9) & (horiz <= max_r * np.maximum(wq, 1e-12) + 1e-9)
    if not near_ok.any():
        world.sky.draw(view.K_inv, pose.R_cl, img)  # all sky
        return H, [], None, [-1] * STRIPS
    A = _l_to_scenario_ne(world, pose)
    all_ground = bool(near_ok.all())
    mask = None
    if not all_ground:  # per-pixel ground mask (w and range are linear/quadratic in u, v)
        mask = _ground_mask(world, H, max_r, h_img, w_img)
        world.sky.draw(view.K_inv, pose.R_cl, img)
    # ground sample distance at the grid points (m per pixel, geometric mean)
    gsd = _gsd(q_all)
    gsd_rows = np.where(near_ok, gsd, np.inf).reshape(9, 9).min(axis=1)
    # bands of rows, each from the level its finest visible ground needs
    bounds = view.bounds
    level_for = world.ground.level_for
    levels = [level_for(g) if math.isfinite(g) else -1
              for g in np.minimum(gsd_rows[:-1], gsd_rows[1:]).tolist()]
    ground = img if mask is None else world.scratch("ground", h_img, w_img, 4)
    rows: list[tuple[int, int]] = []  # the bands of rows with ground
    s = 0
    while s < STRIPS:
        e = s
        while e + 1 < STRIPS and levels[e + 1] == levels[s]:
            e += 1
        y0, y1 = bounds[s], bounds[e + 1]
        if levels[s] >= 0:
            _draw_band(world, H, A, max_r, y0, y1, w_img, levels[s], ground[y0:y1], slot)
            rows.append((y0, y1))
        else:  # no ground in the band (sky where the mask has none)
            ground[y0:y1] = img[y0:y1]
        s = e + 1
    if mask is not None:
        cv2.copyTo(ground, mask, img)
    return H, rows, mask, levels


def _haze_ground(world: World, haze: Haze, pose: Pose, img: np.ndarray, H: np.ndarray,
                 bands: list[tuple[int, int]], mask: np.ndarray | None) -> None:
    """Haze the ground of ``img`` (``_draw_ground``'s bands and mask; the sky
    stays as it is), once it is drawn and shaded, before the targets."""
    haze.ground(img, H, pose, world.spec.ground.max_range_m, bands, mask)


def _ground_mask(world: World, H: np.ndarray, max_r: float, h_img: int, w_img: int
                 ) -> np.ndarray:
    """uint8 mask (255: the pixel's ray reaches the ground within ``max_r``):
    |(n, e)| <= max_r w, evaluated with OpenCV's single-pass float32 kernels
    into reused buffers (numpy's temporaries cost ~7 ms a 640x480 frame)."""
    uu, vv = world.scratch("mask_u", h_img, w_img, 1, np.float32), \
        world.scratch("mask_v", h_img, w_img, 1, np.float32)
    if world._grids.get((-1, h_img, w_img)) is None:  # the pixel coordinates, once
        uu[:] = np.arange(w_img, dtype=np.float32)[None, :]
        vv[:] = np.arange(h_img, dtype=np.float32)[:, None]
        world._grids[(-1, h_img, w_img)] = uu
    q = [world.scratch(f"mask_q{k}", h_img, w_img, 1, np.float32) for k in range(4)]
    for k, scale in ((0, 1.0), (1, 1.0), (2, max_r)):  # q_k = s (H[k, 0] u + H[k, 1] v + H[k, 2])
        cv2.addWeighted(uu, scale * float(H[k, 0]), vv, scale * float(H[k, 1]),
                        scale * float(H[k, 2]), dst=q[k])
    cv2.magnitude(q[0], q[1], q[3])  # horizontal distance (times w)
    mask = world.scratch("mask", h_img, w_img, 1, np.uint8)
    # distance <= max_r w (this also means w > 0: the distance of a ray is never 0)
    cv2.compare(q[3], q[2], cv2.CMP_LE, dst=mask)
    return mask


def _gsd(q: np.ndarray) -> np.ndarray:
    """Ground metres per pixel (square root of a pixel's ground area) at n image
    points from ``q`` (3 x 3n: H times the points, then the points one pixel
    right, then one pixel down; _View.grid); inf where the ray misses the ground."""
    n = q.shape[1] // 3
    with np.errstate(divide="ignore", invalid="ignore"):
        g = q[:2] / q[2]
        g0 = g[:, :n]
        gx = g[:, n:2 * n] - g0
        gy = g[:, 2 * n:] - g0
        area = np.abs(gx[0] * gy[1] - gx[1] * gy[0])
    out: np.ndarray = np.where(np.isfinite(area), np.sqrt(area), np.inf)
    return out


def _band_extent(world: World, H_up: np.ndarray, y0: int, y1: int, w_img: int,
                 max_r: float) -> np.ndarray:
    """L (north, east) points bounding the ground seen in rows [y0, y1)."""
    q = H_up @ world.pixel_grid(y0, y1, w_img, 5)  # L ground homogeneous
    w = q[2]
    horiz = np.hypot(q[0], q[1])
    far = (w <= 1e-9) | (horiz > max_r * np.maximum(w, 1e-12))
    ne = np.empty((2, q.shape[1]))
    ok = ~far
    ne[:, ok] = q[:2, ok] / w[ok]
    if far.any():  # clamp to the range limit along the ray's horizontal direction
        dirn = q[:2, far] / np.maximum(horiz[far], 1e-12)
        ne[:, far] = dirn * max_r
    return ne


def _draw_band(world: World, H: np.ndarray, A: np.ndarray, max_r: float, y0: int, y1: int,
               w_img: int, level: int, out: np.ndarray, slot: Hashable) -> None:
    """Rows [y0, y1) of the ground from ``level`` into ``out`` (BGRA) (H: image ->
    L ground, A: L ground -> scenario north/east; ``slot``: GroundTexture.patch)."""
    ground = world.ground
    HA = A @ H
    ne_l = _band_extent(world, H, y0, y1, w_img, max_r)
    ne = A[:2, :2] @ ne_l + A[:2, 2:3]
    while True:
        P = ground.ne_to_px(level)
        cols = P[0, 1] * ne[1] + P[0, 2]
        rows = P[1, 0] * ne[0] + P[1, 2]
        c0, c1 = math.floor(cols.min()) - 2, math.ceil(cols.max()) + 3
        r0, r1 = math.floor(rows.min()) - 2, math.ceil(rows.max()) + 3
        if max(c1 - c0, r1 - r0) <= MAX_PATCH_PX:
            break
        level += 1
    patch = ground.patch(level, r0, r1, c0, c1, slot)
    shift = np.array([[1.0, 0.0, -c0], [0.0, 1.0, -r0], [0.0, 0.0, 1.0]])
    band = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, float(y0)], [0.0, 0.0, 1.0]])
    M = shift @ P @ HA @ band  # band pixel -> patch pixel
    # one warp of the BGRA patch (4 channels: OpenCV's vectorised path, 2.5x
    # faster than three; the frame stays BGRA down to the video encoder)
    cv2.warpPerspective(patch, M, (w_img, y1 - y0), dst=out,
                        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                        borderMode=cv2.BORDER_REPLICATE)
    if ground.image is not None:
        lay = ground.image
        g = float(abs(np.linalg.det(M[:2, :2])) ** -0.5) * ground.mpp(level)
        k = lay.level_for(g)
        src = lay.levels[k]
        Mi = lay.ne_to_px(k) @ HA @ band
        over = cv2.warpPerspective(src, Mi, (w_img, y1 - y0),
                                   flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT,
                                   borderValue=(0, 0, 0, OPAQUE))
        inside = cv2.warpPerspective(lay.coverage(k), Mi,
                                     (w_img, y1 - y0),
                                     flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_CONSTANT)
        np.copyto(out, over, where=(inside > 0)[..., None])


def _culled(planes: np.ndarray, pts_c: np.ndarray) -> np.ndarray:
    """(T,) True where every one of a target's points (T x n x 3, camera axes)
    lies outside one of the view frustum's ``planes`` (_View.planes)."""
    side = pts_c @ planes.T  # (T, n, 5)
    side[..., 0] -= NEAR_M
    out: np.ndarray = (side < 0).all(axis=1).any(axis=1)
    return out


def _target_faces(pose: Pose, t: TargetSpec, origin_l: np.ndarray, time_s: float, seed: int,
                  tid: int, sun_l: np.ndarray
                  ) -> list[tuple[float, float, np.ndarray, tuple[int, int, int, int], int]]:
    """The front faces of a target's boxes: (painter's depth, depth, camera-axis
    polygon, BGRA, id). The faces of a part under another (an axle under the
    body, legs under the torso) are painted first, at the target's farthest
    depth: seen from above the part's top, the part never hides the other."""
    parts = parts_of(t, time_s, seed)
    lo = np.array([p.lo for p in parts])[:, None, :]
    hi = np.array([p.hi for p in parts])[:, None, :]
    rot = heading_rotation(t)
    corners_l = origin_l + (lo + UNIT_CORNERS * (hi - lo)) @ rot.T  # (P, 8, 3)
    normals = FACE_NORMALS @ rot.T  # (6, 3)
    faces_l = corners_l[:, FACE_IDX]  # (P, 6, 4, 3)
    cent = faces_l.mean(axis=2)
    front = np.einsum("pfk,fk->pf", cent - pose.c_l, normals) < 0
    under = np.zeros(len(parts), dtype=bool)
    if t.kind != "fire":  # a fire's flames change every frame and touch nothing
        hidden = hidden_faces(tuple(parts))
        front &= ~hidden
        under = hidden[:, 4]  # its top lies against another part
    faces_c = (faces_l - pose.c_l) @ pose.R_cl.T
    shade = [lambert(n, sun_l) for n in normals]
    out: list[tuple[float, float, np.ndarray, tuple[int, int, int, int], int]] = []
    from_part = []
    for pi, fi in zip(*np.nonzero(front)):
        v_c = faces_c[pi, fi]
        if v_c[:, 2].min() < NEAR_M:
            v_c = clip_near(v_c)
            if len(v_c) < 3:
                continue
        c, k = parts[pi].color_rgb, shade[fi]
        bgra = (min(255, int(c[2] * k)), min(255, int(c[1] * k)), min(255, int(c[0] * k)), OPAQUE)
        depth_m = float(np.linalg.norm(v_c.mean(axis=0)))
        out.append((depth_m, depth_m, v_c, bgra, tid))
        from_part.append(pi)
    if under.any() and out:
        far_m = max(f[0] for f in out)
        out = [(far_m, *f[1:]) if under[pi] else f for f, pi in zip(out, from_part)]
    return out


def _scenario_to_l(world: World, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and shift taking scenario NED points to the frame's L:
    ``p_l = p @ rot.T + shift``."""
    r_l = _ecef_to_ned(pose.local)
    return r_l @ world.ecef_to_ned.T, r_l @ (world.origin_ecef - pose.local_ecef_m)


def _trees_in_view(world: World, pose: Pose, view: _View, H: np.ndarray, levels: list[int],
                   w_img: int) -> canopy.Trees:
    """The trees drawn in 3-D (``canopy.in_view``) over the bands of rows whose
    ground ``levels`` (``_draw_ground``) show none."""
    max_r = world.spec.ground.max_range_m
    bounds = view.bounds
    extents = []
    s = 0
    while s < len(levels):  # each run of bands whose ground shows no trees, at once
        e = s
        while e < len(levels) and 0 <= levels[e] < canopy.FLAT_FROM_LEVEL:
            e += 1
        if e > s:
            extents.append(_band_extent(world, H, bounds[s], bounds[e], w_img, max_r))
        s = e + 1
    if not extents:
        return canopy.standing(world.spec.seed, 0.0, 0.0, 0.0, 0.0)
    return canopy.in_view(world.spec.seed, view.K, pose, _l_to_scenario_ne(world, pose),
                          bounds, levels, extents, max_r)


def render_frame(world: World, cam: CameraSpec, pose: Pose, tick: int,
                 out: np.ndarray | None = None, stream: Hashable = None
                 ) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """The frame (h x w x 4 uint8, BGRA, alpha 255 everywhere: the ground is warped
    from four-channel tiles, OpenCV's fast path, and the video encoder takes BGRA
    as it is) and one ground-truth dict per target (without frame/vehicle/camera;
    ``truth.ground_truth``).

    ``out`` (h x w x 4 uint8, C-contiguous), if given, receives the frame and is
    returned (a caller rendering many frames reuses one buffer). ``stream`` names
    the camera stream (its ground patch is kept apart from other streams'; the
    pixels do not depend on it)."""
    view = world.view(cam)
    K = view.K
    w_img, h_img = cam.width_px, cam.height_px
    if out is None:
        out = np.empty((h_img, w_img, 4), dtype=np.uint8)
    img = out
    H, ground_rows, ground_mask, levels = _draw_ground(world, cam, pose, view, img, stream)
    ids, dirty = world.ids_buffer(h_img, w_img)
    trees = _trees_in_view(world, pose, view, H, levels, w_img) \
        if world.trees_3d and ground_rows else None
    time_s = tick / world.spec.physics_hz
    seed = world.spec.seed
    targets = world.targets
    origins = targets.origins_in(pose.local, pose.local_ecef_m)
    faces: list[tuple[float, float, np.ndarray, tuple[int, int, int, int], int]] = []
    specs, offsets = targets.specs, world.probe_offsets
    rot, shift = _scenario_to_l(world, pose)  # the buildings' frame -> L
    near = world.buildings.in_view(rot, shift, pose, view.planes)  # buildings in view
    if world.growing:  # growing fires: their size at this frame
        specs = tuple(t.at(time_s) for t in specs)
        offsets = offsets.copy()
        offsets[world.growing] = probe_offsets([specs[k] for k in world.growing])
    tree_shadows = canopy.shadows_l(trees, world.sun_l) \
        if trees is not None and world.shade_table is not None else []
    if world.shade_table is not None and (len(specs) or near or tree_shadows):
        draw_shadows(K, pose, specs, origins, world.sun_l, time_s, seed, img,
                     world.shade_table, world.buildings.shadows_l(rot, shift, near)
                     + tree_shadows)
        draw_smoke_shadows(K, pose, specs, origins, world.sun_l, time_s, seed, img,
                           world.shade_table)
    haze = world.haze
    if haze is not None and ground_rows:  # the shaded ground, before the targets
        _haze_ground(world, haze, pose, img, H, ground_rows, ground_mask)
    probe_c = (origins[:, None, :] + offsets - pose.c_l) @ pose.R_cl.T  # (T, 9, 3)
    box_c = probe_c[:, :8]
    visible = ~_culled(view.planes, probe_c)
    # a target whose box centre is in a building's shadow: lit by the sky alone
    shaded = world.buildings.in_shadow((origins + offsets[:, :8].mean(axis=1) - shift) @ rot,
                                       world.sun_l, near) \
        if world.shade_table is not None and near else np.zeros(len(specs), dtype=bool)
    for k in np.flatnonzero(visible).tolist():
        faces.extend(_target_faces(pose, specs[k], origins[k], time_s, seed + k, k + 1,
                                   _NO_SUN if shaded[k] else world.sun_l))
    faces.extend(world.buildings.faces(rot, shift, pose, world.sun_l, near, K, box_c, faces))
    seen = canopy.drawn(trees, K, pose, world.sun_l, w_img, h_img, view.planes, haze) \
        if trees is not None else None
    done = 0  # the trees drawn so far (in painter's order with the faces)
    faces.sort(key=lambda f: -f[0])  # painter's order: far to near
    outlines: dict[int, list[np.ndarray]] = {}  # per target id, its faces as filled
    for paint_m, depth_m, v_c, bgra, tid in faces:
        if haze is not None:  # a flat face: hazed at its centre's distance
            bgra = haze.bgra(bgra, depth_m)
        if seen is not None:  # the trees farther than the face (in painter's order)
            done = seen.draw_to(paint_m, done, img, ids)
        pts = fixed(project(K, v_c))
        if tid:
            cv2.fillConvexPoly(img, pts, bgra, cv2.LINE_8, SHIFT)
            cv2.fillConvexPoly(ids, pts, tid, cv2.LINE_8, SHIFT)
            outlines.setdefault(tid, []).append(pts)
        else:  # an obstacle's face (a roof may be concave): hides what is behind it
            cv2.fillPoly(img, [pts], bgra, cv2.LINE_8, SHIFT)
            if outlines:  # a target drawn before it may be behind it
                cv2.fillPoly(ids, [pts], 0, cv2.LINE_8, SHIFT)
        lo_px, hi_px = pts.min(axis=0) >> SHIFT, (pts.max(axis=0) >> SHIFT) + 2
        dirty[:] = [max(0, min(dirty[0], int(lo_px[0]))), max(0, min(dirty[1], int(lo_px[1]))),
                    min(w_img, max(dirty[2], int(hi_px[0]))),
                    min(h_img, max(dirty[3], int(hi_px[1])))]
    if seen is not None:  # the trees nearer than every face
        seen.draw_to(-math.inf, done, img, ids)
    for k, t in enumerate(specs):
        if visible[k] and t.kind == "fire":
            draw_smoke(K, pose, t, origins[k], time_s, seed + k, img, world.sun_l, haze)
    rows = ground_truth(K, view.image_quad, cam, box_c, img, ids, visible, outlines,
                        world.zeros(h_img, w_img))
    return img, rows
