"""The search against independent computations: footprints and fire ground
truth against the renderer's, the coverage map against shapely's areas, and
a flown search whose detection time is predicted from the logged track with
a pinhole projection written here."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from shapely.geometry import Polygon, box

from cosim.core.camera import CameraSpec, camera_pose, footprint
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, probe_offsets, render_frame
from cosim.renderer.targets import TargetSet
from cosim.scenario import Scenario, load_scenario, parse_scenario
from cosim.search import sensing
from cosim.search.coverage_map import CoverageMap
from cosim.sync import Run
from cosim.world.ground import GroundSpec
from cosim.world.targets import TargetSpec

LAT0, LON0, GROUND = 37.4, -122.0, 0.0


def _cam(w: int = 1280, h: int = 720, hfov: float = 60.0, stabilised: bool = True,
         rate: float = 2.0) -> CameraSpec:
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(hfov) / 2) * h / w))
    return CameraSpec("search", (0,), "nadir", -90.0, stabilised, hfov, vfov, w, h, rate,
                      round(120 / rate))


def _fire(fid: str, north: float, east: float, size: float = 8.0, growth: float = 0.0
          ) -> TargetSpec:
    return TargetSpec(fid, "fire", north, east, None, None, 0.0, size, size, 3.0,
                      (255, 120, 0), growth)


def test_footprints_of_the_fleet_equal_the_renderers_one_at_a_time() -> None:
    rng = np.random.default_rng(1)
    for stabilised in (True, False):
        cam = _cam(stabilised=stabilised)
        n = 12
        h = rng.uniform(50, 2000, n)
        roll, pitch, yaw = rng.uniform(-30, 30, n), rng.uniform(-15, 15, n), \
            rng.uniform(-180, 180, n)
        got = sensing.footprints(cam, h, roll, pitch, yaw)
        for i in range(n):
            pose = camera_pose(cam, LAT0, LON0, GROUND + h[i], roll[i], pitch[i], yaw[i], GROUND)
            np.testing.assert_allclose(got[i], footprint(cam, pose, sensing.MAX_RANGE_M),
                                       atol=1e-6)


@pytest.mark.parametrize("offset", [(0.0, 0.0), (60.0, 30.0), (95.0, 0.0), (0.0, 175.0),
                                    (400.0, 0.0)])
def test_fire_ground_truth_equals_the_rendered_frames(offset: tuple[float, float]) -> None:
    """``fire_truth`` against ``render_frame``'s ground-truth row for the same
    camera and fire: in view, fully in view and the box agree; the flames'
    pixels are at most the box's projected area."""
    cam = _cam(640, 480, stabilised=False)
    fire = _fire("f", 500.0, 300.0, size=10.0)
    world = World(WorldSpec(LAT0, LON0, GROUND, 3, 120.0, GroundSpec(), (fire,)))
    frame = world.frame
    lat, lon = frame.place(500.0 + offset[0], 300.0 + offset[1], GROUND)
    pose = camera_pose(cam, float(lat), float(lon), GROUND + 200.0, 2.0, -3.0, 10.0, GROUND)
    _, rows = render_frame(world, cam, pose, tick=0)
    truth = rows[0]
    targets = TargetSet((fire,), frame, GROUND)
    origin = targets.origins_in(pose.local, pose.local_ecef_m)[0]
    seen = sensing.fire_truth(cam, pose, origin + probe_offsets([fire])[0, :8])
    assert seen.in_view == bool(truth["in_view"])
    assert seen.fully_in_view == bool(truth["fully_in_view"])
    assert (truth["bbox_x0_px"] is None) == (seen.bbox is None)
    if seen.bbox is not None:
        np.testing.assert_allclose(seen.bbox, [truth[k] for k in (
            "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px")], atol=1e-6)
    if seen.in_view:
        assert 0 < truth["pixels_on_target"] <= seen.pixels * 1.05 + 4
    else:
        assert truth["pixels_on_target"] == 0


