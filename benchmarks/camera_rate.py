"""What a 30 fps camera costs a JSBSim fleet: the same run (N uav700s, one of
them with a 30 Hz nadir camera, states logged at 10 Hz, process backend)
with the whole fleet exchanged at 30 Hz, against a 10 Hz exchange with only
the camera's aircraft gathered at 30 Hz inside each exchange. Both render
the same frames (their digests are compared); alternating rounds, the
real-time factor of each run's tick loop from ``summary.json``.

    python benchmarks/camera_rate.py --vehicles 512 --seconds 4 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

SCENARIO = """\
schema_version: 1
origin: {{lat_deg: 37.4, lon_deg: -122.0, ground_alt_m: 20}}
rates: {{physics_hz: 120, control_hz: {control}, log_hz: 10}}
duration_s: {seconds}
vehicles:
  - {{id: cam, model: uav700, init: {{north_m: 0, east_m: 0, alt_agl_m: 150, heading_deg: 0,
     airspeed_kt: 100}}}}
  - {{id: f, count: {others}, model: uav700, formation: {{type: grid, spacing_m: 300}},
     init: {{north_m: 2000, east_m: 0, alt_agl_m: 1000, airspeed_kt: 100}}}}
targets:
  - {{id: truck1, kind: truck, north_m: 150, east_m: 0}}
cameras:
  digest: true
  views:
    - {{name: belly, vehicles: cam, mount: nadir, vfov_deg: 40, width_px: 320,
       height_px: 240, rate_hz: 30}}
"""


def run(n: int, control: int, seconds: float, tmp: Path, tag: str) -> dict[str, float | str]:
    from cosim.scenario import load_scenario
    from cosim.sync import Run

    f = tmp / f"{tag}.yaml"
    f.write_text(SCENARIO.format(control=control, seconds=seconds, others=n - 1))
    res = Run(load_scenario(f), tmp / tag, backend="process").run()
    if not res.ok:
        raise RuntimeError(f"{tag}: {res.error}")
    (stream,) = res.summary["cameras"]["streams"]
    return {"rtf": res.summary["real_time_factor"], "frames": stream["frames"],
            "digest": stream["frames_sha256"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=512)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    out: dict[int, list[dict[str, float | str]]] = {30: [], 10: []}
    with tempfile.TemporaryDirectory(prefix="cosim-camrate-") as tmp:
        for r in range(a.rounds):
            for control in ((30, 10) if r % 2 == 0 else (10, 30)):
                out[control].append(run(a.vehicles, control, a.seconds, Path(tmp),
                                        f"r{r}-{control}"))
    same = {x["digest"] for xs in out.values() for x in xs}
    ratios = [float(b["rtf"]) / float(f["rtf"]) for f, b in zip(out[30], out[10])]
    print(f"{a.vehicles} uav700s, one 30 Hz camera, {a.seconds:g} s, {a.rounds} rounds")
    for control, xs in out.items():
        how = " + the camera's aircraft gathered at 30 Hz" if control == 10 else ""
        rtfs = ", ".join(f"{float(x['rtf']):.2f}" for x in xs)
        print(f"  exchange {control} Hz{how}: real-time factor {rtfs}; {xs[0]['frames']} frames")
    print(f"  10 Hz / 30 Hz: {statistics.median(ratios):.2f}x (median of the rounds); "
          f"frames identical: {len(same) == 1}")
    print(json.dumps({"ratios": ratios, "runs": out}, default=str))
    return 0 if len(same) == 1 else 1


if __name__ == "__main__":
    sys.exit(main())
