"""A crop of the flyover's belly camera as rendered beside the same frame as a
datalink delivers it: the README's picture of the ``datalink:`` keys. The
camera (640 x 480, 15 Hz) flies north at 51 m/s, 100 m up; its frames go
through the link for a second (a key frame, then predicted frames), and the
last one is shown, its crop around the truck enlarged twice (nearest pixel).
Writes docs/images/datalink_clean_delivered.png:

    python examples/datalink_frames.py [OUT.png] [--datalink YAML]

``--datalink`` is the camera's ``datalink:`` mapping (default 300 kbit/s).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import camera_pose
from cosim.renderer.datalink import Downlink
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import parse_scenario

REPO = Path(__file__).resolve().parent.parent
SCENARIO = REPO / "scenarios/cameras/flyover.yaml"
DEFAULT = "{bitrate_kbps: 300, keyframe_s: 1}"
CROP = (220, 165, 200, 150)  # x, y, w, h of the 640 x 480 frame


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?",
                    default=str(REPO / "docs/images/datalink_clean_delivered.png"))
    ap.add_argument("--datalink", default=DEFAULT)
    a = ap.parse_args()
    text = SCENARIO.read_text().replace("rate_hz: 10}", f"rate_hz: 15, datalink: {a.datalink}}}")
    scn = parse_scenario(text, str(SCENARIO), check_properties=False)
    cam = scn.sections["cameras"].views[0]
    assert cam.datalink is not None
    o = scn.origin
    ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0, scn.world.ground,
                   scn.world.targets)
    world = World(ws)
    n = round(cam.datalink.rate_hz)
    with tempfile.TemporaryDirectory() as d:
        link = Downlink(str(Path(d) / "v.mp4"), cam.datalink, cam.width_px, cam.height_px)
        for i in range(n):  # the truck passes under the camera's centre at the last frame
            north_m = -51.4 * (n - 1 - i) / cam.rate_hz
            la, lo = (float(v) for v in o.frame.place(north_m, 0.0, o.ground_alt_m + 100))
            pose = camera_pose(cam, la, lo, o.ground_alt_m + 100, 0.0, 0.0, 0.0, o.ground_alt_m)
            clean, _ = render_frame(world, cam, pose, i * 8)
            link.send(clean)
        got = link.latest()
        link.close()
    x, y, w, h = CROP
    panels = []
    for img, label in ((clean, "as rendered"),
                       (got, f"delivered at {cam.datalink.bitrate_kbps:g} kbit/s")):
        bgr = cv2.cvtColor(img[y:y + h, x:x + w], cv2.COLOR_BGRA2BGR)
        bgr = cv2.resize(bgr, (2 * w, 2 * h), interpolation=cv2.INTER_NEAREST)
        cv2.putText(bgr, label, (8, 2 * h - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
        panels.append(bgr)
    gap = np.full((2 * h, 4, 3), 255, np.uint8)
    if not cv2.imwrite(a.out, np.hstack([panels[0], gap, panels[1]]),
                       [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise SystemExit(f"could not write {a.out}")
    print(a.out)


if __name__ == "__main__":
    main()
