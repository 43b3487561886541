"""The per-target ground truth of a camera frame, read from the frame as drawn.

Owns the ground-truth columns (``GT_COLUMNS``) and their values; the frame,
its target-id image and the targets' boxes in camera axes are ``frame``'s
(``render_frame`` calls ``ground_truth`` once a frame is drawn), writing the
rows ``outputs``'.

Ground truth (one row per target): ``in_view`` any part of the target's box
projects into the image; ``fully_in_view`` all of it does; ``bbox`` the
projected box's bounding rectangle (not clipped to the image); ``center``
the projected box centre; ``eccentricity_px`` its distance from the image
centre and ``eccentricity_deg`` its angle off the optical axis;
``angular_size_deg`` the largest angle between two corners of the box seen
from the camera; ``pixels_on_target`` the target's visible (unoccluded)
pixels; ``range_m`` camera to box centre; ``contrast`` the Weber luminance
contrast ``(Y_t - Y_b) / Y_b`` of the target's visible pixels against a ring
of background pixels around its bounding rectangle (the rectangle grown by
half its size, at least 4 px, minus the rectangle and any target's pixels),
with Y the relative luminance of linearised sRGB (Rec. 709 weights);
``visible_fraction`` its visible pixels over those its drawn faces cover
with nothing in front of them (within the image: what lies outside it is
not hidden, only out of view). Values that do not exist (a target behind
the camera, no visible pixels) are empty.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from cosim.core.camera import GAMMA, NEAR_M, SHIFT, CameraSpec, clip_near, project
from cosim.renderer.sensor import distort_truth
from cosim.renderer.targets import FACE_IDX

GT_COLUMNS = ("frame", "time_s", "vehicle", "camera", "target", "in_view", "fully_in_view",
              "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px", "center_x_px",
              "center_y_px", "eccentricity_px", "eccentricity_deg", "angular_size_deg",
              "pixels_on_target", "range_m", "contrast", "visible_fraction")
_LIN = ((np.arange(256) / 255.0) ** GAMMA).astype(np.float32)  # sRGB -> linear (approx.)
_LIN_BGRA = np.repeat(_LIN[None, :, None], 4, axis=2)  # cv2.LUT's table for BGRA pixels
_REC709_BGRA = np.array([[0.0722, 0.7152, 0.2126, 0.0]], np.float32)  # linear BGRA -> Y


def _mean_luminance(bgra: np.ndarray, mask: np.ndarray) -> float:
    """Mean relative luminance of the BGRA pixels where ``mask`` (uint8) is set:
    the Rec. 709 weights applied to the mean linearised channels (equal to the
    mean of the pixels' luminances)."""
    b, g, r, _ = cv2.mean(cv2.LUT(bgra, _LIN_BGRA), mask)
    return 0.0722 * b + 0.7152 * g + 0.2126 * r


def ground_truth(K: np.ndarray, image_quad: np.ndarray, cam: CameraSpec, box_c: np.ndarray,
                 img: np.ndarray, ids: np.ndarray, visible: np.ndarray,
                 outlines: Mapping[int, Sequence[np.ndarray]] | None = None,
                 mask: np.ndarray | None = None) -> list[dict[str, Any]]:
    """One row per target (without frame/vehicle/camera) from its box corners
    ``box_c`` (T x 8 x 3, camera axes), the drawn frame ``img`` (BGRA), its
    target-id image ``ids`` and which targets were drawn (``visible``): the
    geometry of all targets at once, then the pixels of those in view. ``K``
    the intrinsics, ``image_quad`` the image's outline (4 x 2, float32);
    ``outlines``: per target id, the convex polygons its faces were filled
    with into ``ids`` (fixed point, ``camera.SHIFT``), and ``mask``, a uint8
    buffer of ``ids``' shape, all zero (left so), for ``visible_fraction``."""
    w_img, h_img = cam.width_px, cam.height_px
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    centre = box_c.sum(axis=1)
    centre *= 0.125  # the mean of the 8 corners (exactly: a power of two)
    rng_m = np.sqrt((centre * centre).sum(axis=1))
    ecc_deg = np.degrees(np.arctan2(np.hypot(centre[:, 0], centre[:, 1]), centre[:, 2]))
    dirs = box_c / np.sqrt((box_c * box_c).sum(axis=2, keepdims=True))
    cos_min = np.einsum("tik,tjk->tij", dirs, dirs).min(axis=(1, 2))
    ang_deg = np.degrees(np.arccos(np.clip(cos_min, -1.0, 1.0)))
    z = box_c[:, :, 2]
    front = np.asarray((z >= NEAR_M).all(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):  # u = f x / z + cx, v = f y / z + cy
        c_xy = np.array([cx, cy])
        uv_all = box_c[:, :, :2] * f
        uv_all /= z[:, :, None]
        uv_all += c_xy
        c_uv = centre[:, :2] * f
        c_uv /= centre[:, 2:]
        c_uv += c_xy
    # the per-target work below on Python floats (a handful of targets: numpy's
    # per-call cost would dominate); the values are numpy's, converted once
    ecc_l, ang_l, rng_l = ecc_deg.tolist(), ang_deg.tolist(), rng_m.tolist()
    front_l, vis_l, cz_l = front.tolist(), visible.tolist(), centre[:, 2].tolist()
    c_uv_l, uv_l = c_uv.tolist(), uv_all.tolist()
    fcx, fcy = float(cx), float(cy)
    xmax, ymax = w_img - 0.5, h_img - 0.5
    rows = []
    for k in range(len(box_c)):
        row: dict[str, Any] = {"in_view": 0, "fully_in_view": 0, "bbox_x0_px": None,
                               "bbox_y0_px": None, "bbox_x1_px": None, "bbox_y1_px": None,
                               "center_x_px": None, "center_y_px": None,
                               "eccentricity_px": None, "eccentricity_deg": ecc_l[k],
                               "angular_size_deg": ang_l[k], "pixels_on_target": 0,
                               "range_m": rng_l[k], "contrast": None,
                               "visible_fraction": None}
        rows.append(row)
        if front_l[k]:
            uv = uv_all[k]
            us, vs = [p[0] for p in uv_l[k]], [p[1] for p in uv_l[k]]
            x0, y0, x1, y1 = min(us), min(vs), max(us), max(vs)
        else:  # the box crosses the near plane: its faces clipped to it
            pts = [project(K, fc) for v in box_c[k][FACE_IDX]
                   if len(fc := clip_near(v)) >= 3]
            if not pts:
                continue
            uv = np.concatenate(pts)
            x0, y0 = (float(a) for a in uv.min(axis=0))
            x1, y1 = (float(a) for a in uv.max(axis=0))
        row.update(bbox_x0_px=x0, bbox_y0_px=y0, bbox_x1_px=x1, bbox_y1_px=y1)
        if cz_l[k] >= NEAR_M:
            cu, cv = c_uv_l[k]
            row.update(center_x_px=cu, center_y_px=cv,
                       eccentricity_px=math.hypot(cu - fcx, cv - fcy))
        if vis_l[k] and x1 >= -0.5 and y1 >= -0.5 and x0 <= xmax and y0 <= ymax:
            inside_bbox = x0 >= -0.5 and y0 >= -0.5 and x1 <= xmax and y1 <= ymax
            if inside_bbox:
                row["in_view"] = 1
            else:  # does the projected box's hull overlap the image?
                hull = cv2.convexHull(uv.astype(np.float32))
                area, _ = cv2.intersectConvexConvex(hull, image_quad)
                row["in_view"] = int(area > 0)
            row["fully_in_view"] = int(inside_bbox and front_l[k])
        if row["in_view"]:
            _pixels(row, img, ids, k + 1, x0, y0, x1, y1)
            drawn = outlines.get(k + 1) if outlines is not None else None
            n_px = unoccluded_pixels(drawn, mask) if drawn and mask is not None else 0
            if n_px:
                row["visible_fraction"] = row["pixels_on_target"] / n_px
    if cam.sensor is not None and (cam.sensor.k1 or cam.sensor.k2):  # where the lens puts it
        distort_truth(rows, cam, uv_all, front, image_quad)
    return rows


def unoccluded_pixels(polys: Sequence[np.ndarray], mask: np.ndarray) -> int:
    """The pixels of the image that convex polygons ``polys`` (k x 2 int32,
    fixed point) cover, each counted once: the polygons filled as the frame
    fills them into ``mask`` (uint8, the image's shape, all zero), counted
    over their bounding rectangle and cleared there again."""
    h_img, w_img = mask.shape
    every = np.concatenate(polys)
    x0, y0 = (max(0, int(v) >> SHIFT) for v in every.min(axis=0))
    x1 = min(w_img, (int(every[:, 0].max()) >> SHIFT) + 2)
    y1 = min(h_img, (int(every[:, 1].max()) >> SHIFT) + 2)
    if x1 <= x0 or y1 <= y0:
        return 0
    for pts in polys:
        cv2.fillConvexPoly(mask, pts, 1, cv2.LINE_8, SHIFT)
    roi = mask[y0:y1, x0:x1]
    n_px = int(cv2.countNonZero(roi))
    roi[:] = 0
    return n_px


def _regions(ids: np.ndarray, tid: int, x0: float, y0: float, x1: float, y1: float
             ) -> tuple[tuple[slice, slice], np.ndarray, tuple[slice, slice], np.ndarray]:
    """Target ``tid``'s bounding rectangle (bbox x0..y1 clipped to the image) and
    its pixels there (uint8 mask), and the background ring's rectangle and mask
    (the rectangle grown by half its size, at least 4 px, minus the rectangle
    and any target's pixels)."""
    h_img, w_img = ids.shape
    bx0, by0 = max(0, math.floor(x0)), max(0, math.floor(y0))
    bx1, by1 = min(w_img, math.ceil(x1) + 1), min(h_img, math.ceil(y1) + 1)
    sub = (ids[by0:by1, bx0:bx1] == tid).view(np.uint8)
    m = max(4, int(0.5 * max(bx1 - bx0, by1 - by0)))
    rx0, ry0 = max(0, bx0 - m), max(0, by0 - m)
    rx1, ry1 = min(w_img, bx1 + m), min(h_img, by1 + m)
    ring = (ids[ry0:ry1, rx0:rx1] == 0).view(np.uint8)
    ring[by0 - ry0:by1 - ry0, bx0 - rx0:bx1 - rx0] = 0
    return (slice(by0, by1), slice(bx0, bx1)), sub, (slice(ry0, ry1), slice(rx0, rx1)), ring


def _pixels(row: dict[str, Any], img: np.ndarray, ids: np.ndarray, tid: int, x0: float,
            y0: float, x1: float, y1: float) -> None:
    """``pixels_on_target`` and ``contrast`` of target ``tid`` (bbox x0..y1)."""
    box, sub, around, ring = _regions(ids, tid, x0, y0, x1, y1)
    n_px = cv2.countNonZero(sub)
    row["pixels_on_target"] = n_px
    if n_px and cv2.countNonZero(ring):
        y_t = _mean_luminance(img[box], sub)
        y_b = _mean_luminance(img[around], ring)
        row["contrast"] = (y_t - y_b) / y_b if y_b > 0 else None


def delivered(rows: list[dict[str, Any]], sent: np.ndarray, got: np.ndarray, ids: np.ndarray
              ) -> list[tuple[int, float | None]]:
    """Per target (``rows``: the frame's ground truth): ``pixels_on_target`` and
    ``contrast`` measured on ``got``, the frame as the downlink delivered it
    (BGRA), with the target's pixels and ring of the frame as drawn (``ids``).
    A delivered pixel counts as the target's if its luminance is nearer the
    mean luminance of the target's pixels in ``sent`` (the frame handed to the
    encoder) than that of its ring there; the contrast is ``contrast``'s
    formula on ``got``'s pixels. Targets out of view: 0 and None."""
    out: list[tuple[int, float | None]] = []
    for k, row in enumerate(rows):
        if not row["in_view"] or not row["pixels_on_target"]:
            out.append((0, None))
            continue
        box, sub, around, ring = _regions(ids, k + 1, row["bbox_x0_px"], row["bbox_y0_px"],
                                          row["bbox_x1_px"], row["bbox_y1_px"])
        if not cv2.countNonZero(ring):
            out.append((0, None))
            continue
        y_t, y_b = _mean_luminance(sent[box], sub), _mean_luminance(sent[around], ring)
        g_t, g_b = _mean_luminance(got[box], sub), _mean_luminance(got[around], ring)
        lum = cv2.transform(cv2.LUT(got[box], _LIN_BGRA), _REC709_BGRA)
        nearer = np.abs(lum - y_t) < np.abs(lum - y_b)
        out.append((int(np.count_nonzero(nearer & sub.view(bool))),
                    (g_t - g_b) / g_b if g_b > 0 else None))
    return out
