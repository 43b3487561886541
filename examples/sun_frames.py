"""The README's sun picture (docs/images/sun_shadows.jpg): the flyover's truck
seen by an oblique camera 60 m up, under the default sun (50 deg up in the
south-east, no shadows) and under `sun: {time: ...}` on a late summer
afternoon at the scenario's origin (shadows on).

    python examples/sun_frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.sun import DEFAULT, SunSpec, solar_position

REPO = Path(__file__).resolve().parent.parent
TIME = "2026-07-15T18:30:00-07:00"


def main(out: Path) -> None:
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    o = scn.origin
    az, el = solar_position(datetime.fromisoformat(TIME), o.lat_deg, o.lon_deg)
    cam = CameraSpec("oblique", (0,), "gimbal", -50.0, False, 50.0, 38.5, 480, 360, 10.0, 12)
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(-50.0, -5.0,
                                                                      o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + 60.0, 0.0, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    tiles = []
    for sun, label in ((DEFAULT, "default sun: 50 deg up, SE, no shadows"),
                       (SunSpec(az, el, TIME, True),
                        f"sun: {{time: {TIME}}}: az {az:.0f}, el {el:.0f} deg")):
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0,
                       scn.world.ground, scn.world.targets, scn.world.obstacles, sun)
        img = render_frame(World(ws), cam, pose, 0)[0][..., :3].copy()
        cv2.rectangle(img, (0, 0), (479, 26), (0, 0, 0), -1)
        cv2.putText(img, label, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(img)
    gap = np.full((360, 8, 3), 255, np.uint8)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.hstack([tiles[0], gap, tiles[1]]), [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/sun_shadows.jpg")
