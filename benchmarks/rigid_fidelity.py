"""How closely the rigid-body tier (class ``fixed_wing_rigid``) and the
point-mass tier (``fixed_wing_batched``) follow JSBSim's uav700 through the
flight-test manoeuvres, and how their level trims compare with JSBSim's.
``--model c172p``: the same for the c172p (its piston engine and propeller
compiled), through manoeuvres of the same kinds written here for a c172p's
speeds (60-110 kt) and trims at 60-110 kt.

Each manoeuvre is a vehicle of a scenario of ``scenarios/flight_test/``
(level turns at 100, 150 and 200 kt, the full-throttle acceleration, the
stall, 50 kt low and slow, goto-loiter, waypoints) or of the two written
here in the same style (a climb, speed steps). The scenario is run once per
tier with every vehicle's ``class`` set to that tier, so the three start
from the same place and get the same commands, each trimmed by its own
trim; the first ``--duration`` seconds (60) are compared, logged at 30 Hz.

For each manoeuvre and tier: the largest difference from JSBSim of the
height (m), the airspeed (kt), the heading (deg, wrapped to +-180) and the
bank (deg), and whether every logged sample is within the bar. The bar at a
sample is the larger of 1 % of JSBSim's value there and a floor of 0.5 m,
0.5 kt or 0.5 deg, where the value is: the height above the ground (what
the manoeuvres command), the true airspeed in knots, the magnitude of the
bank, and for the heading the angle JSBSim has turned since the start (its
unwrapped heading less the first; a heading has no natural zero, so 1 % of
the turn so far). A tier that stopped (an impact) before JSBSim did, or
the other way round, misses the bar. "worst / bar" is the largest ratio of a
difference to its bar over the samples and the four quantities.

The trim: each tier's logged state at t = 0 of a scenario of aircraft
trimmed level at several speeds and heights (JSBSim's ``do_trim(1)``, the
rigid tier's ``RigidAircraft.trim_level``, the point mass's level
throttle): angle of attack, pitch, throttle and roll, and each tier's
differences from JSBSim (bar: 0.1 deg for the angles; the throttle's is
shown, not barred). Prints markdown tables; ``--json FILE`` writes the
figures.

    python benchmarks/rigid_fidelity.py
    python benchmarks/rigid_fidelity.py --model c172p --tiers rigid
    python benchmarks/rigid_fidelity.py --manoeuvres turn_100kt --duration 5 \\
        --tiers rigid --no-trim
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
FLIGHT_TEST = REPO / "scenarios" / "flight_test"
KT = 0.514444
#: tier -> the vehicle class flown (None: the JSBSim tier, the default class)
TIERS: dict[str, str | None] = {"jsbsim": None, "rigid": "fixed_wing_rigid",
                                "point_mass": "fixed_wing_batched"}
#: quantity -> (logged column, scale to the unit shown, floor of the bar)
QUANTITIES = {"alt_m": ("alt_agl_m", 1.0, 0.5), "airspeed_kt": ("airspeed_mps", 1 / KT, 0.5),
              "heading_deg": ("yaw_deg", 1.0, 0.5), "bank_deg": ("roll_deg", 1.0, 0.5)}
RELATIVE = 0.01
TRIM_BAR_DEG = 0.1

ORIGIN = {"lat_deg": 37.0, "lon_deg": -116.0, "ground_alt_m": 1000}
RATES = {"physics_hz": 120, "control_hz": 30, "log_hz": 30}


def _level_300m(vid: str, *later: tuple[float, dict[str, Any]], model: str = "uav700",
                kt: float = 100) -> dict[str, Any]:
    """A scenario in the flight tests' style: one ``model`` level at 300 m
    above the ground, ``kt``, heading north, then the commands ``later``."""
    level = {"heading_deg": 0, "alt_agl_m": 300, "airspeed_kt": kt}
    return {"schema_version": 1, "name": vid, "origin": ORIGIN, "rates": RATES,
            "duration_s": 60,
            "vehicles": [{"id": vid, "model": model, "init": level}],
            "schedule": [{"at_s": t, "vehicles": vid, "command": c}
                         for t, c in ((0.0, level), *later)]}


def _c172p(vid: str, kt: float, *later: tuple[float, dict[str, Any]]) -> dict[str, Any]:
    return _level_300m(vid, *later, model="c172p", kt=kt)


#: the manoeuvres the flight tests lack, and the c172p's (at its speeds:
#: the turns at the 45 deg bank limit, about 12 deg/s at 90 kt, given a new
#: heading about 100 deg further round every 8 s as the flight tests do)
WRITTEN_HERE = {
    "climb": _level_300m("climb", (5.0, {"alt_agl_m": 600})),
    "speed_steps": _level_300m("steps", (5.0, {"airspeed_kt": 140}),
                               (30.0, {"airspeed_kt": 110})),
    "c172p_turn": _c172p("turn", 90, (0.0, {"heading_deg": 100}),
                         *((8.0 * i, {"heading_deg": (100 + 100 * i) % 360})
                           for i in range(1, 8))),
    "c172p_climb": _c172p("climb", 80, (5.0, {"alt_agl_m": 450})),
    "c172p_steps": _c172p("steps", 90, (5.0, {"airspeed_kt": 110}),
                          (30.0, {"airspeed_kt": 70})),
    "c172p_slow": _c172p("slow", 65, (5.0, {"heading_deg": 30})),
    "c172p_acceleration": _c172p("fast", 70, (2.0, {"airspeed_kt": 140})),
    "c172p_goto": _c172p("goto", 90, (0.0, {"goto": {"north_m": 3000, "east_m": 2000,
                                                     "alt_agl_m": 350, "airspeed_kt": 100,
                                                     "loiter_radius_m": 600}})),
}

#: level trims at (kt, m above sea level); the ground at sea level
TRIM_POINTS = ((60, 150), (100, 914.4), (150, 1500), (200, 3048))
C172P_TRIM_POINTS = ((60, 150), (80, 914.4), (100, 1500), (110, 2500))


@dataclass(frozen=True)
class Manoeuvre:
    name: str
    label: str
    scenario: str  # a file of scenarios/flight_test, or a key of WRITTEN_HERE
    vehicle: str


MANOEUVRES = [
    Manoeuvre("turn_100kt", "level turns at 100 kt (45 deg bank)", "level_turns.yaml", "t100"),
    Manoeuvre("turn_150kt", "level turns at 150 kt", "level_turns.yaml", "t150"),
    Manoeuvre("turn_200kt", "level turns at 200 kt", "level_turns.yaml", "t200"),
    Manoeuvre("climb", "climb 300 -> 600 m at 100 kt", "climb", "climb"),
    Manoeuvre("speed_steps", "speed steps 100 -> 140 -> 110 kt", "speed_steps",
              "steps"),
    Manoeuvre("acceleration", "full-throttle acceleration from 100 kt", "acceleration.yaml",
              "fast"),
    Manoeuvre("stall", "stall: idle, protection off, height held", "stall.yaml", "stall"),
    Manoeuvre("slow_low", "50 kt at 30 m", "slow_low.yaml", "slow"),
    Manoeuvre("goto_loiter", "goto 5 km, loiter", "goto_loiter.yaml", "uav"),
    Manoeuvre("waypoints", "3 km square of waypoints at 150 kt", "waypoints.yaml", "uav"),
]
C172P_MANOEUVRES = [
    Manoeuvre("turn_90kt", "level turns at 90 kt (45 deg bank)", "c172p_turn", "turn"),
    Manoeuvre("climb", "climb 300 -> 450 m at 80 kt", "c172p_climb", "climb"),
    Manoeuvre("speed_steps", "speed steps 90 -> 110 -> 70 kt", "c172p_steps", "steps"),
    Manoeuvre("slow", "65 kt, a 30 deg heading change", "c172p_slow", "slow"),
    Manoeuvre("acceleration", "full-throttle acceleration from 70 kt", "c172p_acceleration",
              "fast"),
    Manoeuvre("goto_loiter", "goto 3.6 km at 100 kt, loiter", "c172p_goto", "goto"),
]
#: model -> its manoeuvres, its trim points and the tiers compared by default
#: (the c172p's profile gives the point mass no maximum thrust: rigid only)
MODELS = {"uav700": (MANOEUVRES, TRIM_POINTS, "rigid,point_mass"),
          "c172p": (C172P_MANOEUVRES, C172P_TRIM_POINTS, "rigid")}


def _as_tier(scenario: dict[str, Any], vehicle_class: str | None, duration_s: float,
             keep: set[str] | None = None) -> str:
    """``scenario`` with every vehicle of ``vehicle_class``, run for
    ``duration_s``, logged at 30 Hz, without plots; with ``keep``, only those
    vehicles and their commands (a command names its vehicles, one or a list)."""
    doc = copy.deepcopy(scenario)
    doc["duration_s"] = duration_s
    doc["plot"] = False
    doc.setdefault("rates", {})["log_hz"] = 30
    if keep is not None:
        doc["vehicles"] = [v for v in doc["vehicles"] if v["id"] in keep]
    for v in doc["vehicles"]:
        if vehicle_class is not None:
            v["class"] = vehicle_class
    ids = {v["id"] for v in doc["vehicles"]}
    doc["schedule"] = [e for e in doc.get("schedule", []) if e["at_s"] < duration_s
                       and ids & set([e["vehicles"]] if isinstance(e["vehicles"], str)
                                     else e["vehicles"])]
    return yaml.safe_dump(doc, sort_keys=False)


def _run(text: str, folder: Path) -> dict[str, dict[str, np.ndarray]]:
    """Each vehicle's logged columns of scenario ``text`` run in ``folder``."""
    from cosim.logs import read_states
    from cosim.scenario import parse_scenario
    from cosim.sync import run_scenario

    scn = parse_scenario(text, str(folder / "s.yaml"))
    res = run_scenario(scn, folder / "run", backend="inline")
    if res.stop_reason != "completed":
        raise RuntimeError(f"{scn.name}: the run stopped ({res.stop_reason}): {res.error}")
    t = read_states(folder / "run", ["vehicle", "time_s", "alpha_deg", "pitch_deg",
                                      "throttle", *(c for c, _, _ in QUANTITIES.values())])
    who = np.array(t["vehicle"].to_pylist())
    return {v: {k: np.asarray(t[k].to_pylist(), dtype=float)[who == v]
                for k in t.column_names if k != "vehicle"} for v in sorted(set(who))}


