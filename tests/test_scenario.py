"""The scenario loader: validation (every problem at once, with file:line:
path), model and property checks, formations, positions, seeds, schedule
ticks and the resolved round trip."""

from __future__ import annotations

import math
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from cosim.errors import ConfigError
from cosim.scenario import Scenario, load_scenario, parse_scenario

QUICKSTART = Path(__file__).resolve().parent.parent / "scenarios" / "quickstart.yaml"
FNAME = "s.yaml"
PROBLEM = re.compile(r"^s\.yaml:(\d+): (\S.*?): (.+)$")

HEAD = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: 20
seed: 3
"""

ONE = """\
vehicles:
  - id: a
    model: c172p
    init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
"""


def dd(text: str) -> str:
    return textwrap.dedent(text).lstrip("\n")


def parse(text: str, **kw) -> Scenario:
    return parse_scenario(dd(text), FNAME, **kw)


def problems(text: str, **kw) -> list[str]:
    with pytest.raises(ConfigError) as ei:
        parse_scenario(dd(text), FNAME, **kw)
    probs = ei.value.problems
    assert isinstance(probs, list) and probs
    assert str(ei.value) == "\n".join(probs)
    return probs


def has(probs: list[str], line: int, path: str, fragment: str) -> bool:
    """Is there a problem ``s.yaml:<line>: <path>: ...<fragment>...``?"""
    prefix = f"{FNAME}:{line}: {path}: "
    return any(p.startswith(prefix) and fragment in p[len(prefix):] for p in probs)


def line_of(text: str, needle: str, nth: int = 0) -> int:
    """1-based line of the nth line of (dedented) text containing needle."""
    hits = [i + 1 for i, ln in enumerate(dd(text).splitlines()) if needle in ln]
    return hits[nth]


def ned(scn: Scenario, v) -> tuple[float, float, float]:
    n, e, d = scn.origin.frame.geodetic_to_ned(v.lat_deg, v.lon_deg, v.alt_msl_m)
    return float(n), float(e), float(d)


# --- quickstart ---------------------------------------------------------------

def test_quickstart_loads() -> None:
    scn = load_scenario(QUICKSTART)
    assert scn.name == "quickstart"
    assert [v.id for v in scn.vehicles] == [f"c172-{i}" for i in range(5)]
    assert all(v.model == "c172p" for v in scn.vehicles)
    assert scn.rates.control_every == 4
    assert scn.rates.log_every == 12
    assert scn.total_ticks == 7200
    assert len(scn.schedule) == 1
    item = scn.schedule[0]
    assert item.tick == 1200
    assert item.vehicles == (2,)
    assert item.sets == (("fcs/throttle-cmd-norm", 0.0),)
    # c172p has a fixed-wing profile: the autopilot's setpoints come first, then
    # the schedule's own properties (throttle is already one of them)
    from cosim.vehicles.fixed_wing.guidance import AP_CHANNELS

    assert scn.classes == ("fixed_wing",) and scn.channels == AP_CHANNELS
    assert "fcs/throttle-cmd-norm" in scn.channels
    assert all(v.alt_msl_m == 610.0 for v in scn.vehicles)
    assert all(v.airspeed_mps == pytest.approx(100 * 1852 / 3600, rel=1e-15)
               for v in scn.vehicles)


# --- every problem at once, each with file:line: path: message ------------------

MANY = """
schema_version: 2
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 50, log_hz: 10}
duration_s: 20
colour: red
vehicles:
  - id: a
    model: c172p
    init: {north_m: 0, east_m: 0, alt_agl_m: high, heading_deg: 0, airspeed_kt: 90}
  - id: b
    model: c172p
    init: {north_m: 0, east_m: 100, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    model: c172p
  - id: b
    model: c172p
    init: {north_m: 0, east_m: 200, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
schedule:
  - at_s: 30
    vehicles: zz*
    set: {fcs/throttle-cmd-norm: 0.5}
"""


def test_every_problem_reported_at_once() -> None:
    probs = problems(MANY)
    for p in probs:
        assert PROBLEM.match(p), p
    expect = [
        (line_of(MANY, "schema_version"), "schema_version", "unsupported schema_version 2"),
        (line_of(MANY, "rates:"), "rates.control_hz", "control_hz 50 must divide physics_hz 120"),
        (line_of(MANY, "colour"), "colour", "unknown key 'colour'"),
        (line_of(MANY, "high"), "vehicles[0].init.alt_agl_m", "expected a number, got 'high'"),
        (line_of(MANY, "model: c172p", 2), "vehicles[1].model", "duplicate key 'model'"),
        (line_of(MANY, "id: b", 1), "vehicles[2].id", "duplicate vehicle id 'b'"),
        (line_of(MANY, "at_s: 30"), "schedule[0].at_s",
         "at_s 30 is at or after the end of the run (duration_s 20)"),
        (line_of(MANY, "zz*"), "schedule[0].vehicles", "'zz*' matches no vehicle"),
    ]
    for line, path, frag in expect:
        assert has(probs, line, path, frag), (line, path, frag, probs)
    assert len(probs) == len(expect), probs
    # the duplicate-id message points at the first one
    dup = next(p for p in probs if "duplicate vehicle id" in p)
    assert f"vehicles[1], line {line_of(MANY, 'id: b')}" in dup


def test_non_number_altitude_exact_message() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: a
            model: c172p
            init:
              north_m: 0
              east_m: 0
              alt_agl_m: high
              heading_deg: 0
              airspeed_kt: 90
    """)
    probs = problems(text)
    assert probs == [f"{FNAME}:{line_of(text, 'high')}: vehicles[0].init.alt_agl_m: "
                     f"expected a number, got 'high'"]
    assert line_of(text, "high") == 12


def test_unknown_key_nested() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: a
            model: c172p
            colour: red
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    """)
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "colour"), "vehicles[0].colour", "unknown key 'colour'")
    assert "expected one of: id, class, model" in probs[0]


def test_control_hz_must_divide_physics_hz() -> None:
    text = HEAD.replace("control_hz: 30", "control_hz: 50") + ONE
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, 3, "rates.control_hz", "50")
    assert "120" in probs[0]


def test_log_hz_must_divide_control_hz() -> None:
    text = HEAD.replace("log_hz: 10", "log_hz: 7") + ONE
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, 3, "rates.log_hz", "log_hz 7 must divide control_hz 30")


@pytest.mark.parametrize("physics,control,log", [(120, 30, 10), (100, 50, 25), (60, 60, 60),
                                                 (240, 40, 5)])
def test_good_rates(physics: int, control: int, log: int) -> None:
    text = HEAD.replace("physics_hz: 120, control_hz: 30, log_hz: 10",
                        f"physics_hz: {physics}, control_hz: {control}, log_hz: {log}") + ONE
    scn = parse(text)
    assert scn.rates.control_every == physics // control
    assert scn.rates.log_every == physics // log


def test_duplicate_key() -> None:
    text = HEAD + "duration_s: 30\n" + ONE
    probs = problems(text)
    assert probs == [f"{FNAME}:6: duration_s: duplicate key 'duration_s'"]


def test_duplicate_vehicle_id_from_formation() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: a
            count: 3
            model: c172p
            formation: {type: line, spacing_m: 100}
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
          - id: a1
            model: c172p
            init: {north_m: 500, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    """)
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "id: a1"), "vehicles[1].id", "duplicate vehicle id 'a1'")


