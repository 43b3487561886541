"""Live runs (inline backend, as fast as possible): the behaviours reach
their goals in the flight model, the commands respect the stall speed, and
an outside controller over UDP gives bit-identical tracks."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.analysis.flight import model_numbers
from cosim.cli import main
from cosim.guidance.commands import G_MPS2
from cosim.logs import read_states
from cosim.scenario import Scenario, parse_scenario
from cosim.swarm import laws
from cosim.sync import run_scenario
from tests.mavlink.mavtest import free_udp_port

ORIGIN = "origin: {lat_deg: 36.95, lon_deg: -116.05, ground_alt_m: 1000}\n"


pytestmark = pytest.mark.integration  # swarms flown for minutes of simulated time


def _scenario(tmp: Path, name: str, duration_s: float, vehicles: str, swarm: str) -> Path:
    p = tmp / f"{name}.yaml"
    p.write_text(f"schema_version: 1\nname: {name}\n{ORIGIN}duration_s: {duration_s}\n"
                 f"vehicles:\n{vehicles}swarm:\n{swarm}")
    return p


def _run(path: Path, out: Path) -> tuple[Scenario, dict[str, Any]]:
    scn = parse_scenario(path.read_text(), str(path))
    res = run_scenario(scn, out, backend="inline")
    assert res.stop_reason == "completed", res.summary.get("error")
    return scn, res.summary


def _phases(summary: dict[str, Any], group: str = "swarm") -> list[dict[str, Any]]:
    return list(summary["swarm"]["groups"][group]["phases"])


def _tracks(out: Path, ids: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(times (T,), north/east (T, n, 2)) from states.parquet."""
    t = read_states(out)
    veh = np.array(t["vehicle"].to_pylist())
    time_s = np.array(t["time_s"].to_pylist())
    ne = np.stack([np.array(t["north_m"].to_pylist()), np.array(t["east_m"].to_pylist())], 1)
    times = np.unique(time_s)
    pos = np.stack([ne[veh == v] for v in ids], axis=1)
    return times, pos


EIGHT_ON_4KM = """\
  - id: uav
    count: 8
    model: uav700
    formation: {type: circle, radius_m: 2000, alt_step_m: 30}
    init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 90, airspeed_kt: 100}
"""
K_S, R_M = 0.03, 300.0


@pytest.fixture(scope="module")
def rendezvous(tmp_path_factory: pytest.TempPathFactory) -> tuple[Scenario, dict[str, Any], Path]:
    tmp = tmp_path_factory.mktemp("rv")
    p = _scenario(tmp, "rv8", 120, EIGHT_ON_4KM, f"""\
  groups:
    - name: swarm
      vehicles: all
      layer_spacing_m: 30
      phases: [{{behaviour: rendezvous, mu: 1.0, k_s: {K_S}, radius_m: {R_M:g}}}]
""")
    scn, summary = _run(p, tmp / "out")
    return scn, summary, tmp / "out"


