"""The rigid-body tier's whole aircraft (``cosim.rigid.aircraft``) against
JSBSim flying the same files: from the same trimmed state, through
elevator, aileron and throttle inputs, the two stay together to a fraction
of a millimetre; a 2 % change of one aerodynamic coefficient is seen; the
trim finds JSBSim's; and the compiler refuses what it does not know with
the file, the line and the element."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.aircraft import compile_aircraft, position_ecef, problems
from cosim.rigid.functions import CompileError
from cosim.vehicles.jsb import JSBSIM_ROOT, find_model, has_property, new_fdm, wrapper_root

REPO = Path(__file__).resolve().parents[2]
UAV700 = REPO / "aircraft" / "uav700" / "uav700.xml"
SYSTEMS = REPO / "aircraft" / "systems"
ENGINES = REPO / "aircraft" / "uav700" / "Engines"
KT = 1.68781
#: what is compared, and how far apart the two may end (JSBSim's units)
CHECK = {"position/h-sl-ft": 1e-3, "velocities/vt-fps": 1e-5, "attitude/psi-deg": 1e-5,
         "attitude/phi-deg": 1e-5, "attitude/theta-deg": 1e-5, "aero/alpha-deg": 1e-5,
         "propulsion/engine/thrust-lbs": 1e-5, "position/lat-geod-deg": 1e-9,
         "position/long-gc-deg": 1e-9}


def _trimmed_fdm(h_ft: float = 3000, kt: float = 100, psi_deg: float = 30,
                 model: str = "uav700"):
    fdm = new_fdm(find_model(model), 1 / 120)
    fdm["ic/lat-geod-deg"], fdm["ic/long-gc-deg"] = 47.0, 8.0
    fdm["ic/h-sl-ft"], fdm["ic/vt-fps"], fdm["ic/psi-true-deg"] = h_ft, kt * KT, psi_deg
    fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    fdm.do_trim(1)
    return fdm


def _rigid_from(fdm, path: Path = UAV700, systems: Path = SYSTEMS, engines: Path = ENGINES):
    """A rigid aircraft placed in ``fdm``'s state (its properties copied)."""
    ac = compile_aircraft(path, systems, engines)
    props = ac.new_props(1)
    for k in list(props):
        if not k.startswith("_") and has_property(fdm, k):
            props[k] = np.full(1, float(fdm[k]))
    lat, lon = fdm["position/lat-gc-rad"], fdm["position/long-gc-rad"]
    r = fdm["position/radius-to-vehicle-ft"]
    loc = (np.array([r * np.cos(lat) * np.cos(lon)]), np.array([r * np.cos(lat) * np.sin(lon)]),
           np.array([r * np.sin(lat)]))

    def a(k: str) -> np.ndarray:
        return np.array([fdm[k]])

    ac.place(props, loc, a("attitude/phi-rad"), a("attitude/theta-rad"), a("attitude/psi-rad"),
             (a("velocities/u-fps"), a("velocities/v-fps"), a("velocities/w-fps")),
             (a("velocities/p-rad_sec"), a("velocities/q-rad_sec"), a("velocities/r-rad_sec")))
    return ac, props


#: (time s, property, value): a pull, a roll into a spiral, full throttle
INPUTS = [(1.0, "fcs/elevator-cmd-norm", -0.1), (2.0, "fcs/elevator-cmd-norm", 0.0),
          (2.0, "fcs/aileron-cmd-norm", 0.2), (3.0, "fcs/aileron-cmd-norm", 0.0),
          (4.0, "fcs/throttle-cmd-norm", 1.0)]


def _fly(fdm, ac, props, seconds: float) -> dict[str, float]:
    """Both through ``INPUTS``; the largest difference of each ``CHECK``."""
    worst = dict.fromkeys(CHECK, 0.0)
    todo = list(INPUTS)
    for i in range(int(seconds * 120)):
        t = i / 120
        while todo and todo[0][0] <= t:
            _, k, v = todo.pop(0)
            fdm[k] = v
            props[k] = np.full(1, v)
        fdm.run()
        ac.run(props, 1 / 120)
        for k in CHECK:
            worst[k] = max(worst[k], abs(float(props[k][0]) - fdm[k]))
    return worst