def test_a_growing_fire_is_drawn_and_seen_at_its_size_of_the_moment() -> None:
    cam = _cam(640, 480)
    fire = _fire("f", 0.0, 0.0, size=8.0, growth=2.0 / 60.0)  # 2 m a minute
    world = World(WorldSpec(LAT0, LON0, GROUND, 3, 120.0, GroundSpec(), (fire,)))
    pose = camera_pose(cam, LAT0, LON0, GROUND + 300.0, 0.0, 0.0, 0.0, GROUND)
    widths = []
    for minutes in (0, 10):
        _, rows = render_frame(world, cam, pose, tick=minutes * 60 * 120)
        widths.append(rows[0]["bbox_x1_px"] - rows[0]["bbox_x0_px"])
    f_px = cam.fx_px
    # the box's top (3 m up) is its widest in the image: side * f / (h - 3)
    assert widths[0] == pytest.approx(8.0 * f_px / 297.0, rel=1e-6)
    assert widths[1] == pytest.approx(28.0 * f_px / 297.0, rel=1e-6)
    assert fire.at(600.0).length_m == pytest.approx(28.0)


def test_the_coverage_map_counts_cells_as_shapely_measures_areas() -> None:
    area = [(0.0, 0.0), (0.0, 3000.0), (2000.0, 3000.0), (2000.0, 0.0)]
    zone = [(500.0, 500.0), (500.0, 1100.0), (1300.0, 1100.0), (1300.0, 500.0)]
    cmap = CoverageMap(area, [zone], 5.0)
    searchable = box(0, 0, 3000, 2000).difference(box(500, 500, 1100, 1300))
    assert cmap.cells * 25.0 == pytest.approx(searchable.area, rel=0.01)
    # a swept footprint (a slanted quad, part of it over the zone) at frame 3
    quad = np.array([[100.0, 200.0], [1500.0, 900.0], [1700.0, 700.0], [300.0, 0.0]])
    new = cmap.add(3, [quad])
    expect = Polygon([(e, n) for n, e in quad]).intersection(searchable).area
    assert new * 25.0 == pytest.approx(expect, rel=0.02)
    assert cmap.add(4, [quad]) == 0  # seen already: first seen stays frame 3
    assert set(np.unique(cmap.first)) == {-1, 3}


def _strip_scenario(tmp: Path, fires: str, extra: str = "", duration: float = 95.0) -> Path:
    """One aircraft flying north along a 200 m wide strip (one lane, its
    transit straight on): the simplest track to predict."""
    text = f"""\
schema_version: 1
name: strip
origin: {{lat_deg: {LAT0}, lon_deg: {LON0}, ground_alt_m: {GROUND}}}
rates: {{physics_hz: 120, control_hz: 10, log_hz: 2}}
duration_s: {duration}
seed: 4
vehicles:
  - {{id: a, model: uav700,
     init: {{north_m: -1500, east_m: 0, alt_agl_m: 300, airspeed_kt: 100, heading_deg: 0}}}}
search:
  area: [[0, -100], [0, 100], [8000, 100], [8000, -100]]
  base: {{north_m: -1500, east_m: 0}}
  airspeed_kt: 100
  bank_deg: 30
  alt_agl_m: 300
  overlap: 0
  camera: {{hfov_deg: 60, width_px: 1280, height_px: 720, rate_hz: 2}}
  fires: {fires}
  detection: {{min_pixels: 60, dwell_s: 1.0}}
{extra}"""
    f = tmp / "strip.yaml"
    f.write_text(text)
    return f


