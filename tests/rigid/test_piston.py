"""The rigid-body tier's piston engine and fixed-pitch propeller
(``cosim.rigid.piston_plan``, compiled by ``cosim.rigid.propulsion``)
against JSBSim 1.3 itself: five c172ps flown by JSBSim at three heights
and speeds through throttle and mixture steps, pitch, roll and yaw inputs
(the P-factor), tanks emptied and refilled (the engine starves, stops and
windmills back to life) and the mixture cut (it stops; the starter cranks
it back); the compiled plan, fed each frame the inputs
JSBSim's propulsion saw, carries its own state (manifold pressure, running,
propeller speed, acting location, tanks) from its own steady state on and
must give JSBSim's doubles every frame. A 2 % change of the propeller's
thrust table is caught; what the compiler does not know is refused with
file:line."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.functions import CompileError
from cosim.rigid.piston_plan import Piston
from cosim.rigid.propulsion import Propulsion, compile_propulsion
from cosim.vehicles.jsb import JSBSIM_ROOT, find_model, new_fdm

C172P = Path(find_model("c172p").aircraft_dir) / "c172p" / "c172p.xml"
ENGINES = JSBSIM_ROOT / "engine"
DT_S = 1 / 120
E = "propulsion/engine/"

#: per aircraft, the initial height (ft) and calibrated airspeed (kt)
STARTS = [(3000, 100), (8000, 70), (1000, 110), (5000, 90), (5000, 70)]
#: per aircraft, (second, property, value) commands
SCHEDULES: list[list[tuple[float, str, float]]] = [
    [(0, "fcs/throttle-cmd-norm", 0.6), (3, "fcs/throttle-cmd-norm", 1.0),
     (5, "fcs/mixture-cmd-norm", 0.7), (6, "fcs/elevator-cmd-norm", -0.2),
     (8, "fcs/aileron-cmd-norm", 0.3), (10, "fcs/throttle-cmd-norm", 0.2),
     (12, "fcs/rudder-cmd-norm", 0.4), (14, "fcs/mixture-cmd-norm", 1.0)],
    [(0, "fcs/throttle-cmd-norm", 0.9), (2, "fcs/mixture-cmd-norm", 0.5),
     (4, "fcs/elevator-cmd-norm", 0.2), (7, "fcs/throttle-cmd-norm", 0.0),
     (9, "fcs/rudder-cmd-norm", -0.5), (13, "fcs/throttle-cmd-norm", 0.7)],
    [(0, "fcs/throttle-cmd-norm", 0.3), (2, "fcs/aileron-cmd-norm", -0.4),
     (4, "fcs/throttle-cmd-norm", 1.0), (6, "fcs/elevator-cmd-norm", -0.1),
     (9, "fcs/mixture-cmd-norm", 0.2), (12, "fcs/mixture-cmd-norm", 0.9)],
    # starved: the engine stops and windmills; refuelled, it runs again
    [(0, "fcs/throttle-cmd-norm", 0.8), (2, "propulsion/tank/contents-lbs", 0.0),
     (2, "propulsion/tank[1]/contents-lbs", 0.0), (3, "fcs/elevator-cmd-norm", 0.1),
     (9, "propulsion/tank/contents-lbs", 20.0), (12, "fcs/elevator-cmd-norm", -0.1)],
    # the mixture cut: it stops; the starter cranks it back to life
    [(0, "fcs/throttle-cmd-norm", 0.5), (1, "fcs/mixture-cmd-norm", 0.0),
     (6, "fcs/mixture-cmd-norm", 1.0), (6, "propulsion/starter_cmd", 1.0),
     (10, "propulsion/starter_cmd", 0.0)],
]
#: what the propulsion reads in a frame, final once fdm.run() returns
INPUTS = ("atmosphere/P-psf", "atmosphere/delta", "velocities/mach", "atmosphere/T-R",
          "fcs/throttle-pos-norm", "fcs/mixture-pos-norm", "atmosphere/rho-slugs_ft3",
          "atmosphere/a-fps", "velocities/u-aero-fps", "velocities/v-aero-fps",
          "velocities/w-aero-fps", "velocities/p-aero-rad_sec", "velocities/q-aero-rad_sec",
          "velocities/r-aero-rad_sec", "velocities/pi-rad_sec", "velocities/qi-rad_sec",
          "velocities/ri-rad_sec", "inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in",
          "aero/qbar-psf", "atmosphere/sigma", "propulsion/fuel_freeze")
#: the body's inertial rates, under the rigid tier's names
RATES = {"velocities/pi-rad_sec": "_eom/pi", "velocities/qi-rad_sec": "_eom/qi",
         "velocities/ri-rad_sec": "_eom/ri"}
WRITES = ("propulsion/tank/contents-lbs", "propulsion/tank[1]/contents-lbs",
          "propulsion/starter_cmd")
OUTPUTS = (*(E + k for k in (
    "power-hp", "map-pa", "map-inhg", "fuel-flow-rate-pps", "fuel-used-lbs", "engine-rpm",
    "propeller-rpm", "thrust-lbs", "advance-ratio", "thrust-coefficient", "helical-tip-Mach",
    "prop-induced-velocity_fps", "propeller-power-ftlbps", "propeller-torque-ftlb",
    "x-position", "y-position", "z-position")),
    "propulsion/tank/contents-lbs", "propulsion/tank[1]/contents-lbs",
    "propulsion/total-fuel-lbs", "forces/fbx-prop-lbs", "forces/fby-prop-lbs",
    "forces/fbz-prop-lbs", "moments/l-prop-lbsft", "moments/m-prop-lbsft",
    "moments/n-prop-lbsft", "propulsion/starter_cmd")

Arrays = dict[str, np.ndarray]
Flights = tuple[Arrays, Arrays, Arrays]


def _flights(seconds: float = 16.0) -> Flights:
    """The c172ps of SCHEDULES flown by JSBSim: the state after set-running,
    then per frame (rows) and aircraft (columns) the inputs and outputs."""
    fdms = []
    for h_ft, vc_kt in STARTS:
        fdm = new_fdm(find_model("c172p"), DT_S)
        fdm["ic/h-sl-ft"] = h_ft
        fdm["ic/vc-kts"] = vc_kt
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        fdms.append(fdm)
    keys = (*INPUTS, *OUTPUTS, E + "set-running", "fcs/mixture-cmd-norm",
            "fcs/throttle-cmd-norm")
    start = {k: np.array([f[k] for f in fdms]) for k in keys}
    rec: dict[str, list[list[float]]] = {k: [] for k in keys}
    for i in range(round(seconds / DT_S)):
        for fdm, schedule in zip(fdms, SCHEDULES, strict=True):
            for t_s, prop, value in schedule:
                if round(t_s / DT_S) == i:
                    fdm[prop] = value
            fdm.run()
        for k, rows in rec.items():
            rows.append([f[k] for f in fdms])
    got = {k: np.array(v) for k, v in rec.items()}
    return start, {k: got.pop(k) for k in INPUTS}, got


@pytest.fixture(scope="module")
def flights() -> Flights:
    return _flights()


def _props(start: Arrays, ins: Arrays, i: int | None) -> Arrays:
    props = {k: (start[k] if i is None else ins[k][i]).copy() for k in INPUTS}
    for a, b in RATES.items():
        props[b] = props.pop(a)
    return props


def _replay(plan: Propulsion, start: Arrays, ins: Arrays) -> tuple[Arrays, Arrays]:
    """The plan from its own set-running on the recorded inputs: its
    steady state, then every frame's outputs."""
    n = len(STARTS)
    props = _props(start, ins, None)
    plan.init(props, n)
    plan.set_running(props)
    steady = {k: props[k].copy() for k in OUTPUTS}
    out: dict[str, list[np.ndarray]] = {k: [] for k in OUTPUTS}
    for i in range(len(ins["velocities/mach"])):
        props.update(_props(start, ins, i))
        for j, schedule in enumerate(SCHEDULES):
            for t_s, prop, value in schedule:
                if prop in WRITES and round(t_s / DT_S) == i:
                    props[prop][j] = value
        plan.run(props, DT_S)
        for k in OUTPUTS:
            out[k].append(props[k].copy())
    return steady, {k: np.array(v) for k, v in out.items()}