def test_the_rigid_aircraft_flies_as_jsbsim_does_through_manoeuvres() -> None:
    fdm = _trimmed_fdm()
    ac, props = _rigid_from(fdm)
    start = {k: fdm[k] for k in CHECK}
    worst = _fly(fdm, ac, props, 12.0)
    assert all(worst[k] <= tol for k, tol in CHECK.items()), worst
    # the flight went somewhere: a climbing spiral at full throttle
    assert fdm["position/h-sl-ft"] - start["position/h-sl-ft"] > 100
    assert abs(fdm["attitude/phi-deg"]) > 20
    assert fdm["velocities/vt-fps"] > start["velocities/vt-fps"] + 20


@pytest.mark.integration  # JSBSim and the rigid tier fly 12 s of c172p: 5-8 s
def test_the_rigid_c172p_flies_as_jsbsim_does() -> None:
    """The c172p as cosim gives it JSBSim (the autopilot attached, off): its
    piston engine and propeller, and the ground effect's height of the
    reference point over the span, which the rigid tier did not compute."""
    fdm = _trimmed_fdm(2000, 90, model="c172p")
    xml = wrapper_root(find_model("c172p")) / "c172p" / "c172p.xml"
    ac, props = _rigid_from(fdm, xml, JSBSIM_ROOT / "systems", JSBSIM_ROOT / "engine")
    start = {k: fdm[k] for k in CHECK}
    worst = _fly(fdm, ac, props, 12.0)
    tolerance = {**CHECK, "propulsion/engine/thrust-lbs": 1e-4}
    assert all(worst[k] <= tol for k, tol in tolerance.items()), worst
    assert props["aero/h_b-mac-ft"][0] == pytest.approx(fdm["aero/h_b-mac-ft"], rel=1e-9)
    assert props["propulsion/engine/propeller-rpm"][0] == pytest.approx(
        fdm["propulsion/engine/propeller-rpm"], rel=1e-9)
    assert fdm["position/h-sl-ft"] - start["position/h-sl-ft"] > 50
    assert fdm["propulsion/engine/propeller-rpm"] > 2400 and abs(fdm["attitude/phi-deg"]) > 10


def test_burning_fuel_lightens_it_as_jsbsim_does() -> None:
    """With the fuel no longer frozen the weight, centre of gravity and
    inertia follow the tank (the mass balance recomputes only when a tank's
    contents change)."""
    fdm = _trimmed_fdm()
    ac, props = _rigid_from(fdm)
    for target in (fdm, props):
        target["uav700/fuel-freeze"] = 0.0 if target is fdm else np.zeros(1)
    start = fdm["inertia/weight-lbs"]
    for _ in range(6 * 120):
        fdm.run()
        ac.run(props, 1 / 120)
    assert fdm["inertia/weight-lbs"] < start - 0.05  # it burnt fuel
    for k in ("inertia/weight-lbs", "inertia/ixx-slugs_ft2", "inertia/cg-x-in",
              "position/h-sl-ft", "velocities/vt-fps"):
        assert abs(props[k][0] - fdm[k]) < 1e-6 * max(1.0, abs(fdm[k])), k


def test_a_two_percent_lift_coefficient_is_seen(tmp_path: Path) -> None:
    text = UAV700.read_text()
    aircraft = tmp_path / "uav700"
    aircraft.mkdir()
    # the wing-body lift at 5 deg (0.58) 2 % higher
    changed = text.replace("            5   0.58\n", "            5   0.5916\n", 1)
    assert changed != text
    (aircraft / "uav700.xml").write_text(changed)
    shutil.copytree(ENGINES, aircraft / "Engines")
    fdm = _trimmed_fdm()
    ac, props = _rigid_from(fdm, aircraft / "uav700.xml")
    worst = _fly(fdm, ac, props, 10.0)
    assert worst["position/h-sl-ft"] > 0.5, worst  # half a foot, where equal files give 1e-5



