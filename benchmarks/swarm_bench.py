"""Swarm benchmark (target: flocking with 256 uav700s at >= 1x real
time on the 2-core machine, controller and MAVLink included).

Runs ``cosim run``'s loop (``cosim.sync.Run``) on a generated flocking
scenario as fast as possible and reports the real-time factor and where the
driver's time goes, by timing the parts of the loop in place:

- ``pool.send`` + ``pool.wait``: the physics (process backend: starting the
  workers, stepping the driver's own shard, waiting for the others; inline:
  JSBSim itself);
- ``mavlink exchange``: every endpoint's ``receive`` and ``send_telemetry``
  (handling the swarm's injected commands, telemetry packing, tlogs; the
  telemetry runs while the workers step);
- ``swarm controller``: ``SwarmController.step`` (laws, WGS-84 conversions,
  building commands) and ``to_message`` (encoding each command as the wire
  would);
- ``swarm monitor``: ``SwarmMonitor.update`` (closest pairs every exchange);
- ``guidance``: ``FixedWingGuidance.update`` / ``command``;
- the rest of the loop (state log, events, status checks).

Usage: ``python benchmarks/swarm_bench.py [--vehicles 256] [--seconds 60]
[--backend process] [--workers 2] [--json FILE] [--no-swarm]``. Not a test: numbers go
to benchmarks/README.md by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

TIMES: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)


def _wrap(owner: Any, name: str, label: str) -> None:
    fn = getattr(owner, name)

    def timed(*a: Any, **kw: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            TIMES[label] += time.perf_counter() - t0
            CALLS[label] += 1

    setattr(owner, name, timed)


def scenario_text(n: int, seconds: float) -> str:
    cols = int(math.ceil(math.sqrt(n)))
    return f"""\
schema_version: 1
name: swarm_bench_{n}
origin: {{lat_deg: 36.95, lon_deg: -116.05, ground_alt_m: 1000}}
duration_s: {seconds}
vehicles:
  - id: uav
    count: {n}
    model: uav700
    formation: {{type: grid, spacing_m: 400, columns: {cols}, alt_step_m: 10}}
    init: {{north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}}
swarm:
  rate_hz: 1
  separation_warn_m: 5
  groups:
    - name: swarm
      vehicles: all
      phases:
        - {{behaviour: flocking, mu: 0.5, k_s: 0.05, duration_s: {seconds * 2},
           q: {{bearing_deg: 45, distance_m: 2000}}}}
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=256)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--backend", choices=("inline", "process"), default="process")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--json", metavar="FILE")
    ap.add_argument("--no-swarm", action="store_true",
                    help="the same vehicles without the swarm: section (no controller, no "
                         "MAVLink): the physics ceiling for comparison")
    a = ap.parse_args(argv)

    from cosim.fdm_pool.base import Pool
    from cosim.mavlink.endpoint import MavlinkEndpoint
    from cosim.scenario import parse_scenario
    from cosim.swarm import participant as swarm_participant
    from cosim.swarm.controller import SwarmController
    from cosim.swarm.metrics import SwarmMonitor
    from cosim.sync import Run
    from cosim.vehicles.fixed_wing.guidance import FixedWingGuidance

    _wrap(Pool, "send", "physics (pool.send + wait)")  # both pools' (they implement _send)
    _wrap(Pool, "wait", "physics (pool.send + wait)")
    _wrap(MavlinkEndpoint, "receive", "mavlink exchange")
    _wrap(MavlinkEndpoint, "send_telemetry", "mavlink exchange")
    _wrap(SwarmController, "step", "swarm controller (laws + commands)")
    _wrap(swarm_participant, "to_message", "swarm commands -> messages")
    _wrap(SwarmMonitor, "update", "swarm monitor (separation)")
    _wrap(FixedWingGuidance, "update", "guidance")
    _wrap(FixedWingGuidance, "command", "guidance")

    with tempfile.TemporaryDirectory() as tmp:
        text = scenario_text(a.vehicles, a.seconds)
        if a.no_swarm:
            text = text[:text.index("swarm:\n")]
        scn = parse_scenario(text, str(Path(tmp) / "bench.yaml"), check_properties=False)
        t0 = time.perf_counter()
        res = Run(scn, Path(tmp) / "out", backend=a.backend, workers=a.workers).run()
        total_s = time.perf_counter() - t0
    s = res.summary
    loop_s = float(s["wall_time_s"])
    parts = {k: round(v, 3) for k, v in sorted(TIMES.items(), key=lambda kv: -kv[1])}
    in_parts = sum(TIMES.values())  # the timed parts do not nest
    out = {
        "vehicles": a.vehicles, "backend": s["backend"], "workers": s["workers"],
        "sim_time_s": s["sim_time_s"], "startup_s": s["startup_s"], "loop_s": loop_s,
        "real_time_factor": s["real_time_factor"], "stop_reason": res.stop_reason,
        "total_s": round(total_s, 2), "parts_s": parts,
        "rest_of_loop_s": round(loop_s - in_parts, 3),
        "swarm_commands": s.get("swarm", {}).get("commands_sent"),
        "mavlink_packets_out": s.get("mavlink", {}).get("counters", {}).get("packets_out"),
    }
    print(json.dumps(out, indent=1))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0 if res.stop_reason == "completed" else 1


if __name__ == "__main__":
    raise SystemExit(main())
