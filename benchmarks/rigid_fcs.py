"""How long the rigid-body tier's compiled flight controls take a frame:
the uav700's systems, cosim autopilot (engaged, every hold on) and flight
control (``cosim.rigid.fcs``) run for N aircraft at the physics rate, on
inputs spread around a cruise. Reports the best of several rounds, in ms a
frame and aircraft-steps a second (one core).

    python benchmarks/rigid_fcs.py --vehicles 1000,10000 --rounds 15
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from cosim.rigid.fcs import compile_systems

REPO = Path(__file__).resolve().parents[1]
DT_S = 1 / 120

#: a cruise at 3000 ft, 100 kt (the recorded values the plan reads)
CRUISE = {"aero/qbar-psf": 30.0, "velocities/vt-fps": 170.0, "velocities/vtrue-kts": 100.0,
          "inertia/weight-lbs": 70.0, "metrics/Sw-sqft": 12.9, "atmosphere/sigma": 0.91,
          "position/h-sl-ft": 3000.0, "cosim/ap/alt-cmd-ft": 3100.0,
          "cosim/ap/speed-cmd-kt": 95.0, "cosim/ap/heading-cmd-deg": 40.0}


def measure(n: int, rounds: int, frames: int) -> float:
    """Seconds a frame for ``n`` aircraft (best round)."""
    plan = compile_systems(REPO / "aircraft" / "uav700" / "uav700.xml",
                           REPO / "aircraft" / "systems")
    props: dict[str, np.ndarray] = {}
    plan.init(props, n)
    rng = np.random.default_rng(0)
    for k in plan.inputs:
        props[k] = props[k] + CRUISE.get(k, 0.0) + rng.normal(0.0, 0.01, n)
    for k in ("engage", "heading-hold", "alt-hold", "speed-hold"):
        props[f"cosim/ap/{k}"][:] = 1.0
    plan.run_ic(props, DT_S)
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(frames):
            plan.run(props, DT_S)
        best = min(best, (time.perf_counter() - t0) / frames)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", default="1000", help="comma-separated fleet sizes")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--frames", type=int, default=240, help="frames a round")
    args = ap.parse_args()
    for n in (int(v) for v in args.vehicles.split(",")):
        s = measure(n, args.rounds, args.frames)
        print(f"{n} aircraft: {s * 1e3:.3f} ms a frame, {n / s:,.0f} aircraft-steps/s")


if __name__ == "__main__":
    main()
