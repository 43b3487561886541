"""The swarm: section: validation with lines, all problems at once; the
controller's speeds against the stall speed with synthetic telemetry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.mavlink import adapter as mav
from cosim.scenario import parse_scenario
from cosim.swarm.config import SwarmSpec
from cosim.swarm.controller import SwarmController, to_message

HEAD = """\
schema_version: 1
origin: {lat_deg: 36.95, lon_deg: -116.05, ground_alt_m: 1000}
duration_s: 10
vehicles:
  - id: uav
    count: 4
    model: uav700
    formation: {type: line, spacing_m: 500}
    init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 90, airspeed_kt: 100}
  - id: cessna
    model: c172p
    init: {north_m: 2000, east_m: 0, alt_agl_m: 400, heading_deg: 90, airspeed_kt: 90}
"""


def test_a_good_section_parses_with_defaults() -> None:
    scn = parse_scenario(HEAD + """\
swarm:
  groups:
    - vehicles: "uav*"
      layer_spacing_m: 20
      phases:
        - {behaviour: anti_rendezvous, radius_m: 800}
        - {behaviour: flocking, duration_s: 60, q: {bearing_deg: 90, distance_m: 1000}}
        - {behaviour: rendezvous, radius_m: 300, timeout_s: 100}
""", "s.yaml")
    spec = scn.sections["swarm"]
    assert isinstance(spec, SwarmSpec)
    assert spec.rate_hz == 1.0 and spec.every_ticks == 120
    g = spec.groups[0]
    assert g.name == "group0" and g.rows == (0, 1, 2, 3) and g.layer_spacing_m == 20
    assert [p.behaviour for p in g.phases] == ["anti_rendezvous", "flocking", "rendezvous"]
    assert g.phases[0].mu == -1.0 and g.phases[1].mu == 0.5 and g.phases[2].mu == 1.0
    assert g.phases[1].q_ne_m == pytest.approx((0.0, 1000.0))
    assert g.phases[2].timeout_s == 100


def test_every_problem_with_its_line() -> None:
    text = HEAD + """\
swarm:
  rate_hz: 7
  groups:
    - name: a
      vehicles: ["uav0", "uav1", "nobody*"]
      phases:
        - {behaviour: rendezvous, mu: -0.5, radius_m: 300}
        - {behaviour: anti_rendezvous, mu: 0.5}
        - {behaviour: flocking, duration_s: 10}
        - {behaviour: flocking, radius_m: 3, duration_s: 5, q: {bearing_deg: 1, north_m: 3}}
        - {behaviour: hover}
    - name: a
      vehicles: "uav1"
      phases: []
"""
    with pytest.raises(ConfigError) as ei:
        parse_scenario(text, "sw.yaml")
    msgs = ei.value.problems
    joined = "\n".join(msgs)

    def has(line: int, fragment: str) -> bool:
        return any(m.startswith(f"sw.yaml:{line}: ") and fragment in m for m in msgs)

    assert has(14, "swarm.rate_hz: rate_hz 7 must divide physics_hz 120"), joined
    assert has(17, "'nobody*' matches no vehicle"), joined
    assert has(19, "rendezvous needs 0 < mu <= 1"), joined
    assert has(20, "anti_rendezvous needs mu < 0"), joined
    assert has(20, "missing required key 'radius_m'"), joined
    assert has(21, "flocking needs q"), joined
    assert has(22, "flocking ends after duration_s, not at a radius"), joined
    assert has(22, "give q as bearing_deg + distance_m or as north_m + east_m, not both"), joined
    assert has(23, "expected one of: rendezvous, anti_rendezvous, flocking; got 'hover'"), joined
    assert has(24, "duplicate group name 'a'"), joined
    assert has(25, "vehicle 'uav1' is already in group 'a'"), joined
    assert has(25, "a swarm group needs at least 2 vehicles"), joined
    assert has(26, "expected phases: a non-empty list"), joined


def test_rate_must_be_whole_exchanges() -> None:
    # 120 Hz physics, 30 Hz exchanges (4 ticks): 40 Hz gives 3 ticks per step
    with pytest.raises(ConfigError, match=r"rate_hz 40 gives 3 physics ticks per step, not a "
                                          r"multiple of the 4 ticks per exchange"):
        parse_scenario(HEAD + "swarm:\n  rate_hz: 40\n  groups:\n    - phases: "
                              "[{behaviour: rendezvous, radius_m: 300}]\n", "s.yaml")


def test_telemetry_the_controller_reads_cannot_be_switched_off() -> None:
    with pytest.raises(ConfigError, match=r"s.yaml:13: mavlink.rates_hz.ATTITUDE: the swarm "
                                          r"controller reads ATTITUDE"):
        parse_scenario(HEAD + "mavlink: {rates_hz: {ATTITUDE: 0}}\nswarm:\n  groups:\n"
                              "    - phases: [{behaviour: rendezvous, radius_m: 300}]\n",
                       "s.yaml")


def _controller(roll_deg: float) -> SwarmController:
    scn = parse_scenario(HEAD + """\