def compare(ref: dict[str, np.ndarray], got: dict[str, np.ndarray]) -> dict[str, Any]:
    """The largest differences of ``got`` from ``ref`` (one vehicle's
    columns) and whether each sample is within the bar (module docstring)."""
    n = min(len(ref["time_s"]), len(got["time_s"]))
    assert np.array_equal(ref["time_s"][:n], got["time_s"][:n])
    out: dict[str, Any] = {"seconds": float(ref["time_s"][n - 1]),
                           "same_length": len(ref["time_s"]) == len(got["time_s"])}
    ok = out["same_length"]
    for q, (col, scale, floor) in QUANTITIES.items():
        a, b = ref[col][:n] * scale, got[col][:n] * scale
        if q == "heading_deg":
            d = (b - a + 180.0) % 360.0 - 180.0
            turned = np.degrees(np.unwrap(np.radians(a)))
            value = np.abs(turned - turned[0])
        else:
            d, value = b - a, np.abs(a)
        bar = np.maximum(RELATIVE * value, floor)
        worst = int(np.argmax(np.abs(d)))
        within = bool(np.all(np.abs(d) <= bar))
        out[q] = {"max_diff": float(np.abs(d[worst])), "at_s": float(ref["time_s"][worst]),
                  "bar_there": float(bar[worst]),
                  "value_range": [float(value.min()), float(value.max())],
                  "worst_fraction_of_bar": float(np.max(np.abs(d) / bar)), "within": within}
        ok = ok and within
    out["within_bar"] = ok
    return out