def test_rendezvous_of_8_uav700_from_4km_within_the_derived_bound(
        rendezvous: tuple[Scenario, dict[str, Any], Path]) -> None:
    """The bound. Each vehicle starts d0 = 2000 m from the centroid (a 4 km
    circle; symmetric, so the centroid starts at the centre), heading east.
    The commanded speed is k_s d clipped below by the loiter floor
    v_floor = 1.2 s_stall(45 deg) and above by AIRSPEED_MAX, so it never
    exceeds v_hi = k_s d0 = 60 m/s (d only shrinks toward the goal) and
    the airspeed never drops below v_floor. Worst case, a vehicle flies
    directly away from the centroid: it turns through 180 deg at the bank
    limit (radius r = v_hi^2 / (g tan 45 deg) = 367 m, a half circle pi r
    long), which puts it at most d0 + 2 r from the centroid, then flies
    straight to within R. Path <= pi r + d0 + 2 r - R; time <= path /
    v_floor, plus one controller period and one exchange of latency:
    T <= (pi 367 + 2000 + 734 - 300) / 32.0 + 1 + 1/30 = about 114 s."""
    scn, summary, _ = rendezvous
    nums = model_numbers("uav700")
    alt = scn.vehicles[0].alt_msl_m
    k_stall = float(laws.level_stall_constant_mps(nums.mass_kg, nums.wing_area_m2, nums.clmax,
                                                   alt))
    v_floor = 1.2 * k_stall / math.sqrt(math.cos(math.radians(45)))
    d0 = 2000.0
    v_hi = K_S * d0
    r_turn = v_hi ** 2 / (G_MPS2 * math.tan(math.radians(45)))
    bound_s = (math.pi * r_turn + d0 + 2 * r_turn - R_M) / v_floor + 1.0 + 1 / 30
    assert 100 < bound_s < 120  # the number stated above
    (ph,) = _phases(summary)
    assert ph["reason"] == "converged" and ph["converged"]
    assert ph["time_s"] <= bound_s, (ph["time_s"], bound_s)
    assert ph["final_spread_max_m"] <= R_M + 20  # ground truth agrees (1 s of flight later)
    # altitude layers: the closest pair is never nearer than about the layer spacing
    assert summary["swarm"]["min_separation_3d"]["distance_m"] > 15.0
    assert summary["events"].get("ground_impact", 0) == 0


def test_commands_never_below_the_stall_speed(
        rendezvous: tuple[Scenario, dict[str, Any], Path]) -> None:
    """Every command sent, against the stall speed recomputed here from the model
    (JSBSim's mass and wing area, the profile's CL_max) and the telemetry's bank."""
    _, summary, out = rendezvous
    nums = model_numbers("uav700")
    rows = list(csv.DictReader(open(out / "swarm_commands.csv")))
    assert len(rows) == summary["swarm"]["commands_sent"] > 8 * 30
    assert summary["swarm"]["acks"] == {"accepted": len(rows)}
    # the telemetry it used is the truth at the command's tick (the controller acts
    # right after that tick's telemetry; float32 roll, millimetre altitude)
    t = read_states(out)
    truth = {(tk, v): (rl, al) for tk, v, rl, al in zip(
        t["tick"].to_pylist(), t["vehicle"].to_pylist(), t["roll_deg"].to_pylist(),
        t["alt_msl_m"].to_pylist())}
    checked = 0
    for r in rows:
        k = laws.level_stall_constant_mps(nums.mass_kg, nums.wing_area_m2, nums.clmax,
                                          float(r["alt_msl_m"]))
        stall = float(k) / math.sqrt(math.cos(float(r["roll_rad"])))
        assert float(r["speed_mps"]) >= stall, r
        assert float(r["speed_mps"]) >= 26.0  # AIRSPEED_MIN of the uav700
        true = truth.get((int(r["tick"]), r["vehicle"]))
        if true is not None:
            assert float(r["roll_rad"]) == pytest.approx(math.radians(true[0]), abs=1e-6), r
            assert float(r["alt_msl_m"]) == pytest.approx(true[1], abs=1e-3), r
            checked += 1
    assert checked == len(rows)


def test_swarm_plot_and_phase_events(rendezvous: tuple[Scenario, dict[str, Any], Path]) -> None:
    _, summary, out = rendezvous
    assert (out / "swarm.png").stat().st_size > 10_000
    # the closest pair at every exchange (120 s at 30 Hz: ticks 0, 4, ..., 14396)
    sep = list(csv.DictReader(open(out / "swarm_separation.csv")))
    assert len(sep) == 120 * 30
    d3 = [float(r["min_separation_3d_m"]) for r in sep]
    assert min(d3) == pytest.approx(summary["swarm"]["min_separation_3d"]["distance_m"],
                                    abs=1e-3)
    assert all(float(r["min_separation_horizontal_m"]) <= float(r["min_separation_3d_m"])
               for r in sep)
    ev = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
    ph = [e for e in ev if e["event"] == "swarm_phase"]
    assert [(e["state"], e.get("reason")) for e in ph] == [("start", None),
                                                           ("end", "converged")]
    assert ph[1]["tick"] / 120 == _phases(summary)[0]["time_s"]


