"""The README's buildings picture (docs/images/buildings.png): the village
example (examples/village/village.yaml: gable, hip and flat roofs, a car and
a person, the afternoon sun) seen obliquely from its quadrotor's side of the
village, with the sun's shadows off and on (the person then in a house's
shadow, lit by the sky alone), each target's box labelled with its ground
truth's visible_fraction.

    python examples/building_frames.py [OUT.png]
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent
#: where the picture is taken from: north, east and height above the ground (m)
AT_NE_AGL_M = (-44.0, -7.0, 40.0)
W_PX, H_PX, HFOV_DEG = 316, 300, 40.0


def _label(img: np.ndarray, text: str, x: int, y: int, colour: tuple[int, int, int]) -> None:
    for thick, c in ((3, (0, 0, 0)), (1, colour)):
        cv2.putText(img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.4, c, thick, cv2.LINE_AA)


def main(out: Path) -> None:
    scn = load_scenario(REPO / "examples/village/village.yaml", check_properties=False)
    o, w = scn.origin, scn.world
    view = scn.sections["cameras"].views[0]
    cam = dataclasses.replace(view, width_px=W_PX, height_px=H_PX, hfov_deg=HFOV_DEG,
                              vfov_deg=HFOV_DEG * H_PX / W_PX)
    n, e, agl = AT_NE_AGL_M
    lat, lon = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m).place(n, e, o.ground_alt_m)
    pose = camera_pose(cam, float(lat), float(lon), o.ground_alt_m + agl, 0.0, 0.0, 0.0,
                       ground_alt_m=o.ground_alt_m)
    tiles = []
    for shadows in (False, True):
        sun = dataclasses.replace(w.sun, shadows=shadows)
        ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, scn.rates.physics_hz,
                       w.ground, w.targets, w.obstacles, sun)
        img, rows = render_frame(World(ws), cam, pose, 0)
        img = img[..., :3].copy()
        for t, r in zip(w.targets, rows):
            if not r["in_view"]:
                continue
            x0, y0 = int(r["bbox_x0_px"]) - 2, int(r["bbox_y0_px"]) - 2
            x1, y1 = int(r["bbox_x1_px"]) + 3, int(r["bbox_y1_px"]) + 3
            cv2.rectangle(img, (x0, y0), (x1, y1), (0, 255, 255), 1)
            _label(img, f"{t.id} {r['visible_fraction']:.2f}", x0, y0 - 4, (0, 255, 255))
            if shadows:
                print(f"{t.id}: pixels_on_target {r['pixels_on_target']}, "
                      f"visible_fraction {r['visible_fraction']:.3f}")
        cv2.rectangle(img, (0, 0), (W_PX - 1, 20), (0, 0, 0), -1)
        _label(img, f"sun az {sun.azimuth_deg:g}, el {sun.elevation_deg:g} deg, shadows: "
                    f"{'on' if shadows else 'false'}", 6, 14, (255, 255, 255))
        tiles.append(img)
    gap = np.full((H_PX, 8, 3), 255, np.uint8)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), np.hstack([tiles[0], gap, tiles[1]]), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/buildings.png")