def fly(names: list[str], tiers: list[str], duration_s: float, tmp: Path,
        model: str = "uav700") -> dict[str, dict[str, Any]]:
    """Each manoeuvre of ``names`` (``model``'s) flown by JSBSim and by ``tiers``."""
    chosen = [m for m in MODELS[model][0] if m.name in names]
    runs: dict[tuple[str, str], dict[str, dict[str, np.ndarray]]] = {}
    for m in chosen:
        doc = WRITTEN_HERE.get(m.scenario) or yaml.safe_load(
            (FLIGHT_TEST / m.scenario).read_text())
        keep = {c.vehicle for c in chosen if c.scenario == m.scenario}
        for tier in ["jsbsim", *tiers]:
            if (m.scenario, tier) not in runs:
                folder = tmp / f"{len(runs)}"
                folder.mkdir()
                runs[m.scenario, tier] = _run(_as_tier(doc, TIERS[tier], duration_s, keep),
                                              folder)
    return {m.name: {"label": m.label, **{tier: compare(runs[m.scenario, "jsbsim"][m.vehicle],
                                                         runs[m.scenario, tier][m.vehicle])
                                          for tier in tiers}} for m in chosen}


def trims(tiers: list[str], tmp: Path, model: str = "uav700") -> list[dict[str, Any]]:
    """Each tier's level trim at ``model``'s trim points (the first logged row)."""
    points = MODELS[model][1]
    doc = {"schema_version": 1, "origin": {**ORIGIN, "ground_alt_m": 0}, "rates": RATES,
           "vehicles": [{"id": f"p{i}", "model": model,
                         "init": {"north_m": 2000 * i, "east_m": 0, "alt_msl_m": h,
                                  "heading_deg": 0, "airspeed_kt": kt}}
                        for i, (kt, h) in enumerate(points)]}
    got = {}
    for tier in ["jsbsim", *tiers]:
        folder = tmp / f"trim-{tier}"
        folder.mkdir()
        got[tier] = _run(_as_tier(doc, TIERS[tier], 0.1), folder)
    rows = []
    for i, (kt, h) in enumerate(points):
        row: dict[str, Any] = {"airspeed_kt": kt, "alt_msl_m": h}
        for tier in ["jsbsim", *tiers]:
            c = got[tier][f"p{i}"]
            assert c["time_s"][0] == 0.0
            row[tier] = {k: float(c[k][0]) for k in ("alpha_deg", "pitch_deg", "throttle",
                                                     "roll_deg")}
        for tier in tiers:
            d = {k: row[tier][k] - row["jsbsim"][k] for k in row["jsbsim"]}
            row[tier]["diff"] = d
            row[tier]["within_bar"] = all(abs(d[k]) <= TRIM_BAR_DEG
                                          for k in ("alpha_deg", "pitch_deg", "roll_deg"))
        rows.append(row)
    return rows


