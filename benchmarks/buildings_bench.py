"""What buildings and ``visible_fraction`` cost a frame, each timed A against B
in the same run (not a test).

The village example (examples/village/village.yaml: four buildings with
gable, hip and flat roofs, a car and a person, the sun's shadows on), its
gimbal camera at 640 x 480 along the quadrotor's path (40 m up, north
toward the village), OpenCV on one thread as in the render workers:

- buildings: ``render_frame`` of the same frames with the scenario's
  obstacles (their faces and their shadows) and without them, round after
  round, so the machine's load falls on both alike;
- visible_fraction: ``truth.ground_truth`` on the same drawn frames with the
  targets' outlines (the column computed) and without (left empty).

Prints the median milliseconds a frame of each and their difference
(process time).

    python benchmarks/buildings_bench.py [--rounds 15] [--frames 20]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cosim.core.camera import camera_pose
from cosim.core.geo import LocalFrame
from cosim.renderer import frame as frame_mod
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.truth import ground_truth
from cosim.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--frames", type=int, default=20, help="poses per round")
    a = ap.parse_args(argv)
    cv2.setNumThreads(1)  # one core, as the render workers
    scn = load_scenario(REPO / "examples/village/village.yaml", check_properties=False)
    o, w = scn.origin, scn.world
    cam = scn.sections["cameras"].views[0]
    local = LocalFrame(o.lat_deg, o.lon_deg, o.ground_alt_m)
    poses = []
    for n in np.linspace(-70.0, -20.0, a.frames):
        lat, lon = local.place(float(n), -4.0, o.ground_alt_m)
        poses.append(camera_pose(cam, float(lat), float(lon), o.ground_alt_m + 40.0, 0.0, 0.0,
                                 0.0, ground_alt_m=o.ground_alt_m))

    def world(obstacles: tuple[Any, ...]) -> World:
        return World(WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0, w.ground,
                               w.targets, obstacles, w.sun))

    worlds = {"without buildings": world(()), "with buildings": world(w.obstacles)}
    out = np.empty((cam.height_px, cam.width_px, 4), np.uint8)
    # the ground truth's inputs of every frame with buildings, captured once
    calls: list[tuple[Any, ...]] = []
    real = frame_mod.ground_truth

    def capture(*args: Any) -> Any:
        calls.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args))
        return real(*args)

    setattr(frame_mod, "ground_truth", capture)  # noqa: B010 (a spy, undone below)
    try:
        for p in poses:
            render_frame(worlds["with buildings"], cam, p, 0, out)
    finally:
        setattr(frame_mod, "ground_truth", real)  # noqa: B010
    for wd in worlds.values():  # ground tiles made before any timing
        for p in poses:
            render_frame(wd, cam, p, 0, out)
    times: dict[str, list[float]] = {k: [] for k in (*worlds, "visible_fraction", "without it")}
    for _ in range(a.rounds):
        for name, wd in worlds.items():
            t0 = time.process_time()
            for p in poses:
                render_frame(wd, cam, p, 0, out)
            times[name].append((time.process_time() - t0) * 1e3 / len(poses))
        for name, n_args in (("visible_fraction", 9), ("without it", 7)):
            t0 = time.process_time()
            for args in calls:
                ground_truth(*args[:n_args])
            times[name].append((time.process_time() - t0) * 1e3 / len(calls))
    med = {k: statistics.median(v) for k, v in times.items()}
    seen = [r["visible_fraction"] for args in calls for r in ground_truth(*args)
            if r["in_view"]]
    print(f"{a.rounds} rounds of {len(poses)} frames, 640 x 480, one thread, process time; "
          f"{len(seen)} target rows in view (visible_fraction {min(seen):.2f} to "
          f"{max(seen):.2f})")
    for k, v in med.items():
        print(f"  {k:>18}: {v:6.3f} ms a frame (range {min(times[k]):.3f} to "
              f"{max(times[k]):.3f})")
    print(f"  buildings cost {med['with buildings'] - med['without buildings']:.3f} ms a frame "
          f"({med['with buildings'] / med['without buildings']:.3f}x); visible_fraction "
          f"{med['visible_fraction'] - med['without it']:.3f} ms a frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
