"""The rigid-body tier's flight-control compiler (``cosim.rigid.fcs``)
against JSBSim itself: the uav700's systems, cosim autopilot and flight
control, flown by JSBSim through engagement, heading, altitude and speed
changes, stall protection and a disengagement, are replayed by the
compiled plan on the values JSBSim's FCS saw, and every output equals
JSBSim's frame by frame; the c172p's flight control the same; each filter
against its difference equation; refusals with file:line."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.fcs import CompileError, Systems, compile_systems
from cosim.vehicles.jsb import (
    JSBSIM_ROOT,
    SYSTEMS_DIR,
    ModelInfo,
    find_model,
    new_fdm,
    wrapper_root,
)

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


def _fly(model: str | ModelInfo, plan: Systems, schedule: dict[int, dict[str, float]],
         frames: int) -> tuple[list[dict[str, float]], dict[str, np.ndarray]]:
    """JSBSim flying ``model``: per frame the inputs its FCS saw (frame 0
    is run_ic) and every output of ``plan`` after the frame."""
    fdm = new_fdm(find_model(model) if isinstance(model, str) else model, DT_S)
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
        if f == 0:
            plan.run_ic(props, DT_S)
        else:
            plan.run(props, DT_S)
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
    assert plan.fused is not None  # the uav700's systems run as numba loops
    seen, outs = _fly("uav700", plan, _autopilot_schedule(), _s(20))
    return plan, seen, outs


def _path(plan: Systems, path: str) -> Systems:
    """The plan as its numba loops (``fused``) or its numpy steps."""
    return plan if path == "fused" else dataclasses.replace(plan, fused=None)


@pytest.mark.parametrize("path", ["fused", "numpy"])
def test_the_uav700_autopilot_and_flight_control_equal_jsbsim_frame_by_frame(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]],
        path: str) -> None:
    plan, seen, want = uav700_flight
    plan = _path(plan, path)
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


@pytest.mark.parametrize("path", ["fused", "numpy"])
def test_a_one_percent_gain_error_is_caught(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]],
        path: str) -> None:
    plan, seen, want = uav700_flight
    plan = _path(plan, path)
    got = _replay(plan, seen, _autopilot_schedule(), tweak={"cosim/ap/gain/roll-ki": 1.01})
    with pytest.raises(AssertionError, match="cosim/ap/roll-pi"):
        np.testing.assert_allclose(got["cosim/ap/roll-pi"], want["cosim/ap/roll-pi"],
                                   rtol=1e-9, err_msg="cosim/ap/roll-pi")


@pytest.mark.parametrize("path", ["fused", "numpy"])
def test_the_c172p_flight_control_with_the_cosim_autopilot_equals_jsbsim(path: str) -> None:
    """The c172p as cosim flies it (JSBSim's own files with the autopilot
    attached): its flaps' kinematic through three settings, the trims and
    the aileron scaling, under the autopilot."""
    model = find_model("c172p")
    root = wrapper_root(model)  # the files new_fdm gives JSBSim
    plan = compile_systems(root / "c172p" / "c172p.xml", JSBSIM_ROOT / "systems")
    assert plan.fused is not None
    plan = _path(plan, path)
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


#: every component type and option the compiler knows, driven by zoo/*
_ZOO = """
<system name="zoo">
  <property value="0">zoo/u</property>
  <property value="0">zoo/v</property>
  <property value="0">zoo/gate</property>
  <property value="1.5">zoo/k</property>
  <property value="1">zoo/run</property>
  <function name="zoo/pre"><product><property>fcs/zoo-pure-gain</property><value>2</value>
    </product></function>
  <function name="zoo/post" type="post"><sum><property>zoo/sum</property>
    <property>zoo/pre</property></sum></function>
  <channel name="filters">
    <lag_filter name="zoo/lag"><input>zoo/u</input><c1>5</c1></lag_filter>
    <lead_lag_filter name="zoo/leadlag"><input>-zoo/u</input>
      <c1>1</c1><c2>2</c2><c3>0.5</c3><c4>3</c4></lead_lag_filter>
    <washout_filter name="zoo/washout"><input>zoo/u</input><c1>2</c1></washout_filter>
    <second_order_filter name="zoo/order2"><input>zoo/u</input>
      <c1>1</c1><c2>2</c2><c3>3</c3><c4>1</c4><c5>0.8</c5><c6>25</c6></second_order_filter>
    <integrator name="zoo/integ"><input>zoo/u</input><c1>2</c1><trigger>zoo/gate</trigger>
      <clipto><min>-3</min><max>zoo/k</max></clipto></integrator>
    <deadband name="zoo/deadband"><input>zoo/u</input><width>0.4</width><gain>2</gain></deadband>
  </channel>
  <channel name="pids" execrate="3">
    <pid name="zoo/pid-rect"><input>zoo/u</input><kp>0.5</kp><ki type="rect">0.3</ki>
      <kd>0.01</kd><trigger>zoo/gate</trigger></pid>
    <pid name="zoo/pid-trap"><input>zoo/u</input><kp>zoo/k</kp><ki type="trap">0.3</ki></pid>
    <pid name="zoo/pid-ab3" type="standard"><input>zoo/u</input><kp>0.5</kp>
      <ki type="ab3">0.3</ki><kd>0.02</kd><clipto><min>-0.5</min><max>0.5</max></clipto></pid>
    <pid name="zoo/pid-pvdot"><input>zoo/u</input><ki>0.2</ki><kd>0.1</kd>
      <pvdot>zoo/v</pvdot></pid>
  </channel>
  <channel name="actuators" execute="zoo/run">
    <actuator name="zoo/act"><input>zoo/u</input><lag>8</lag>
      <rate_limit sense="incr">2</rate_limit><rate_limit sense="decr">zoo/k</rate_limit>
      <deadband_width>0.05</deadband_width><hysteresis_width>0.1</hysteresis_width>
      <bias>0.01</bias><clipto><min>-0.8</min><max>0.7</max></clipto></actuator>
    <actuator name="zoo/act-stuck"><input>zoo/u</input><rate_limit>1</rate_limit>
      <clipto><min>-1</min><max>1</max></clipto></actuator>
    <kinematic name="zoo/kin"><input>zoo/v</input><noscale/><traverse>
      <setting><position>-1</position><time>0</time></setting>
      <setting><position>0</position><time>1.5</time></setting>
      <setting><position>2</position><time>0.5</time></setting></traverse></kinematic>
  </channel>
  <channel name="gains">
    <pure_gain name="Zoo Pure Gain"><input>zoo/u</input><gain>-zoo/k</gain></pure_gain>
    <scheduled_gain name="zoo/sched"><input>zoo/u</input><gain>2</gain>
      <table><independentVar>zoo/v</independentVar>
        <tableData>-1 0.5
                   0 1
                   1 3</tableData></table></scheduled_gain>
    <aerosurface_scale name="zoo/scale"><input>zoo/u</input><zero_centered>0</zero_centered>
      <domain><min>-2</min><max>1</max></domain><range><min>-10</min><max>30</max></range>
      <gain>0.5</gain></aerosurface_scale>
    <summer name="zoo/sum"><input>zoo/u</input><input>-zoo/v</input>
      <input>fcs/zoo-pure-gain</input><bias>0.25</bias>
      <clipto type="cyclic"><min>-1</min><max>1</max></clipto></summer>
    <switch name="zoo/switch">
      <default value="-zoo/v"/>
      <test logic="OR" value="zoo/k">zoo/u GT 0.5
        <test logic="AND">zoo/v LT 0
          zoo/gate NE 0</test></test>
      <test value="2">zoo/u LE -0.5</test>
      <output>zoo/switch-copy</output>
    </switch>
    <switch name="zoo/run2"><default value="0"/><test value="1">zoo/u gt -0.3</test></switch>
  </channel>
  <channel name="switched by a component" execute="zoo/run2" execrate="2">
    <lag_filter name="zoo/lag2"><input>zoo/v</input><c1>3</c1></lag_filter>
  </channel>
