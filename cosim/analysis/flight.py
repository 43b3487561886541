"""Flight-test measurements from logged ground truth, against the equations
of docs/physics.md ("Fixed-wing aircraft").

- turn radius of a steady level turn (least-squares circle through the
  ground track) vs ``R = v^2 / (g tan(phi))`` with the measured speed and bank
- level stall speed ``v_s = sqrt(2 m g / (rho S CL_max))`` from the model's
  own mass, wing area and CL_max, vs the true airspeed at the logged stall
  onset
- speeds, heights and their spread over a window

``python -m cosim.analysis.flight RUN_DIR...`` prints a report of each run.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.units import FT_TO_M, G_MPS2, KT_TO_MPS
from cosim.guidance.commands import min_turn_radius_m
from cosim.logs import read_states

LB_TO_KG = 0.45359237
SQFT_TO_M2 = FT_TO_M ** 2


def isa_density(h_m: Any) -> Any:
    """ISA density (kg/m^3) in the troposphere (below 11 km)."""
    return 1.225 * (1.0 - 2.25577e-5 * np.asarray(h_m, dtype=float)) ** 4.2559


def level_stall_speed_mps(mass_kg: float, wing_area_m2: float, clmax: float,
                          rho: float) -> float:
    """v_s = sqrt(2 m g / (rho S CL_max)): lift at CL_max equals the weight."""
    return math.sqrt(2.0 * mass_kg * G_MPS2 / (rho * wing_area_m2 * clmax))


#: R = v^2 / (g tan(phi)): guidance's own formula
turn_radius_m = min_turn_radius_m


def circle_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares circle (Kasa): centre (x, y) and radius."""
    a = np.column_stack([x, y, np.ones_like(x)])
    b = x * x + y * y
    (c0, c1, c2), *_ = np.linalg.lstsq(a, b, rcond=None)
    xc, yc = c0 / 2.0, c1 / 2.0
    return float(xc), float(yc), float(math.sqrt(c2 + xc * xc + yc * yc))


@dataclass(frozen=True)
class ModelNumbers:
    mass_kg: float
    wing_area_m2: float
    clmax: float


def model_numbers(model: str) -> ModelNumbers:
    """Mass and wing area as JSBSim reads them from the model file; CL_max from
    the model's cosim profile."""
    from cosim.vehicles.jsb import find_model, new_fdm

    m = find_model(model)
    fdm = new_fdm(m, 1 / 120)
    fdm["ic/h-sl-ft"] = 1000.0
    fdm.run_ic()
    if "clmax" not in m.profile:
        raise ValueError(f"model {model!r} has no clmax in its cosim profile")
    return ModelNumbers(fdm["inertia/weight-lbs"] * LB_TO_KG,
                        fdm["metrics/Sw-sqft"] * SQFT_TO_M2, float(m.profile["clmax"]))


def vehicle_columns(run_dir: str | Path, vehicle: str) -> dict[str, np.ndarray]:
    """One vehicle's logged columns as numpy arrays."""
    import pyarrow.compute as pc

    t = read_states(run_dir)
    s = t.filter(pc.equal(t["vehicle"].cast("string"), vehicle))
    if s.num_rows == 0:
        raise ValueError(f"{run_dir}: no vehicle {vehicle!r}")
    return {c: s[c].to_numpy() for c in s.column_names if c not in ("vehicle", "command")}


def events(run_dir: str | Path, kind: str | None = None) -> list[dict[str, Any]]:
    out = [json.loads(x) for x in (Path(run_dir) / "events.jsonl").read_text().splitlines()]
    return [e for e in out if kind is None or e["event"] == kind]


