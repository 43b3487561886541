"""The fused functions (``cosim.rigid.fused``): one numba loop gives the same
doubles as the numpy kernels, for the bundled aircraft's aerodynamics and
for every operation the fuser writes; from the on-disk cache or, where no
cache folder can be written, compiled in memory; what it cannot fuse (a
table of three dimensions) is refused, and the aerodynamics then keep
numpy's kernels."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from cosim.rigid.airframe import read_aerodynamics
from cosim.rigid.functions import CompileError, compile_function, parse
from cosim.rigid.fused import fuse
from cosim.vehicles.jsb import find_model

ALL_OPS = """<function name="t/all">
  <sum>
    <product> <property> a </property> <value> 2.5 </value> <property> -b </property> </product>
    <difference> <p> a </p> <v> 1 </v> <property> c </property> </difference>
    <quotient> <property> a </property> <property> b </property> </quotient>
    <pow> <abs> <property> a </property> </abs> <value> 1.5 </value> </pow>
    <min> <property> a </property> <property> b </property> <value> 0.5 </value> </min>
    <max> <property> a </property> <property> c </property> </max>
    <sin> <property> a </property> </sin> <cos> <property> b </property> </cos>
    <atan2> <property> a </property> <property> b </property> </atan2>
    <toradians> <property> c </property> </toradians>
    <ifthen> <and> <gt> <property> a </property> <value> 0 </value> </gt>
                   <not> <eq> <property> b </property> <value> 0 </value> </eq> </not> </and>
      <value> 1 </value>
      <or> <lt> <p> c </p> <v> 0 </v> </lt> <le> <p> a </p> <p> b </p> </le> </or> </ifthen>
    <table> <independentVar lookup="row"> a </independentVar>
      <tableData> -1 0.5 0 1.0 2 -3.0 </tableData> </table>
    <table> <independentVar lookup="row"> a </independentVar>
            <independentVar lookup="column"> b </independentVar>
      <tableData>
             -1   0    3
         -2   1   2    0
          0   4  -1    2
          5   0   1    7
      </tableData> </table>
  </sum>
</function>"""


def _numpy_chain(functions, values):
    vals = dict(values)
    out = []
    for f in functions:
        v = np.broadcast_to(f.kernel(vals), values["_n"].shape)
        if f.name:
            vals[f.name] = v
        out.append(v)
    return out


def test_every_operation_fused_equals_numpy(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("COSIM_CACHE_DIR", str(tmp_path / "cache"))
    el = ET.fromstring(ALL_OPS.replace("-1 0.5 0 1.0 2 -3.0", "\n -1 0.5\n 0 1.0\n 2 -3.0\n"))
    f = compile_function(el, "t.xml")
    rng = np.random.default_rng(3)
    n = 5000
    v = {"a": rng.uniform(-3, 6, n), "b": rng.uniform(-3, 6, n), "c": rng.uniform(-2, 2, n),
         "_n": np.zeros(n)}
    v["b"][:50] = 0.0  # quotients by zero: infinite, as JSBSim
    fz = fuse([f], "t.xml", name="test_ops")
    got = fz.run(v)[0]
    want = f.evaluate(v)
    assert np.isinf(want[:50]).all() and np.isinf(got[:50]).all()
    # sin, cos, atan2 and pow: numpy's vectorised functions and the C library's
    # (which numba calls) may differ in the last bit
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
    assert list((tmp_path / "cache" / "fused").glob("cosim_fused_test_ops_*.py"))


@pytest.mark.parametrize("model", ["uav700", pytest.param("c172p", marks=pytest.mark.integration)])
def test_an_aircrafts_aerodynamics_fused_equal_numpy(model: str) -> None:
    info = find_model(model)
    path = Path(info.aircraft_dir) / model / f"{model}.xml"
    aero = read_aerodynamics(parse(path), str(path))
    every = [*aero.variables, *(c for a in aero.forces for c in a),
             *(c for a in aero.moments for c in a)]
    names = set().union(*(c.inputs for c in every))
    rng = np.random.default_rng(5)
    n = 2000
    values = {k: rng.uniform(-10, 10, n) for k in names}
    values["_n"] = np.zeros(n)
    fz = fuse(every, str(path), name=f"test_{model}")
    got = fz.run(values)
    for k, want in enumerate(_numpy_chain(every, values)):
        np.testing.assert_array_equal(got[k], want, err_msg=every[k].name)


def test_without_a_writable_cache_it_compiles_in_memory(tmp_path: Path, monkeypatch) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setenv("COSIM_CACHE_DIR", str(blocker))
    f = compile_function(ET.fromstring(
        "<function name='x'><product><p>a</p><v>3</v></product></function>"), "t.xml")
    fz = fuse([f], "t.xml", name="test_memory")
    np.testing.assert_array_equal(fz.run({"a": np.arange(4.0), "_n": np.zeros(4)})[0],
                                  np.arange(4.0) * 3)


def test_a_three_dimensional_table_is_not_fused_and_numpy_flies_it() -> None:
    info = find_model("c172x")
    path = Path(info.aircraft_dir) / "c172x" / "c172x.xml"
    aero = read_aerodynamics(parse(path), str(path))
    every = [*aero.variables, *(c for a in aero.forces for c in a),
             *(c for a in aero.moments for c in a)]
    with pytest.raises(CompileError, match=r"c172x\.xml:\d+: <table>: only tables of one or two"):
        fuse(every, str(path), name="test_c172x")
    assert aero._fused is None  # the aerodynamics keep numpy's kernels