</system>
"""


def test_every_component_type_equals_jsbsim(tmp_path: Path) -> None:
    """A system with every component and option, added to the uav700 and
    driven by random walks, gates, a disabled channel, a stuck and a
    hardover actuator, with functions before and after the channels: every
    output equals JSBSim's in every frame."""
    folder = tmp_path / "uav700"
    folder.mkdir()
    (folder / "Engines").symlink_to(UAV700.parent / "Engines")
    xml = UAV700.read_text()
    at = xml.index("<flight_control")
    (folder / "uav700.xml").write_text(xml[:at] + _ZOO + xml[at:])
    plan = compile_systems(folder / "uav700.xml", SYSTEMS_DIR)
    frames = 900
    rng = np.random.default_rng(3)
    u = np.clip(np.cumsum(rng.normal(0, 0.08, frames)), -1.2, 1.2)
    v = np.clip(np.cumsum(rng.normal(0, 0.1, frames)), -1.5, 2.5)
    schedule: dict[int, dict[str, float]] = {f: {"zoo/u": u[f], "zoo/v": v[f]}
                                             for f in range(frames)}
    for first, last, key, value in ((200, 260, "zoo/gate", 1), (400, 410, "zoo/gate", -1),
                                    (450, 470, "zoo/gate", 5e-7), (480, 490, "zoo/gate", -5e-7),
                                    (600, 610, "zoo/gate", 2e-6), (620, 630, "zoo/gate", -2e-6),
                                    (300, frames, "zoo/k", 0.8), (500, 560, "zoo/run", 0),
                                    (600, 650, "zoo/act-stuck/malfunction/fail_stuck", 1),
                                    (700, 720, "zoo/act/malfunction/fail_hardover", 1)):
        schedule[first][key] = value
        if last < frames:
            schedule[last][key] = {"zoo/k": 1.5, "zoo/run": 1}.get(key, 0)
    model = ModelInfo("uav700", str(tmp_path), "user")
    seen, want = _fly(model, plan, schedule, frames)
    got = _replay(plan, seen, schedule)
    zoo = sorted(k for k in plan.outputs if "zoo" in k)
    assert len(zoo) == 25
    for name in sorted(plan.outputs - _WRITE_ONLY):
        np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=1e-12, err_msg=name)
    for name in zoo:  # each moved
        assert np.ptp(want[name]) > 0.01, name


