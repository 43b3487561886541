"""`cosim export`: the ACMI, KML and CZML of a short run of a fixed-wing, a
quadrotor and a car, parsed back and compared with the logged states, and
the CZML orientation checked against directions computed independently."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.export import export_run
from cosim.export.tracks import load_tracks
from cosim.export.writers import body_to_ecef_quaternion
from cosim.logs import read_states
from tests.helpers import finished_run

SCENARIO = """\
schema_version: 1
name: three_classes
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 30, log_hz: 30}
duration_s: 4
vehicles:
  - {id: plane, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300,
     heading_deg: 30, airspeed_kt: 80}}
  - {id: quad, model: F450, init: {north_m: 0, east_m: 50, alt_agl_m: 20}}
  - {id: car, class: ground, max_speed_mps: 6, init: {north_m: 0, east_m: 100,
     heading_deg: 0}}
schedule:
  - {at_s: 0, vehicles: car, command: {airspeed_mps: 4, goto: {north_m: 100, east_m: 100}}}
"""
KML = "{http://www.opengis.net/kml/2.2}"
GX = "{http://www.google.com/kml/ext/2.2}"
TYPES = {"plane": "Air+FixedWing", "quad": "Air+Rotorcraft", "car": "Ground+Vehicle"}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return finished_run(SCENARIO, tmp_path_factory.mktemp("export"))


def _states(run: Path) -> dict[str, dict[str, np.ndarray]]:
    t = read_states(run)
    ids = np.array(t["vehicle"].to_pylist())
    return {v: {c: np.asarray(t[c].to_pylist())[ids == v]
                for c in ("time_s", "lat_deg", "lon_deg", "alt_msl_m", "yaw_deg")}
            for v in TYPES}


def _at(states: dict[str, np.ndarray], t: float) -> int:
    i = int(np.argmin(np.abs(states["time_s"] - t)))
    assert abs(states["time_s"][i] - t) < 1e-9
    return i


def test_acmi_has_the_header_frames_and_every_vehicle(run: Path) -> None:
    path = export_run(run, "acmi", rate_hz=5.0)
    assert path == run / "track.acmi"
    lines = path.read_text().splitlines()
    assert lines[:2] == ["FileType=text/acmi/tacview", "FileVersion=2.2"]
    assert "0,ReferenceTime=2000-01-01T00:00:00Z" in lines
    ref_lon = float(next(x for x in lines if x.startswith("0,ReferenceLongitude=")).split("=")[1])
    ref_lat = float(next(x for x in lines if x.startswith("0,ReferenceLatitude=")).split("=")[1])
    frames = [float(x[1:]) for x in lines if x.startswith("#")]
    assert frames == pytest.approx([k / 5.0 for k in range(len(frames))])
    assert 19 <= len(frames) <= 21  # 4 s at 5 Hz
    states = _states(run)
    seen: dict[str, str] = {}
    t = None
    objects = {}
    for line in lines:
        if line.startswith("#"):
            t = float(line[1:])
            continue
        if not re.match(r"^[0-9a-f]+,T=", line) or line.startswith("0,"):
            continue
        oid, rest = line.split(",", 1)
        props = dict(p.split("=", 1) for p in rest.split(","))
        if "CallSign" in props:
            objects[oid] = props["CallSign"]
            seen[props["CallSign"]] = props["Type"]
        vid = objects[oid]
        lon, lat, alt, *_ = (float(x) for x in props["T"].split("|"))
        s = states[vid]
        i = _at(s, t)
        assert lon + ref_lon == pytest.approx(s["lon_deg"][i], abs=2e-7)
        assert lat + ref_lat == pytest.approx(s["lat_deg"][i], abs=2e-7)
        assert alt == pytest.approx(s["alt_msl_m"][i], abs=0.01)
    assert seen == TYPES
    assert all(int(oid, 16) > 0 for oid in objects)


def test_kml_has_one_track_per_vehicle_matching_the_states(run: Path) -> None:
    path = export_run(run, "kml", out=run / "t.kml")
    doc = ET.parse(path).getroot()
    placemarks = doc.findall(f"{KML}Document/{KML}Placemark")
    assert [p.findtext(f"{KML}name") for p in placemarks] == list(TYPES)
    states = _states(run)
    for p in placemarks:
        vid = p.findtext(f"{KML}name")
        assert TYPES[vid] in p.findtext(f"{KML}description")
        track = p.find(f"{GX}Track")
        assert track.findtext(f"{KML}altitudeMode") == "absolute"
        whens = [datetime.fromisoformat(w.text.replace("Z", "+00:00"))
                 for w in track.findall(f"{KML}when")]
        coords = [[float(x) for x in c.text.split()] for c in track.findall(f"{GX}coord")]
        angles = track.findall(f"{GX}angles")
        slots = len(np.unique(np.floor(states[vid]["time_s"] * 10.0 + 1e-9)))
        assert len(whens) == len(coords) == len(angles) == slots  # 4 s at 10 Hz
        assert all(b > a for a, b in zip(whens, whens[1:]))
        t0 = datetime(2000, 1, 1, tzinfo=timezone.utc)
        for w, (lon, lat, alt) in zip(whens, coords):
            i = _at(states[vid], (w - t0).total_seconds())
            assert (lon, lat) == (pytest.approx(states[vid]["lon_deg"][i], abs=1e-7),
                                  pytest.approx(states[vid]["lat_deg"][i], abs=1e-7))
            assert alt == pytest.approx(states[vid]["alt_msl_m"][i], abs=0.01)


def test_czml_is_cesium_json_with_monotonic_samples(run: Path) -> None:
    epoch = datetime(2026, 6, 1, 12, tzinfo=timezone.utc)
    packets = json.loads(export_run(run, "czml", epoch=epoch).read_text())
    assert packets[0]["id"] == "document" and packets[0]["version"] == "1.0"
    assert packets[0]["clock"]["interval"].startswith("2026-06-01T12:00:00.000Z/")
    states = _states(run)
    assert [p["id"] for p in packets[1:]] == list(TYPES)
    for p in packets[1:]:
        pos = np.array(p["position"]["cartographicDegrees"]).reshape(-1, 4)
        q = np.array(p["orientation"]["unitQuaternion"]).reshape(-1, 5)
        assert np.all(np.diff(pos[:, 0]) > 0) and np.array_equal(pos[:, 0], q[:, 0])
        assert np.allclose(np.linalg.norm(q[:, 1:], axis=1), 1.0, atol=1e-6)
        s = states[p["id"]]
        for t, lon, lat, h in pos[::7]:
            i = _at(s, t)
            assert (lon, lat, h) == (pytest.approx(s["lon_deg"][i], abs=1e-7),
                                     pytest.approx(s["lat_deg"][i], abs=1e-7),
                                     pytest.approx(s["alt_msl_m"][i], abs=1e-6))


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v rotated by unit quaternion (x, y, z, w): v + 2w(u x v) + 2u x (u x v)."""
    u, w = q[:3], q[3]
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


