"""The rigid-body tier's flight-control compiler (``cosim.rigid.fcs``)
against JSBSim itself: the uav700's systems, cosim autopilot and flight
control, flown by JSBSim through engagement, heading, altitude and speed
changes, stall protection and a disengagement, are replayed by the
compiled plan on the values JSBSim's FCS saw, and every output equals
JSBSim's frame by frame; the c172p's flight control the same; each filter
against its difference equation; refusals with file:line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.fcs import Systems, compile_systems
from cosim.vehicles.jsb import JSBSIM_ROOT, SYSTEMS_DIR, _wrapper_root, find_model, new_fdm

REPO = Path(__file__).resolve().parents[2]
UAV700 = REPO / "aircraft" / "uav700" / "uav700.xml"
DT_S = 1 / 120

#: properties JSBSim computes before the FCS in a frame (FGPropagate and
#: FGAtmosphere run first): the FCS sees this frame's value. Everything
#: else it reads (FGAuxiliary's airspeeds and angles, FGMassBalance's
#: weight) is computed after it: it sees the previous frame's.
#: JSBSim ties these to a setter only: reading them gives 0 whatever was
#: written (the plan keeps what the FCS wrote, for the part that uses it)
_WRITE_ONLY = {"propulsion/fuel_freeze"}

_BEFORE_FCS = ("attitude/", "position/", "atmosphere/", "velocities/p-rad_sec",
               "velocities/q-rad_sec", "velocities/r-rad_sec", "velocities/v-north-fps",
               "velocities/v-east-fps", "velocities/v-down-fps")


def _fly(model: str, plan: Systems, schedule: dict[int, dict[str, float]], frames: int
         ) -> tuple[list[dict[str, float]], dict[str, np.ndarray]]:
    """JSBSim flying ``model``: per frame the inputs its FCS saw (frame 0
    is run_ic) and every output of ``plan`` after the frame."""
    fdm = new_fdm(find_model(model), DT_S)
    fdm["ic/h-sl-ft"] = 3000
    fdm["ic/vc-kts"] = 100
    seen: list[dict[str, float]] = []
    outs: dict[str, list[float]] = {k: [] for k in plan.outputs - _WRITE_ONLY}
    for f in range(frames):
        for k, v in schedule.get(f, {}).items():
            fdm[k] = v
        before = {k: fdm[k] for k in plan.inputs}
        if f == 0:
            fdm.run_ic()
        else:
            fdm.run()
        seen.append({k: fdm[k] if k.startswith(_BEFORE_FCS) else v for k, v in before.items()})
        for k in outs:
            outs[k].append(fdm[k])
    return seen, {k: np.array(v) for k, v in outs.items()}


def _replay(plan: Systems, seen: list[dict[str, float]], schedule: dict[int, dict[str, float]],
            tweak: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    props: dict[str, np.ndarray] = {}
    plan.init(props, 1)
    got: dict[str, list[float]] = {k: [] for k in plan.outputs}
    for f, values in enumerate(seen):
        for k, v in schedule.get(f, {}).items():  # what the pilot wrote
            props[k] = np.array([v])
        for k, v in values.items():
            props[k] = np.array([v])
        for k, v in (tweak or {}).items():
            props[k] = props[k] * v
        plan.run(props, DT_S, suspended=f == 0)
        for k in plan.outputs:
            got[k].append(float(props[k][0]))
    return {k: np.array(v) for k, v in got.items()}


def _s(t_s: float) -> int:
    return round(t_s / DT_S)


def _autopilot_schedule() -> dict[int, dict[str, float]]:
    """Engage with every hold, then heading, altitude and speed changes
    (one below the stall floor), a disengagement and a re-engagement."""
    return {
        0: {"fcs/throttle-cmd-norm": 0.7},
        1: {"propulsion/set-running": -1, "cosim/ap/engage": 1, "cosim/ap/heading-hold": 1,
            "cosim/ap/heading-cmd-deg": 0,
            "cosim/ap/alt-hold": 1, "cosim/ap/alt-cmd-ft": 3000, "cosim/ap/speed-hold": 1,
            "cosim/ap/speed-cmd-kt": 100, "cosim/ap/throttle-bias": 0.7},
        _s(2): {"cosim/ap/heading-cmd-deg": 70},
        _s(5): {"cosim/ap/alt-cmd-ft": 3250},
        _s(8): {"cosim/ap/speed-cmd-kt": 40},  # below the stall floor: protection
        _s(11): {"cosim/ap/heading-cmd-deg": 300, "cosim/ap/alt-cmd-ft": 2900,
                 "cosim/ap/speed-cmd-kt": 115},
        _s(14): {"cosim/ap/engage": 0, "fcs/elevator-cmd-norm": -0.05,
                 "fcs/aileron-cmd-norm": 0.1},
        _s(15) + 1: {"cosim/ap/engage": 1, "cosim/ap/bank-limit-deg": 20},
        _s(14) + 60: {"fcs/throttle-cmd-norm": 0.5},
        _s(17): {"cosim/ap/heading-cmd-deg": 200, "cosim/ap/alt-mode": 1,
                 "cosim/ap/alt-cmd-ft": 2600},
    }


@pytest.fixture(scope="module")
def uav700_flight() -> tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]]:
    plan = compile_systems(UAV700, SYSTEMS_DIR)
    seen, outs = _fly("uav700", plan, _autopilot_schedule(), _s(20))
    return plan, seen, outs


def test_the_uav700_autopilot_and_flight_control_equal_jsbsim_frame_by_frame(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]]) -> None:
    plan, seen, want = uav700_flight
    assert {"fcs/elevator-pos-rad", "fcs/left-aileron-pos-rad", "fcs/throttle-pos-norm",
            "cosim/ap/roll-pi", "cosim/ap/speed-pi", "cosim/ap/stall-protection-active",
            "propulsion/fuel_freeze"} <= plan.outputs
    got = _replay(plan, seen, _autopilot_schedule())
    for name in sorted(plan.outputs - _WRITE_ONLY):
        np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=1e-12, err_msg=name)
    # the flight exercised the autopilot: the holds moved the surfaces and
    # the integrators, and stall protection came on
    for name in ("fcs/elevator-pos-rad", "fcs/left-aileron-pos-rad", "fcs/throttle-pos-norm",
                 "cosim/ap/roll-pi", "cosim/ap/theta-pi", "cosim/ap/speed-pi",
                 "cosim/ap/roll-cmd-lim-deg"):
        assert np.ptp(want[name]) > 0.01, name
    assert want["cosim/ap/stall-protection-active"].max() == 1.0


def test_a_one_percent_gain_error_is_caught(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]]) -> None:
    plan, seen, want = uav700_flight
    got = _replay(plan, seen, _autopilot_schedule(), tweak={"cosim/ap/gain/roll-ki": 1.01})
    with pytest.raises(AssertionError, match="cosim/ap/roll-pi"):
        np.testing.assert_allclose(got["cosim/ap/roll-pi"], want["cosim/ap/roll-pi"],
                                   rtol=1e-9, err_msg="cosim/ap/roll-pi")


def test_the_c172p_flight_control_with_the_cosim_autopilot_equals_jsbsim() -> None:
    """The c172p as cosim flies it (JSBSim's own files with the autopilot
    attached): its flaps' kinematic through three settings, the trims and
    the aileron scaling, under the autopilot."""
    model = find_model("c172p")
    root = _wrapper_root(model)  # the files new_fdm gives JSBSim
    plan = compile_systems(root / "c172p" / "c172p.xml", JSBSIM_ROOT / "systems")
    assert {"fcs/flap-pos-deg", "fcs/flap-pos-norm", "cosim/ap/roll-pi"} <= plan.outputs
    schedule = _autopilot_schedule()
    for t_s, flap, trim in ((1, 0.5, 0.02), (4, 1.0, -0.03), (7, 0.1, 0.0), (7.5, 0.0, 0.01)):
        schedule.setdefault(_s(t_s), {}).update({"fcs/flap-cmd-norm": flap,
                                                 "fcs/pitch-trim-cmd-norm": trim})
    seen, want = _fly("c172p", plan, schedule, _s(10))
    got = _replay(plan, seen, schedule)
    for name in sorted(plan.outputs - _WRITE_ONLY):
        np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=1e-12, err_msg=name)
    # the flaps moved through their detents at each interval's own rate
    assert set(np.round(want["fcs/flap-pos-deg"][_s(3.9):_s(4)], 9)) == {15.0}
    assert want["fcs/flap-pos-deg"].max() == 30.0
