"""The README's sky picture (docs/images/sky.png): the flyover's trucks seen
from 60 m up and 200 m south of the first, looking north 5 deg down and
rolled 10 deg, under the default sun in clear air, through
``atmosphere: {visibility_km: 2}``, and under a low sun ahead (6 deg up,
north-north-east) through 8 km of haze: the sky's colour follows each ray's
elevation, the far ground fades into it, and a low sun dims it and warms it
around the sun.

    python examples/sky_frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.sun import DEFAULT, SunSpec

REPO = Path(__file__).resolve().parent.parent
W, H = 320, 240


def main(out: Path) -> None:
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    o = scn.origin
    cam = CameraSpec("oblique", (0,), "gimbal", -5.0, False, 60.0, 46.8, W, H, 10.0, 12)
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(-200.0, 0.0,
                                                                      o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + 60.0, 10.0, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    low = SunSpec(azimuth_deg=20.0, elevation_deg=6.0)
    tiles = []
    for sun, air, label in ((DEFAULT, None, "sun 50 deg, clear air"),
                            (DEFAULT, AtmosphereSpec(2.0), "sun 50 deg, visibility 2 km"),
                            (low, AtmosphereSpec(8.0), "sun 6 deg ahead, visibility 8 km")):
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0,
                       scn.world.ground, scn.world.targets, scn.world.obstacles, sun,
                       atmosphere=air)
        img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        cv2.rectangle(img, (0, H - 20), (W - 1, H - 1), (0, 0, 0), -1)
        cv2.putText(img, label, (6, H - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(img)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.hstack(tiles), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/sky.png")