def _predicted_detection_s(run: Path, fire_ne: tuple[float, float], size0: float,
                           growth_mps: float, height: float, cam: CameraSpec, min_px: float,
                           dwell: int) -> float | None:
    """When the fire should count as detected, from the logged track: its box
    projected by a pinhole camera looking straight down (image up = the
    aircraft's heading), clipped to the image by shapely, for ``dwell``
    frames in a row."""
    t = pq.read_table(run / "states.parquet")
    ts, n, e = (t.column(c).to_numpy() for c in ("time_s", "north_m", "east_m"))
    agl, yaw = t.column("alt_agl_m").to_numpy(), t.column("yaw_deg").to_numpy()
    f_px = cam.fx_px
    cx, cy = (cam.width_px - 1) / 2, (cam.height_px - 1) / 2
    image = box(-0.5, -0.5, cam.width_px - 0.5, cam.height_px - 0.5)
    run_len = 0
    for k in range(len(ts)):
        side = size0 + growth_mps * ts[k]
        psi = math.radians(yaw[k])
        fwd, right = np.array([math.cos(psi), math.sin(psi)]), \
            np.array([-math.sin(psi), math.cos(psi)])
        pts = []
        for dn in (-side / 2, side / 2):
            for de in (-side / 2, side / 2):
                for up in (0.0, height):
                    d = np.array([fire_ne[0] + dn - n[k], fire_ne[1] + de - e[k]])
                    depth = agl[k] - up
                    pts.append((cx + f_px * float(d @ right) / depth,
                                cy - f_px * float(d @ fwd) / depth))
        area = Polygon(pts).convex_hull.intersection(image).area
        run_len = run_len + 1 if area >= min_px else 0
        if run_len >= dwell:
            return float(ts[k])
    return None