swarm:
  stall_margin: 1.0
  groups:
    - vehicles: "uav*"
      phases: [{behaviour: rendezvous, k_s: 0.001, radius_m: 10}]
""", "s.yaml")
    ctl = SwarmController(scn.sections["swarm"], scn.vehicles, scn.origin.frame, 120.0)
    for i, v in enumerate(scn.vehicles[:4]):
        ctl.on_message(mav.make_message(
            "GLOBAL_POSITION_INT", src_system=i + 1, src_component=1,
            lat=round(v.lat_deg * 1e7), lon=round(v.lon_deg * 1e7),
            alt=round(v.alt_msl_m * 1000)))
        ctl.on_message(mav.make_message("ATTITUDE", src_system=i + 1, src_component=1,
                                        roll=math.radians(roll_deg)))
    return ctl


def test_speed_never_below_the_stall_speed_in_the_current_bank() -> None:
    # k_s tiny: the law asks for ~0 m/s, so the floor decides. Level: the
    # envelope minimum (AIRSPEED_MIN 26 m/s) is above the stall speed (~21.8
    # m/s at 1300 m); in a 70 deg bank the stall speed (21.8 / sqrt(cos 70) =
    # 37.3 m/s) is above AIRSPEED_MIN and wins.
    for roll, expect_stall_wins in ((0.0, False), (70.0, True)):
        ctl = _controller(roll)
        out = ctl.step(0)
        assert len(out) == 4 and all(o.fields["command"] == mav.MAV_CMD_DO_REPOSITION
                                     for o in out)
        stall = ctl.stall_mps(np.arange(4))
        k = stall * math.sqrt(math.cos(math.radians(roll)))
        assert k == pytest.approx(21.8, abs=0.3)  # the model's level stall TAS at 1300 m
        sent = np.array([o.fields["param1"] for o in out])
        # what a receiver decodes (float32) is never below the stall speed
        wire = np.array([mav.make_message("COMMAND_INT", **o.fields).fields["param1"]
                         for o in out])
        # the in-process message is exactly what the wire would deliver
        for o in out:
            assert to_message(o).fields == mav.make_message(
                "COMMAND_INT", src_system=245, src_component=190, **o.fields).fields
        assert (wire >= stall).all() and (sent >= 26.0).all()
        if expect_stall_wins:
            assert wire == pytest.approx(stall, abs=1e-5)
        else:
            assert (wire == 26.0).all()


def test_the_loiter_floor_follows_the_bank_limit_the_vehicles_announce() -> None:
    # level flight, tiny k_s: the floor decides. At the default 45 deg limit the
    # loiter floor (21.8 / sqrt(cos 45) = 25.9 m/s) is under AIRSPEED_MIN (26);
    # once the vehicles announce ROLL_LIMIT_DEG 70 it is k / sqrt(cos 70), about 37 m/s
    ctl = _controller(0.0)
    assert all(o.fields["param1"] == pytest.approx(26.0) for o in ctl.step(0))
    for sysid in range(1, 5):
        ctl.on_message(mav.make_message("PARAM_VALUE", src_system=sysid, src_component=1,
                                        param_id="ROLL_LIMIT_DEG", param_value=70.0,
                                        param_type=9, param_count=11, param_index=0))
    k = ctl.stall_mps(np.arange(4))  # level: the stall constant itself
    speeds = np.array([o.fields["param1"] for o in ctl.step(120)])
    assert speeds == pytest.approx(k / math.sqrt(math.cos(math.radians(70))), abs=1e-4)
    assert (speeds > 36.0).all()  # about 37 m/s, well above AIRSPEED_MIN


def test_monitor_separations_match_brute_force() -> None:
    from cosim.swarm.config import SwarmGroup
    from cosim.swarm.metrics import SwarmMonitor

    rng = np.random.default_rng(5)
    n = 9
    groups = (SwarmGroup("a", (0, 2, 4, 6, 8), (), None), SwarmGroup("b", (1, 3, 5, 7), (), None))
    spec = SwarmSpec(groups, 1.0, 120, 50.0)
    mon = SwarmMonitor(spec, [f"v{i}" for i in range(n)], [np.array(g.rows) for g in groups],
                       120.0)
    for g in ("a", "b"):
        mon.phase_event(0, {"group": g, "state": "start", "phase": 0, "behaviour": "rendezvous"})
    best3, besth, best_b = np.inf, np.inf, np.inf
    for k in range(20):
        pos = rng.uniform(-300, 300, (n, 3))
        mon.update(4 * k, pos)
        for i in range(n):
            for j in range(i + 1, n):
                d = pos[i] - pos[j]
                best3 = min(best3, float(np.sqrt(d @ d)))
                besth = min(besth, float(np.hypot(d[0], d[1])))
                if i % 2 and j % 2:
                    best_b = min(best_b, float(np.sqrt(d @ d)))
    mon.phase_event(80, {"group": "b", "state": "end", "reason": "timeout"})
    s = mon.summary()
    assert s["min_separation_3d"]["distance_m"] == pytest.approx(best3)
    assert s["min_separation_horizontal"]["distance_m"] == pytest.approx(besth)
    assert s["phases"]["b"][0]["min_separation_3d_m"] == pytest.approx(best_b)
    assert len(mon.separation_log) == 20


def test_phase_sequence_timeout_then_converged_then_done() -> None:
    scn = parse_scenario(HEAD + """\