def steady_turn(cols: dict[str, np.ndarray], bank_deg: float, tol_deg: float = 1.0,
                min_s: float = 10.0) -> dict[str, float] | None:
    """The longest stretch banked within ``tol_deg`` of ``bank_deg`` (either
    side), at least ``min_s`` long: fitted radius vs the formula."""
    ok = np.abs(np.abs(cols["roll_deg"]) - bank_deg) <= tol_deg
    best: tuple[int, int] | None = None
    i = 0
    while i < ok.size:
        if ok[i]:
            j = i
            while j + 1 < ok.size and ok[j + 1]:
                j += 1
            if best is None or j - i > best[1] - best[0]:
                best = (i, j)
            i = j + 1
        else:
            i += 1
    if best is None:
        return None
    sl = slice(best[0], best[1] + 1)
    t = cols["time_s"][sl]
    if t[-1] - t[0] < min_s:
        return None
    _, _, r = circle_fit(cols["north_m"][sl], cols["east_m"][sl])
    v = float(np.mean(np.hypot(cols["vn_mps"][sl], cols["ve_mps"][sl])))
    phi = float(np.mean(np.abs(cols["roll_deg"][sl])))
    r_eq = turn_radius_m(v, phi)
    return {"duration_s": float(t[-1] - t[0]), "speed_mps": v, "speed_kt": v / KT_TO_MPS,
            "bank_deg": phi, "radius_m": r, "radius_formula_m": r_eq,
            "radius_error": r / r_eq - 1.0,
            "alt_spread_m": float(np.ptp(cols["alt_msl_m"][sl]))}


def stall_onset(run_dir: str | Path, vehicle: str, model: str) -> dict[str, float]:
    """True airspeed at the first logged stall onset vs the level stall speed
    from the model's numbers at the density of that height."""
    onset = [e for e in events(run_dir, "stall")
             if e["vehicle"] == vehicle and e["phase"] == "onset"]
    if not onset:
        raise ValueError(f"{run_dir}: {vehicle} never stalled")
    cols = vehicle_columns(run_dir, vehicle)
    k = int(np.searchsorted(cols["tick"], onset[0]["tick"]))
    k = min(k, cols["tick"].size - 1)
    nums = model_numbers(model)
    rho = float(isa_density(cols["alt_msl_m"][k]))
    vs = level_stall_speed_mps(nums.mass_kg, nums.wing_area_m2, nums.clmax, rho)
    v = float(cols["airspeed_mps"][k])
    return {"time_s": float(cols["time_s"][k]), "tas_mps": v, "tas_kt": v / KT_TO_MPS,
            "formula_mps": vs, "formula_kt": vs / KT_TO_MPS, "error": v / vs - 1.0,
            "eas_kt": v * math.sqrt(rho / 1.225) / KT_TO_MPS,
            "formula_eas_kt": vs * math.sqrt(rho / 1.225) / KT_TO_MPS,
            "alt_msl_m": float(cols["alt_msl_m"][k])}


def report(run_dir: str | Path) -> dict[str, Any]:
    """Per vehicle: speed and height range, largest bank, steady 45-deg turn,
    stall onset (when the run has one)."""
    import yaml

    run = Path(run_dir)
    t = read_states(run)
    out: dict[str, Any] = {}
    summary = json.loads((run / "summary.json").read_text())
    resolved = (run / "scenario.resolved.yaml").read_text()
    models = {v["id"]: v["model"] for v in yaml.safe_load(resolved)["vehicles"]}
    for vid in dict.fromkeys(t["vehicle"].cast("string").to_pylist()):
        c = vehicle_columns(run, vid)
        r: dict[str, Any] = {
            "airspeed_kt": [float(c["airspeed_mps"].min() / KT_TO_MPS),
                            float(c["airspeed_mps"].max() / KT_TO_MPS)],
            "alt_agl_m": [float(c["alt_agl_m"].min()), float(c["alt_agl_m"].max())],
            "max_abs_bank_deg": float(np.abs(c["roll_deg"]).max()),
        }
        turn = steady_turn(c, 45.0)
        if turn:
            r["turn_45"] = turn
        try:
            r["stall"] = stall_onset(run, vid, models[vid])
        except ValueError:
            pass
        out[vid] = r
    return {"run": str(run), "scenario": summary["scenario"], "vehicles": out}


def main(argv: list[str] | None = None) -> int:
    for d in argv if argv is not None else sys.argv[1:]:
        print(json.dumps(report(d), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
