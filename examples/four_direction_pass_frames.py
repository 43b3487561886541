"""Experiment 1's four passes, one frame of each: the quadrotor flying north,
east, south and west over a truck, 1.3 s before it is
overhead, labelled with the way the target crosses the screen (from the
ground truth). Writes docs/images/four_direction_pass.jpg (the README's
figure):

    python examples/four_direction_pass_frames.py [OUT.jpg]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from cosim.conspicuity import passes, read_ground_truth
from cosim.scenario import load_scenario
from cosim.sync import run_scenario

REPO = Path(__file__).resolve().parent.parent
SCENARIO = REPO / "scenarios/conspicuity/four_direction_pass.yaml"


def frames_of(video: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(video))
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            return out
        out.append(f)


def main(png: Path) -> None:
    tiles = []
    with tempfile.TemporaryDirectory() as tmp:
        for heading, name in ((0, "north"), (90, "east"), (180, "south"), (270, "west")):
            point = {"heading_deg": heading, "target": "truck", "speed_mps": 5,
                     "alt_agl_m": 60, "width_px": 320, "height_px": 240, "vfov_deg": 40,
                     "lead_s": 4, "tail_s": 2}
            out = Path(tmp) / name
            res = run_scenario(load_scenario(SCENARIO, sweep_point=point), out,
                               backend="inline")
            if not res.ok:
                raise SystemExit(f"the {name} pass failed: {res.error}")
            gt = read_ground_truth(out / "cameras" / "quad_nadir.gt.csv")
            [p] = passes(gt[("quad", "nadir", "truck")], 1 / 30)
            video = next(f for f in (out / "cameras").iterdir()
                         if f.name.startswith("quad_nadir.") and not f.name.endswith(".csv"))
            f = frames_of(video)[p.overhead_frame - 40].copy()
            cv2.putText(f, f"flying {name}: target moves {p.screen_direction}", (8, 22),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
            tiles.append(f)
    img = np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])])
    png.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(png), img, [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(png)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/four_direction_pass.jpg")
