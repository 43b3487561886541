"""A simple image-based fire detector for rendered camera frames.

What it detects: **flame-coloured pixels** -- orange to yellow hue (10-54
deg), strongly saturated (>= 0.55) and bright (value >= 0.39), in HSV as
OpenCV computes it -- grouped into blobs (fragments closer than
``merge_dist_px``, or than ``merge_rel`` times their size, are one blob),
each blob at least ``min_area_px`` (6) flame pixels. The renderer's fires
(``cosim.renderer.targets``) are a dark charred patch with six flickering
boxes of orange (255, 120, 0) and yellow (255, 200, 40) flame under grey smoke
puffs; they reach the image as hue 28 and 45 deg, saturation 1.0 and 0.85,
value 0.45-1.0 (shaded sides to sunlit tops). Grey smoke around a blob
raises its score.

What it cannot tell apart: anything fire-coloured is a fire. A decoy fire is
detected exactly like a real one (that is how decoys' false alarms are
counted: match the blobs against the decoys' ground truth with
``match_blobs``); an orange target (a ``person`` in the default orange,
large enough in the image, or a vehicle given an orange ``color``) is
detected too, and so would be orange features of a user's ground image.
What it rejects: the procedural ground (its most orange colours, ploughed
soil, wheat and dry grass, reach saturation 0.47 at most in the 464 frames
checked: 20 seeds, 4 places, 30-600 m up), the red fire truck (hue 0 deg, outside the band) and its
lime-yellow roof band (68 deg), white trucks, blue cars, roads and smoke
(grey).

What it misses: flames it cannot see. A fire's smoke drifts with a per-seed
wind; where that wind is under about 1 m/s the puffs stack over the fire and,
seen from straight above, hide its flames in nearly every frame (2 seeds of
12 tried; an oblique camera, 30-60 deg below the horizon, sees those flames
under the smoke). And fires too small: at least 6 flame pixels are needed.
A default 8 m fire under a nadir 640 px, 60 deg camera, fires with wind
>= 1.6 m/s, share of frames detected:

    height above ground  200 m  300 m  400 m  500 m  600 m  800 m  1000 m  1200 m  2000 m
    fire across (px)        22     15     11      9      7    5.5     4.4     3.7     2.2
    frames detected       100%    99%    96%    89%    81%    74%     58%     25%      0%

Over all 12 seeds tried at 300 m (calm ones included) 73% of frames.

Speed: 0.4 ms (no fire) to 0.6 ms (two fires) a 640x480 BGRA frame and
1.1-1.6 ms a 1280x720 one (OpenCV with 2 threads; with 1 thread 0.55-0.85 ms
and 2.2-2.4 ms). The HSV conversion and the threshold over the whole frame are
the cost; grouping and scoring work on the flame pixels only. Deterministic:
the same pixels give the same blobs in the same order.

This module owns the detector and its matching against ground truth; it
does not render, fly or plan anything.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import cv2
import numpy as np

__all__ = ["BlobMatch", "FireBlob", "FireDetectorParams", "detect_fires", "flame_mask",
           "match_blobs", "to_hsv"]


@dataclass(frozen=True)
class FireDetectorParams:
    """The detector's thresholds. Hue, saturation and value are OpenCV's 8-bit
    HSV: hue 0..179 in units of 2 deg, saturation and value 0..255.

    Why the defaults: the flames are hue 14 (orange) and 22 (yellow) at
    saturation 255 and 215, value 115-255 (shaded sides to sunlit tops); the
    band ``hue_min..hue_max`` = 5..27 (10-54 deg) keeps them with margin and
    leaves out the fire truck's red (hue 0/179) and its roof band (hue 34).
    The ground's orange-hued colours (ploughed soil, wheat, dry grass) stay
    at saturation <= 120, hence ``min_saturation`` 140; a flame under a fresh
    smoke puff (alpha 0.55) keeps about 142 and still counts, one under
    several puffs does not. ``min_value`` 100 keeps a flame's shaded sides
    (value 115) and drops dark soil."""

    #: hue band of flame (inclusive), OpenCV units (deg / 2)
    hue_min: int = 5
    hue_max: int = 27
    #: minimum saturation and value of a flame pixel (0..255)
    min_saturation: int = 140
    min_value: int = 100
    #: a blob needs at least this many flame pixels
    min_area_px: int = 6
    #: flame fragments are one blob when the gap between them (in pixels,
    #: the larger of the horizontal and vertical gaps between their boxes) is
    #: at most ``merge_dist_px``, or at most ``merge_rel`` times the larger
    #: fragment's size (the larger side of its box): one fire's six flames,
    #: or a flame cut in two by smoke, at any altitude. Two fires closer than
    #: that in the image merge into one blob (two default 8 m fires need about
    #: 20 m of ground between their patches to stay apart).
    merge_dist_px: int = 16
    merge_rel: float = 2.5
    #: smoke: grey pixels (saturation <= smoke_max_saturation, value in
    #: smoke_min_value..smoke_max_value) in a window around the blob (its
    #: bounding box grown by smoke_margin_px on each side)
    smoke_max_saturation: int = 60
    smoke_min_value: int = 90
    smoke_max_value: int = 235
    smoke_margin_px: int = 12
    #: smoke covering this fraction of the window (flame pixels excluded)
    #: counts fully towards the score
    smoke_full_fraction: float = 0.25

    def __post_init__(self) -> None:
        problems = []
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type in ("float", float):
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                    problems.append(f"{f.name}: expected a number, got {v!r}")
                elif f.name == "smoke_full_fraction" and not 0.0 < v <= 1.0:
                    problems.append(f"{f.name}: expected a fraction in (0, 1], got {v}")
                elif v < 0:
                    problems.append(f"{f.name}: expected at least 0, got {v}")
                continue
            if isinstance(v, bool) or not isinstance(v, int):
                problems.append(f"{f.name}: expected an integer, got {v!r}")
                continue
            top = 179 if f.name.startswith("hue") else (1 << 20 if f.name.endswith("px")
                                                        else 255)
            if not 0 <= v <= top:
                problems.append(f"{f.name}: expected 0..{top}, got {v}")
        if not problems:
            if self.hue_min > self.hue_max:
                problems.append(f"hue_min ({self.hue_min}) > hue_max ({self.hue_max})")
            if self.min_area_px < 1:
                problems.append(f"min_area_px: expected at least 1, got {self.min_area_px}")
            if self.smoke_min_value > self.smoke_max_value:
                problems.append(f"smoke_min_value ({self.smoke_min_value}) > "
                                f"smoke_max_value ({self.smoke_max_value})")
        if problems:
            raise ValueError("FireDetectorParams: " + "; ".join(problems))


@dataclass(frozen=True)
class FireBlob:
    """One detected fire. Pixel coordinates: pixel (col, row) has its centre
    at ``(x, y) = (col, row)`` (the renderer's convention: its ground-truth
    boxes use the same axes)."""

    #: centroid of the blob's flame pixels
    centroid_x_px: float
    centroid_y_px: float
    #: number of flame pixels
    area_px: int
    #: bounding box of the flame pixels, inclusive pixel indices
    bbox_x0_px: int
    bbox_y0_px: int
    bbox_x1_px: int
    bbox_y1_px: int
    #: fraction of grey (smoke-like) pixels in the window around the blob
    smoke_fraction: float
    #: 0..1: 0.6 x size term (area / (3 min_area_px), capped at 1) + 0.4 x
    #: smoke term (smoke_fraction / smoke_full_fraction, capped at 1)
    score: float

    @property
    def bbox_px(self) -> tuple[int, int, int, int]:
        return (self.bbox_x0_px, self.bbox_y0_px, self.bbox_x1_px, self.bbox_y1_px)


_DEFAULT = FireDetectorParams()


def flame_mask(hsv: np.ndarray, params: FireDetectorParams = _DEFAULT) -> np.ndarray:
    """uint8 mask (255: a flame-coloured pixel) of an HSV image (OpenCV 8-bit)."""
    p = params
    out: np.ndarray = cv2.inRange(hsv, (p.hue_min, p.min_saturation, p.min_value),
                                  (p.hue_max, 255, 255))
    return out


def to_hsv(bgr_or_bgra: np.ndarray) -> np.ndarray:
    """OpenCV 8-bit HSV of a BGR or BGRA uint8 image (h x w x 3 or 4)."""
    img = bgr_or_bgra
    if not (isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.ndim == 3
            and img.shape[2] in (3, 4) and img.shape[0] > 0 and img.shape[1] > 0):
        desc = (f"shape {img.shape}, dtype {img.dtype}" if isinstance(img, np.ndarray)
                else type(img).__name__)
        raise ValueError(f"detect_fires: expected a BGR or BGRA uint8 image (h x w x 3 or 4), "
                         f"got {desc}")
    # BGRA -> BGR first: OpenCV's BGR->HSV on a strided 3-channel view of a
    # BGRA frame copies it element by element (10x slower than the two calls)
    bgr = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR) if img.shape[2] == 4 else img
    out: np.ndarray = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    return out


def detect_fires(bgr_or_bgra: np.ndarray, params: FireDetectorParams = _DEFAULT
                 ) -> list[FireBlob]:
    """The fires in a frame (h x w x 3 BGR or h x w x 4 BGRA, uint8, as
    ``render_frame`` gives them), highest score first (ties: top to bottom,
    then left to right).

    Flame pixels (``flame_mask``) are grouped by dilating their mask by half
    of ``merge_dist_px`` and labelling the result
    (``cv2.connectedComponentsWithStats``, 8-connected), then groups within
    ``merge_rel`` times their size of each other are merged (repeatedly);
    each blob's area, centroid and box are those of its flame pixels only.
    Blobs under ``min_area_px`` are dropped. Raises ``ValueError`` for
    anything but a 3- or 4-channel uint8 image."""
    p = params
    hsv = to_hsv(bgr_or_bgra)
    flame = flame_mask(hsv, p)
    if cv2.countNonZero(flame) < p.min_area_px:
        return []
    h_img, w_img = flame.shape
    # work on the flame pixels' bounding rectangle, grown by the dilation
    r = (p.merge_dist_px + 1) // 2
    fx, fy, fw, fh = cv2.boundingRect(flame)
    x0, y0 = max(0, fx - r), max(0, fy - r)
    x1, y1 = min(w_img, fx + fw + r), min(h_img, fy + fh + r)
    roi = flame[y0:y1, x0:x1]
    grouped = roi
    if r > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1, 2 * r + 1))
        grouped = cv2.dilate(roi, kernel)
    n, labels, _, _ = cv2.connectedComponentsWithStats(grouped, connectivity=8,
                                                       ltype=cv2.CV_32S)
    pts = cv2.findNonZero(roi).reshape(-1, 2)  # (k, 2) x, y of every flame pixel
    px, py = pts[:, 0], pts[:, 1]
    # group g = label - 1 (label 0, the background, holds no flame pixel; every
    # group holds at least one: it is the dilation of its flame pixels)
    lab = labels[py, px] - 1
    area = np.bincount(lab, minlength=n - 1)
    sum_x = np.bincount(lab, weights=px, minlength=n - 1)
    sum_y = np.bincount(lab, weights=py, minlength=n - 1)
    order = np.argsort(lab, kind="stable")  # one run of pixels per group
    starts = np.concatenate(([0], np.cumsum(area)[:-1]))
    sx, sy = px[order], py[order]
    boxes = np.stack([np.minimum.reduceat(sx, starts), np.minimum.reduceat(sy, starts),
                      np.maximum.reduceat(sx, starts), np.maximum.reduceat(sy, starts)], axis=1)
    if len(boxes) > 1 and p.merge_rel > 0:
        area, sum_x, sum_y, boxes = _merge_near(area, sum_x, sum_y, boxes, p)
    blobs = []
    for k in np.flatnonzero(area >= p.min_area_px).tolist():
        a = int(area[k])
        bb = (int(boxes[k, 0]) + x0, int(boxes[k, 1]) + y0, int(boxes[k, 2]) + x0,
              int(boxes[k, 3]) + y0)
        smoke = _smoke_fraction(hsv, flame, bb, p)
        size_term = min(1.0, a / (3.0 * p.min_area_px))
        smoke_term = min(1.0, smoke / p.smoke_full_fraction)
        blobs.append(FireBlob(float(sum_x[k]) / a + x0, float(sum_y[k]) / a + y0, a, *bb,
                              smoke_fraction=smoke,
                              score=round(0.6 * size_term + 0.4 * smoke_term, 6)))
    blobs.sort(key=lambda b: (-b.score, b.centroid_y_px, b.centroid_x_px))
    return blobs


#: groups beyond this many are not merged by size (``merge_rel``): the pairwise
#: test costs groups squared (a frame this full of flame colour is no fire scene)
MAX_MERGE_GROUPS = 1024


def _merge_near(area: np.ndarray, sum_x: np.ndarray, sum_y: np.ndarray, boxes: np.ndarray,
                p: FireDetectorParams) -> tuple[np.ndarray, ...]:
    """Merge groups whose boxes' gap is at most ``merge_rel`` times the larger
    one's size (``FireDetectorParams.merge_rel``), until none is; returns the
    merged groups' area, x and y sums and boxes (``boxes``: n x 4 inclusive
    x0, y0, x1, y1)."""
    while 1 < len(boxes) <= MAX_MERGE_GROUPS:
        x0, y0, x1, y1 = (boxes[:, i] for i in range(4))
        size = np.maximum(x1 - x0, y1 - y0) + 1
        gap_x = np.maximum(x0[None, :] - x1[:, None], x0[:, None] - x1[None, :]) - 1
        gap_y = np.maximum(y0[None, :] - y1[:, None], y0[:, None] - y1[None, :]) - 1
        gap = np.maximum(gap_x, gap_y)  # < 0: the boxes overlap
        reach = np.maximum(p.merge_dist_px, p.merge_rel * np.maximum(size[:, None], size[None, :]))
        near = gap <= reach
        if near.sum() == len(boxes):  # each group near itself only
            break
        comp = np.arange(len(boxes))
        while True:  # connected components of ``near``: least index reachable
            new = np.where(near, comp[None, :], len(boxes)).min(axis=1)
            if np.array_equal(new, comp):
                break
            comp = new
        _, comp = np.unique(comp, return_inverse=True)
        m = int(comp.max()) + 1
        area = np.bincount(comp, weights=area, minlength=m).astype(np.int64)
        sum_x = np.bincount(comp, weights=sum_x, minlength=m)
        sum_y = np.bincount(comp, weights=sum_y, minlength=m)
        merged = np.empty((m, 4), dtype=boxes.dtype)
        merged[:, :2] = np.iinfo(boxes.dtype).max
        merged[:, 2:] = np.iinfo(boxes.dtype).min
        np.minimum.at(merged[:, 0], comp, x0)
        np.minimum.at(merged[:, 1], comp, y0)
        np.maximum.at(merged[:, 2], comp, x1)
        np.maximum.at(merged[:, 3], comp, y1)
        boxes = merged
    return area, sum_x, sum_y, boxes


def _smoke_fraction(hsv: np.ndarray, flame: np.ndarray, bb: tuple[int, int, int, int],
                    p: FireDetectorParams) -> float:
    """Grey pixels' share of the window around box ``bb`` (flame pixels left out)."""
    h_img, w_img = flame.shape
    m = p.smoke_margin_px
    x0, y0 = max(0, bb[0] - m), max(0, bb[1] - m)
    x1, y1 = min(w_img, bb[2] + m + 1), min(h_img, bb[3] + m + 1)
    grey = cv2.inRange(hsv[y0:y1, x0:x1], (0, 0, p.smoke_min_value),
                       (179, p.smoke_max_saturation, p.smoke_max_value))
    n_win = (x1 - x0) * (y1 - y0) - cv2.countNonZero(flame[y0:y1, x0:x1])
    return round(cv2.countNonZero(grey) / n_win, 6) if n_win > 0 else 0.0