def test_schedule_selecting_no_vehicle() -> None:
    text = HEAD + ONE + dd("""
        schedule:
          - at_s: 1
            vehicles: [a, b]
            set: {fcs/throttle-cmd-norm: 0.5}
    """)
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "vehicles: [a, b]"), "schedule[0].vehicles",
               "'b' matches no vehicle (vehicles: a)")


def test_schedule_at_or_after_end() -> None:
    """An item at the very end (or rounded up onto it) would never run."""
    text = HEAD + ONE + dd("""
        schedule:
          - at_s: 19.966
            set: {fcs/throttle-cmd-norm: 0.5}
          - at_s: 20
            set: {fcs/throttle-cmd-norm: 0.5}
          - at_s: 20.5
            set: {fcs/throttle-cmd-norm: 0.5}
          - at_s: 19.97
            set: {fcs/throttle-cmd-norm: 0.5}
    """)
    probs = problems(text)
    assert len(probs) == 3, probs
    assert has(probs, line_of(text, "at_s: 20.5"), "schedule[2].at_s",
               "at_s 20.5 is at or after the end of the run (duration_s 20)")
    assert has(probs, line_of(text, "at_s: 20"), "schedule[1].at_s",
               "at_s 20 is at or after the end of the run (duration_s 20), so it would never "
               "run; the last control exchange starts at 19.9667 s")
    assert has(probs, line_of(text, "at_s: 19.97"), "schedule[3].at_s",  # rounds up to 20 s
               "at_s 19.97 is at or after the end of the run")