@pytest.mark.integration
def test_a_fire_on_the_track_is_detected_when_predicted_and_one_beside_it_never(
        tmp_path: Path) -> None:
    growth = 3.0  # m/min
    fires = (f"{{target: {{north_m: 2500, east_m: 0}}, size_m: 6, height_m: 3, "
             f"growth_m_per_min: {growth}, decoys: [{{north_m: 3000, east_m: 1200}}]}}")
    scn = load_scenario(_strip_scenario(tmp_path, fires))
    res = Run(scn, tmp_path / "run", backend="inline").run()
    assert res.ok, res.error
    s = res.summary["search"]
    spec = scn.sections["search"]
    cam = spec.camera
    dwell = math.ceil(spec.detection.dwell_s * cam.rate_hz)  # frames of 1 / rate_hz s each
    want = _predicted_detection_s(tmp_path / "run", (2500.0, 0.0), 6.0, growth / 60.0, 3.0,
                                  cam, 60.0, dwell=dwell)
    assert want is not None and dwell == 2
    assert s["target"]["detected"]
    assert abs(s["target"]["time_to_detect_s"] - want) <= 1.0 / cam.rate_hz + 1e-9
    assert s["target"]["time_to_detect_s"] == pytest.approx(want)  # (in fact the same frame)
    # the decoy 1.2 km beside the track never comes under the 346 m swath
    assert s["decoys_detected"] == 0
    first = s["first_detections"][0]
    assert first["fire"] == "fire_target" and first["error_m"] < 3.0  # no sensor errors
    assert first["size_m"] == pytest.approx(first["true_size_m"], rel=0.35)
    rows = (tmp_path / "run" / "search" / "detections.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].split(",")[2] == "fire_target"
    events = [json.loads(x) for x in (tmp_path / "run" / "events.jsonl").read_text().splitlines()]
    det = [ev for ev in events if ev["event"] == "fire_detected"]
    assert [ev["fire"] for ev in det] == ["fire_target"]
    # the plan was flown as a mission: loaded, items reached, no refusals
    counters = res.summary["mavlink"]["counters"]
    assert counters["missions_loaded"] == 1 and counters["mission_items_reached"] >= 2
    for name in ("plan.json", "coverage.csv", "coverage_map.png", "coverage.png"):
        assert (tmp_path / "run" / "search" / name).stat().st_size > 0


@pytest.mark.integration
def test_navigation_errors_move_the_reported_position_by_their_size(tmp_path: Path) -> None:
    fires = "{target: {north_m: 1000, east_m: 0}, size_m: 8}"
    f = _strip_scenario(tmp_path, fires, duration=60.0)
    text = f.read_text().replace("dwell_s: 1.0}", "dwell_s: 1.0, position_sigma_m: 20}")
    f.write_text(text)
    res = Run(load_scenario(f), tmp_path / "run", backend="inline").run()
    assert res.ok, res.error
    err = res.summary["search"]["first_detections"][0]["error_m"]
    assert 1.0 < err < 100.0  # a 20 m (1 sigma, each axis) navigation error


def _parse(body: str, vehicles: str = "", top: str = "") -> Scenario:
    """A scenario of uav700 ``a`` (and ``vehicles``) with the search section ``body``."""
    return parse_scenario(f"""\
schema_version: 1
origin: {{lat_deg: {LAT0}, lon_deg: {LON0}}}
rates: {{physics_hz: 120, control_hz: 10}}
duration_s: 10
{top}vehicles:
  - {{id: a, model: uav700, init: {{alt_agl_m: 300, airspeed_kt: 100}}}}
{vehicles}search:
{body}""", "search.yaml", check_properties=False)


@pytest.mark.parametrize("body,message", [
    ("  area: [[0, 0], [0, 70000], [1000, 70000], [1000, 0]]\n", "at most 64 km a side"),
    ("  area: [[0, 0], [0, 1000]]\n", "3 to 1000"),
    ("  area: [[0, 0], [1000, 1000], [0, 1000], [1000, 0]]\n", "edges cross"),
    ("  base: {north_m: 0, east_m: 0}\n", "missing required key 'area'"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  camera: {rate_hz: 20}\n",
     "must fall on exchanges"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  camera: {mount: forward}\n",
     "looks straight down"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  bank_deg: 50\n"
     "  flown_bank_deg: 40\n", "at least the plan's bank"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  fires: {decoys: 500}\n",
     "0 to 99 decoys"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n"
     "  no_fly: [[[-10, -10], [-10, 1010], [1010, 1010], [1010, -10]]]\n",
     "could not place"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  aircraft: b\n", "b"),
    ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  coverage_cell_m: 0.1\n",
     "must be >= 2"),
])
def test_bad_search_sections_are_refused_with_where_and_what(body: str, message: str) -> None:
    with pytest.raises(ConfigError) as e:
        _parse(body)
    assert message in str(e.value)
    assert "search.yaml:" in str(e.value)


def test_fires_are_placed_from_the_seed_inside_the_area_and_join_the_targets() -> None:
    body = ("  area_latlon: [[37.40, -122.00], [37.40, -121.98], [37.42, -121.98], "
            "[37.42, -122.00]]\n  fires: {target: random, decoys: 3, growth_m_per_min: 2}\n")
    text = f"""\
schema_version: 1
origin: {{lat_deg: {LAT0}, lon_deg: {LON0}}}
duration_s: 10
seed: SEED
vehicles:
  - {{id: a, model: uav700, init: {{alt_agl_m: 300, airspeed_kt: 100}}}}
targets:
  - {{id: truck1, kind: truck, north_m: 10, east_m: 10}}
search:
{body}"""
    scn = parse_scenario(text.replace("SEED", "5"), "s.yaml", check_properties=False)
    again = parse_scenario(text.replace("SEED", "5"), "s.yaml", check_properties=False)
    other = parse_scenario(text.replace("SEED", "6"), "s.yaml", check_properties=False)
    fires = scn.sections["search"].fires
    assert [f.id for f in fires] == ["fire_target", "decoy1", "decoy2", "decoy3"]
    assert fires == again.sections["search"].fires
    assert fires != other.sections["search"].fires
    area = Polygon([(e, n) for n, e in scn.sections["search"].area_ne])
    assert area.area == pytest.approx(1775.0 * 2210.0, rel=0.02)  # 0.02 deg by 0.02 deg
    from shapely.geometry import Point

    assert all(area.contains(Point(f.east_m, f.north_m)) for f in fires)
    ids = [t.id for t in scn.world.targets]
    assert ids == ["truck1", "fire_target", "decoy1", "decoy2", "decoy3"]
    assert scn.world.targets[1].growth_m_per_s == pytest.approx(2.0 / 60.0)
    # the resolved scenario, parsed again, hides them in the same places
    import yaml

    back = parse_scenario(yaml.safe_dump(scn.resolved_dict()), "r.yaml", check_properties=False)
    assert back.sections["search"].fires == fires


def test_the_altitude_follows_the_detection_requirement() -> None:
    body = ("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n"
            "  camera: {hfov_deg: 60, width_px: 1280, height_px: 720}\n"
            "  fires: {size_m: 10}\n  detection: {min_pixels: 64}\n")
    s = _parse(body).sections["search"]
    # 8 pixels across 10 m: h = 10 m * f / 8 with f = 640 / tan(30 deg)
    assert s.alt_auto and s.alt_agl_m == pytest.approx(10.0 * 640 / math.tan(math.radians(30))
                                                       / 8.0)


@pytest.mark.integration
def test_search_plan_reports_the_minimum_fleet_and_its_change_with_altitude(capsys) -> None:
    from cosim.cli import main

    code = main(["-q", "search-plan", str(Path(__file__).parents[2] / "scenarios" / "xprize"
                                           / "search.yaml"), "--altitudes", "300,2770"])
    assert code == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln.replace("(this)", "").split() for ln in out.splitlines()
            if ln.strip() and ln.split()[0].isdigit()}
    assert rows["1386"][3] == "23"  # the scenario's own altitude: its 23 aircraft
    assert rows["300"][3] == "103" and int(rows["300"][4]) <= 600
    assert "below the 64 px detection needs" in out.splitlines()[-1]  # 2770 m: 16 px


