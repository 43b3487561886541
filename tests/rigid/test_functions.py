"""The rigid-body tier's function compiler (``cosim.rigid.functions``)
against JSBSim itself: every aerodynamic function of the uav700 evaluated on
the states of a JSBSim flight through manoeuvres equals what JSBSim
computed in that frame; tables against an independent interpolation over
and beyond their ends; and what the compiler does not know is refused with
the file, the line and the element."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.functions import CompileError, compile_function, parse, read_functions
from cosim.vehicles.jsb import find_model, new_fdm

REPO = Path(__file__).resolve().parents[2]
UAV700 = REPO / "aircraft" / "uav700" / "uav700.xml"


def _flight(functions: dict, steps: int = 600, model: str = "uav700", flaps: bool = False
            ) -> tuple[dict[str, np.ndarray], dict]:
    """The model flown by JSBSim through elevator, aileron and rudder
    doublets: each input property and each function's value, per frame."""
    fdm = new_fdm(find_model(model), 1 / 120)
    fdm["ic/h-sl-ft"] = 3000
    fdm["ic/vc-kts"] = 100
    fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    names = sorted(set().union(*(f.inputs for f in functions.values())))
    inputs: dict[str, list[float]] = {n: [] for n in names}
    outputs: dict[str, list[float]] = {n: [] for n in functions}
    rng = np.random.default_rng(7)
    for i in range(steps):
        if i % 40 == 0:  # a new command every third of a second
            for c in ("fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm"):
                fdm[c] = float(rng.uniform(-1, 1))
            fdm["fcs/throttle-cmd-norm"] = float(rng.uniform(0, 1))
            if flaps:  # through and between the flap table's breakpoints
                fdm["fcs/flap-cmd-norm"] = float(rng.uniform(0, 1))
        fdm.run()
        for n in names:
            inputs[n].append(fdm[n])
        for n in functions:
            outputs[n].append(fdm[n])
    return ({k: np.array(v) for k, v in inputs.items()},
            {k: np.array(v) for k, v in outputs.items()})


@pytest.mark.parametrize("model", ["uav700", "c172p"])
def test_every_function_of_a_model_equals_jsbsims_own_value_in_flight(model: str) -> None:
    info = find_model(model)
    functions = read_functions(Path(info.aircraft_dir) / model / f"{model}.xml")
    assert len(functions) >= 25
    inputs, outputs = _flight(functions, model=model)
    # the manoeuvres moved most of them
    assert sum(np.ptp(v) > 0 for v in outputs.values()) > 0.7 * len(outputs)
    for name, f in functions.items():
        got = f.evaluate(inputs)
        np.testing.assert_allclose(got, outputs[name], rtol=1e-12, atol=1e-9, err_msg=name)


def test_three_dimensional_tables_equal_jsbsims_in_flight() -> None:
    """JSBSim's c172x: its lift and moment tables of alpha, beta and flap
    angle, flown with the flaps moving through and between breakpoints."""
    info = find_model("c172x")
    functions = read_functions(Path(info.aircraft_dir) / "c172x" / "c172x.xml")
    text = (Path(info.aircraft_dir) / "c172x" / "c172x.xml").read_text()
    assert 'lookup="table"' in text
    inputs, outputs = _flight(functions, steps=900, model="c172x", flaps=True)
    assert np.ptp(inputs["fcs/flap-pos-deg"]) > 10  # across the 10 deg breakpoint
    for name, f in functions.items():
        np.testing.assert_allclose(f.evaluate(inputs), outputs[name], rtol=1e-12, atol=1e-9,
                                   err_msg=name)


def test_a_perturbed_coefficient_is_caught() -> None:
    """The comparison above fails when one coefficient is 2 % off."""
    text = UAV700.read_text().replace("<value> 0.30 </value>", "<value> 0.306 </value>", 1)
    bad = Path(str(UAV700) + ".test")
    try:
        bad.write_text(text)
        functions = read_functions(bad)
    finally:
        bad.unlink(missing_ok=True)
    inputs, outputs = _flight(read_functions(UAV700), steps=120)
    name = "aero/force/Lift_elevator"
    assert not np.allclose(functions[name].evaluate(inputs), outputs[name], rtol=1e-3)


def test_tables_interpolate_and_clamp_as_an_independent_interpolation() -> None:
    root = parse(UAV700)
    el = next(e for e in root.iter("function") if e.get("name") == "aero/uav700/cl-wb")
    f = compile_function(el, str(UAV700))
    rows = [[float(x) for x in line.split()] for line in
            el.find("table/tableData").text.strip().splitlines()]  # type: ignore[union-attr]
    bp, val = np.array(rows).T
    alpha = np.linspace(-150, 150, 3001)  # beyond both ends: clamped
    np.testing.assert_allclose(f.evaluate({"aero/alpha-deg": alpha}),
                               np.interp(alpha, bp, val), rtol=0, atol=1e-12)


def _compile(tmp_path: Path, body: str):
    p = tmp_path / "a.xml"
    p.write_text(f"<aero>\n  <function name='x'>\n{body}\n  </function>\n</aero>\n")
    el = next(parse(p).iter("function"))
    return compile_function(el, str(p)), p


def test_two_dimensional_tables_and_operations(tmp_path: Path) -> None:
    f, _ = _compile(tmp_path, """
      <sum>
        <table>
          <independentVar lookup="row"> a </independentVar>
          <independentVar lookup="column"> b </independentVar>
          <tableData>
                 0    10
            0    1     3
            2    5    11
          </tableData>
        </table>
        <ifthen> <gt> <property> a </property> <value> 1 </value> </gt>
                 <quotient> <value> 1 </value> <property> -b </property> </quotient>
                 <value> 0 </value> </ifthen>
      </sum>""")
    a = np.array([-1.0, 0.0, 1.0, 2.0, 3.0, 1.0])
    b = np.array([0.0, 5.0, 5.0, 10.0, 20.0, 0.0])
    # bilinear inside, clamped outside; 1/-b where a > 1 (infinite for b = 0)
    with np.errstate(divide="ignore"):
        want = np.array([1.0, 2.0, 5.0, 11.0, 11.0, 3.0]) + np.where(a > 1, -1 / b, 0)
    np.testing.assert_allclose(f.evaluate({"a": a, "b": b}), want)
    assert f.inputs == {"a", "b"}


@pytest.mark.parametrize("body, message", [
    ("<integral> <value> 1 </value> </integral>", r":3: <integral>: not supported"),
    ("<product scale='2'> <value> 1 </value> </product>", r":3: <product>: attribute 'scale'"),
    ("<quotient> <value> 1 </value> </quotient>", r":3: <quotient>: takes 2 arguments, has 1"),
    ("<table> <independentVar lookup='row'> a </independentVar>\n"
     "<tableData>\n 0 1\n 0 2\n</tableData> </table>", r":4: <tableData>: breakpoints"),
    ("<value> one </value>", r":3: <value>: not a number"),
])
def test_what_is_not_supported_is_refused_with_file_line_and_element(
        tmp_path: Path, body: str, message: str) -> None:
    with pytest.raises(CompileError, match=r"a\.xml" + message):
        _compile(tmp_path, body)