def test_schema_version_2() -> None:
    probs = problems(HEAD.replace("schema_version: 1", "schema_version: 2") + ONE)
    assert probs == [f"{FNAME}:1: schema_version: unsupported schema_version 2; "
                     f"this cosim reads 1"]


def test_yaml_syntax_error_reports_line() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: a
           model: c172p
    """)
    probs = problems(text)
    assert len(probs) == 1
    m = re.match(r"^s\.yaml:(\d+): YAML syntax error", probs[0])
    assert m, probs
    assert int(m.group(1)) in (line_of(text, "model"), line_of(text, "model") + 1)

    text = "schema_version: 1\norigin: {lat_deg: 47.0, lon_deg: 8.0\nduration_s: 5\n"
    probs = problems(text)
    assert len(probs) == 1 and re.match(r"^s\.yaml:[23]: YAML syntax error", probs[0]), probs


def test_missing_vehicles() -> None:
    probs = problems(HEAD)
    assert probs == [f"{FNAME}:1: (top level): missing required key 'vehicles'"]


def test_missing_required_keys() -> None:
    text = dd("""
        schema_version: 1
        origin: {lat_deg: 47.0}
        vehicles:
          - id: a
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0}
    """)
    probs = problems(text)
    assert has(probs, 2, "origin", "missing required key 'lon_deg'")
    assert has(probs, 1, "(top level)", "missing required key 'duration_s'")
    assert has(probs, 4, "vehicles[0]", "missing required key 'model'")
    assert has(probs, 5, "vehicles[0].init", "missing the airspeed")
    assert len(probs) == 4, probs


def test_problem_in_block_mapping_points_at_its_key() -> None:
    """A problem with a whole block mapping is reported on the line of its key,
    not on the line where its contents start."""
    text = HEAD + dd("""
        vehicles:
          - id: a
            model: c172p
            formation:
              type: zigzag
              spacing_m: 10
            init:
              north_m: 0
              east_m: 0
              heading_deg: 0
              airspeed_kt: 90
    """)
    probs = problems(text)
    assert has(probs, line_of(text, "init:"), "vehicles[0].init", "missing the altitude")
    assert has(probs, line_of(text, "zigzag"), "vehicles[0].formation.type",
               "expected one of: line, grid, circle; got 'zigzag'")
    assert len(probs) == 2, probs


def test_out_of_range_and_wrong_types() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: "bad id"
            model: c172p
            trim: yes please
            count: 0
            init: {lat_deg: 95, lon_deg: 8, alt_msl_m: 500, alt_agl_m: 10, heading_deg: 0,
                   airspeed_kt: true}
    """)
    probs = problems(text)
    assert has(probs, 7, "vehicles[0].id", "may only contain letters")
    assert has(probs, 9, "vehicles[0].trim", "expected true or false, got 'yes please'")
    assert has(probs, 10, "vehicles[0].count", "must be >= 1, got 0")
    assert has(probs, 11, "vehicles[0].init.lat_deg", "must be <= 90, got 95")
    assert has(probs, 11, "vehicles[0].init", "give only one of alt_msl_m / alt_agl_m")
    assert has(probs, 12, "vehicles[0].init.airspeed_kt", "expected a number, got True")


