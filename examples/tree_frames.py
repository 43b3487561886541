"""The README's trees picture (docs/images/trees_flat_3d.png): the edge of a wood
north of the flyover's track seen by an oblique camera 40 m up, with the
procedural ground's trees flat (``ground: {trees: flat}``, the default) and in
3-D (``trees: 3d``), the sun in the south-west with shadows; a car parked
in the wood is partly hidden by the crowns in front of it.

    python examples/tree_frames.py [OUT.png]
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.sun import SunSpec
from cosim.world.targets import TargetSpec

REPO = Path(__file__).resolve().parent.parent
SUN = SunSpec(azimuth_deg=220.0, elevation_deg=45.0, shadows=True)
CROP = (slice(60, 420), slice(80, 560))  # rows, columns of the 640 x 480 frame


def frames(trees: tuple[str, ...]) -> list[np.ndarray]:
    """The oblique view of the wood's edge (640 x 480 BGR) for each ``trees``."""
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    o = scn.origin
    cam = CameraSpec("oblique", (0,), "gimbal", -40.0, False, 60.0, 46.8, 640, 480, 10.0, 12)
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(335.0, 10.0,
                                                                      o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + 40.0, 0.0, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    car = TargetSpec("car1", "car", 387.0, 12.5, None, None, 80.0, 4.5, 1.8, 1.5, (200, 30, 30))
    out = []
    for mode in trees:
        ground = dataclasses.replace(scn.world.ground, trees=mode)
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0, ground,
                       (car,), (), SUN)
        img, rows = render_frame(World(ws), cam, pose, 0)
        print(f"trees: {mode}: the car's pixels_on_target {rows[0]['pixels_on_target']}")
        out.append(img[..., :3].copy())
    return out


def main(path: Path) -> None:
    tiles = []
    for img, label in zip(frames(("flat", "3d")), ("trees: flat (default)", "trees: 3d")):
        img = np.ascontiguousarray(img[CROP])
        cv2.rectangle(img, (0, 0), (img.shape[1] - 1, 24), (0, 0, 0), -1)
        cv2.putText(img, label, (8, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(cv2.resize(img, None, fx=2 / 3, fy=2 / 3, interpolation=cv2.INTER_AREA))
    gap = np.full((tiles[0].shape[0], 6, 3), 255, np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.hstack([tiles[0], gap, tiles[1]]), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {path}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/trees_flat_3d.png")
