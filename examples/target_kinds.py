"""The README's picture of the target kinds (docs/images/target_kinds.jpg):
a truck, a fire truck, a car and a person at their default sizes and
colours, each seen obliquely (30 deg down, from ahead and to the left) in
the flyover's sun and ground.

    python examples/target_kinds.py [OUT.jpg]
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

REPO = Path(__file__).resolve().parent.parent
W, H = 240, 180
KINDS = ("truck", "fire_truck", "car", "person")


def main(out: Path) -> None:
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    o = scn.origin
    frame = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m)
    cam = CameraSpec("oblique", (0,), "gimbal", -30.0, False, 40.0, 30.6, W, H, 10.0, 12)
    tiles = []
    for kind in KINDS:
        L, Wd, Ht, c = TARGET_DEFAULTS[kind]
        # the target faces north-west; the camera looks north, 30 deg down
        t = TargetSpec(kind, kind, 0.0, 0.0, None, None, 235.0, L, Wd, Ht, c)
        range_m = 2.2 * max(L, Ht)
        down = math.radians(30.0)
        lat, lon = frame.place(-range_m * math.cos(down), 0.0, o.ground_alt_m)
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0,
                       scn.world.ground, (t,), (), scn.world.sun)
        pose = camera_pose(cam, float(lat), float(lon),
                           o.ground_alt_m + Ht / 2 + range_m * math.sin(down), 0.0, 0.0, 0.0,
                           ground_alt_m=o.ground_alt_m)
        img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        cv2.rectangle(img, (0, H - 18), (W - 1, H - 1), (0, 0, 0), -1)
        cv2.putText(img, kind, (6, H - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(img)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.hstack(tiles), [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(f"wrote {out} ({out.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/target_kinds.jpg")