# --- models and properties ------------------------------------------------------

def test_unknown_model_lists_available_and_suggests_case() -> None:
    text = HEAD + ONE.replace("model: c172p", "model: C172P")
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, 8, "vehicles[0].model", "unknown aircraft model 'C172P'")
    assert "did you mean 'c172p'?" in probs[0]
    avail = probs[0].split("available: ", 1)[1].split(", ")
    assert "c172p" in avail and "c172x" in avail


def test_unknown_model_without_close_match() -> None:
    probs = problems(HEAD + ONE.replace("model: c172p", "model: nosuchplane"))
    assert len(probs) == 1 and "did you mean" not in probs[0]
    assert "c172p" in probs[0]


SCHED = """\
schedule:
  - at_s: 1
    vehicles: a
    set:
      fcs/mixture-cmd-norm: 1
      {prop}: 0.5
"""


def test_misspelled_property_in_schedule() -> None:
    text = HEAD + ONE + SCHED.replace("{prop}", "fcs/throtle-cmd-norm")
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "throtle"), "schedule[0].set.fcs/throtle-cmd-norm",
               "JSBSim property 'fcs/throtle-cmd-norm' does not exist in model c172p")
    # the correct spelling passes, and is not checked at all when asked not to
    scn = parse(HEAD + ONE + SCHED.replace("{prop}", "fcs/throttle-cmd-norm"))
    assert scn.schedule[0].sets == (("fcs/mixture-cmd-norm", 1.0),
                                    ("fcs/throttle-cmd-norm", 0.5))
    parse(text, check_properties=False)


VSET = """\
vehicles:
  - id: a
    model: c172p
    set:
      {prop}: 0.7
    init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
"""


def test_misspelled_property_in_vehicle_set() -> None:
    text = HEAD + VSET.replace("{prop}", "fcs/throtle-cmd-norm")
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "throtle"), "vehicles[0].set.fcs/throtle-cmd-norm",
               "'fcs/throtle-cmd-norm' does not exist in model c172p")
    scn = parse(HEAD + VSET.replace("{prop}", "fcs/throttle-cmd-norm"))
    assert scn.vehicles[0].initial_props == (("fcs/throttle-cmd-norm", 0.7),)


def test_read_only_property_is_rejected() -> None:
    """JSBSim silently ignores writes to read-only properties such as vt-fps."""
    text = HEAD + VSET.replace("{prop}", "fcs/mag-elevator-pos-rad").replace("0.7", "0.1")
    probs = problems(text)
    assert len(probs) == 1
    assert has(probs, line_of(text, "mag-elevator"), "vehicles[0].set.fcs/mag-elevator-pos-rad",
               "JSBSim property 'fcs/mag-elevator-pos-rad' is read-only in model c172p")
    text = HEAD + ONE + SCHED.replace("{prop}", "aero/alpha-deg")
    assert has(problems(text), line_of(text, "alpha-deg"), "schedule[0].set.aero/alpha-deg",
               "is read-only in model c172p")


# --- count and formations --------------------------------------------------------

SWARM = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
duration_s: 10
vehicles:
  - id: uav
    count: 1000
    model: c172p
    formation: {type: grid, spacing_m: 50}
    init: {north_m: 300, east_m: -200, alt_agl_m: 300, heading_deg: 30, airspeed_kt: 60}
