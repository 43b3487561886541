"""The picture of a study's target that the participant page shows: what to
look for.

Owns choosing the still and cutting it out: for each target (``Clip.target``)
the frame, among the clips of that target, where its ground-truth box is
largest and wholly inside the picture (the practice clips' frames when they
have one, so that the main clips are not shown before their trial); the
square around the box, twice its longer side (the target in the middle, its
surroundings around it), cut from that video frame as the renderer drew it
and encoded as PNG. Nothing is drawn on it. It does not serve (``server``)
or read the study (``study``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.errors import ConfigError
from cosim.trials.files import open_regular
from cosim.trials.study import Clip

#: the smallest square cut out (camera px), for a target of a few pixels
MIN_SIDE_PX = 16


@dataclass(frozen=True)
class Still:
    """Where a target's picture comes from: frame ``frame`` of ``clip``, the
    square ``x0, y0`` (its top-left pixel) of ``side_px`` pixels."""

    clip: Clip
    frame: int
    x0: int
    y0: int
    side_px: int


def choose_still(clips: tuple[Clip, ...], practice: tuple[Clip, ...], target: str
                 ) -> Still | None:
    """The still for ``target`` (see the module docstring); None if no frame
    of any of its clips has it in view."""
    for pool in (practice, clips):
        best: tuple[tuple[bool, float], Clip, int] | None = None
        for c in pool:
            if c.target != target:
                continue
            for k, g in enumerate(c.frames):
                if not g.in_view or g.bbox_px is None:
                    continue
                x0, y0, x1, y1 = g.bbox_px
                inside = x0 >= -0.5 and y0 >= -0.5 and x1 <= c.width_px - 0.5 and \
                    y1 <= c.height_px - 0.5
                seen = (min(x1, c.width_px - 0.5) - max(x0, -0.5)) * \
                    (min(y1, c.height_px - 0.5) - max(y0, -0.5))
                score = (inside, seen)
                if best is None or score > best[0]:
                    best = (score, c, k)
        if best is not None:
            _, c, k = best
            return Still(c, k, *_square(c, k))
    return None


def _square(c: Clip, k: int) -> tuple[int, int, int]:
    """(x0, y0, side) of the square around frame ``k``'s box, inside the picture."""
    x0, y0, x1, y1 = c.frames[k].bbox_px or (0.0, 0.0, 0.0, 0.0)
    side = max(MIN_SIDE_PX, math.ceil(2 * max(x1 - x0, y1 - y0)))
    side = min(side, c.width_px, c.height_px)
    left = round((x0 + x1) / 2 - side / 2)
    top = round((y0 + y1) / 2 - side / 2)
    return (min(max(left, 0), c.width_px - side), min(max(top, 0), c.height_px - side), side)


def decode_frame(c: Clip, k: int) -> np.ndarray:
    """Frame ``k`` of clip ``c``'s video (height x width x 3, RGB): the frame
    shown at ``k / rate_hz``, as the page maps a presentation time to a frame."""
    import av

    with open_regular(c.video) as f, av.open(f, mode="r") as container:
        s = container.streams.video[0]
        tb = s.time_base
        start = s.start_time or 0
        if tb is None:
            raise ConfigError(f"{c.video}: no time base: cannot find frame {k}")
        container.seek(start + int(k / c.rate_hz / tb), stream=s, backward=True)
        for frame in container.decode(s):
            if frame.pts is None:
                continue
            n = round(float((frame.pts - start) * tb) * c.rate_hz)
            if n == k:
                return np.asarray(frame.to_ndarray(format="rgb24"))
            if n > k:
                break
    raise ConfigError(f"{c.video}: no frame {k} (clip {c.id!r})")


def target_png(still: Still) -> bytes:
    """The PNG of ``still``'s square, its pixels as the video has them."""
    import cv2

    img = decode_frame(still.clip, still.frame)
    s = still.side_px
    crop = img[still.y0:still.y0 + s, still.x0:still.x0 + s]
    ok, png = cv2.imencode(".png", np.ascontiguousarray(crop[:, :, ::-1]))
    if not ok:
        raise ConfigError(f"cannot encode the picture of target {still.clip.target!r}")
    return bytes(png)
