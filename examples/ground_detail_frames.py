"""The README's ground-detail picture (docs/images/ground_detail.png): the
altitude_speed trial's nadir camera (37.6 deg along track, 640 x 480) 30 m
over its truck, the middle 318 x 240 pixels of the frame (about 14 x 10 m at
4.3 cm a pixel), with the ground texture of version 8 (its fine detail smooth
value-noise octaves, the within-field brightness down to 7.5 m only, no
tramlines) and today's (clods, stones, leaf litter and tufts,
``cosim.renderer.detail``).
Each half is labelled with the frame's spectral exponent (the whole frame,
``cosim.conspicuity.spectrum``).

The earlier texture is rebuilt here from its formula, for the picture only;
the ground's tile cache is turned off so that no tile of it is kept.

    python examples/ground_detail_frames.py [OUT.png]
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from cosim.conspicuity.spectrum import luminance, spectral_exponent
from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer import noise, texture
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.noise import value_noise
from cosim.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent
W, H, VFOV_DEG, ALT_M = 640, 480, 37.6, 30.0


def detail_v8(seed: int) -> tuple[np.ndarray, ...]:
    """The fine detail of texture version 8: five value-noise octaves (8 to 256
    cells across 512 px), each 0.8 of the one before, times 0.6."""
    y, x = np.mgrid[0:512, 0:512].astype(np.float64)
    d = np.zeros((512, 512), np.float32)
    amp = 0.5
    for k, cells in enumerate((8, 32, 64, 128, 256)):
        d += amp * (value_noise(x * cells / 512, y * cells / 512, seed + 31 + k,
                                period=cells) - 0.5)
        amp *= 0.8
    levels = [np.repeat((1.0 + 0.6 * d).astype(np.float32)[..., None], 3, axis=2)]  # grey
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    return tuple(levels)


@contextmanager
def version_8() -> Iterator[None]:
    """The ground texture as it was in version 8, within the block (no tramlines;
    its own per-cell tables, which the tramlines' strength is part of)."""
    kept = (texture.detail_pyramid, texture.BRIGHT_M, texture.BRIGHT_AMP, texture.TRACK_DARK,
            noise.TABLES)
    texture.detail_pyramid = detail_v8  # type: ignore[assignment]
    texture.BRIGHT_M, texture.BRIGHT_AMP = (60.0, 30.0, 15.0, 7.5), (0.35, 0.175, 0.0875,
                                                                     0.04375)
    texture.TRACK_DARK, noise.TABLES = 0.0, noise.Tables(noise.TABLES.max_bytes)
    try:
        yield
    finally:
        (texture.detail_pyramid, texture.BRIGHT_M, texture.BRIGHT_AMP, texture.TRACK_DARK,
         noise.TABLES) = kept


def main(out: Path) -> None:
    os.environ["COSIM_GROUND_CACHE"] = "off"
    scn = load_scenario(REPO / "scenarios/conspicuity/altitude_speed.yaml",
                        check_properties=False)
    o = scn.origin
    hfov = 2 * math.degrees(math.atan(math.tan(math.radians(VFOV_DEG / 2)) * W / H))
    cam = CameraSpec("nadir", (0,), "nadir", -90.0, True, hfov, VFOV_DEG, W, H, 30.0, 4)
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(-4.0, 3.0,
                                                                      o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + ALT_M, 0.0, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    halves = []
    for old, label in ((True, "before (texture version 8)"),
                       (False, f"today (version {texture.TEXTURE_VERSION})")):
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0,
                       scn.world.ground, scn.world.targets, scn.world.obstacles, scn.world.sun)
        if old:
            with version_8():
                img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        else:
            img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        a = spectral_exponent(luminance(img[..., ::-1])).exponent
        crop = img[H // 4:H // 4 + H // 2, W // 4 + 2:W // 4 + W // 2].copy()  # 318 px wide
        cv2.rectangle(crop, (0, H // 2 - 20), (W // 2 - 3, H // 2 - 1), (0, 0, 0), -1)
        cv2.putText(crop, f"{label}: a = {a:.2f}", (6, H // 2 - 6), cv2.FONT_HERSHEY_SIMPLEX,
                    0.42, (255, 255, 255), 1, cv2.LINE_AA)
        halves.append(crop)
        print(f"{label}: spectral exponent of the whole frame {a:.2f}")
    gap = np.full((H // 2, 4, 3), 255, np.uint8)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.hstack([halves[0], gap, halves[1]]),
                [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/ground_detail.png")