"""


def _nearest(n: np.ndarray, e: np.ndarray) -> np.ndarray:
    dist = np.hypot(n[:, None] - n[None, :], e[:, None] - e[None, :])
    np.fill_diagonal(dist, np.inf)
    return dist.min(axis=1)


def test_thousand_vehicles_in_ten_lines(tmp_path: Path) -> None:
    assert len(SWARM.splitlines()) <= 10
    p = tmp_path / "swarm.yaml"
    p.write_text(SWARM)
    scn = load_scenario(p)
    assert len(scn.vehicles) == 1000
    ids = [v.id for v in scn.vehicles]
    assert len(set(ids)) == 1000
    assert ids[0] == "uav000" and ids[-1] == "uav999"
    assert ids == [f"uav{i:03d}" for i in range(1000)]
    n, e, _ = scn.origin.frame.geodetic_to_ned(
        np.array([v.lat_deg for v in scn.vehicles]), np.array([v.lon_deg for v in scn.vehicles]),
        np.array([v.alt_msl_m for v in scn.vehicles]))
    nn = _nearest(n, e)
    assert np.max(np.abs(nn - 50.0)) < 1e-3
    # grid rows are across the heading (30 deg): vehicles 0 and 1 are abreast
    h = math.radians(30.0)
    step = np.array([n[1] - n[0], e[1] - e[0]])
    assert step @ np.array([math.cos(h), math.sin(h)]) == pytest.approx(0.0, abs=1e-6)
    assert np.linalg.norm(step) == pytest.approx(50.0, abs=1e-6)
    assert all(v.alt_msl_m == 700.0 for v in scn.vehicles)


def test_line_formation_centred_and_abreast() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: l
            count: 5
            model: c172p
            formation: {type: line, spacing_m: 150}
            init: {north_m: 2000, east_m: -3000, alt_agl_m: 600, heading_deg: 45,
                   airspeed_kt: 100}
    """)
    scn = parse(text)
    pts = np.array([ned(scn, v)[:2] for v in scn.vehicles])
    np.testing.assert_allclose(pts.mean(axis=0), [2000.0, -3000.0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(pts[2], [2000.0, -3000.0], rtol=0, atol=1e-6)
    right = np.array([math.cos(math.radians(135.0)), math.sin(math.radians(135.0))])
    for a, b in zip(pts[:-1], pts[1:]):
        np.testing.assert_allclose(b - a, 150.0 * right, rtol=0, atol=1e-6)


def test_line_formation_anchored_at_lat_lon_far_from_origin() -> None:
    """Anchored at a lat/lon 55 km from the origin: the middle one is at the anchor."""
    text = HEAD + dd("""
        vehicles:
          - id: l
            count: 3
            model: c172p
            formation: {type: line, spacing_m: 100}
            init: {lat_deg: 47.5, lon_deg: 8.0, alt_agl_m: 500, heading_deg: 0,
                   airspeed_kt: 90}
    """)
    scn = parse(text)
    mid = scn.vehicles[1]
    assert mid.lat_deg == pytest.approx(47.5, abs=1e-9)
    assert mid.lon_deg == pytest.approx(8.0, abs=1e-9)
    n0, e0, _ = ned(scn, scn.vehicles[0])
    n1, e1, _ = ned(scn, mid)
    assert math.hypot(n1 - n0, e1 - e0) == pytest.approx(100.0, abs=1e-3)


def test_circle_formation_equidistant() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: r
            count: 8
            model: c172p
            formation: {type: circle, radius_m: 300}
            init: {north_m: 100, east_m: 50, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 90}
          - id: s
            count: 6
            model: c172p
            formation: {type: circle, spacing_m: 120}
            init: {north_m: -900, east_m: 0, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 90}
    """)
    scn = parse(text)
    assert [v.id for v in scn.vehicles] == [f"r{i}" for i in range(8)] + [f"s{i}"
                                                                         for i in range(6)]
    pts = np.array([ned(scn, v)[:2] for v in scn.vehicles])
    r = np.hypot(pts[:8, 0] - 100.0, pts[:8, 1] - 50.0)
    np.testing.assert_allclose(r, 300.0, rtol=0, atol=1e-6)
    s = pts[8:]
    r2 = np.hypot(s[:, 0] + 900.0, s[:, 1])
    np.testing.assert_allclose(r2, r2[0], rtol=0, atol=1e-6)
    gaps = np.hypot(*(np.roll(s, -1, axis=0) - s).T)
    np.testing.assert_allclose(gaps, 120.0, rtol=0, atol=1e-6)


def test_alt_step_layers_altitudes() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: v
            count: 4
            model: c172p
            formation: {type: line, spacing_m: 80, alt_step_m: 25}
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 90, airspeed_kt: 90}
    """)
    scn = parse(text)
    assert [v.alt_msl_m for v in scn.vehicles] == [900.0, 925.0, 950.0, 975.0]
    # horizontal layout unaffected by the height
    pts = np.array([ned(scn, v)[:2] for v in scn.vehicles])
    np.testing.assert_allclose(np.diff(pts, axis=0), [[-80.0, 0.0]] * 3, rtol=0, atol=1e-6)


def test_count_without_formation_is_an_error() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: v
            count: 3
            model: c172p
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    """)
    probs = problems(text)
    assert has(probs, line_of(text, "id: v"), "vehicles[0]", "count 3 needs a formation")


def test_count_without_formation_is_one_problem() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: v
            count: 3
            model: c172p
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    """)
    assert len(problems(text)) == 1