def test_anti_rendezvous_reaches_r(tmp_path: Path) -> None:
    p = _scenario(tmp_path, "anti", 75, """\
  - id: uav
    count: 6
    model: uav700
    formation: {type: circle, radius_m: 300, alt_step_m: 30}
    init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 90, airspeed_kt: 80}
""", """\
  groups:
    - name: swarm
      vehicles: all
      phases: [{behaviour: anti_rendezvous, mu: -1.0, k_s: 0.05, radius_m: 1200}]
""")
    scn, summary = _run(p, tmp_path / "out")
    (ph,) = _phases(summary)
    assert ph["reason"] == "converged", ph
    assert ph["time_s"] < 70
    # ground truth: at the end every vehicle is at least R from the centroid (the
    # controller decided on telemetry up to one exchange old)
    ids = [v.id for v in scn.vehicles]
    times, pos = _tracks(tmp_path / "out", ids)
    k = int(np.searchsorted(times, ph["end_s"]))
    d = laws.distances_to_centroid_m(pos[k])
    assert d.min() >= 1200 - 5


def test_flocking_moves_the_centroid_along_q_with_bounded_spread(tmp_path: Path) -> None:
    p = _scenario(tmp_path, "flock", 60, """\
  - id: uav
    count: 8
    model: uav700
    formation: {type: grid, spacing_m: 500, columns: 4, alt_step_m: 30}
    init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0, airspeed_kt: 100}
""", """\
  groups:
    - name: swarm
      vehicles: all
      layer_spacing_m: 30
      phases: [{behaviour: flocking, mu: 0.5, k_s: 0.05, duration_s: 50,
                q: {bearing_deg: 120, distance_m: 1500}}]
""")
    scn, summary = _run(p, tmp_path / "out")
    (ph,) = _phases(summary)
    assert ph["reason"] == "duration" and ph["time_s"] == 50
    assert summary["events"]["swarm_phase"] == 2
    times, pos = _tracks(tmp_path / "out", [v.id for v in scn.vehicles])
    c = pos.mean(axis=1)
    # after the first 20 s (the turn onto q), the centroid moves along q
    k0, k1 = int(np.searchsorted(times, 20.0)), int(np.searchsorted(times, 50.0))
    dn, de = c[k1] - c[k0]
    bearing = math.degrees(math.atan2(de, dn)) % 360
    assert abs(bearing - 120) <= 10, bearing
    assert math.hypot(dn, de) > 30 * 26  # at least AIRSPEED_MIN for 30 s
    spread = np.array([laws.distances_to_centroid_m(pos[k]).max() for k in range(k1)])
    assert spread.max() <= spread[0] * 1.1  # never wider than the start (+10%)
    assert spread[k1 - 1] < 0.5 * spread[0]  # and it gathered


def test_mixed_group_converges(tmp_path: Path) -> None:
    p = _scenario(tmp_path, "mixed", 90, """\
  - id: jet
    count: 2
    model: uav700
    formation: {type: line, spacing_m: 1500, bearing_deg: 90}
    init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
  - id: cessna
    count: 2
    model: c172p
    formation: {type: line, spacing_m: 1500, bearing_deg: 90}
    init: {north_m: 1500, east_m: 0, alt_agl_m: 560, heading_deg: 180, airspeed_kt: 90}
""", """\
  groups:
    - name: swarm
      vehicles: all
      layer_spacing_m: 30
      phases: [{behaviour: rendezvous, mu: 1.0, k_s: 0.03, radius_m: 400, timeout_s: 85}]
""")
    _, summary = _run(p, tmp_path / "out")
    (ph,) = _phases(summary)
    assert ph["reason"] == "converged", ph
    assert summary["swarm"]["acks"].get("refused", 0) == 0
    # each model's own envelope: the c172p never below its 55 kt (29 m/s) minimum
    rows = list(csv.DictReader(open(tmp_path / "out" / "swarm_commands.csv")))
    cessna = [float(r["speed_mps"]) for r in rows if r["vehicle"].startswith("cessna")]
    jet = [float(r["speed_mps"]) for r in rows if r["vehicle"].startswith("jet")]
    assert min(cessna) >= 29.0 and min(jet) >= 26.0