@pytest.mark.parametrize("lat, lon, roll, pitch, yaw, axis, expect", [
    (47.0, 8.0, 0, 0, 0, (1, 0, 0), "north"),
    (47.0, 8.0, 0, 0, 90, (1, 0, 0), "east"),
    (47.0, 8.0, 0, 0, 0, (0, 0, 1), "down"),
    (-33.9, 151.2, 0, 0, 90, (0, 1, 0), "south"),  # right wing of an east-bound aircraft
    (47.0, 8.0, 0, 30, 0, (1, 0, 0), "north30up"),
    (10.0, -70.0, 90, 0, 0, (0, 1, 0), "down"),  # rolled right 90: the right wing points down
])
def test_czml_orientation_against_directions_computed_independently(
        lat: float, lon: float, roll: float, pitch: float, yaw: float, axis: tuple,
        expect: str) -> None:
    la, lo = math.radians(lat), math.radians(lon)
    up = np.array([math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)])
    east = np.array([-math.sin(lo), math.cos(lo), 0.0])
    north = np.cross(up, east)
    want = {"north": north, "east": east, "down": -up, "south": -north,
            "north30up": math.cos(math.radians(30)) * north + 0.5 * up}[expect]
    q = body_to_ecef_quaternion(np.array([lat]), np.array([lon]), np.array([roll]),
                                np.array([pitch]), np.array([yaw]))[0]
    assert np.allclose(_rotate(q, np.array(axis, float)), want, atol=1e-9)


def test_bad_input_is_refused_clearly(run: Path, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not a cosim run folder"):
        export_run(tmp_path, "kml")
    with pytest.raises(ConfigError, match="unknown export format 'gpx'"):
        export_run(run, "gpx")
    with pytest.raises(ConfigError, match="rate-hz"):
        load_tracks(run, 0.0)
    r = subprocess.run([sys.executable, "-m", "cosim", "export", str(run), "--format", "kml",
                        "--epoch", "yesterday"], capture_output=True, text=True)
    assert r.returncode == 2 and "--epoch" in r.stderr
    r = subprocess.run([sys.executable, "-m", "cosim", "export", str(run), "--format", "czml",
                        "--epoch", "2026-06-01T12:00:00Z"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip().endswith("track.czml")
