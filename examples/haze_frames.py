"""The README's haze picture (docs/images/haze_off_on.png): the flyover's
trucks seen from 60 m up and 200 m south of the first, looking north 10 deg
down (the second truck 500 m away, the ground's range 5 km), in clear air
(no ``atmosphere:`` section) and through ``atmosphere: {visibility_km: 2}``.

    python examples/haze_frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.sun import SunSpec

REPO = Path(__file__).resolve().parent.parent
W, H = 320, 240


def row(cam: CameraSpec, roll_deg: float,
        variants: Sequence[tuple[SunSpec | None, AtmosphereSpec | None, str]]) -> np.ndarray:
    """The flyover's trucks seen by ``cam`` from 60 m up and 200 m south of the
    first, looking north and rolled ``roll_deg``, once per variant (its sun,
    None: the scenario's; its atmosphere; its label), side by side."""
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    o = scn.origin
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(-200.0, 0.0,
                                                                      o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + 60.0, roll_deg, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    tiles = []
    for sun, air, label in variants:
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0,
                       scn.world.ground, scn.world.targets, scn.world.obstacles,
                       scn.world.sun if sun is None else sun, atmosphere=air)
        img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        h, w = img.shape[:2]
        cv2.rectangle(img, (0, h - 20), (w - 1, h - 1), (0, 0, 0), -1)
        cv2.putText(img, label, (6, h - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(img)
    return np.hstack(tiles)


def write(img: np.ndarray, out: Path) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")


def main(out: Path) -> None:
    cam = CameraSpec("oblique", (0,), "gimbal", -10.0, False, 40.0, 30.6, W, H, 10.0, 12)
    write(row(cam, 0.0, ((None, None, "clear air (no atmosphere:)"),
                         (None, AtmosphereSpec(2.0), "atmosphere: {visibility_km: 2}"))), out)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/haze_off_on.png")