def test_the_c172p_engine_and_propeller_equal_jsbsim_bit_for_bit(flights: Flights) -> None:
    start, ins, jsb = flights
    plan = compile_propulsion(C172P, ENGINES)
    assert [type(e) for e in plan.engines] == [Piston] and len(plan.tanks) == 2
    assert plan.lateral_trim  # the propeller's torque rolls and yaws the airframe
    assert plan.inputs >= {"fcs/mixture-pos-norm", "atmosphere/P-psf", "velocities/u-aero-fps"}
    steady, ours = _replay(plan, start, ins)
    # the flights moved what is compared: the throttle and mixture both
    # ways, the propeller sped up and slowed, the acting location moved by
    # the P-factor, fuel burnt, one engine starved to a stop and relit, one
    # stopped by its mixture and cranked by the starter
    rpm, power = jsb[E + "propeller-rpm"], jsb[E + "power-hp"]
    assert (np.diff(rpm, axis=0) > 1).any() and (np.diff(rpm, axis=0) < -1).any()
    assert np.ptp(jsb[E + "map-inhg"]) > 10 and np.ptp(ins["fcs/mixture-pos-norm"]) > 0.7
    assert np.ptp(jsb[E + "y-position"]) > 1 and np.ptp(jsb[E + "z-position"]) > 1
    assert np.ptp(jsb["moments/n-prop-lbsft"]) > 100
    burnt = start["propulsion/total-fuel-lbs"] - jsb["propulsion/total-fuel-lbs"][-1]
    assert (burnt[:3] > 0.05).all()
    stopped = jsb[E + "set-running"][:, 3]
    assert stopped[0] == 1 and stopped.min() == 0 and stopped[-1] == 1
    assert power[:, 3].min() < 0 < power[-1, 3]
    cranked = jsb[E + "set-running"][:, 4]
    assert cranked[719] == 0 and cranked[-1] == 1 and rpm[719, 4] < 550 < rpm[-1, 4]
    assert power[720, 4] > 0  # the starter's, before the engine runs
    assert np.ptp(ins["velocities/mach"]) > 0.05 and np.ptp(ins["atmosphere/P-psf"]) > 300
    # set-running's steady state at full throttle (the engine's; the forces
    # are the next frame's), then every frame: the same operations on the
    # same doubles (libm's atan2 and pow, FGTable's interpolation), so the
    # same bits
    for k in OUTPUTS:
        if not k.startswith(("forces/", "moments/")):
            np.testing.assert_array_equal(steady[k], start[k], err_msg=f"steady state: {k}")
        np.testing.assert_array_equal(ours[k], jsb[k], err_msg=k)
    # set-running puts the mixture at full, not the throttle (JSBSim 1.3.3)
    props = _props(start, ins, None)
    plan.init(props, len(STARTS))
    props["fcs/mixture-cmd-norm"] = props["fcs/throttle-cmd-norm"] = np.full(len(STARTS), 0.3)
    plan.set_running(props)
    assert (start["fcs/mixture-cmd-norm"] == 1).all()
    assert (start["fcs/throttle-cmd-norm"] == 0).all()
    assert (props["fcs/mixture-cmd-norm"] == 1).all()
    assert (props["fcs/throttle-cmd-norm"] == 0.3).all()