def table(flights: dict[str, dict[str, Any]], trim_rows: list[dict[str, Any]],
          tiers: list[str]) -> str:
    out = ["| manoeuvre | tier | altitude (m) | airspeed (kt) | heading (deg) | bank (deg) "
           "| worst / bar | within the bar |", "|---|---|---|---|---|---|---|---|"]
    for f in flights.values():
        for tier in tiers:
            r = f[tier]
            cells = [f"{r[q]['max_diff']:.3g}" + ("" if r[q]["within"] else " ✗")
                     for q in QUANTITIES]
            verdict = "yes" if r["within_bar"] else "no" + (
                "" if r["same_length"] else f" (stopped apart at {r['seconds']:.1f} s)")
            worst = max(r[q]["worst_fraction_of_bar"] for q in QUANTITIES)
            out.append(f"| {f['label']} | {tier} | " + " | ".join(cells)
                       + f" | {worst:.3g} | {verdict} |")
    if trim_rows:
        out += ["", "| trim (kt, m MSL) | tier | alpha (deg) | pitch (deg) | throttle "
                "| roll (deg) | within 0.1 deg |", "|---|---|---|---|---|---|---|"]
        for row in trim_rows:
            where = f"{row['airspeed_kt']} kt, {row['alt_msl_m']:g} m"
            j = row["jsbsim"]
            out.append(f"| {where} | JSBSim | {j['alpha_deg']:.4f} | {j['pitch_deg']:.4f} "
                       f"| {j['throttle']:.5f} | {j['roll_deg']:.4f} | |")
            for tier in tiers:
                r, d = row[tier], row[tier]["diff"]
                out.append(f"| | {tier} (diff) | {r['alpha_deg']:.4f} ({d['alpha_deg']:+.1e}) "
                           f"| {r['pitch_deg']:.4f} ({d['pitch_deg']:+.1e}) "
                           f"| {r['throttle']:.5f} ({d['throttle']:+.1e}) "
                           f"| {r['roll_deg']:.4f} ({d['roll_deg']:+.1e}) "
                           f"| {'yes' if r['within_bar'] else 'no'} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="uav700", choices=sorted(MODELS),
                    help="the aircraft flown (uav700)")
    ap.add_argument("--manoeuvres",
                    help="comma-separated, of the model's (all): uav700: "
                         + ",".join(m.name for m in MANOEUVRES) + "; c172p: "
                         + ",".join(m.name for m in C172P_MANOEUVRES))
    ap.add_argument("--tiers",
                    help="compared with JSBSim, comma-separated: rigid, point_mass (both for "
                         "the uav700; the c172p's profile gives no point mass: rigid)")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds flown (60)")
    ap.add_argument("--no-trim", action="store_true", help="skip the trim table")
    ap.add_argument("--json", type=Path, help="write the figures here")
    a = ap.parse_args(argv)
    from cosim.errors import CosimError

    known = MODELS[a.model][0]
    names = [x for x in (a.manoeuvres or ",".join(m.name for m in known)).split(",") if x]
    tiers = [x for x in (a.tiers or MODELS[a.model][2]).split(",") if x]
    bad = [x for x in names if x not in {m.name for m in known}] + [
        x for x in tiers if x not in TIERS or x == "jsbsim"]
    if bad:
        ap.error(f"unknown manoeuvre or tier {bad}: the {a.model}'s manoeuvres are "
                 f"{', '.join(m.name for m in known)}; tiers rigid, point_mass")
    if not 0 < a.duration <= 600:
        ap.error(f"--duration {a.duration:g}: expected seconds in (0, 600]")
    with tempfile.TemporaryDirectory() as tmp:
        try:
            flights = fly(names, tiers, a.duration, Path(tmp), a.model)
            trim_rows = [] if a.no_trim else trims(tiers, Path(tmp), a.model)
        except (RuntimeError, CosimError) as e:
            print(e, file=sys.stderr)
            return 1
    print(table(flights, trim_rows, tiers))
    if a.json:
        a.json.write_text(json.dumps({"model": a.model, "duration_s": a.duration,
                                      "manoeuvres": flights,
                                      "trim": trim_rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
