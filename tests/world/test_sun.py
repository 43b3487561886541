"""The sun: its position against NREL's published example and an independent
low-precision almanac, the ``sun:`` section's checks, and targets shaded by
it in rendered frames."""

from __future__ import annotations

import dataclasses
import math
import textwrap
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from cosim.core.camera import CameraSpec, camera_pose
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.targets import AMBIENT, box_corners, parts_of
from cosim.scenario import load_scenario
from cosim.world.ground import GroundSpec
from cosim.world.sun import DEFAULT, SunSpec, solar_position
from cosim.world.targets import TargetSpec


def test_nrels_example_position() -> None:
    """Reda and Andreas (2004), NREL/TP-560-34302, table A5.1: Golden,
    Colorado, 2003-10-17 12:30:30 at UTC-7: topocentric zenith 50.11162 deg
    (refraction for 820 mbar and 11 C lifts it by 0.0163 deg, parallax lowers
    it by 0.0024 deg: both taken out here), azimuth 194.34024 deg."""
    when = datetime(2003, 10, 17, 12, 30, 30, tzinfo=timezone(timedelta(hours=-7)))
    az, el = solar_position(when, 39.742476, -105.1786)
    assert az == pytest.approx(194.34024, abs=0.01)
    geometric_el = 90.0 - 50.11162 - 0.0163 + 0.0024
    assert el == pytest.approx(geometric_el, abs=0.01)