def test_a_thrust_table_two_percent_off_is_caught(flights: Flights, tmp_path: Path) -> None:
    start, ins, jsb = flights
    engines = tmp_path / "engine"
    shutil.copytree(ENGINES, engines)
    prop = engines / "prop_75in2f.xml"
    text = prop.read_text()
    head, sep, tail = text.partition('<table name="C_THRUST" type="internal">')
    assert sep and "<!--" in head  # the commented-out table comes first
    tail = re.sub(r"(\n\s+0\.7\s+)0\.055", r"\g<1>0.0561", tail, count=1)
    prop.write_text(head + sep + tail)
    _, ours = _replay(compile_propulsion(C172P, engines), start, ins)
    off = np.abs(ours[E + "thrust-lbs"] - jsb[E + "thrust-lbs"])
    assert off.max() > 0.5


def _write(tmp_path: Path, piston: str, propeller: str, thruster: str = "") -> Path:
    (tmp_path / "Engines").mkdir(exist_ok=True)
    (tmp_path / "Engines" / "eng.xml").write_text(f'<piston_engine name="p">\n{piston}\n'
                                                  f"</piston_engine>\n")
    (tmp_path / "Engines" / "prop.xml").write_text(
        f'<propeller name="pr">\n  <ixx> 1 </ixx> <diameter unit="IN"> 70 </diameter>\n'
        f"{propeller}\n"
        f'  <table name="C_THRUST" type="internal"> <tableData> 0 0.07\n 2 -0.07 '
        f"</tableData> </table>\n"
        f'  <table name="C_POWER" type="internal"> <tableData> 0 0.05\n 2 0.04 '
        f"</tableData> </table>\n</propeller>\n")
    xml = tmp_path / "a.xml"
    xml.write_text(f"""<fdm_config>
  <propulsion>
  <engine file="eng">
    <feed> 0 </feed>
    <thruster file="prop">
      <location unit="IN"> <x> -30 </x> <y> 0 </y> <z> 20 </z> </location>
{thruster}
    </thruster>
  </engine>
  <tank type="FUEL">
    <location unit="IN"> <x> 1 </x> <y> 0 </y> <z> 0 </z> </location>
    <capacity unit="LBS"> 10 </capacity> <contents unit="LBS"> 5 </contents>
  </tank>
  </propulsion>
</fdm_config>
""")
    return xml


