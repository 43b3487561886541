"""The rigid-body tier's propulsion (``cosim.rigid.propulsion``) against
JSBSim itself: three uav700s flown by JSBSim through throttle steps,
climbs and dives, fuel freeze on and off, a reverser angle and a thruster
moved off the CG; the compiled plan, fed each frame the inputs JSBSim's
propulsion saw, carries its own state (N1, N2, fuel flow, tanks) for the
three aircraft at once and must give JSBSim's thrust, spools, fuel,
forces and moments every frame. A perturbed table is caught; what the
compiler does not know is refused with file:line. The running frame's
loop and the numpy steps, flown side by side through the same frames,
leave every property bit for bit the same."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.rigid.functions import CompileError
from cosim.rigid.propulsion import Propulsion, PropulsionError, compile_propulsion
from cosim.rigid.turbine_plan import Turbine
from cosim.vehicles.jsb import JSBSIM_ROOT, find_model, new_fdm

REPO = Path(__file__).resolve().parents[2]
UAV700 = REPO / "aircraft" / "uav700" / "uav700.xml"
ENGINES = JSBSIM_ROOT / "engine"
DT_S = 1 / 120

#: what JSBSim's propulsion reads in a frame, all final once fdm.run() returns
#: (the atmosphere, auxiliary, FCS and mass balance run before it, nothing
#: after it changes them); the fuel freeze is write-only in JSBSim: the
#: uav700's system copies uav700/fuel-freeze into it before propulsion runs
INPUTS = ("velocities/mach", "atmosphere/density-altitude", "atmosphere/sigma",
          "atmosphere/T-R", "fcs/throttle-pos-norm", "inertia/cg-x-in", "inertia/cg-y-in",
          "inertia/cg-z-in", "aero/qbar-psf")
#: the plan's state a user writes: the schedule's writes go to props as to JSBSim
WRITES = ("propulsion/engine/reverser-angle-rad", "propulsion/engine/x-position",
          "propulsion/engine/y-position", "propulsion/engine/z-position",
          "propulsion/cutoff_cmd", "propulsion/starter_cmd", "propulsion/tank/contents-lbs")
OUTPUTS = ("propulsion/engine/thrust-lbs", "propulsion/engine/n1", "propulsion/engine/n2",
           "propulsion/engine/fuel-flow-rate-pps", "propulsion/engine/fuel-used-lbs",
           "propulsion/engine/tsfc", "propulsion/engine/IdleThrust",
           "propulsion/engine/MilThrust", "propulsion/tank/contents-lbs",
           "propulsion/total-fuel-lbs", "forces/fbx-prop-lbs", "forces/fby-prop-lbs",
           "forces/fbz-prop-lbs", "moments/l-prop-lbsft", "moments/m-prop-lbsft",
           "moments/n-prop-lbsft", "propulsion/cutoff_cmd", "propulsion/starter_cmd")
#: the same operations in the same order on the same doubles: equal bit for
#: bit. The rest depend on the thrust tables, whose interpolation
#: (cosim.rigid.functions) agrees with FGTable's to the last bits only
#: (up to 2e-16 of the value); the moments' atol is for their zeros
EXACT = ("propulsion/engine/n1", "propulsion/engine/n2", "propulsion/engine/fuel-flow-rate-pps",
         "propulsion/engine/fuel-used-lbs", "propulsion/engine/tsfc",
         "propulsion/tank/contents-lbs", "propulsion/total-fuel-lbs", "propulsion/cutoff_cmd",
         "propulsion/starter_cmd")

#: per aircraft, (second, property, value) commands
SCHEDULES: list[list[tuple[float, str, float]]] = [
    [(0, "fcs/throttle-cmd-norm", 0.0), (4, "fcs/throttle-cmd-norm", 1.0),
     (5, "uav700/fuel-freeze", 0.0), (6, "fcs/elevator-cmd-norm", -0.3),
     (9, "fcs/throttle-cmd-norm", 0.3), (11, "fcs/elevator-cmd-norm", 0.2),
     (14, "fcs/throttle-cmd-norm", 0.8), (16, "uav700/fuel-freeze", 1.0)],
    [(0, "fcs/throttle-cmd-norm", 1.0), (0, "uav700/fuel-freeze", 0.0),
     (0, "propulsion/engine/z-position", -6.0), (0, "propulsion/engine/y-position", 4.0),
     (3, "fcs/throttle-cmd-norm", 0.05), (7, "fcs/elevator-cmd-norm", 0.25),
     (10, "fcs/throttle-cmd-norm", 0.6), (13, "propulsion/engine/reverser-angle-rad", 0.3),
     (15, "fcs/throttle-cmd-norm", 1.0)],
    [(0, "fcs/throttle-cmd-norm", 0.5), (2, "fcs/elevator-cmd-norm", -0.5),
     (5, "fcs/throttle-cmd-norm", 0.0), (8, "fcs/elevator-cmd-norm", 0.4),
     (12, "fcs/throttle-cmd-norm", 0.9), (12, "uav700/fuel-freeze", 0.0)],
    # cut off, spun up by the starter, started, run
    [(0, "fcs/throttle-cmd-norm", 0.4), (0, "uav700/fuel-freeze", 0.0),
     (1, "propulsion/cutoff_cmd", 1.0),
     (3, "propulsion/starter_cmd", 1.0), (6, "propulsion/cutoff_cmd", 0.0),
     (9, "propulsion/cutoff_cmd", 0.0), (15, "fcs/throttle-cmd-norm", 0.8)],
    # starved (off, windmilling), refuelled, relit by the airflow
    [(0, "uav700/fuel-freeze", 0.0), (0, "fcs/throttle-cmd-norm", 0.7),
     (2, "propulsion/tank/contents-lbs", 0.05), (2.5, "fcs/elevator-cmd-norm", 0.1),
     (3.3, "propulsion/tank/contents-lbs", 10.0), (6, "fcs/elevator-cmd-norm", 0.0)],
    # the starter cleared by the running engine; cut off and relit at once
    [(0, "fcs/throttle-cmd-norm", 0.6), (1, "propulsion/starter_cmd", 1.0),
     (2, "propulsion/cutoff_cmd", 1.0), (2.5, "propulsion/cutoff_cmd", 0.0),
     (4, "fcs/throttle-cmd-norm", 1.0)],
    # cut off in a zoom until it nearly stops, windmilled up again in a dive
    [(0.5, "propulsion/cutoff_cmd", 1.0), (1, "fcs/elevator-cmd-norm", -0.2),
     (9, "fcs/elevator-cmd-norm", 0.3)],
]

#: frames of suspended integration (dt 0: JSBSim's trim phase), for all
SUSPENDED = {*range(264, 267), *range(960, 963), *range(1704, 1707)}
#: frames with JSBSim's trim status set: no fuel consumed
TRIMMING = set(range(1300, 1330))

Arrays = dict[str, np.ndarray]
Flights = tuple[Arrays, Arrays, Arrays]


def _flights(seconds: float = 20.0) -> Flights:
    """The uav700s of SCHEDULES flown by JSBSim: the state after set-running,
    then per frame (rows) and aircraft (columns) the inputs and outputs."""
    fdms = []
    for _ in SCHEDULES:
        fdm = new_fdm(find_model("uav700"), DT_S)
        fdm["ic/h-sl-ft"] = 3000
        fdm["ic/vc-kts"] = 100
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        fdms.append(fdm)
    start = {k: np.array([f[k] for f in fdms]) for k in (*INPUTS, *OUTPUTS)}
    frames = round(seconds / DT_S)
    rec: dict[str, list[list[float]]] = {k: [] for k in (*INPUTS, "uav700/fuel-freeze",
                                                           *OUTPUTS)}
    for i in range(frames):
        for fdm, schedule in zip(fdms, SCHEDULES):
            for t_s, prop, value in schedule:
                if round(t_s / DT_S) == i:
                    fdm[prop] = value
            if i in SUSPENDED and i - 1 not in SUSPENDED:
                fdm.suspend_integration()
            elif i - 1 in SUSPENDED and i not in SUSPENDED:
                fdm.resume_integration()
            fdm.set_trim_status(i in TRIMMING)
            fdm.run()
        for k, rows in rec.items():
            rows.append([f[k] for f in fdms])
    got = {k: np.array(v) for k, v in rec.items()}
    ins = {k: got.pop(k) for k in (*INPUTS, "uav700/fuel-freeze")}
    ins["propulsion/fuel_freeze"] = ins.pop("uav700/fuel-freeze")
    return start, ins, got


@pytest.fixture(scope="module")
def flights() -> Flights:
    return _flights()


def _replay(plan: Propulsion, start: Arrays, ins: Arrays) -> Arrays:
    """The plan run on the recorded inputs, its state its own from init on."""
    n = len(start["velocities/mach"])
    props = {k: start[k].copy() for k in INPUTS}
    plan.init(props, n)
    out: dict[str, list[np.ndarray]] = {k: [] for k in OUTPUTS}
    for i in range(len(ins["velocities/mach"])):
        for k, v in ins.items():
            props[k] = v[i].copy()
        for j, schedule in enumerate(SCHEDULES):
            for t_s, prop, value in schedule:
                if prop in WRITES and round(t_s / DT_S) == i:
                    props[prop][j] = value
        plan.run(props, 0.0 if i in SUSPENDED else DT_S, trimming=i in TRIMMING)
        for k in OUTPUTS:
            out[k].append(props[k].copy())
    return {k: np.array(v) for k, v in out.items()}


def test_the_uav700_equals_jsbsim_frame_by_frame(flights: Flights) -> None:
    start, ins, jsb = flights
    plan = compile_propulsion(UAV700, ENGINES)
    assert plan.inputs >= {"velocities/mach", "atmosphere/density-altitude",
                           "fcs/throttle-pos-norm", "inertia/cg-x-in", "propulsion/fuel_freeze"}
    assert not plan.lateral_trim  # a direct thruster: no torque to trim out
    # set-running: full-throttle spools and the tank's initial contents
    props = {k: start[k].copy() for k in INPUTS}
    plan.init(props, len(SCHEDULES))
    for k in ("propulsion/engine/n1", "propulsion/engine/n2", "propulsion/tank/contents-lbs",
              "propulsion/total-fuel-lbs"):
        np.testing.assert_array_equal(props[k], start[k], err_msg=k)
    ours = _replay(plan, start, ins)
    # the flights moved what is compared: spools both ways, fuel burnt and
    # frozen, moments from the offset thruster, the reverser's cosine
    n2 = jsb["propulsion/engine/n2"]
    assert (np.diff(n2, axis=0) > 0).any() and (np.diff(n2, axis=0) < 0).any()
    burnt = jsb["propulsion/tank/contents-lbs"][-1] - start["propulsion/tank/contents-lbs"]
    assert (burnt[:3] < -0.01).all()
    # the phases: off, spun up below idle and relit, starved and relit
    thrust = jsb["propulsion/engine/thrust-lbs"]
    assert (thrust[:, 3:6] == 0).any(axis=0).all() and (thrust[-1, 3:6] > 5).all()
    assert (np.diff(n2[:, 6]) > 0).sum() > 600 and thrust[-1, 6] == 0  # windmilled up
    fuel = jsb["propulsion/tank/contents-lbs"][:, 1]
    assert fuel[1329] == fuel[1299] > fuel[1330]  # no fuel burnt while trimming
    starter = jsb["propulsion/starter_cmd"][:, 3]
    assert n2[:, 3].min() < 30 and starter.max() == 1 and starter[-1] == 0
    # the trims: thrust at the throttle's N2 at once; a starting engine
    # leaves the trim cut off
    assert thrust[1704, 0] > thrust[1703, 0] + 1 and n2[1707, 0] > n2[1703, 0] + 5
    assert jsb["propulsion/cutoff_cmd"][970, 3] == 1 and jsb["propulsion/cutoff_cmd"][950, 3] == 0
    assert np.ptp(jsb["moments/m-prop-lbsft"][:, 1]) > 1.0
    assert np.ptp(jsb["moments/n-prop-lbsft"][:, 1]) > 1.0
    assert np.ptp(ins["velocities/mach"]) > 0.05
    assert np.ptp(ins["atmosphere/density-altitude"]) > 300
    for k in OUTPUTS:
        if k in EXACT:
            np.testing.assert_array_equal(ours[k], jsb[k], err_msg=k)
        else:
            np.testing.assert_allclose(ours[k], jsb[k], rtol=1e-12, atol=1e-12, err_msg=k)


def test_a_perturbed_table_value_is_caught(flights: Flights, tmp_path: Path) -> None:
    start, ins, jsb = flights
    bad_dir = tmp_path / "uav700"
    shutil.copytree(UAV700.parent, bad_dir)
    engine = bad_dir / "Engines" / "uav700_turbojet.xml"
    text = engine.read_text()
    assert text.count("0.922") == 1
    engine.write_text(text.replace("0.922", "0.912"))  # MilThrust, mach 0.3, 0 ft: 1 % off
    ours = _replay(compile_propulsion(bad_dir / "uav700.xml", ENGINES), start, ins)
    k = "propulsion/engine/thrust-lbs"
    assert not np.allclose(ours[k], jsb[k], rtol=1e-3)


def _loop_and_numpy(plan: Propulsion, start: Arrays, ins: Arrays, columns: list[int],
                    writes: dict[int, list[tuple[int, str, float]]],
                    monkeypatch: pytest.MonkeyPatch) -> tuple[list[bool], Arrays]:
    """The recorded flights' ``columns`` run twice side by side, by the
    running frame's loop where it applies and by the numpy steps always
    (``writes``: per frame, (column, property, value) written into both):
    every property equal, bit for bit, after every frame. Returns, per
    frame, whether the loop ran, and the last frame's properties."""
    from cosim.rigid import turbine_plan

    calls: list[int] = []
    loop = turbine_plan._turbine

    def counted(*args: Any) -> None:
        calls.append(1)
        loop(*args)

    monkeypatch.setattr(turbine_plan, "_turbine", counted)
    both = [{k: start[k][columns].copy() for k in ins if k in start} for _ in range(2)]
    for props in both:
        plan.init(props, len(columns))
    ran = []
    for i in range(len(ins["velocities/mach"])):
        before = len(calls)
        for props, use_loop in zip(both, (True, False)):
            for k, v in ins.items():
                props[k] = v[i][columns].copy()
            for j, prop, value in writes.get(i, []):
                props[prop][j] = value
            plan.run(props, 0.0 if i in SUSPENDED else DT_S, trimming=i in TRIMMING,
                     loop=use_loop)
        ran.append(len(calls) > before)
        fast, slow = both
        assert fast.keys() == slow.keys()
        for k, v in slow.items():  # bit for bit; numpy says where they part
            if fast[k].dtype != v.dtype or fast[k].tobytes() != v.tobytes():
                np.testing.assert_array_equal(fast[k], v, err_msg=f"frame {i}: {k}")
                pytest.fail(f"frame {i}: {k}: {fast[k]!r} and {v!r} equal, not bit for bit")
    owners: dict[int, list[str]] = {}
    for k, v in both[0].items():
        owners.setdefault(id(v), []).append(k)
    assert [ks for ks in owners.values() if len(ks) > 1] == []
    return ran, both[0]


