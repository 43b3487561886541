"""One frame of the flyover's belly camera with its sensor off and on, side
by side (320 x 240 each): the README's picture of the ``sensor:`` keys.
Writes docs/images/sensor_off_on.png:

    python examples/sensor_frames.py [OUT.png] [--sensor YAML]

``--sensor`` is the camera's ``sensor:`` mapping (default: barrel distortion,
natural cos^4 vignetting, a 20 ms exposure of the flyover's 51.4 m/s and 20 dB
at mid-grey, on an 80 degree lens).
"""

from __future__ import annotations

import argparse
import dataclasses
import textwrap
from pathlib import Path

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, camera_pose
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.sensor import Sensor
from cosim.scenario import parse_scenario

REPO = Path(__file__).resolve().parent.parent
SCENARIO = REPO / "scenarios/cameras/flyover.yaml"
DEFAULT = "{distortion: {k1: -0.15}, vignetting: cos4, exposure_ms: 20, snr_db: 20}"
#: the flyover's flight: north at 51.4 m/s (100 kt), level
MOTION = (51.4, 0.0, 0.0, 0.0, 0.0, 0.0)


def camera(sensor_yaml: str) -> tuple[CameraSpec, object]:
    """The flyover's belly camera at 320 x 240, 80 deg across, with ``sensor_yaml``."""
    text = SCENARIO.read_text().replace(
        "vfov_deg: 40, width_px: 640, height_px: 480",
        f"hfov_deg: 80, width_px: 320, height_px: 240, sensor: {sensor_yaml}")
    scn = parse_scenario(text, str(SCENARIO), check_properties=False)
    return scn.sections["cameras"].views[0], scn


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?", default=str(REPO / "docs/images/sensor_off_on.png"))
    ap.add_argument("--sensor", default=DEFAULT)
    a = ap.parse_args()
    cam, scn = camera(a.sensor)
    assert cam.sensor is not None
    o = scn.origin  # type: ignore[attr-defined]
    ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed,  # type: ignore[attr-defined]
                   120.0, scn.world.ground, scn.world.targets)  # type: ignore[attr-defined]
    world = World(ws)
    la, lo = o.frame.place(-20.0, 0.0, o.ground_alt_m + 60)  # 20 m short of the truck
    pose6 = (float(la), float(lo), o.ground_alt_m + 60, 0.0, 0.0, 0.0)
    pose = camera_pose(cam, *pose6, o.ground_alt_m)
    plain = dataclasses.replace(cam, sensor=None)
    off, _ = render_frame(world, plain, pose, 0)
    sensor = Sensor(cam, cam.sensor, ws.seed, 0)
    smear = sensor.smear_px(pose6, MOTION, None, pose, o.ground_alt_m)
    wide, _ = render_frame(world, sensor.source, pose, 0)  # what the lens sees, past the pinhole
    on = sensor.apply(wide, 0, smear)
    panels = []
    for img, label in ((off, "sensor off"), (on, f"sensor: {a.sensor}")):
        bgr = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
        lines = textwrap.wrap(label, 48)  # 48 characters fit 320 px
        for j, text in enumerate(lines):
            cv2.putText(bgr, text, (6, 232 - 13 * (len(lines) - 1 - j)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
        panels.append(bgr)
    gap = np.full((240, 4, 3), 255, np.uint8)
    if not cv2.imwrite(a.out, np.hstack([panels[0], gap, panels[1]])):
        raise SystemExit(f"could not write {a.out}")
    print(a.out)


if __name__ == "__main__":
    main()
