"""The flight controls fused into numba loops (``cosim.rigid.fcs_fused``)
against the numpy plan they replace (``cosim.rigid.fcs``, itself checked
against JSBSim in test_fcs.py): the same doubles in every property, frame by
frame, over the uav700's autopilot through setpoint changes on several
aircraft with different settings, RunIC and suspended frames, and the two
paths taking turns; every component type the loops know; what they do not
know runs on numpy's steps."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Collection
from pathlib import Path

import numpy as np
import pytest
from test_fcs import _ZOO

from cosim.rigid.fcs import CompileError, Systems, compile_systems
from cosim.rigid.fcs_fused import fuse_systems
from cosim.vehicles.jsb import SYSTEMS_DIR

REPO = Path(__file__).resolve().parents[2]
UAV700 = REPO / "aircraft" / "uav700" / "uav700.xml"
DT_S = 1 / 120
N = 6


@pytest.fixture(scope="module")
def uav700() -> Systems:
    plan = compile_systems(UAV700, SYSTEMS_DIR)
    assert plan.fused is not None
    return plan


def _numpy(plan: Systems) -> Systems:
    return dataclasses.replace(plan, fused=None)


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray], frame: int) -> None:
    """Every property the same double (NaN equal to NaN, 0.0 to -0.0)."""
    keys = sorted(a)
    assert keys == sorted(b), f"frame {frame}: keys differ"
    if np.array_equal(np.concatenate([a[k] for k in keys]),
                      np.concatenate([b[k] for k in keys]), equal_nan=True):
        return
    for k in keys:
        np.testing.assert_array_equal(a[k], b[k], err_msg=f"frame {frame}: {k}")


#: setpoints by frame, each a value for each of the N aircraft
def _schedule() -> dict[int, dict[str, list[float]]]:
    nan = float("nan")
    return {
        0: {"cosim/ap/engage": [0, 0, 0, 0, 0, 0], "fcs/throttle-cmd-norm": [0.7] * N},
        1: {"cosim/ap/engage": [1, 1, 1, 0, 1, 1], "cosim/ap/heading-hold": [1, 1, 0, 1, 1, 1],
            "cosim/ap/heading-cmd-deg": [0, 90, 0, 180, 270, 45],
            "cosim/ap/alt-hold": [1, 1, 1, 1, 0, 1],
            "cosim/ap/alt-cmd-ft": [3000, 3300, 2800, 3000, 3000, 3100],
            "cosim/ap/speed-hold": [1, 1, 1, 1, 1, 0],
            "cosim/ap/speed-cmd-kt": [100, 60, 120, 100, 90, 100],
            "cosim/ap/throttle-bias": [0.7, 0.5, 0.8, 0.7, 0.6, 0.7],
            "cosim/ap/stall-protect": [1, 1, 0, 1, 0, 1],
            "cosim/ap/alt-mode": [0, 0, 1, 0, 0, 1]},
        90: {"cosim/ap/heading-cmd-deg": [70, 300, 10, 180, 200, nan]},  # a NaN setpoint
        151: {"cosim/ap/engage": [0, 1, 1, 1, 1, 0]},                  # off on an odd frame
        200: {"cosim/ap/speed-cmd-kt": [40, 40, 40, 115, 35, 100],     # below the floor
              "cosim/ap/alt-cmd-ft": [3250, 2900, 3000, 3100, 2700, 3000]},
        263: {"cosim/ap/engage": [1, 1, 1, 1, 1, 1], "cosim/ap/bank-limit-deg": [20] * N},
        330: {"cosim/ap/stall-protect": [0, 1, 1, 0, 1, 1], "cosim/ap/landing": [0, 0, 2, 0, 0, 0],
              "cosim/ap/heading-cmd-deg": [200, 20, 100, 0, 90, 10]},
        420: {"cosim/ap/engage": [1, 0, 1, 0, 1, 0], "fcs/aileron-cmd-norm": [0.1] * N},
        421: {"cosim/ap/engage": [1, 1, 1, 1, 1, 1]},
        500: {"cosim/ap/speed-hold": [0, 1, 1, 1, 1, 1], "cosim/ap/alt-mode": [1, 0, 0, 0, 1, 0]},
    }


def _world(props: dict[str, np.ndarray], f: int) -> None:
    """What the rest of the aircraft would give the systems: smooth and
    different on every row (alpha through the stall, the speed through the
    floor, the bank beyond its limit)."""
    t = f * DT_S + np.arange(N) * 0.7
    props["aero/alpha-deg"] = 8.0 + 8.0 * np.sin(0.9 * t)
    props["aero/qbar-psf"] = 30.0 + 10.0 * np.sin(0.3 * t)
    props["velocities/vt-fps"] = 150.0 + 40.0 * np.sin(0.2 * t)
    props["velocities/vtrue-kts"] = props["velocities/vt-fps"] * 0.592484
    props["velocities/v-down-fps"] = 10.0 * np.cos(0.5 * t)
    props["velocities/p-rad_sec"] = 0.2 * np.sin(1.3 * t)
    props["velocities/q-rad_sec"] = 0.1 * np.cos(1.1 * t)
    props["attitude/phi-rad"] = 0.9 * np.sin(0.4 * t)
    props["attitude/phi-deg"] = np.degrees(props["attitude/phi-rad"])
    props["attitude/theta-deg"] = 5.0 * np.sin(0.6 * t)
    props["attitude/psi-deg"] = (40.0 * t) % 360.0
    props["position/h-sl-ft"] = 3000.0 + 200.0 * np.sin(0.1 * t)
    props["position/h-agl-ft"] = props["position/h-sl-ft"] - 500.0
    props["inertia/weight-lbs"] = np.full(N, 70.0)
    props["metrics/Sw-sqft"] = np.full(N, 12.9)
    props["atmosphere/sigma"] = np.full(N, 0.91)


def _fly(plan: Systems, frames: int, *, numpy_on: Collection[int] = (),
         poke: tuple[int, str] | None = None) -> list[dict[str, np.ndarray]]:
    """Every property after every frame; frames in ``numpy_on`` run on the
    numpy plan; frame 0 is RunIC, 300-301 suspended frames."""
    ref = _numpy(plan)
    props: dict[str, np.ndarray] = {}
    plan.init(props, N)
    schedule = _schedule()
    out = []
    for f in range(frames):
        _world(props, f)
        for k, v in schedule.get(f, {}).items():
            props[k] = np.array(v, dtype=np.float64)
        which = ref if f in numpy_on else plan
        if f == 0:
            which.run_ic(props, DT_S)
        else:
            which.run(props, DT_S, suspended=f in (300, 301))
        if poke is not None and f == poke[0]:
            props[poke[1]] = np.nextafter(props[poke[1]], np.inf)
        out.append({k: v.copy() for k, v in props.items()})
    return out


def test_fused_and_numpy_plans_give_the_same_doubles_over_600_frames(uav700: Systems) -> None:
    frames = 600
    want = _fly(_numpy(uav700), frames)
    got = _fly(uav700, frames)
    # the paths taking turns (a snapshot of one resumed by the other)
    turns = _fly(uav700, frames, numpy_on={f for f in range(frames) if (f // 37) % 2})
    for f in range(frames):
        _same(got[f], want[f], f)
        _same(turns[f], want[f], f)
    # the flight exercised what it should: every hold moved its output on
    # some row, stall protection came on, the NaN setpoint reached a state
    last = {k: np.array([w[k] for w in want]) for k in want[0]}
    for k in ("cosim/ap/roll-pi", "cosim/ap/theta-pi", "cosim/ap/speed-pi",
              "cosim/ap/roll-cmd-lim-deg", "fcs/elevator-pos-rad", "fcs/left-aileron-pos-rad",
              "fcs/throttle-pos-norm"):
        assert np.nanmax(np.ptp(last[k], axis=0)) > 0.01, k
    assert last["cosim/ap/stall-protection-active"].max() == 1.0
    assert last["cosim/ap/stalled"].max() == 1.0
    assert np.isnan(last["cosim/ap/heading-error-deg"][150, 5])
    assert len({tuple(r) for r in last["_fcs:frames:cosim/ap/engage:4"][-50:].T}) > 1


def test_a_one_ulp_difference_is_caught(uav700: Systems) -> None:
    want = _fly(_numpy(uav700), 40)
    got = _fly(uav700, 40, poke=(30, "_fcs:cosim/ap/speed-pi:i_out_total"))
    for f in range(30):
        _same(got[f], want[f], f)
    with pytest.raises(AssertionError, match="frame 30: _fcs:cosim/ap/speed-pi:i_out_total"):
        _same(got[30], want[30], 30)


def test_arrays_of_other_kinds_are_read_and_written_through_float64_copies(
        uav700: Systems) -> None:
    """A read-only or integer array under a key the plan writes is replaced
    by a float64 copy, not written through (nor refused by numba); an
    integer array it only reads is read through a float64 copy and kept
    (numba compiles its loops for float64 arrays only)."""
    props: dict[str, np.ndarray] = {}
    uav700.init(props, N)
    frozen = np.broadcast_to(np.float64(0.3), (N,))
    props["fcs/throttle-cmd-norm"] = frozen
    props["fcs/elevator-cmd-norm"] = np.zeros(N, dtype=np.int64)
    engage = props["cosim/ap/engage"] = np.ones(N, dtype=np.int64)
    props["cosim/ap/heading-hold"] = np.ones(N, dtype=np.int32)
    want = {k: v.copy() for k, v in props.items()}
    assert uav700.fused is not None
    # other tests in this process may have compiled other array layouts already
    before = [max(len(k.signatures), 1) for k, _, _ in uav700.fused.segments]
    for f in range(1, 9):
        _numpy(uav700).run(want, DT_S)
        uav700.run(props, DT_S)
        _same(props, want, f)
    assert props["fcs/throttle-pos-norm"][0] == 0.3 and frozen[0] == 0.3
    assert props["fcs/elevator-cmd-norm"].dtype == np.float64
    assert props["cosim/ap/engage"] is engage
    # no loop compiled again for the integer arrays
    assert [len(k.signatures) for k, _, _ in uav700.fused.segments] == before


def _fusable(zoo: str) -> str:
    """test_fcs.py's zoo of every component, without what the loops do not
    know (the filters, the cyclic clip, the channel a component switches),
    with transcendental functions (the loops cut for numpy's), a domain
    ending at 0 and a surface position in degrees."""
    for tag in ("lag_filter", "lead_lag_filter", "washout_filter", "second_order_filter",
                "integrator"):
        zoo = re.sub(rf"<{tag} .*?</{tag}>", "", zoo, flags=re.S)
    zoo = zoo.replace(' type="cyclic"', "")
    zoo = re.sub(r'<channel name="switched by a component".*?</channel>', "", zoo, flags=re.S)
    zoo = zoo.replace('<channel name="actuators" execute="zoo/run">',
                      '<channel name="actuators" execute="zoo/run" execrate="2">')
    more = """
    <fcs_function name="zoo/trig"><function><sum><pow><property>zoo/k</property>
      <abs><property>zoo/u</property></abs></pow>
      <atan2><property>-zoo/v</property><property>zoo/k</property></atan2>
      </sum></function><clipto><min>-50</min><max>zoo/k</max></clipto></fcs_function>
    <aerosurface_scale name="zoo/scale0"><input>zoo/u</input>
      <domain><min>0</min><max>2</max></domain><range><min>-3</min><max>5</max></range>
    </aerosurface_scale>
    <summer name="zoo/surface"><input>zoo/u</input><output>fcs/rudder-pos-deg</output></summer>
  </channel>"""
    at = zoo.index("</channel>", zoo.index('<channel name="gains">'))
    return zoo[:at] + more + zoo[at + len("</channel>"):]


def _zoo(tmp_path: Path, zoo: str) -> Path:
    """An aircraft of these systems only (the loops compile in seconds)."""
    xml = tmp_path / "zoo.xml"
    xml.write_text(f'<?xml version="1.0"?>\n<fdm_config name="zoo">\n{zoo}\n</fdm_config>\n')
    return xml


def test_every_component_the_loops_know_gives_the_numpy_plans_doubles(tmp_path: Path) -> None:
    """Random walks through gates, triggers, a disabled channel, a stuck and
    a hardover actuator, on 5 aircraft, each row its own; 400 frames."""
    plan = compile_systems(_zoo(tmp_path, _fusable(_ZOO)), SYSTEMS_DIR)
    assert plan.fused is not None
    ref = _numpy(plan)
    n, frames = 5, 400
    rng = np.random.default_rng(7)
    u = np.clip(np.cumsum(rng.normal(0, 0.08, (frames, n)), axis=0), -1.2, 1.2)
    v = np.clip(np.cumsum(rng.normal(0, 0.1, (frames, n)), axis=0), -1.5, 2.5)
    a: dict[str, np.ndarray] = {}
    plan.init(a, n)
    b = {k: x.copy() for k, x in a.items()}
    hist: dict[str, list[np.ndarray]] = {k: [] for k in plan.outputs}
    for f in range(frames):
        now = {"zoo/u": u[f], "zoo/v": v[f],
               "zoo/gate": np.where(rng.random(n) < 0.2, [1, -1, 5e-7, -2e-6, 0], 0.0),
               "zoo/run": ((np.arange(n) + f // 40) % 4 != 0).astype(np.float64),
               "zoo/act-stuck/malfunction/fail_stuck": np.array([0, 1, 0, 0, 0.0]) * (f > 200),
               "zoo/act/malfunction/fail_hardover": np.array([0, 0, 1, 0, 0.0]) * (f > 300),
               "zoo/k": np.full(n, 1.5 if f < 150 else 0.8)}
        for p in (a, b):
            p.update({k: x.copy() for k, x in now.items()})
        if f == 0:
            plan.run_ic(a, DT_S)
            ref.run_ic(b, DT_S)
        else:
            plan.run(a, DT_S)
            ref.run(b, DT_S)
        _same(a, b, f)
        for k in hist:
            hist[k].append(b[k].copy())
    zoo = sorted(k for k in plan.outputs if "zoo" in k)
    assert len(zoo) == 22
    for k in zoo:  # each moved
        assert np.ptp(hist[k]) > 0.01, k


@pytest.mark.parametrize(("body", "match"), [
    ('<lag_filter name="f"><input>zoo/u</input><c1>2</c1></lag_filter>',
     r"zoo\.xml:\d+: <lag_filter>: not fused \(fused: actuator, aerosurface_scale"),
    ('<summer name="f"><input>zoo/u</input><clipto type="cyclic"><min>0</min><max>1</max>'
     '</clipto></summer>', r"zoo\.xml:\d+: <clipto type='cyclic'>: not fused"),
    ('<fcs_function name="f"><function><atan><value>1</value></atan></function></fcs_function>',
     r"zoo\.xml:\d+: <atan>: a function of a constant is not fused"),
])
def test_what_the_loops_do_not_know_runs_on_numpys_steps(tmp_path: Path, body: str,
                                                          match: str) -> None:
    zoo = (f'<system name="zoo"><property>zoo/u</property>'
           f'<channel name="c">{body}</channel></system>')
    plan = compile_systems(_zoo(tmp_path, zoo), SYSTEMS_DIR)
    assert plan.fused is None
    with pytest.raises(CompileError, match=match):
        fuse_systems(plan.pre, plan.channels, plan.post, plan.engines)
    props: dict[str, np.ndarray] = {}
    plan.init(props, 2)
    plan.run(props, DT_S)  # the numpy steps
    assert np.isfinite(props["fcs/f"]).all()


def test_a_loops_sine_and_cosine_are_numpys_to_the_bit() -> None:
    """The loops compute sine and cosine themselves (the math library, as
    numba calls it), where the numpy plan calls numpy: the two paths agree
    only while numpy computes float64 sines and cosines with the same
    library. Should a numpy release vectorise them, this says why the paths
    part."""
    import math

    import numba

    @numba.njit
    def both(x: np.ndarray, s: np.ndarray, c: np.ndarray) -> None:
        for i in range(len(x)):
            s[i], c[i] = math.sin(x[i]), math.cos(x[i])

    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-10.0, 10.0, 200_000), rng.uniform(-1e6, 1e6, 20_000),
                        [0.0, -0.0, math.pi, -math.pi, 0.5 * math.pi, 1e-300, 1e22]])
    s, c = np.empty_like(x), np.empty_like(x)
    both(x, s, c)
    assert np.array_equal(s, np.sin(x)) and np.array_equal(c, np.cos(x))
