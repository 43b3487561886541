"""The project's F450 quadrotor model (``aircraft/F450``): it loads without
JSBSim's "Failed to tie property" messages, each rotor's thrust is
``T = C_T rho n^2 D^4`` and, at the hover throttle, the rotors carry the weight."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

AIRCRAFT = Path(__file__).resolve().parent.parent.parent / "aircraft"
D_M = 9.4 * 0.0254  # DJI 9450 propeller diameter
C_T0 = 0.1288  # its thrust coefficient at J = 0 (DJI_9450.xml)
LBF_TO_N = 4.4482216152605
SLUG_FT3_TO_KG_M3 = 515.378818


def _fdm(throttle: float, seconds: float = 4.0):
    import jsbsim

    root = jsbsim.get_default_root_dir()
    f = jsbsim.FGFDMExec(root)
    f.set_debug_level(0)
    assert f.load_model_with_paths("F450", str(AIRCRAFT), root + "/engine",
                                   str(AIRCRAFT / "systems"))
    f.set_dt(1 / 120)
    f["ic/h-agl-ft"] = 300.0
    f["ic/lat-geod-deg"], f["ic/long-gc-deg"] = 47.0, 8.0
    f["ic/u-fps"] = f["ic/v-fps"] = f["ic/w-fps"] = 0.0
    f.run_ic()
    for i in range(4):
        f[f"propulsion/engine[{i}]/set-running"] = 1
    for esc in ("FR", "AL", "FL", "AR"):  # straight to the motors (cosim's controller off)
        f[f"fcs/cmd{esc}_ext_nd"] = throttle
    for _ in range(round(seconds * 120)):
        f.run()
    return f


def _climb_accel(throttle: float) -> tuple[float, object]:
    f = _fdm(throttle)
    v0 = f["velocities/h-dot-fps"]
    for _ in range(60):
        f.run()
    return (f["velocities/h-dot-fps"] - v0) / 0.5, f


def test_the_model_loads_without_property_tie_failures() -> None:
    code = ("import jsbsim, sys; r = jsbsim.get_default_root_dir(); f = jsbsim.FGFDMExec(r); "
            f"ok = f.load_model_with_paths('F450', {str(AIRCRAFT)!r}, r + '/engine', "
            f"{str(AIRCRAFT / 'systems')!r}); sys.exit(0 if ok else 1)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0, p.stdout + p.stderr
    out = p.stdout + p.stderr
    assert "Failed to tie property" not in out and "INCOMPATIBLE" not in out, out


def test_rotor_thrust_is_ct_rho_n2_d4_and_carries_the_weight_at_hover() -> None:
    lo, hi = 0.1, 0.9  # bisect the throttle on the vertical acceleration
    for _ in range(20):
        mid = (lo + hi) / 2
        a, _ = _climb_accel(mid)
        lo, hi = (lo, mid) if a > 0 else (mid, hi)
    a, f = _climb_accel((lo + hi) / 2)
    assert (lo + hi) / 2 == pytest.approx(0.409, abs=0.005)
    rho = f["atmosphere/rho-slugs_ft3"] * SLUG_FT3_TO_KG_M3
    total = 0.0
    for i in range(4):
        n = f[f"propulsion/engine[{i}]/propeller-rpm"] / 60.0
        thrust_n = f[f"propulsion/engine[{i}]/thrust-lbs"] * LBF_TO_N
        assert f[f"propulsion/engine[{i}]/thrust-coefficient"] == pytest.approx(C_T0)
        assert thrust_n == pytest.approx(C_T0 * rho * n ** 2 * D_M ** 4, rel=1e-5)
        total += thrust_n
    weight_n = f["inertia/weight-lbs"] * LBF_TO_N
    assert weight_n == pytest.approx(1.4 * 9.80665, rel=1e-3)
    assert total == pytest.approx(weight_n, rel=2e-3)