def test_the_running_frames_loop_gives_the_numpy_steps_doubles(
        flights: Flights, monkeypatch: pytest.MonkeyPatch) -> None:
    """The uav700s that stay running (one frozen for 5 s, one with its
    thruster off the CG and a reverser angle), one starved and refuelled,
    and one cut off for five frames: the loop runs the frames where every
    engine runs, the numpy steps the others (dt 0, trimming, an engine
    cut off, off or starting), and the two give the same doubles."""
    start, ins, _ = flights
    columns = [0, 1, 2, 4]
    writes: dict[int, list[tuple[int, str, float]]] = {}
    for j, column in enumerate(columns):
        for t_s, prop, value in SCHEDULES[column]:
            if prop in WRITES:
                writes.setdefault(round(t_s / DT_S), []).append((j, prop, value))
    writes.setdefault(100, []).append((2, "propulsion/cutoff_cmd", 1.0))
    writes.setdefault(105, []).append((2, "propulsion/cutoff_cmd", 0.0))
    plan = compile_propulsion(UAV700, ENGINES)
    ran, _ = _loop_and_numpy(plan, start, ins, columns, writes, monkeypatch)
    # the loop ran, left for the cut-off, the starvation, the trims, came back
    assert ran[99] and not any(ran[100:106]) and ran[120]
    assert not ran[264] and ran[300] and not any(ran[1300:1330]) and ran[-1]
    assert 0.5 * len(ran) < sum(ran) < len(ran) - 60