@pytest.mark.parametrize("render_workers", [None, 0])
@pytest.mark.integration
def test_the_image_detector_finds_the_fire_in_the_raw_frames_and_a_decoy_like_it(
        tmp_path: Path, render_workers: int | None) -> None:
    """A rendered nadir camera on the aircraft, its raw frames searched by the
    image detector: the fire found when the geometry finds it (within a
    frame), the decoy on the track found too (it looks like a fire: the
    detector's false alarm on a decoy), the one beside never, no blob on
    the ground."""
    fires = ("{target: {north_m: 1500, east_m: 0}, size_m: 8, decoys: "
             "[{north_m: 2400, east_m: 30}, {north_m: 1800, east_m: 1500}]}")
    workers = "" if render_workers is None else f"  render_workers: {render_workers}\n"
    extra = f"""cameras:
{workers}  views:
    - {{name: belly, vehicles: a, mount: nadir, hfov_deg: 60, width_px: 640, height_px: 480,
       rate_hz: 2, stabilised: true}}
"""
    f = _strip_scenario(tmp_path, fires, extra, duration=85.0)
    f.write_text(f.read_text().replace("dwell_s: 1.0}", "dwell_s: 1.0, image: true}")
                 .replace("seed: 4", "seed: 5"))  # a wind that blows the smoke aside
    res = Run(load_scenario(f), tmp_path / "run", backend="inline").run()
    assert res.ok, res.error
    s = res.summary["search"]
    img = s["image_detector"]
    assert img["frames"] == 170 and img["frames_without_pose"] == 0
    assert img["target"]["detected"]
    assert abs(img["target"]["time_to_detect_s"] - s["target"]["time_to_detect_s"]) <= 0.5
    assert [d["fire"] for d in img["first_detections"]] == ["fire_target", "decoy1"]
    assert img["decoys_detected"] == 1 and s["decoys_detected"] == 1
    assert img["frames_with_false_alarms"] == 0


def test_the_image_detector_needs_a_camera_on_a_search_aircraft() -> None:
    with pytest.raises(ConfigError, match="the image detector needs a camera"):
        _parse("  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n"
               "  detection: {image: true}\n")