# --- positions ------------------------------------------------------------------

def test_lat_lon_kept_exactly() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: a
            model: c172p
            init: {lat_deg: 47.0123456789012, lon_deg: 8.0987654321098, alt_msl_m: 1234.5,
                   heading_deg: -90, airspeed_mps: 44.4}
    """)
    v = parse(text).vehicles[0]
    assert v.lat_deg == 47.0123456789012
    assert v.lon_deg == 8.0987654321098
    assert v.alt_msl_m == 1234.5
    assert v.heading_deg == 270.0
    assert v.airspeed_mps == 44.4
    assert v.terrain_alt_m == 400.0


@pytest.mark.parametrize("n,e", [(0.0, 0.0), (1500.0, -700.0), (25_000.0, -40_000.0),
                                 (-80_000.0, 5.0)])
def test_north_east_map_back(n: float, e: float) -> None:
    text = HEAD + dd(f"""
        vehicles:
          - id: a
            model: c172p
            init: {{north_m: {n}, east_m: {e}, alt_agl_m: 2500, heading_deg: 0,
                   airspeed_kt: 90}}
    """)
    scn = parse(text)
    v = scn.vehicles[0]
    assert v.alt_msl_m == 2900.0
    n2, e2, d2 = ned(scn, v)
    assert n2 == pytest.approx(n, abs=1e-6)
    assert e2 == pytest.approx(e, abs=1e-6)
    if n == e == 0.0:
        assert d2 == pytest.approx(-2500.0, abs=1e-6)


def test_altitude_and_airspeed_conversions() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: agl
            model: c172p
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 100}
          - id: msl
            model: c172p
            init: {north_m: 0, east_m: 300, alt_msl_m: 500, heading_deg: 0, airspeed_mps: 50}
    """)
    agl, msl = parse(text).vehicles
    assert agl.alt_msl_m == 900.0
    assert msl.alt_msl_m == 500.0
    assert agl.airspeed_mps == pytest.approx(100 * 1852 / 3600, rel=1e-15)
    assert agl.airspeed_mps == pytest.approx(51.4444444, abs=1e-6)
    assert msl.airspeed_mps == 50.0


# --- determinism -----------------------------------------------------------------

def test_resolution_is_deterministic_and_seeds_differ() -> None:
    a = parse(SWARM.replace("1000", "40"))
    b = parse(SWARM.replace("1000", "40"))
    assert a.vehicles == b.vehicles
    seeds = [v.random_seed for v in a.vehicles]
    assert len(set(seeds)) == len(seeds)
    c = parse(SWARM.replace("1000", "40").replace("duration_s: 10", "duration_s: 10\nseed: 5"))
    seeds_c = [v.random_seed for v in c.vehicles]
    assert all(x != y for x, y in zip(seeds, seeds_c))
    assert [v.lat_deg for v in c.vehicles] == [v.lat_deg for v in a.vehicles]