def _aircraft(tmp_path: Path, body: str) -> Path:
    xml = tmp_path / "plane.xml"
    xml.write_text(f'<?xml version="1.0"?>\n<fdm_config name="plane">\n{body}\n</fdm_config>\n')
    return xml


@pytest.mark.parametrize(("body", "match"), [
    ('<flight_control name="f">\n<channel name="c">\n<sensor name="s"><input>a/b</input>'
     '</sensor>\n</channel>\n</flight_control>',
     r"plane\.xml:5: <sensor>: is not supported \(supported components: .*actuator"),
    ('<flight_control name="f">\n<channel name="c">\n<summer name="s"><input>a/b</input>\n'
     '<delay>2</delay></summer>\n</channel>\n</flight_control>',
     r"plane\.xml:6: <delay>: is not supported in <summer> \(supported: .*bias"),
    ('<system name="s">\n<channel name="c" execrate="2.5">\n</channel>\n</system>',
     r"plane\.xml:4: <channel>: execrate='2\.5': expected a whole number"),
    ('<system name="s">\n<channel name="c">\n<lag_filter name="f"><input>a/b</input>\n'
     '<c1>a/tau</c1></lag_filter>\n</channel>\n</system>',
     r"plane\.xml:6: <c1>: a coefficient given as a property \('a/tau'\) is not supported"),
    ('<system name="s">\n<channel name="c">\n<switch name="w">\n<test value="1">\n'
     'a/b EQ 1\na/c GTT 2\n</test>\n</switch>\n</channel>\n</system>',
     r"plane\.xml:8: <test>: condition 'a/c GTT 2': expected 'PROPERTY OP VALUE'"),
    ('<system name="s">\n<channel name="c">\n<actuator name="a" kind="fast">'
     '<input>a/b</input></actuator>\n</channel>\n</system>',
     r"plane\.xml:5: <actuator>: attribute kind='fast' is not supported"),
    ('<system name="s">\n<channel name="c">\n<summer name="s">\n<input>1.5</input></summer>\n'
     '</channel>\n</system>',
     r"plane\.xml:6: <input>: expected a property, got the number '1\.5'"),
    ('<system name="s">\n<channel name="c">\n<switch name="w">\n<test value="1">a/b Gt 1\n'
     '</test>\n</switch>\n</channel>\n</system>',
     r"plane\.xml:6: <test>: condition 'a/b Gt 1': expected 'PROPERTY OP VALUE'"),
    ('<system file="nowhere"/>',
     r"plane\.xml:3: <system>: file 'nowhere' not found in .*, .*Systems or "),
    ('<flight_control file="nowhere"/>',
     r"plane\.xml:3: <flight_control>: file 'nowhere' not found in [^,]*$"),
])
def test_what_it_does_not_know_is_refused_with_the_file_and_line(
        tmp_path: Path, body: str, match: str) -> None:
    with pytest.raises(CompileError, match=match):
        compile_systems(_aircraft(tmp_path, body), tmp_path)