def test_the_atmosphere_computes_what_some_part_reads(tmp_path: Path) -> None:
    """The atmosphere's outputs nobody reads are not computed each frame
    (the uav700 reads the density altitude, in its engine's tables, not the
    pressure altitude); a system that reads the pressure altitude gets
    JSBSim's value."""
    from cosim.rigid.atmosphere import standard_atmosphere

    plain = compile_aircraft(UAV700, SYSTEMS, ENGINES)
    assert "atmosphere/density-altitude" in plain.atmosphere.wanted
    assert "atmosphere/pressure-altitude" not in plain.atmosphere.wanted
    probe = ('<system name="probe"><channel name="c"><fcs_function name="probe/pa">'
             '<function><property>atmosphere/pressure-altitude</property></function>'
             '</fcs_function></channel></system>\n</fdm_config>')
    text = UAV700.read_text()
    aircraft = tmp_path / "uav700"
    aircraft.mkdir()
    (aircraft / "uav700.xml").write_text(text.replace("</fdm_config>", probe, 1))
    shutil.copytree(ENGINES, aircraft / "Engines")
    ac = compile_aircraft(aircraft / "uav700.xml", SYSTEMS, ENGINES)
    assert "atmosphere/pressure-altitude" in ac.atmosphere.wanted
    props = ac.new_props(2)
    loc = position_ecef(np.full(2, 47.0), np.full(2, 8.0), np.array([3000.0, 12000.0]))
    assert ac.trim_level(props, loc, np.zeros(2), np.full(2, 100 * KT)).all()
    ac.run(props, 1 / 120)
    want = standard_atmosphere(props["position/h-sl-ft"])["atmosphere/pressure-altitude"]
    np.testing.assert_array_equal(props["atmosphere/pressure-altitude"], want)
    assert want[1] > want[0] + 8000.0

def test_set_running_after_the_initial_conditions_leaves_jsbsims_engine() -> None:
    """Untrimmed starts: the initial conditions, then propulsion/set-running.
    JSBSim leaves the engine at its full-throttle N1, N2 and thrust, running,
    and its first frames spool it down to the closed throttle; so does the
    rigid aircraft (its engine had started from the throttle's N2). An
    aircraft with empty tanks and its fuel not frozen is starved there:
    JSBSim winds its engine down, off, and so does the rigid one."""
    ac = compile_aircraft(UAV700, SYSTEMS, ENGINES)
    props = ac.new_props(2)
    props["uav700/fuel-freeze"] = np.array([1.0, 0.0])
    props["propulsion/tank/contents-lbs"] = np.array([props["propulsion/tank/contents-lbs"][0],
                                                      0.0])
    fdms = []
    for i in range(2):
        fdm = new_fdm(find_model("uav700"), 1 / 120)
        fdm["ic/lat-geod-deg"], fdm["ic/long-gc-deg"] = 47.0, 8.0
        fdm["ic/h-sl-ft"], fdm["ic/vt-fps"], fdm["ic/psi-true-deg"] = 3000, 100 * KT, 0
        if i == 1:
            fdm["uav700/fuel-freeze"], fdm["propulsion/tank/contents-lbs"] = 0.0, 0.0
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        fdms.append(fdm)
    z = np.zeros(2)
    loc = position_ecef(np.full(2, 47.0), np.full(2, 8.0), np.full(2, 3000.0))
    ac.place(props, loc, z, z, z, (np.full(2, 100 * KT), z, z))
    ac.propulsion.set_running(props)
    keys = ("propulsion/engine/n1", "propulsion/engine/n2", "propulsion/engine/thrust-lbs")
    for i, fdm in enumerate(fdms):
        for k in keys:
            assert props[k][i] == pytest.approx(fdm[k], rel=1e-12, abs=1e-12), (i, k)
    assert props["propulsion/engine/n2"][0] == 100.0 and props["propulsion/engine/n2"][1] < 5
    for _ in range(60):
        ac.run(props, 1 / 120)
        for fdm in fdms:
            fdm.run()
    for k in keys:
        assert props[k][0] == pytest.approx(fdms[0][k], rel=1e-6), k
    assert 50 < props["propulsion/engine/n2"][0] < 70  # half-way down to idle (33 %)
    assert props["propulsion/engine/thrust-lbs"][1] == fdms[1]["propulsion/engine/thrust-lbs"]
    assert props["propulsion/engine/n2"][1] == pytest.approx(fdms[1]["propulsion/engine/n2"],
                                                             abs=1e-3)


