"""Camera rendering benchmark (not a test).

1. ms per 640x480 frame on one core, including the ground-truth rows and mp4v
   encoding (a nadir camera at 100 m AGL, 51 m/s over the flyover targets,
   tile generation included as it happens in flight), and frames/s per core;
2. a real run: N uav700s each with a 10 Hz 640x480 nadir camera for D s through
   the lockstep loop (process backend, render pool), its real-time factor.

    python benchmarks/render_bench.py [--frames 200] [--vehicles 20] [--duration-s 10]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from cosim.geo import LocalFrame
from cosim.renderer.config import CameraSpec
from cosim.renderer.participant import RenderWorker, Stream
from cosim.scenario import load_scenario, parse_scenario
from cosim.sync.runner import run_scenario

REPO = Path(__file__).resolve().parent.parent


def per_frame(frames: int) -> tuple[float, float]:
    cv2.setNumThreads(1)
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    from cosim.renderer.frame import WorldSpec

    ws = WorldSpec(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m, scn.seed,
                   120.0, scn.sections["ground"], scn.sections["targets"])
    cam: CameraSpec = scn.sections["cameras"].views[0]
    frame = LocalFrame(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m)
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "cameras").mkdir()
        s = Stream(0, "uav1", 0, cam, "cameras/b.mp4", "cameras/b.gt.csv", None)
        w = RenderWorker(ws, [s], Path(d), "mp4v", False)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for i in range(frames):
            t = i / 10.0
            la, lo = frame.place(-150 + 51.4 * t, 0.0, scn.origin.ground_alt_m + 100)
            w.render(0, i, i * 12, (float(la), float(lo), scn.origin.ground_alt_m + 100,
                                    0.0, 0.0, 0.0))
        w.close()
        return ((time.process_time() - cpu0) / frames * 1000,
                (time.perf_counter() - wall0) / frames * 1000)


def swarm(n: int, duration_s: float) -> dict[str, object]:
    text = (REPO / "scenarios/cameras/flyover.yaml").read_text()
    text = text.replace("  - id: uav1\n", f"  - id: uav\n    count: {n}\n"
                        "    formation: {type: line, spacing_m: 200}\n")
    text = text.replace("vehicles: uav1", "vehicles: all").replace("operator_view: true",
                                                                   "operator_view: false")
    scn = parse_scenario(text, str(REPO / "scenarios/cameras/bench.yaml")).with_duration(
        duration_s)
    with tempfile.TemporaryDirectory() as d:
        r = run_scenario(scn, d)
        return {"real_time_factor": r.summary["real_time_factor"],
                "wall_time_s": r.summary["wall_time_s"], "stop": r.stop_reason,
                "frames": sum(s["frames"] for s in r.summary["cameras"]["streams"])}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--vehicles", type=int, default=20)
    ap.add_argument("--duration-s", type=float, default=10.0)
    a = ap.parse_args()
    cpu_ms, wall_ms = per_frame(a.frames)
    print(f"640x480 nadir frame incl. ground truth + mp4v: {cpu_ms:.2f} ms CPU "
          f"({wall_ms:.2f} ms wall), {1000 / cpu_ms:.0f} frames/s per core")
    if a.vehicles:
        res = swarm(a.vehicles, a.duration_s)
        print(f"{a.vehicles} uav700 x 10 Hz 640x480 cameras, {a.duration_s:g} s: "
              + json.dumps(res))
    _ = np


if __name__ == "__main__":
    main()