swarm:
  groups:
    - name: g
      vehicles: "uav*"
      phases:
        - {behaviour: rendezvous, radius_m: 10, timeout_s: 2}
        - {behaviour: anti_rendezvous, radius_m: 1}
""", "s.yaml")
    ctl = SwarmController(scn.sections["swarm"], scn.vehicles, scn.origin.frame, 120.0)
    assert ctl.step(0) == []  # no telemetry yet: wait, do not start
    assert ctl.drain_events() == []
    for i, v in enumerate(scn.vehicles[:4]):  # a 1.5 km line that never moves
        ctl.on_message(mav.make_message(
            "GLOBAL_POSITION_INT", src_system=i + 1, src_component=1,
            lat=round(v.lat_deg * 1e7), lon=round(v.lon_deg * 1e7),
            alt=round(v.alt_msl_m * 1000)))
        ctl.on_message(mav.make_message("ATTITUDE", src_system=i + 1, src_component=1))
    assert len(ctl.step(120)) == 4
    assert len(ctl.step(240)) == 4
    # 2 s after the start the rendezvous times out; the anti-rendezvous (every
    # vehicle >= 1 m from the centroid) ends at once; nothing more to command
    assert ctl.step(360) == []
    ev = [(t, f["phase"], f["state"], f.get("reason")) for _, t, f in ctl.drain_events()]
    assert ev == [(120, 0, "start", None), (360, 0, "end", "timeout"),
                  (360, 1, "start", None), (360, 1, "end", "converged")]
    assert ctl.finished and ctl.step(480) == []


def test_a_group_held_below_the_command_floor_is_refused() -> None:
    """The swarm holds start altitudes; commands below the class minimum above
    the ground (20 m) are refused on every path, so validation says so."""
    text = HEAD.replace("alt_agl_m: 300", "alt_agl_m: 15") + """\
swarm:
  groups:
    - {vehicles: "uav*", phases: [{behaviour: rendezvous, radius_m: 300}]}
"""
    with pytest.raises(ConfigError, match=r"s\.yaml:\d+: swarm\.groups\[0\]\.vehicles: vehicle "
                                          r"'uav0' starts 15 m above the ground: the swarm "
                                          r"holds that altitude, and commands below 20 m"):
        parse_scenario(text, "s.yaml")