@pytest.mark.parametrize(("h_ft", "kt"), [(3000, 100), (500, 60), (10000, 200)])
def test_the_trim_finds_jsbsims(h_ft: float, kt: float) -> None:
    fdm = _trimmed_fdm(h_ft, kt, 30)
    ac = compile_aircraft(UAV700, SYSTEMS, ENGINES)
    props = ac.new_props(1)
    loc = position_ecef(np.array([47.0]), np.array([8.0]), np.array([float(h_ft)]))
    ok = ac.trim_level(props, loc, np.radians([30.0]), np.array([kt * KT]))
    assert ok.all()
    assert abs(props["position/h-sl-ft"][0] - h_ft) < 1e-6
    assert abs(props["aero/alpha-deg"][0] - fdm["aero/alpha-deg"]) < 1e-3
    # JSBSim also trims the roll of the Earth's rotation: a few hundredths of a degree
    assert abs(props["attitude/phi-deg"][0] - fdm["attitude/phi-deg"]) < 0.1
    assert abs(props["fcs/throttle-cmd-norm"][0] - fdm["fcs/throttle-cmd-norm"]) < 1e-4
    assert abs(props["fcs/pitch-trim-cmd-norm"][0] - fdm["fcs/pitch-trim-cmd-norm"]) < 1e-4


def test_the_c172ps_trim_balances_the_propellers_roll_and_yaw_as_jsbsims() -> None:
    """The propeller's torque and P-factor roll and yaw the c172p in level
    flight: JSBSim's full trim holds them with aileron, rudder and a little
    bank, and so does the rigid trim (it trimmed wings level, no aileron or
    rudder, before: the autopilot's heading then drifted 1.8 deg from
    JSBSim's in a climb)."""
    fdm = _trimmed_fdm(4300, 70, 30, model="c172p")
    xml = wrapper_root(find_model("c172p")) / "c172p" / "c172p.xml"
    ac = compile_aircraft(xml, JSBSIM_ROOT / "systems", JSBSIM_ROOT / "engine")
    props = ac.new_props(1)
    loc = position_ecef(np.array([47.0]), np.array([8.0]), np.array([4300.0]))
    assert ac.trim_level(props, loc, np.radians([30.0]), np.array([70 * KT])).all()
    assert abs(fdm["fcs/rudder-cmd-norm"]) > 0.01 and abs(fdm["fcs/aileron-cmd-norm"]) > 0.03
    for k, tol in (("fcs/aileron-cmd-norm", 1e-3), ("fcs/rudder-cmd-norm", 1e-3),
                   ("attitude/phi-deg", 1e-3), ("aero/alpha-deg", 1e-3), ("aero/beta-deg", 1e-3),
                   ("fcs/throttle-cmd-norm", 1e-4), ("fcs/pitch-trim-cmd-norm", 1e-4)):
        assert abs(props[k][0] - fdm[k]) < tol, (k, props[k][0], fdm[k])


def test_unknown_elements_are_refused_with_file_line_and_element(tmp_path: Path) -> None:
    text = UAV700.read_text()
    bad = text.replace("<aerodynamics>", "<aerodynamics>\n    <aero_ref_pt_shift_x/>", 1)
    bad = bad.replace('<axis name="DRAG"', '<axis name="AXIAL"', 1)
    bad = bad.replace("</fdm_config>", "  <buoyant_forces/>\n</fdm_config>", 1)
    aircraft = tmp_path / "uav700"
    aircraft.mkdir()
    path = aircraft / "uav700.xml"
    path.write_text(bad)
    shutil.copytree(ENGINES, aircraft / "Engines")
    found = [str(e) for e in problems(path, SYSTEMS, ENGINES)]
    assert any("<buoyant_forces>: not supported" in m for m in found), found
    assert any("<aero_ref_pt_shift_x>: not supported" in m for m in found), found
    assert any("axis 'AXIAL' is not supported" in m for m in found), found
    assert all(m.startswith(f"{path}:") for m in found), found
    with pytest.raises(CompileError, match=r"uav700\.xml:\d+: <buoyant_forces>"):
        compile_aircraft(path, SYSTEMS, ENGINES)