@pytest.mark.integration
def test_two_aircraft_search_an_area_round_a_no_fly_zone_to_its_end(tmp_path: Path) -> None:
    """The whole chain on a small area: two JSBSim aircraft from a formation
    beside the base, a zone cut out of the area, their plans flown as
    missions: the area is covered (as the map counts it and, independently,
    as shapely counts the logged tracks' swaths), and no track enters the
    zone."""
    from shapely.geometry import LineString
    from shapely.ops import unary_union

    text = f"""\
schema_version: 1
origin: {{lat_deg: {LAT0}, lon_deg: {LON0}, ground_alt_m: 0}}
rates: {{physics_hz: 120, control_hz: 10, log_hz: 2}}
duration_s: 1700
seed: 3
vehicles:
  - {{id: s, count: 2, model: uav700, formation: {{type: line, spacing_m: 150}},
     init: {{north_m: -600, east_m: -600, alt_agl_m: 300, airspeed_kt: 120, heading_deg: 45}}}}
search:
  area: [[0, 0], [0, 4000], [2500, 4000], [2500, 0]]
  no_fly: [[[900, 1500], [900, 2300], [1600, 2300], [1600, 1500]]]
  base: {{north_m: -600, east_m: -600}}
  airspeed_kt: 120
  bank_deg: 25
  alt_agl_m: 300
  fires: {{target: random, decoys: 0}}
"""
    f = tmp_path / "zone.yaml"
    f.write_text(text)
    res = Run(load_scenario(f), tmp_path / "run", backend="inline").run()
    assert res.ok, res.error
    s = res.summary["search"]
    # (the band the plan keeps clear round the zone is the most of what stays unseen)
    assert s["coverage"]["final"] > 0.95, s["coverage"]
    assert s["coverage"]["time_to_fraction_s"]["0.95"] <= s["plan_completion_s"] * 1.1
    t = pq.read_table(tmp_path / "run" / "states.parquet")
    who = np.array(t.column("vehicle").to_pylist())
    n, e = t.column("north_m").to_numpy(), t.column("east_m").to_numpy()
    zone = box(1500, 900, 2300, 1600)
    area = box(0, 0, 4000, 2500).difference(zone)
    swaths = []
    for vid in ("s0", "s1"):
        track = LineString(np.column_stack([e[who == vid], n[who == vid]]))
        assert track.intersection(zone).length < 1.0  # never over the zone
        swaths.append(track.buffer(s["swath_m"] / 2, cap_style="flat"))
    seen = unary_union(swaths).intersection(area).area / area.area
    assert seen > 0.95
    assert abs(seen - s["coverage"]["final"]) < 0.03  # the map agrees with shapely's count


@pytest.mark.parametrize("top,body,message", [
    ("", "  area: [[0, 0], [0, 24000], [24000, 24000], [24000, 0]]\n  alt_agl_m: 100\n",
     "a mission holds at most 699"),
    ("", "  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  alt_agl_m: 9000\n",
     "the camera's footprint reaches"),
    ("", "  area: [[0, 0], [0, 3000], [3000, 3000], [3000, 0]]\n"
         "  base: {north_m: 1500, east_m: 1500}\n"
         "  no_fly: [[[1000, 1000], [1000, 2000], [2000, 2000], [2000, 1000]]]\n",
     "cannot plan the search"),
    ("mavlink: {vehicles: b}\n", "  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n",
     "a not on MAVLink"),
    ("", "  area: [[0, 0], [0, 1000], [1000, 1000], [1000, 0]]\n  aircraft: c\n",
     "flies no missions"),
])
def test_a_search_that_cannot_be_flown_is_refused_when_read(top: str, body: str,
                                                           message: str) -> None:
    with pytest.raises(ConfigError) as e:
        _parse(body if "aircraft:" in body else "  aircraft: a\n" + body, vehicles="""\
  - {id: b, model: uav700, init: {north_m: 500, alt_agl_m: 300, airspeed_kt: 100}}
  - {id: c, model: c172p, class: jsbsim, init: {north_m: 900, alt_agl_m: 300,
                                               airspeed_kt: 100}}
""", top=top)
    assert message in str(e.value), str(e.value)
    assert "search.yaml:" in str(e.value)