@pytest.mark.parametrize(("piston", "propeller", "thruster", "match"), [
    ("<numboostspeeds> 1 </numboostspeeds>", "", "",
     r"eng.xml:2: <numboostspeeds>: not supported in a piston_engine .*no supercharger"),
    ("<function name=\"x\"> <value> 1 </value> </function>", "", "",
     r"eng.xml:2: <function>: not supported in a piston_engine"),
    ("<maxmp unit=\"PSI\"> 20 </maxmp>", "", "", r"eng.xml:2: <maxmp>: unit 'PSI'"),
    ("", "<minpitch> 10 </minpitch> <maxpitch> 30 </maxpitch>", "",
     r"prop.xml:1: <propeller>: a variable-pitch propeller .* is not compiled"),
    ("", "<maxrpm> 2500 </maxrpm>", "", r"prop.xml:3: <maxrpm>: not supported in a propeller"),
    ("", "<table name=\"CT_MACH\" type=\"internal\"> <tableData> 0.9 1\n 0.8 0.5 </tableData>"
         " </table>", "", r"prop.xml:3: <tableData>: breakpoints must increase"),
    ("", "", "<orient unit=\"DEG\"> <roll> 0 </roll> <pitch> 2 </pitch> <yaw> 0 </yaw> </orient>",
     r"a.xml:7: <orient>: a propeller turned off the body's x axis is not compiled"),
    ("", "", "<p_factor> -1 </p_factor>", r"a.xml:7: <p_factor>: the P-factor must be 0"),
])
def test_what_the_piston_and_propeller_do_not_compile_is_refused_with_file_and_line(
        tmp_path: Path, piston: str, propeller: str, thruster: str, match: str) -> None:
    xml = _write(tmp_path, piston, propeller, thruster)
    with pytest.raises(CompileError, match=match):
        compile_propulsion(xml, ENGINES)


def test_a_small_piston_file_compiles_with_jsbsims_defaults(tmp_path: Path) -> None:
    """The defaults of FGPiston's constructor (an O-360, more or less) and
    its derived ISFC when no <bsfc> is given."""
    plan = compile_propulsion(_write(tmp_path, "<maxhp> 180 </maxhp>", ""), ENGINES)
    e = plan.engines[0]
    assert isinstance(e, Piston)
    assert (e.idle_rpm, e.max_rpm, e.stroke_in, e.starter_torque) == (600, 2800, 4.375, 72)
    assert 0.3 < e.isfc < 0.6 and e.propeller.diameter_ft == pytest.approx(70 / 12)


def test_a_turbine_turning_a_propeller_is_refused(tmp_path: Path) -> None:
    xml = _write(tmp_path, "", "")
    (tmp_path / "Engines" / "eng.xml").write_text(
        '<turbine_engine name="t">\n  <milthrust> 100 </milthrust>\n'
        '  <function name="IdleThrust"> <value> 0.05 </value> </function>\n'
        '  <function name="MilThrust"> <value> 1 </value> </function>\n</turbine_engine>\n')
    with pytest.raises(CompileError, match=r"a.xml:3: <engine>: a turbine_engine with a "
                                           r"propeller is not compiled"):
        compile_propulsion(xml, ENGINES)