def test_explicit_random_seed_kept() -> None:
    text = HEAD + ONE.replace("    model: c172p", "    model: c172p\n    random_seed: 12345")
    assert parse(text).vehicles[0].random_seed == 12345


# --- resolved round trip ----------------------------------------------------------

ROUND = HEAD + dd("""
    vehicles:
      - id: g
        count: 7
        model: c172p
        formation: {type: grid, spacing_m: 90, columns: 3, alt_step_m: 3.3}
        init: {north_m: 1234.5, east_m: -987.6, alt_agl_m: 611.1, heading_deg: 33.3,
               airspeed_kt: 97}
      - id: solo
        model: c172x
        trim: false
        set: {fcs/throttle-cmd-norm: 0.25}
        init: {lat_deg: 47.1234567, lon_deg: 7.95, alt_msl_m: 1500, heading_deg: 359.9,
               airspeed_mps: 45.5}
    schedule:
      - at_s: 3.3
        vehicles: g*
        set: {fcs/throttle-cmd-norm: 0.4}
      - at_s: 0.01
        vehicles: [solo, g3]
        set: {fcs/aileron-cmd-norm: 0.1, fcs/elevator-cmd-norm: -0.05}
""")


def test_resolved_round_trip(tmp_path: Path) -> None:
    scn = parse(ROUND)
    p = tmp_path / "resolved.yaml"
    p.write_text(yaml.safe_dump(scn.resolved_dict(), sort_keys=False))
    back = load_scenario(p)
    assert back.vehicles == scn.vehicles
    assert [s.tick for s in back.schedule] == [s.tick for s in scn.schedule]
    assert [s.vehicles for s in back.schedule] == [s.vehicles for s in scn.schedule]
    assert [s.sets for s in back.schedule] == [s.sets for s in scn.schedule]
    assert back.rates == scn.rates and back.origin == scn.origin
    assert back.total_ticks == scn.total_ticks
    # and it is a fixed point
    assert back.resolved_dict()["vehicles"] == scn.resolved_dict()["vehicles"]


@pytest.mark.parametrize("init_alt,step", [("alt_agl_m: 99900", 0.0),
                                           ("alt_agl_m: 200", -800.0)])
def test_resolved_round_trip_at_altitude_limits(tmp_path: Path, init_alt: str,
                                                step: float) -> None:
    text = HEAD + dd(f"""
        vehicles:
          - id: v
            count: 3
            model: c172p
            formation: {{type: line, spacing_m: 50, alt_step_m: {step}}}
            init: {{north_m: 0, east_m: 0, {init_alt}, heading_deg: 0, airspeed_kt: 90}}
    """)
    with pytest.raises(ConfigError,
                       match=r"init\.alt_agl_m: gives altitudes .* allowed -500\.\.100000"):
        parse(text)
    ok = parse(text.replace("99900", "99000").replace("-800.0", "-90.0"))
    p = tmp_path / "resolved.yaml"
    p.write_text(yaml.safe_dump(ok.resolved_dict()))
    assert load_scenario(p).vehicles == ok.vehicles


# --- schedule ticks -------------------------------------------------------------

def test_schedule_rounded_up_to_control_tick_and_sorted() -> None:
    text = HEAD + ONE + dd("""
        schedule:
          - at_s: 5
            set: {fcs/throttle-cmd-norm: 0.1}
          - at_s: 0.01
            set: {fcs/throttle-cmd-norm: 0.2}
          - at_s: 1.0
            set: {fcs/throttle-cmd-norm: 0.3}
          - at_s: 0.02
            set: {fcs/throttle-cmd-norm: 0.4}
          - at_s: 0
            set: {fcs/throttle-cmd-norm: 0.5}
          - at_s: 0.1
            set: {fcs/throttle-cmd-norm: 0.6}
    """)
    scn = parse(text)
    assert [(s.at_s, s.tick) for s in scn.schedule] == [
        (0.0, 0), (0.01, 4), (0.02, 4), (0.1, 12), (1.0, 120), (5.0, 600)]
    assert [s.index for s in scn.schedule] == [4, 1, 3, 5, 2, 0]
    assert all(s.tick % scn.rates.control_every == 0 for s in scn.schedule)
    assert all(s.tick >= s.at_s * scn.rates.physics_hz - 1e-9 for s in scn.schedule)
    assert all(s.vehicles == (0,) for s in scn.schedule)