@dataclass(frozen=True)
class BlobMatch:
    """``match_blobs``' result.

    ``hits[i]``: the targets blob ``i`` hit, nearest first (usually one; more
    where ground-truth boxes overlap). ``false_alarms``: the indices of the
    blobs that hit no target. ``detected``: the targets hit by at least one
    blob, in the order of ``truth_rows``; ``missed``: the in-view targets hit
    by none. A target split into several blobs is detected once and none of
    its blobs is a false alarm."""

    hits: tuple[tuple[str, ...], ...]
    false_alarms: tuple[int, ...]
    detected: tuple[str, ...]
    missed: tuple[str, ...]


def match_blobs(blobs: Sequence[FireBlob], truth_rows: Iterable[Mapping[str, Any]],
                max_dist_px: float) -> BlobMatch:
    """Pair the blobs of one frame with the ground truth of the same frame.

    ``truth_rows``: ``render_frame``'s ground-truth rows with a ``target`` id
    added (``center_x_px``, ``center_y_px``, ``bbox_x0_px`` .. ``bbox_y1_px``,
    ``in_view``); pass the rows of the targets a blob may rightly hit --
    usually the fires, decoys included (a blob on a decoy then hits the
    decoy's id, and the caller counts it as the decoy's false alarm). Rows not
    ``in_view`` or without a box are ignored: they can be neither hit nor
    missed.

    A blob hits a target when its centroid lies within ``max_dist_px`` of the
    target's ground-truth box (distance 0 inside it). The box, not the centre,
    is the gate because a fire's flames fill its patch unevenly and smoke
    hides some of them, so the flames' centroid wanders over the patch;
    ``max_dist_px`` absorbs a box drawn a pixel or two small. Several targets
    within reach are all hit, nearest box first (ties: nearest centre)."""
    if not max_dist_px >= 0:
        raise ValueError(f"match_blobs: max_dist_px must be >= 0, got {max_dist_px!r}")
    targets: list[tuple[str, tuple[float, float, float, float], tuple[float, float] | None]] = []
    for row in truth_rows:
        box = tuple(row.get(k) for k in ("bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                                         "bbox_y1_px"))
        if not row.get("in_view") or any(v is None for v in box):
            continue
        cx, cy = row.get("center_x_px"), row.get("center_y_px")
        centre = None if cx is None or cy is None else (float(cx), float(cy))
        x0, y0, x1, y1 = (float(v) for v in box)  # type: ignore[arg-type]
        targets.append((str(row["target"]), (x0, y0, x1, y1), centre))
    hits: list[tuple[str, ...]] = []
    hit_ids: set[str] = set()
    for b in blobs:
        x, y = b.centroid_x_px, b.centroid_y_px
        near = []
        for tid, (x0, y0, x1, y1), centre in targets:
            d_box = math.hypot(max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1))
            if d_box <= max_dist_px:
                d_c = math.hypot(x - centre[0], y - centre[1]) if centre else math.inf
                near.append((d_box, d_c, tid))
        near.sort()
        hits.append(tuple(t for _, _, t in near))
        hit_ids.update(t for _, _, t in near)
    ids = [t for t, _, _ in targets]
    return BlobMatch(hits=tuple(hits),
                     false_alarms=tuple(i for i, h in enumerate(hits) if not h),
                     detected=tuple(t for t in ids if t in hit_ids),
                     missed=tuple(t for t in ids if t not in hit_ids))