def test_the_loop_sums_two_engines_turned_off_the_axes_as_numpy(
        flights: Flights, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two engines, pitched, yawed and rolled, with bleed, feeding from one
    tank (the second reads what the first left) until it runs dry: each
    force and moment the sum of both engines' terms, in the loop as in the
    numpy steps."""
    work = tmp_path / "uav700"
    shutil.copytree(UAV700.parent, work)
    xml = work / "uav700.xml"
    text = xml.read_text()
    engine = text[text.index("    <engine"):text.index("    <tank")]
    text = text.replace(engine, engine.replace(
        "<roll> 0 </roll> <pitch> 0 </pitch> <yaw> 0 </yaw>",
        "<roll> 3 </roll> <pitch> 4 </pitch> <yaw> -2 </yaw>") + engine.replace(
        "<roll> 0 </roll> <pitch> 0 </pitch> <yaw> 0 </yaw>",
        "<roll> 0 </roll> <pitch> -5 </pitch> <yaw> 0 </yaw>").replace(
        "<y> 0.0 </y>", "<y> 1.2 </y>"))
    text = text.replace("<contents unit=\"KG\"> 8.0 </contents>",
                        "<contents unit=\"KG\"> 0.3 </contents>")
    xml.write_text(text)
    turbine = work / "Engines" / "uav700_turbojet.xml"
    turbine.write_text(turbine.read_text().replace("<bleed>                 0.0",
                                                   "<bleed> 0.02"))
    plan = compile_propulsion(xml, ENGINES)
    turbines = [e for e in plan.engines if isinstance(e, Turbine)]
    assert len(turbines) == len(plan.engines) == 2 and turbines[0].axis[2] != 0.0
    start, ins, _ = flights
    ins = {k: v[:720] for k, v in ins.items()}  # the tank runs dry at frame 543
    ins["fcs/throttle-pos-norm[1]"] = 0.5 * ins["fcs/throttle-pos-norm"]
    start = dict(start, **{"fcs/throttle-pos-norm[1]": start["fcs/throttle-pos-norm"]})
    ran, props = _loop_and_numpy(plan, start, ins, [0, 1, 2], {}, monkeypatch)
    assert ran[1] and ran[500] and not any(ran[600:])  # starved: the numpy steps
    assert (props["_propulsion/engine[1]/starved"] == 1.0).any()


def test_the_loops_maximum_and_minimum_are_numpys() -> None:
    """NaN from either side, and of two equal values (+0 and -0) the
    second, as numpy's own loops give them, short arrays and long."""
    from cosim.rigid.turbine_plan import _maximum, _minimum

    special = [np.nan, -0.0, 0.0, 1.0, -1.0, np.inf, -np.inf]
    pairs = [(a, b) for a in special for b in special]
    a, b = (np.array(v * 40) for v in zip(*pairs, strict=True))
    for loop, ufunc in ((_maximum, np.maximum), (_minimum, np.minimum)):
        ours = np.array([loop(x, y) for x, y in zip(a, b, strict=True)])
        assert ours.tobytes() == ufunc(a, b).tobytes(), ufunc
        assert ours[:3].tobytes() == ufunc(a[:3], b[:3]).tobytes(), ufunc


def test_the_thrusters_orientation_and_tanks_of_a_file(tmp_path: Path) -> None:
    """A thruster pitched, yawed and rolled and two tanks fed by priority,
    compiled and flown by JSBSim from the same files."""
    import jsbsim

    work = tmp_path / "uav700"
    shutil.copytree(UAV700.parent, work)
    xml = work / "uav700.xml"
    text = xml.read_text()
    text = text.replace("<roll> 0 </roll> <pitch> 0 </pitch> <yaw> 0 </yaw>",
                        "<roll> 3 </roll> <pitch> 4 </pitch> <yaw> -2 </yaw>")
    text = text.replace("      <feed> 0 </feed>\n", "      <feed> 0 </feed> <feed> 1 </feed>\n")
    text = text.replace("    </tank>\n", """    </tank>
    <tank type="FUEL">
      <location unit="IN"> <x> 30 </x> <y> 2 </y> <z> -1 </z> </location>
      <capacity unit="LBS"> 0.3 </capacity>
      <contents unit="LBS"> 0.02 </contents>
      <priority> 1 </priority>
    </tank>
""", 1)
    text = text.replace("<contents unit=\"KG\"> 8.0 </contents>",
                        "<contents unit=\"KG\"> 8.0 </contents> <priority> 2 </priority>")
    xml.write_text(text)
    engine = work / "Engines" / "uav700_turbojet.xml"
    text = engine.read_text()
    for a, b in (("<bypassratio>           0.0", "<bypassratio> 1.5"),
                 ("<tsfc>                  1.55", "<tsfc> 4.0"),  # above the idle flow
                 ("<bleed>                 0.0", "<bleed> 0.02")):
        assert a in text
        text = text.replace(a, b)
    engine.write_text(text)
    fdm = jsbsim.FGFDMExec(str(JSBSIM_ROOT))
    fdm.set_debug_level(0)
    assert fdm.load_model_with_paths("uav700", str(tmp_path), str(ENGINES),
                                     str(REPO / "aircraft" / "systems"))
    fdm.set_dt(DT_S)
    fdm["ic/h-sl-ft"] = 2000
    fdm["ic/vc-kts"] = 110
    fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    fdm["uav700/fuel-freeze"] = 0
    fdm["fcs/throttle-cmd-norm"] = 0.7
    plan = compile_propulsion(xml, ENGINES)
    assert [t.contents_key for t in plan.tanks] == ["propulsion/tank/contents-lbs",
                                                    "propulsion/tank[1]/contents-lbs"]
    props = {k: np.array([fdm[k]]) for k in INPUTS}
    plan.init(props, 1)
    keys = (*OUTPUTS, "propulsion/tank[1]/contents-lbs")
    flow = []
    for i in range(600):  # the small tank empties, then the big one feeds
        fdm.run()
        for k in (*INPUTS, "propulsion/engine/reverser-angle-rad"):
            props[k] = np.array([fdm[k]])
        props["propulsion/fuel_freeze"] = np.array([fdm["uav700/fuel-freeze"]])
        plan.run(props, DT_S)
        for k in keys:
            assert props[k][0] == pytest.approx(fdm[k], rel=1e-12, abs=1e-12), (i, k)
        flow.append(fdm["propulsion/engine/fuel-flow-rate-pps"])
        if i == 240:
            fdm["fcs/throttle-cmd-norm"] = 0.2
    flow_pps = np.array(flow)
    assert fdm["propulsion/tank[1]/contents-lbs"] == 0.0
    assert flow_pps.max() > 1.1 * flow_pps.min() > 263.0 / 3600  # sought, above idle
    assert fdm["forces/fbz-prop-lbs"] != 0.0 and fdm["forces/fby-prop-lbs"] != 0.0


def _write(tmp_path: Path, propulsion: str, engine: str | None = None,
           thruster: str | None = None) -> Path:
    (tmp_path / "Engines").mkdir(exist_ok=True)
    if engine is not None:
        (tmp_path / "Engines" / "eng.xml").write_text(engine)
    (tmp_path / "Engines" / "thr.xml").write_text(thruster or '<direct name="thr"/>\n')
    xml = tmp_path / "a.xml"
    xml.write_text(f"<fdm_config>\n  <propulsion>\n{propulsion}\n  </propulsion>\n"
                   f"</fdm_config>\n")
    return xml


_ENGINE = """  <engine file="eng">
    <feed> 0 </feed>
    <thruster file="thr">
      <location unit="IN"> <x> 1 </x> <y> 0 </y> <z> 0 </z> </location>
    </thruster>
  </engine>
  <tank type="FUEL">
    <location unit="IN"> <x> 1 </x> <y> 0 </y> <z> 0 </z> </location>
    <capacity unit="LBS"> 10 </capacity> <contents unit="LBS"> 5 </contents>
  </tank>"""
_TURBINE = """<turbine_engine name="t">
  <milthrust> 100 </milthrust>
  {extra}
  <function name="IdleThrust"> <value> 0.05 </value> </function>
  <function name="MilThrust"> <value> 1 </value> </function>
</turbine_engine>
"""


@pytest.mark.parametrize(("extra", "match"), [
    ("<augmented> 1 </augmented>", r"eng.xml:3: <augmented>: only 0 is supported"),
    ("<injected> 1 </injected>", r"eng.xml:3: <injected>: only 0 is supported"),
    ("<function name=\"N2SpoolUp\"> <value> 1 </value> </function>",
     r"eng.xml:3: <function>: function 'N2SpoolUp' is not supported"),
    ("<tsfc> <function> <value> 1 </value> </function> </tsfc>",
     r"eng.xml:3: <tsfc>: expected a number"),
    ("<afterburner> 1 </afterburner>", r"eng.xml:3: <afterburner>: not supported in a "
                                       r"turbine_engine"),
])
def test_unsupported_turbine_elements_are_refused_with_file_and_line(
        tmp_path: Path, extra: str, match: str) -> None:
    xml = _write(tmp_path, _ENGINE, _TURBINE.format(extra=extra))
    with pytest.raises(CompileError, match=match):
        compile_propulsion(xml, ENGINES)


def test_the_c172ps_piston_engine_and_propeller_compile() -> None:
    """They were refused; tests/rigid/test_piston.py flies them against JSBSim."""
    info = find_model("c172p")
    xml = Path(info.aircraft_dir) / "c172p" / "c172p.xml"
    problems: list[CompileError] = []
    plan = compile_propulsion(xml, ENGINES, problems=problems)
    assert problems == [] and len(plan.engines) == 1 and len(plan.tanks) == 2
    assert not any(isinstance(e, Turbine) for e in plan.engines)
    assert plan.engines[0].feeds == (0, 1)


def test_every_problem_is_listed_when_asked(tmp_path: Path) -> None:
    tanks = """  <tank type="OXIDIZER">
    <location unit="IN"> <x> 1 </x> <y> 0 </y> <z> 0 </z> </location>
  </tank>
  <tank type="FUEL">
    <location unit="FURLONG"> <x> 1 </x> <y> 0 </y> <z> 0 </z> </location>
    <temperature> 20 </temperature>
  </tank>
  <dump-rate> 3 </dump-rate>"""
    xml = _write(tmp_path, _ENGINE.replace("<feed> 0 </feed>", "<feed> 7 </feed>") + "\n" + tanks,
                 _TURBINE.format(extra="<injected> 1 </injected> <bogus/>"))
    problems: list[CompileError] = []
    compile_propulsion(xml, ENGINES, problems=problems)
    text = "\n".join(str(p) for p in problems)
    for expected in (r"a.xml:13: <tank>: type 'OXIDIZER' is not supported",
                     r"a.xml:18: <temperature>: not supported in a tank",
                     r"a.xml:20: <dump-rate>: not supported in <propulsion>",
                     r"a.xml:4: <feed>: tank 7 does not exist \(3 tanks\)",
                     r"eng.xml:3: <injected>: only 0 is supported",
                     r"eng.xml:3: <bogus>: not supported in a turbine_engine"):
        assert any(re.search(expected, str(p)) for p in problems), (
            expected, text)
    with pytest.raises(CompileError, match=r"a.xml:\d+: "):
        compile_propulsion(xml, ENGINES)


def test_the_starter_of_several_engines_is_refused_when_used(tmp_path: Path) -> None:
    two = _ENGINE.replace("  <tank", _ENGINE.split("  <tank")[0] + "  <tank", 1)
    plan = compile_propulsion(_write(tmp_path, two, _TURBINE.format(extra="")), ENGINES)
    assert len(plan.engines) == 2
    props = {"velocities/mach": np.full(2, 0.15), "atmosphere/density-altitude": np.zeros(2),
             "atmosphere/sigma": np.ones(2), "atmosphere/T-R": np.full(2, 518.67),
             "aero/qbar-psf": np.full(2, 20.0), "fcs/throttle-pos-norm": np.ones(2),
             "fcs/throttle-pos-norm[1]": np.ones(2), "inertia/cg-x-in": np.zeros(2),
             "inertia/cg-y-in": np.zeros(2), "inertia/cg-z-in": np.zeros(2)}
    plan.init(props, 2)
    props["propulsion/cutoff_cmd"][1] = 1.0  # cut-off is one command for all: flown
    plan.run(props, DT_S)
    assert props["propulsion/engine[1]/thrust-lbs"][1] == 0.0
    assert props["propulsion/engine[1]/thrust-lbs"][0] > 0.0
    props["propulsion/starter_cmd"][1] = 1.0
    with pytest.raises(PropulsionError, match=r"a.xml: the starter of an aircraft with 2 "
                                              r"engines is not compiled"):
        plan.run(props, DT_S)


def test_units_are_converted_with_jsbsims_factors_or_refused(tmp_path: Path) -> None:
    turbine = _TURBINE.replace("<milthrust> 100 </milthrust>",
                               "<milthrust unit=\"N\"> 400 </milthrust>")
    plan = compile_propulsion(_write(tmp_path, _ENGINE, turbine.format(extra="")), ENGINES)
    engine = plan.engines[0]
    assert isinstance(engine, Turbine) and engine.milthrust_lbs == 400 * 0.22482
    turbine = turbine.replace("unit=\"N\"", "unit=\"KGF\"")
    with pytest.raises(CompileError, match=r"eng.xml:2: <milthrust>: unit 'KGF' is not "
                                           r"supported here \(supported: KG, LBS, N\)"):
        compile_propulsion(_write(tmp_path, _ENGINE, turbine.format(extra="")), ENGINES)