def test_with_a_problem_list_every_problem_is_listed_and_the_rest_compiled(
        tmp_path: Path) -> None:
    body = ('<system name="s">\n<property value="2">a/k</property>\n<channel name="c">\n'
            '<sensor name="s1"><input>a/b</input></sensor>\n'
            '<pure_gain name="g"><input>a/b</input><gain>a/k</gain></pure_gain>\n'
            '<pid name="p"><input>a/b</input><kp>1</kp><noise>1</noise></pid>\n'
            '</channel>\n<function name="x"><value>1</value></function>\n</system>')
    problems: list[CompileError] = []
    plan = compile_systems(_aircraft(tmp_path, body), tmp_path, problems=problems)
    assert [str(p).split(": ", 2)[:2] for p in problems] == [
        [f"{tmp_path / 'plane.xml'}:6", "<sensor>"], [f"{tmp_path / 'plane.xml'}:8", "<noise>"],
        [f"{tmp_path / 'plane.xml'}:10", "<function>"]]
    props = {"a/b": np.array([1.0, -3.0])}
    plan.init(props, 2)
    plan.run(props, DT_S)
    np.testing.assert_array_equal(props["fcs/g"], [2.0, -6.0])
    assert "fcs/p" not in plan.outputs


def test_a_system_file_is_found_as_jsbsim_finds_it(tmp_path: Path) -> None:
    """The aircraft's folder, then its Systems folder, then the systems
    folder given; the first found wins."""
    def system(folder: Path, value: float) -> None:
        folder.mkdir(exist_ok=True)
        (folder / "extra.xml").write_text(
            f'<system name="e"><property value="{value}">a/k</property></system>')
    xml = _aircraft(tmp_path, '<system file="extra"/>')
    system(tmp_path / "shared", 3.0)
    props: dict[str, np.ndarray] = {}
    compile_systems(xml, tmp_path / "shared").init(props, 1)
    assert props["a/k"][0] == 3.0
    system(tmp_path / "Systems", 2.0)
    props = {}
    compile_systems(xml, tmp_path / "shared").init(props, 1)
    assert props["a/k"][0] == 2.0
    system(tmp_path, 1.0)
    props = {}
    compile_systems(xml, tmp_path / "shared").init(props, 1)
    assert props["a/k"][0] == 1.0


@pytest.mark.parametrize("path", ["fused", "numpy"])
def test_no_array_serves_two_properties(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]],
        path: str) -> None:
    """The shared contract: an array belongs to one key (the uav700's
    fuel-freeze command is a function of one property, its value that
    property's array; a PID keeps its input as state)."""
    plan, seen, _ = uav700_flight
    plan = _path(plan, path)
    props: dict[str, np.ndarray] = {}
    plan.init(props, 3)
    plan.run_ic(props, DT_S)
    props["cosim/ap/engage"][:] = 1
    for _ in range(8):
        plan.run(props, DT_S)
    owners: dict[int, list[str]] = {}
    for k, v in props.items():
        owners.setdefault(id(v), []).append(k)
    assert [ks for ks in owners.values() if len(ks) > 1] == []