def _almanac(when: datetime, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """The Astronomical Almanac's low-precision sun (right ascension and
    declination from the mean longitude and anomaly, the hour angle from
    Greenwich mean sidereal time): another route to the same answer."""
    jd = when.timestamp() / 86400.0 + 2440587.5
    n = jd - 2451545.0
    L = math.radians((280.460 + 0.9856474 * n) % 360)
    g = math.radians((357.528 + 0.9856003 * n) % 360)
    lam = L + math.radians(1.915) * math.sin(g) + math.radians(0.020) * math.sin(2 * g)
    eps = math.radians(23.439 - 0.0000004 * n)
    ra = math.atan2(math.cos(eps) * math.sin(lam), math.cos(lam))
    dec = math.asin(math.sin(eps) * math.sin(lam))
    gmst_deg = (280.46061837 + 360.98564736629 * n) % 360
    ha = math.radians(gmst_deg + lon_deg) - ra
    lat = math.radians(lat_deg)
    el = math.asin(math.sin(lat) * math.sin(dec) + math.cos(lat) * math.cos(dec) * math.cos(ha))
    az = math.atan2(-math.sin(ha) * math.cos(dec),
                    math.sin(dec) * math.cos(lat) - math.cos(dec) * math.sin(lat) * math.cos(ha))
    return math.degrees(az) % 360, math.degrees(el)


def test_it_agrees_with_the_almanac_everywhere_and_every_season() -> None:
    rng = np.random.default_rng(5)
    t0 = datetime(1960, 1, 1, tzinfo=timezone.utc).timestamp()
    t1 = datetime(2090, 1, 1, tzinfo=timezone.utc).timestamp()
    checked = 0
    for _ in range(400):
        when = datetime.fromtimestamp(float(rng.uniform(t0, t1)), tz=timezone.utc)
        lat, lon = float(rng.uniform(-70, 70)), float(rng.uniform(-180, 180))
        az, el = solar_position(when, lat, lon)
        az2, el2 = _almanac(when, lat, lon)
        assert el == pytest.approx(el2, abs=0.05), (when, lat, lon)
        if el2 < 89.0:  # the azimuth of a sun at the zenith is anything
            assert abs((az - az2 + 180) % 360 - 180) < 0.1 / math.cos(math.radians(el2)), \
                (when, lat, lon)
        checked += el2 > 0
    assert checked > 150  # daylight cases among them


def test_local_noon_at_the_june_solstice_stands_over_the_tropic() -> None:
    # 2024-06-20 20:51 UTC; at 23.44 N the sun culminates at the zenith on that day
    when = datetime(2024, 6, 20, 12, 0, tzinfo=timezone.utc)
    best = max(solar_position(when + timedelta(minutes=m), 23.44, 0.0)[1]
               for m in range(-30, 30))
    assert best == pytest.approx(90.0, abs=0.3)


SCENARIO = """
schema_version: 1
name: sunny
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
duration_s: 2
vehicles:
  - {id: a, model: c172p, init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0,
                                 airspeed_kt: 100}}
"""


def _load(tmp_path: Path, sun: str) -> object:
    p = tmp_path / "s.yaml"
    p.write_text(textwrap.dedent(SCENARIO) + sun)
    return load_scenario(p, check_properties=False)


def test_a_time_puts_the_sun_where_it_stands_at_the_origin(tmp_path: Path) -> None:
    scn = _load(tmp_path, "sun: {time: '2026-06-21T14:30:00+02:00'}\n")
    sun = scn.world.sun  # type: ignore[attr-defined]
    az, el = solar_position(datetime(2026, 6, 21, 12, 30, tzinfo=timezone.utc), 47.0, 8.0)
    assert (sun.azimuth_deg, sun.elevation_deg) == (pytest.approx(az), pytest.approx(el))
    assert 180 < sun.azimuth_deg < 240 and 55 < sun.elevation_deg < 66  # early afternoon
    scn = _load(tmp_path, "sun: {azimuth_deg: 270, elevation_deg: 20}\n")
    assert scn.world.sun == SunSpec(270.0, 20.0, "", True)  # type: ignore[attr-defined]
    scn = _load(tmp_path, "sun: {azimuth_deg: 270, elevation_deg: 20, shadows: false}\n")
    assert not scn.world.sun.shadows  # type: ignore[attr-defined]
    assert _load(tmp_path, "").world.sun == DEFAULT  # type: ignore[attr-defined]


@pytest.mark.parametrize("sun,msg", [
    ("{time: '2026-06-21T23:30:00+02:00'}", r"sun\.time: at 2026-06-21T23:30:00\+02:00 the sun "
                                            r"is -\d+\.\d deg above the horizon"),
    ("{time: '2026-06-21T14:30:00'}", r"sun\.time: .* has no UTC offset"),
    ("{time: 'midday'}", r"sun\.time: 'midday' is not an ISO 8601 time"),
    ("{time: '2500-06-21T14:30:00Z'}", r"sun\.time: .*the year must be in 1900\.\.2099"),
    ("{time: '2026-06-21T14:30:00Z', azimuth_deg: 3}", r"sun: give time, or azimuth_deg"),
    ("{azimuth_deg: 30}", r"sun: expected time, or azimuth_deg and elevation_deg"),
    ("{azimuth_deg: 30, elevation_deg: 0.5}", r"sun\.elevation_deg"),
    ("{azimuth_deg: 361, elevation_deg: 30}", r"sun\.azimuth_deg"),
    ("{azimuth_deg: 30, elevation_deg: 30, colour: red}", r"sun\.colour: unknown key 'colour'"),
])
def test_a_bad_sun_is_refused_with_its_line(tmp_path: Path, sun: str, msg: str) -> None:
    with pytest.raises(ConfigError, match=r"s\.yaml:\d+: " + msg):
        _load(tmp_path, f"sun: {sun}\n")


def _roof(sun: SunSpec) -> np.ndarray:
    """The colour straight below a camera 60 m above a grey car: its roof."""
    t = TargetSpec("b", "car", 0.0, 0.0, None, None, 0.0, 4.0, 4.0, 3.0, (200, 200, 200))
    world = World(WorldSpec(47.0, 8.0, 400.0, 1, 120.0, GroundSpec(), (t,), (), sun))
    cam = CameraSpec("c", (0,), "gimbal", -90.0, False, 20.0, 15.0, 320, 240, 10.0, 12)
    pose = camera_pose(cam, 47.0, 8.0, 460.0, 0.0, 0.0, 0.0, ground_alt_m=400.0)
    img, _ = render_frame(world, cam, pose, 0)
    out: np.ndarray = img[120, 160, :3].astype(float)
    return out


def test_a_face_is_as_bright_as_the_sun_on_it() -> None:
    """The roof (normal up) of a grey car seen from straight above has the
    brightness AMBIENT + (1 - AMBIENT) sin(elevation) of its colour (the roof
    part is drawn at 0.7 of the body's colour)."""
    for el in (20.0, 50.0, 85.0):
        top = _roof(SunSpec(135.0, el))
        k = AMBIENT + (1 - AMBIENT) * math.sin(math.radians(el))
        want = int(int(200 * 0.7) * k)
        assert np.all(np.abs(top - want) <= 1), (el, top, want)


BLOCK = TargetSpec("b", "car", 0.0, 0.0, None, None, 0.0, 2.0, 2.0, 1.0, (90, 90, 90))


def _shadow_mask(az_deg: float, el_deg: float, height_m: float) -> tuple[np.ndarray, float]:
    """Pixels a 2 m x 2 m car ``height_m`` tall darkens on the ground, seen
    by a nadir camera 100 m above it (image up = north, right = east), and
    the ground metres per pixel."""
    t = dataclasses.replace(BLOCK, height_m=height_m)
    cam = CameraSpec("c", (0,), "gimbal", -90.0, False, 60.0, 46.8, 400, 300, 10.0, 12)
    pose = camera_pose(cam, 47.0, 8.0, 500.0, 0.0, 0.0, 0.0, ground_alt_m=400.0)
    frames = []
    for shadows in (False, True):
        ws = WorldSpec(47.0, 8.0, 400.0, 1, 120.0, GroundSpec(), (t,), (),
                       SunSpec(az_deg, el_deg, "", shadows))
        frames.append(render_frame(World(ws), cam, pose, 0)[0][..., :3].astype(int))
    darker = (frames[1] < frames[0]).any(axis=2)
    assert not (frames[1] > frames[0]).any()  # shade only darkens
    f_px = 200 / math.tan(math.radians(30))
    return darker, 100.0 / f_px


@pytest.mark.parametrize("az,el,h", [(90.0, 45.0, 20.0), (90.0, 30.0, 20.0),
                                     (225.0, 40.0, 25.0), (0.0, 60.0, 30.0)])
def test_a_shadow_falls_away_from_the_sun_h_over_tan_elevation_long(az: float, el: float,
                                                                    h: float) -> None:
    """The shadow's farthest pixel from the car's centre lies opposite the
    sun's azimuth, as far as its farthest box corner reaches: the corner's
    own offset plus its height h over tan(elevation), within two pixels."""
    darker, m_per_px = _shadow_mask(az, el, h)
    ys, xs = np.nonzero(darker)
    assert len(xs) > 20
    cx, cy = (darker.shape[1] - 1) / 2, (darker.shape[0] - 1) / 2
    east_px, north_px = xs - cx, cy - ys
    away = math.radians(az + 180.0)
    along = (north_px * math.cos(away) + east_px * math.sin(away)) * m_per_px
    across = (-north_px * math.sin(away) + east_px * math.cos(away)) * m_per_px
    reach = [c[0] * math.cos(away) + c[1] * math.sin(away) - c[2] / math.tan(math.radians(el))
             for p in parts_of(dataclasses.replace(BLOCK, height_m=h))
             for c in box_corners(p.lo, p.hi)]  # corners: x north, y east, z down
    assert along.max() == pytest.approx(max(reach), abs=2 * m_per_px)
    tip = along > along.max() - 1.0
    assert abs(float(np.median(across[tip]))) < 2 * m_per_px  # straight away from the sun
    assert along.min() > -2 * m_per_px  # nothing toward the sun


def test_without_a_sun_section_nothing_casts_a_shadow() -> None:
    assert not DEFAULT.shadows