def test_total_ticks_rounded_up_to_control_exchange() -> None:
    scn = parse(HEAD.replace("duration_s: 20", "duration_s: 1.01") + ONE)
    assert scn.total_ticks == 124
    scn = parse(HEAD.replace("duration_s: 20", "duration_s: 0.1") + ONE)
    assert scn.total_ticks == 12


# --- YAML details ---------------------------------------------------------------

@pytest.mark.parametrize("body", ["description: !foo x\n", "name: !!binary zz\n"])
def test_construct_errors_are_config_errors(body: str) -> None:
    text = HEAD + body + ONE
    with pytest.raises(ConfigError) as ei:
        parse(text)
    e = ei.value
    assert all(PROBLEM.match(p) for p in e.problems)
    assert any(p.startswith(f"{FNAME}:6:") for p in e.problems), e.problems


def test_yaml_merge_key_accepted() -> None:
    text = HEAD + dd("""
        vehicles:
          - &base
            id: a
            model: c172p
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
          - <<: *base
            id: b
            init: {north_m: 0, east_m: 0, alt_agl_m: 600, heading_deg: 0, airspeed_kt: 90}
    """)
    scn = parse(text)
    assert [v.id for v in scn.vehicles] == ["a", "b"]
    assert scn.vehicles[0].model == scn.vehicles[1].model == "c172p"
    assert scn.vehicles[0].heading_deg == scn.vehicles[1].heading_deg


def test_random_seed_with_count_is_an_error() -> None:
    text = HEAD + dd("""
        vehicles:
          - id: v
            count: 3
            random_seed: 5
            model: c172p
            formation: {type: line, spacing_m: 50}
            init: {north_m: 0, east_m: 0, alt_agl_m: 500, heading_deg: 0, airspeed_kt: 90}
    """)
    with pytest.raises(ConfigError, match=r"vehicles\[0\]\.random_seed: random_seed is for a "
                                          r"single vehicle"):
        parse(text)


def test_mavlink_section_is_validated_with_lines() -> None:
    text = HEAD + ONE + dd("""
        mavlink:
          url: udpout:127.0.0.1
          rates_hz: {GLOBAL_POSITION_INT: 10, NOT_A_MESSAGE: 1}
    """)
    probs = problems(text)
    assert any("mavlink.url: mavlink URL 'udpout:127.0.0.1': expected udpout:HOST:PORT" in p
               for p in probs), probs
    assert any("mavlink.rates_hz: 'NOT_A_MESSAGE' is not a message cosim streams" in p
               for p in probs), probs
    ok = parse(HEAD + ONE + "mavlink: true\n")
    assert ok.mavlink == {"url": "udpout:127.0.0.1:14550", "rates_hz": {}}
    assert parse(HEAD + ONE).mavlink is None


@pytest.mark.parametrize("name", ["hetero/quad_guides_car.yaml", "quadrotor/hover_goto.yaml",
                                  "ground/route_obstacles.yaml", "quickstart.yaml"])
def test_resolved_round_trip_of_every_class(tmp_path: Path, name: str) -> None:
    """A resolved scenario names each vehicle's class and only the keys its
    class reads, and loads back to the same vehicles (quadrotors, cars and
    fixed-wings alike)."""
    scn = load_scenario(Path(__file__).resolve().parent.parent / "scenarios" / name)
    p = tmp_path / "resolved.yaml"
    p.write_text(yaml.safe_dump(scn.resolved_dict(), sort_keys=False))
    back = load_scenario(p)
    assert back.vehicles == scn.vehicles
    assert [v["class"] for v in back.resolved_dict()["vehicles"]] == [
        v.vehicle_class for v in scn.vehicles]