@pytest.mark.parametrize(("tag", "coeffs", "num", "den"), [
    ("lag_filter", {"c1": 5.0}, [5.0], [1.0, 5.0]),                    # c1/(s+c1)
    ("washout_filter", {"c1": 2.0}, [1.0, 0.0], [1.0, 2.0]),           # s/(s+c1)
    ("lead_lag_filter", {"c1": 1.0, "c2": 2.0, "c3": 0.5, "c4": 3.0},  # (c1 s+c2)/(c3 s+c4)
     [1.0, 2.0], [0.5, 3.0]),
    ("second_order_filter", {"c1": 1.0, "c2": 2.0, "c3": 3.0, "c4": 1.0, "c5": 0.8, "c6": 25.0},
     [1.0, 2.0, 3.0], [1.0, 0.8, 25.0]),
    ("integrator", {"c1": 2.0}, [2.0], [1.0, 0.0]),                    # c1/s
])
def test_each_filter_is_its_transfer_function_discretised_by_tustin(
        tmp_path: Path, tag: str, coeffs: dict[str, float], num: list[float],
        den: list[float]) -> None:
    """Independently: scipy's bilinear transform of the filter's transfer
    function, run by lfilter from rest, against the compiled filter on 3
    aircraft with different inputs (after its first, initialising run)."""
    from scipy import signal

    cs = "".join(f"<{k}>{v}</{k}>" for k, v in coeffs.items())
    xml = _aircraft(tmp_path, f'<system name="s"><channel name="c"><{tag} name="f">'
                              f'<input>a/u</input>{cs}</{tag}></channel></system>')
    plan = compile_systems(xml, tmp_path)
    dt_s = 1 / 120
    b, a = signal.bilinear(num, den, fs=1 / dt_s)
    u = np.random.default_rng(5).normal(size=(3, 400))
    props: dict[str, np.ndarray] = {}
    plan.init(props, 3)
    plan.run(props, dt_s)  # the first run: the past set to the held input, 0
    got = []
    for k in range(u.shape[1]):
        props["a/u"] = u[:, k].copy()
        plan.run(props, dt_s)
        got.append(props["fcs/f"].copy())
    want = signal.lfilter(b, a, u, axis=1)
    # the same filter to rounding: scipy rounds its coefficients in another
    # order (measured: 5e-16 to 4e-14 of the largest output)
    scale = np.abs(want).max()
    assert np.abs(np.array(got).T - want).max() < 1e-12 * scale
    # and a gain 1e-9 off would be seen
    off = signal.lfilter(b * (1 + 1e-9), a, u, axis=1)
    assert np.abs(np.array(got).T - off).max() > 1e-11 * scale


@pytest.mark.parametrize("path", ["fused", "numpy"])
def test_each_aircraft_runs_its_own_channels_whatever_the_others_do(
        uav700_flight: tuple[Systems, list[dict[str, float]], dict[str, np.ndarray]],
        path: str) -> None:
    """Three aircraft on the recorded flight, the autopilot engaged on
    different frames (so channels run for some rows only and their frame
    counters drift apart): each row equals the plan run on it alone."""
    plan, seen, _ = uav700_flight
    plan = _path(plan, path)
    frames = 1600
    engage = np.ones((3, frames))
    engage[:, 0] = 0.0
    engage[1, 301:707] = 0.0   # off a while, back on an odd frame
    engage[2, :1203] = 0.0      # on late
    engage[2, 1500:1503] = 0.0  # off for three frames

    def run(rows: list[int]) -> dict[str, np.ndarray]:
        props: dict[str, np.ndarray] = {}
        plan.init(props, len(rows))
        out: dict[str, list[np.ndarray]] = {k: [] for k in plan.outputs}
        for f, values in enumerate(seen[:frames]):
            for k, v in values.items():
                props[k] = np.full(len(rows), v)
            props["cosim/ap/engage"] = engage[rows, f].copy()
            if f == 0:
                plan.run_ic(props, DT_S)
            else:
                plan.run(props, DT_S)
            if f % 3 == 0:  # a difference stays in the state: every third frame shows it
                for k in out:
                    out[k].append(props[k].copy())
        return {k: np.array(v) for k, v in out.items()}

    together = run([0, 1, 2])
    for row in range(3):
        alone = run([row])
        for name in sorted(plan.outputs):
            np.testing.assert_array_equal(together[name][:, row], alone[name][:, 0],
                                          err_msg=f"{name}, aircraft {row}")
    # the rows did differ
    assert np.ptp(together["cosim/ap/roll-pi"][-1]) > 0