def test_external_controller_gives_the_same_tracks_as_in_process(tmp_path: Path) -> None:
    p = _scenario(tmp_path, "ext", 15, EIGHT_ON_4KM, """\
  rate_hz: 2
  groups:
    - name: swarm
      vehicles: all
      layer_spacing_m: 30
      phases: [{behaviour: rendezvous, mu: 0.7, k_s: 0.03, radius_m: 300}]
""")
    _run(p, tmp_path / "inproc")
    port = free_udp_port()
    sim = subprocess.Popen(
        [sys.executable, "-m", "cosim", "run", str(p), "--out", str(tmp_path / "ext"),
         "--backend", "inline", "--no-progress", "--mavlink", f"udpin:127.0.0.1:{port}",
         "--external-controller"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        assert main(["swarm", str(p), "--connect", f"udpout:127.0.0.1:{port}", "--out",
                     str(tmp_path / "ctl"), "--connect-timeout-s", "60"]) == 0
        out, _ = sim.communicate(timeout=60)
    finally:
        if sim.poll() is None:
            sim.kill()
    assert sim.returncode == 0, out.decode()[-2000:]
    a, b = read_states(tmp_path / "inproc"), read_states(tmp_path / "ext")
    assert a.num_rows == b.num_rows == 8 * (150 + 1)
    for col in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "airspeed_mps", "command"):
        assert a[col].to_pylist() == b[col].to_pylist(), col
    # the outside controller sent exactly the in-process commands
    ext = json.loads((tmp_path / "ctl" / "swarm.json").read_text())
    inproc = json.loads((tmp_path / "inproc" / "summary.json").read_text())["swarm"]
    assert ext["commands_sent"] == inproc["commands_sent"] == 8 * 30
    assert (tmp_path / "ctl" / "swarm_commands.csv").read_text() == \
        (tmp_path / "inproc" / "swarm_commands.csv").read_text()
    assert (tmp_path / "ctl" / "swarm.png").exists()
    # the same phase events, the unfinished phase closed by the end of the run
    ext_ev = [json.loads(x) for x in (tmp_path / "ctl" / "swarm_events.jsonl").read_text()
              .splitlines() if '"swarm_phase"' in x]
    in_ev = [json.loads(x) for x in (tmp_path / "inproc" / "events.jsonl").read_text()
             .splitlines() if '"swarm_phase"' in x]
    assert [(e["tick"], e["state"], e.get("reason")) for e in ext_ev] == \
        [(e["tick"], e["state"], e.get("reason")) for e in in_ev] == \
        [(0, "start", None), (1800, "end", "run_end")]


def test_cosim_swarm_usage_and_no_simulation(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                             ) -> None:
    p = _scenario(tmp_path, "lone", 5, EIGHT_ON_4KM, """\
  groups: [{vehicles: all, phases: [{behaviour: rendezvous, radius_m: 300}]}]
""")
    assert main(["swarm", str(p), "--connect", "udpin:127.0.0.1:5"]) == 2
    assert "expected udpout:HOST:PORT" in capsys.readouterr().err
    port = free_udp_port()  # nobody listens there
    assert main(["swarm", str(p), "--connect", f"udpout:127.0.0.1:{port}",
                 "--connect-timeout-s", "0.6"]) == 1
    assert "no answer from the simulation" in capsys.readouterr().err