def test_the_bundled_aircraft_compiles_without_a_problem() -> None:
    assert problems(UAV700, SYSTEMS, ENGINES) == []



@pytest.mark.parametrize("fuse", [True, False], ids=["fused-systems", "numpy-systems"])
def test_blocks_written_over_in_place_fly_as_two_blocks_in_turn_do(
        fuse: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """The integrated and derived states, auxiliary values, accelerations
    and aerodynamic terms and forces are written over in place each frame
    (one block each, half the memory): a part keeping one of their rows
    from a frame before (a filter's past input kept by reference, say)
    would read this frame's values instead. With the autopilot engaged
    through a heading change, every property ends as it does with two
    blocks used in turn."""
    from cosim.rigid import airframe, body

    def fly() -> dict[str, np.ndarray]:
        ac = compile_aircraft(UAV700, SYSTEMS, ENGINES, fuse=fuse)
        n = 3
        props = ac.new_props(n)
        loc = position_ecef(np.full(n, 47.0), np.full(n, 8.0), np.full(n, 3000.0))
        props["cosim/ap/qbar-ref-psf"] = np.full(n, 34.0)
        assert ac.trim_level(props, loc, np.zeros(n), np.full(n, 100 * KT)).all()
        for k, v in {"cosim/ap/engage": 1.0, "cosim/ap/heading-hold": 1.0,
                     "cosim/ap/heading-cmd-deg": 90.0, "cosim/ap/alt-hold": 1.0,
                     "cosim/ap/alt-cmd-ft": 3300.0, "cosim/ap/speed-hold": 1.0,
                     "cosim/ap/speed-cmd-kt": 110.0}.items():
            props[k] = np.full(n, v)
        for _ in range(240):
            ac.run(props, 1 / 120)
        return props

    reused = fly()
    assert not {"_eom/state1", "_eom/derived1", "_eom/auxiliary1"} & set(reused)

    def two(props: dict[str, np.ndarray], name: str, keys: tuple[str, ...], n: int
            ) -> np.ndarray:
        """Two blocks used in turn: the one the properties do not show now."""
        for k in "01":
            kept = props.get(name + k)
            if kept is None or kept.shape != (len(keys), n):
                props[name + k] = np.empty((len(keys), n))
        shown = props.get(keys[0])
        a, b = props[name + "0"], props[name + "1"]
        return b if shown is not None and np.shares_memory(shown, a) else a

    monkeypatch.setattr(body, "block", two)
    monkeypatch.setattr(airframe, "block", two)
    alternating = fly()
    assert "_eom/derived1" in alternating and "_aero/terms1" in alternating
    public = [k for k in alternating if not k.startswith("_")]
    assert len(public) > 250
    assert alternating["attitude/psi-deg"][0] > 2.0  # it turned toward 90 deg
    for k in public:
        np.testing.assert_array_equal(reused[k], alternating[k], err_msg=k)


@pytest.mark.parametrize("wind", [True, False], ids=["wind-axes", "body-axes"])
def test_the_aerodynamic_force_kernel_is_the_formula_to_the_bit(wind: bool) -> None:
    """``kernels.aero_forces`` against the formula written with numpy: the
    wind axes turned into body axes (drag and lift against their axes), the
    moment of the body force about the centre of gravity from the reference
    point (structural frame, JSBSim's inch-to-foot factor) plus the axes'
    moments; a reference point away from the centre of gravity (the
    uav700's is at it, so its flights cannot tell)."""
    from cosim.rigid import kernels
    from cosim.rigid.airframe import structural_to_body
    from cosim.rigid.units import INCHTOFT

    rng = np.random.default_rng(3)
    n = 2000
    f = rng.normal(0.0, 500.0, (3, n))
    m = rng.normal(0.0, 900.0, (3, n))
    alpha, beta = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.3, 0.3, n)
    cg = rng.normal([[40.0], [0.0], [-3.0]], 2.0, (3, n))
    rp = (37.5, 0.4, -1.25)
    out = np.empty((9, n))
    kernels.aero_forces(f[0], f[1], f[2], alpha, beta, m[0], m[1], m[2], cg[0], cg[1], cg[2],
                        *rp, INCHTOFT, wind, out)
    if wind:
        fd, fs, fl = -f[0], f[1], -f[2]
        ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
        fx = ca * cb * fd - ca * sb * fs - sa * fl
        fy = sb * fd + cb * fs
        fz = sa * cb * fd - sa * sb * fs + ca * fl
        np.testing.assert_array_equal(out[6:], [fd, fs, fl])
    else:
        fx, fy, fz = f
    rx, ry, rz = structural_to_body(rp, cg[0], cg[1], cg[2])
    assert np.abs(rx).min() > 0.0  # the arm is not nothing
    want = [fx, fy, fz, (ry * fz - rz * fy) + m[0], (rz * fx - rx * fz) + m[1],
            (rx * fy - ry * fx) + m[2]]
    np.testing.assert_array_equal(out[:6], want)


