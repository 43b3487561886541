"""How closely the batched point-mass fixed-wing (class ``fixed_wing_batched``)
follows JSBSim's uav700 under the same autopilot commands, flown side by side
in one run: a 180-degree heading change at 100 kt (its turn radius at the
45-degree bank limit, and the time to 63% and 90% of the heading change), a
speed step from 100 to 140 kt, a climb from 300 to 600 m (the highest climb
rate and the time to 63% of the height) and a deceleration with the throttle
closed and stall protection off while holding height (the airspeed at the
stall). Prints a markdown table; ``--json FILE`` writes the figures.

    python benchmarks/batched_fidelity.py
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

KT = 0.514444
G = 9.80665

SCENARIO = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 30}
duration_s: 160
vehicles:
  - {id: jsb, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}
  - {id: pm, class: fixed_wing_batched, model: uav700,
     init: {north_m: 0, east_m: 500, alt_agl_m: 300, airspeed_kt: 100}}
  - {id: jsb_stall, model: uav700,
     init: {north_m: 5000, east_m: 0, alt_agl_m: 1000, airspeed_kt: 80}}
  - {id: pm_stall, class: fixed_wing_batched, model: uav700,
     init: {north_m: 5000, east_m: 500, alt_agl_m: 1000, airspeed_kt: 80}}
schedule:
  - {at_s: 1, vehicles: [jsb, pm], command: {heading_deg: 0, alt_agl_m: 300, airspeed_kt: 100}}
  - {at_s: 10, vehicles: [jsb, pm], command: {heading_deg: 180}}
  - {at_s: 50, vehicles: [jsb, pm], command: {airspeed_kt: 140}}
  - {at_s: 80, vehicles: [jsb, pm], command: {alt_agl_m: 600}}
  - {at_s: 1, vehicles: [jsb_stall, pm_stall],
     command: {heading_deg: 0, alt_agl_m: 1000, stall_protection: false, throttle: 0}}
"""


def measure(run: Path) -> dict[str, dict[str, float]]:
    from cosim.logs import read_states

    t = read_states(run)
    who = np.array(t["vehicle"].to_pylist())
    events = [json.loads(x) for x in (run / "events.jsonl").read_text().splitlines()]

    def col(v: str, k: str) -> np.ndarray:
        return np.asarray(t[k].to_pylist(), dtype=float)[who == v]

    out: dict[str, dict[str, float]] = {}
    for tier, (v, vs) in {"jsbsim": ("jsb", "jsb_stall"), "batched": ("pm", "pm_stall")}.items():
        ts, yaw, spd = col(v, "time_s"), col(v, "yaw_deg"), col(v, "airspeed_mps")
        roll, alt, vd = col(v, "roll_deg"), col(v, "alt_agl_m"), col(v, "vd_mps")
        r: dict[str, float] = {}
        m = (ts >= 10) & (ts < 50)
        y = np.degrees(np.unwrap(np.radians(yaw[m])))
        y = np.abs(y - y[0])
        tt = ts[m] - 10
        r["heading_t63_s"] = float(tt[np.argmax(y >= 0.632 * 180)])
        r["heading_t90_s"] = float(tt[np.argmax(y >= 0.9 * 180)])
        steady = np.abs(np.abs(roll[m]) - 45.0) < 1.0
        rate = np.abs(np.gradient(np.radians(np.unwrap(np.radians(yaw[m])) * 180 / math.pi),
                                  ts[m]))
        r["turn_radius_45_m"] = float(np.median(spd[m][steady] / rate[steady]))
        r["turn_radius_formula_m"] = float(np.median(spd[m][steady] ** 2
                                                     / (G * math.tan(math.radians(45)))))
        m = (ts >= 50) & (ts < 80)
        s, tt = spd[m], ts[m] - 50
        s0, s1 = s[0], 140 * KT
        r["speed_t63_s"] = float(tt[np.argmax(s >= s0 + 0.632 * (s1 - s0))])
        r["speed_t90_s"] = float(tt[np.argmax(s >= s0 + 0.9 * (s1 - s0))])
        m = ts >= 80
        r["climb_max_mps"] = float((-vd[m]).max())
        r["climb_t63_s"] = float((ts[m] - 80)[np.argmax(alt[m] >= 300 + 0.632 * 300)])
        onset = [e for e in events if e["event"] == "stall" and e["vehicle"] == vs
                 and e["phase"] == "onset"]
        tss = col(vs, "time_s")
        r["stall_speed_kt"] = float(col(vs, "airspeed_mps")[np.argmin(
            np.abs(tss - onset[0]["time_s"]))] / KT) if onset else math.nan
        out[tier] = r
    return out


LABELS = {
    "turn_radius_45_m": "turn radius at 45 deg bank (m)",
    "heading_t63_s": "180 deg heading change: time to 63% (s)",
    "heading_t90_s": "180 deg heading change: time to 90% (s)",
    "speed_t63_s": "speed 100 -> 140 kt: time to 63% (s)",
    "speed_t90_s": "speed 100 -> 140 kt: time to 90% (s)",
    "climb_max_mps": "climb 300 -> 600 m: highest climb rate (m/s)",
    "climb_t63_s": "climb 300 -> 600 m: time to 63% (s)",
    "stall_speed_kt": "level stall speed, 1000 m AGL (kt TAS)",
}


def table(res: dict[str, dict[str, float]]) -> str:
    rows = ["| measure | JSBSim uav700 | batched | difference |", "|---|---|---|---|"]
    for k, label in LABELS.items():
        a, b = res["jsbsim"][k], res["batched"][k]
        rows.append(f"| {label} | {a:.2f} | {b:.2f} | {100 * (b - a) / a:+.1f}% |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", type=Path, help="write the figures here")
    a = ap.parse_args(argv)
    from cosim.scenario import parse_scenario
    from cosim.sync import run_scenario

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        scn = parse_scenario(SCENARIO, str(Path(tmp) / "fidelity.yaml"))
        res = run_scenario(scn, out, backend="inline")
        if res.stop_reason != "completed":
            print(f"run failed: {res.error}", file=sys.stderr)
            return 1
        got = measure(out)
    print(table(got))
    if a.json:
        a.json.write_text(json.dumps(got, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