def test_cutting_aircraft_out_leaves_the_others_flying_the_same_doubles() -> None:
    """The class takes a stopped aircraft out of its group's arrays with a
    mask (``v[..., keep]``: numpy leaves a cut block strided, not
    C-contiguous): the next frame's blocks are contiguous again, and the
    aircraft left fly the same doubles as the same aircraft never cut."""
    ac = compile_aircraft(UAV700, SYSTEMS, ENGINES)
    n = 4

    def start() -> dict[str, np.ndarray]:
        props = ac.new_props(n)
        loc = position_ecef(np.full(n, 47.0), np.full(n, 8.0), np.full(n, 3000.0))
        props["cosim/ap/qbar-ref-psf"] = np.full(n, 34.0)
        assert ac.trim_level(props, loc, np.radians([0.0, 30.0, 60.0, 90.0]),
                             np.full(n, 100 * KT)).all()
        props["fcs/elevator-cmd-norm"] = np.array([0.0, -0.05, 0.02, 0.0])
        return props

    whole, cut = start(), start()
    for _ in range(30):
        ac.run(whole, 1 / 120)
        ac.run(cut, 1 / 120)
    keep = np.array([True, False, True, True])
    cut = {k: v[..., keep] for k, v in cut.items()}
    assert not cut["_eom/derived0"].flags.c_contiguous  # what numpy gives
    for _ in range(60):
        ac.run(whole, 1 / 120)
        ac.run(cut, 1 / 120)
    for name in ("_eom/state0", "_eom/derived0", "_eom/auxiliary0", "_eom/accelerations0",
                 "_aero/terms0", "_aero/forces0"):
        assert cut[name].strides[1] == 8 and cut[name].flags.c_contiguous, name
    for k, v in whole.items():
        if not k.startswith("_"):
            np.testing.assert_array_equal(cut[k], v[..., keep], err_msg=k)



def test_a_multiple_of_512_aircraft_pads_the_blocks_rows_and_flies_the_same_doubles() -> None:
    """At a multiple of 512 aircraft a row of doubles is a whole number of
    4 KiB pages, and a kernel writing one row and reading another at the
    same offset stalls (4K aliasing): such blocks get rows a cache line
    longer, still contiguous, and the aircraft fly the same doubles as a
    batch that needs no padding (the same aircraft and one more)."""
    ac = compile_aircraft(UAV700, SYSTEMS, ENGINES)

    def fly(n: int) -> dict[str, np.ndarray]:
        props = ac.new_props(n)
        loc = position_ecef(47.0 + np.arange(n) * 1e-4, np.full(n, 8.0), np.full(n, 3000.0))
        props["cosim/ap/qbar-ref-psf"] = np.full(n, 34.0)
        assert ac.trim_level(props, loc, np.linspace(0.0, 6.0, 513)[:n],
                             np.full(n, 100 * KT)).all()
        for _ in range(30):
            ac.run(props, 1 / 120)
        return props

    padded, plain = fly(512), fly(513)
    for name in ("_eom/state0", "_eom/derived0", "_eom/auxiliary0", "_aero/terms0"):
        assert padded[name].strides == (8 * 520, 8), name
        assert plain[name].strides == (8 * 513, 8), name
    for k, v in padded.items():
        if not k.startswith("_"):
            np.testing.assert_array_equal(v, plain[k][:512], err_msg=k)
