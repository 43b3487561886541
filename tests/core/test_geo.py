"""cosim.core.geo: WGS-84 geodetic <-> ECEF <-> local NED, checked against textbook
points, JSBSim's own ECEF position and exact geometric identities."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.core.geo import (
    WGS84_A_M,
    WGS84_B_M,
    WGS84_E2,
    LocalFrame,
    ecef_to_geodetic,
    geodetic_to_ecef,
)
from cosim.core.units import FT_TO_M

A, B, E2 = WGS84_A_M, WGS84_B_M, WGS84_E2


def meridian_radius(lat_deg: float) -> float:
    """Meridian radius of curvature M(phi) = a (1 - e^2) / (1 - e^2 sin^2 phi)^1.5."""
    s = math.sin(math.radians(lat_deg))
    return A * (1.0 - E2) / (1.0 - E2 * s * s) ** 1.5


def wrap180(deg: np.ndarray) -> np.ndarray:
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0


# --- constants ---------------------------------------------------------------

def test_wgs84_constants() -> None:
    assert A == 6378137.0
    assert B == pytest.approx(6356752.314245, abs=1e-6)
    assert E2 == pytest.approx(6.69437999014e-3, rel=1e-11)


# --- geodetic_to_ecef: textbook points ---------------------------------------

def test_ecef_equator_prime_meridian() -> None:
    x, y, z = geodetic_to_ecef(0.0, 0.0, 0.0)
    assert float(x) == pytest.approx(A, abs=1e-9)
    assert float(y) == pytest.approx(0.0, abs=1e-9)
    assert float(z) == pytest.approx(0.0, abs=1e-9)


def test_ecef_north_pole() -> None:
    x, y, z = geodetic_to_ecef(90.0, 0.0, 0.0)
    assert float(x) == pytest.approx(0.0, abs=1e-6)
    assert float(y) == pytest.approx(0.0, abs=1e-6)
    assert float(z) == pytest.approx(B, abs=1e-6)


def test_ecef_south_pole_with_height() -> None:
    x, y, z = geodetic_to_ecef(-90.0, 123.0, 500.0)
    assert math.hypot(float(x), float(y)) == pytest.approx(0.0, abs=1e-6)
    assert float(z) == pytest.approx(-(B + 500.0), abs=1e-6)


@pytest.mark.parametrize("h", [0.0, 1234.5, -300.0])
def test_ecef_equator_lon90_with_height(h: float) -> None:
    x, y, z = geodetic_to_ecef(0.0, 90.0, h)
    assert float(x) == pytest.approx(0.0, abs=1e-6)
    assert float(y) == pytest.approx(A + h, abs=1e-9)
    assert float(z) == pytest.approx(0.0, abs=1e-9)


def test_ecef_point_lies_on_ellipsoid() -> None:
    """Any h = 0 point satisfies (x^2 + y^2)/a^2 + z^2/b^2 = 1."""
    lat = np.linspace(-89.0, 89.0, 37)
    lon = np.linspace(-179.0, 179.0, 37)
    x, y, z = geodetic_to_ecef(lat, lon, 0.0)
    np.testing.assert_allclose((x * x + y * y) / A**2 + z * z / B**2, 1.0, rtol=0, atol=1e-14)


# --- geodetic_to_ecef against JSBSim ----------------------------------------

@pytest.fixture(scope="module")
def fdm():
    from cosim.vehicles.jsb import find_model, new_fdm

    return new_fdm(find_model("c172p"), 1 / 120)


def _jsbsim_ecef(fdm, lat: float, lon: float, h_m: float) -> np.ndarray:
    fdm["ic/lat-geod-deg"] = lat
    fdm["ic/long-gc-deg"] = lon
    fdm["ic/h-sl-ft"] = h_m / FT_TO_M
    fdm.run_ic()
    return np.array([fdm["position/ecef-x-ft"], fdm["position/ecef-y-ft"],
                     fdm["position/ecef-z-ft"]]) * FT_TO_M


JSB_POINTS = [
    (37.4, -122.0, 100.0),
    (-33.9, 151.2, 500.0),
    (64.0, -21.0, 3000.0),
    (0.5, 0.5, 0.0),
    (-80.0, -170.0, 20.0),
    (89.0, 10.0, 10000.0),
]


@pytest.mark.parametrize("lat,lon,h", JSB_POINTS)
def test_ecef_matches_jsbsim(fdm, lat: float, lon: float, h: float) -> None:
    """JSBSim's h-sl-ft is not exactly the geodetic height (about 1 cm apart at
    64 deg, 3000 m), hence 2 cm; a wrong ellipsoid or a geocentric latitude
    would be off by metres to kilometres."""
    jsb = _jsbsim_ecef(fdm, lat, lon, h)
    ours = np.array(geodetic_to_ecef(lat, lon, h))
    assert np.linalg.norm(jsb - ours) < 0.02


@pytest.mark.parametrize("lat,lon,h", JSB_POINTS)
def test_ecef_matches_jsbsim_geodetic_altitude(fdm, lat: float, lon: float, h: float) -> None:
    """With JSBSim's own geodetic altitude (position/geod-alt-ft) the two agree
    to well below a millimetre."""
    jsb = _jsbsim_ecef(fdm, lat, lon, h)
    ours = np.array(geodetic_to_ecef(fdm["position/lat-geod-deg"], fdm["position/long-gc-deg"],
                                     fdm["position/geod-alt-ft"] * FT_TO_M))
    assert np.linalg.norm(jsb - ours) < 1e-3


# --- ecef_to_geodetic ---------------------------------------------------------

def test_ecef_to_geodetic_round_trip_random() -> None:
    rng = np.random.default_rng(20240611)
    n = 20000
    lat = rng.uniform(-89.9, 89.9, n)
    lon = rng.uniform(-180.0, 180.0, n)
    h = rng.uniform(-400.0, 100_000.0, n)
    lat2, lon2, h2 = ecef_to_geodetic(*geodetic_to_ecef(lat, lon, h))
    assert np.max(np.abs(lat2 - lat)) < 1e-9
    assert np.max(np.abs(wrap180(lon2 - lon))) < 1e-9
    assert np.max(np.abs(h2 - h)) < 1e-6


def test_ecef_to_geodetic_poles_and_equator() -> None:
    lat, _, h = ecef_to_geodetic(0.0, 0.0, B + 250.0)
    assert float(lat) == pytest.approx(90.0, abs=1e-12)
    assert float(h) == pytest.approx(250.0, abs=1e-6)
    lat, lon, h = ecef_to_geodetic(0.0, -(A + 10.0), 0.0)
    assert float(lat) == pytest.approx(0.0, abs=1e-12)
    assert float(lon) == pytest.approx(-90.0, abs=1e-12)
    assert float(h) == pytest.approx(10.0, abs=1e-6)


# --- LocalFrame ---------------------------------------------------------------

FRAMES = [LocalFrame(47.0, 8.0, 400.0), LocalFrame(-33.9, 151.2, 0.0),
          LocalFrame(0.0, 0.0, -50.0), LocalFrame(78.2, 15.6, 1200.0)]


@pytest.mark.parametrize("f", FRAMES)
def test_frame_origin_maps_to_zero(f: LocalFrame) -> None:
    n, e, d = f.geodetic_to_ned(f.lat_deg, f.lon_deg, f.alt_m)
    assert abs(float(n)) < 1e-9 and abs(float(e)) < 1e-9 and abs(float(d)) < 1e-9


@pytest.mark.parametrize("f", FRAMES)
def test_frame_straight_up(f: LocalFrame) -> None:
    n, e, d = f.geodetic_to_ned(f.lat_deg, f.lon_deg, f.alt_m + 1000.0)
    assert float(d) == pytest.approx(-1000.0, abs=1e-6)
    assert abs(float(n)) < 1e-6 and abs(float(e)) < 1e-6


@pytest.mark.parametrize("f", FRAMES)
def test_frame_round_trip(f: LocalFrame) -> None:
    rng = np.random.default_rng(7)
    n = rng.uniform(-50_000, 50_000, 500)
    e = rng.uniform(-50_000, 50_000, 500)
    d = rng.uniform(-10_000, 300, 500)
    n2, e2, d2 = f.geodetic_to_ned(*f.ned_to_geodetic(n, e, d))
    assert np.max(np.abs(n2 - n)) < 1e-6
    assert np.max(np.abs(e2 - e)) < 1e-6
    assert np.max(np.abs(d2 - d)) < 1e-6


@pytest.mark.parametrize("lat0", [0.0, 45.0, 70.0])
def test_frame_one_km_north_drops_below_tangent_plane(lat0: float) -> None:
    """A point 1 km north along the meridian, on the ellipsoid: the tangent
    plane leaves the surface, so down = M (1 - cos dphi) ~ n^2 / (2M) ~ 7.8 cm."""
    f = LocalFrame(lat0, 11.0, 0.0)
    m = meridian_radius(lat0)
    dphi = 1000.0 / m
    n, e, d = f.geodetic_to_ned(lat0 + math.degrees(dphi), 11.0, 0.0)
    assert float(n) == pytest.approx(m * math.sin(dphi), abs=1e-3)
    assert float(n) == pytest.approx(1000.0, abs=1e-3)
    assert abs(float(e)) < 1e-9
    expected_d = m * (1.0 - math.cos(dphi))
    assert expected_d == pytest.approx(0.0785, abs=1.5e-3)
    assert float(d) == pytest.approx(expected_d, abs=1e-3)
    assert float(d) == pytest.approx(1000.0**2 / (2.0 * m), abs=1e-3)


def test_frame_east_is_east() -> None:
    """A point a little east of the origin has a positive east coordinate."""
    f = LocalFrame(30.0, 20.0, 0.0)
    n, e, _ = f.geodetic_to_ned(30.0, 20.01, 0.0)
    assert float(e) > 900.0 and abs(float(n)) < 1.0


def _chord(f: LocalFrame, lat, lon, h) -> np.ndarray:
    p = np.array(geodetic_to_ecef(lat, lon, h))
    o = np.array(geodetic_to_ecef(f.lat_deg, f.lon_deg, f.alt_m))
    return np.linalg.norm(p - o.reshape(3, *([1] * (p.ndim - 1))), axis=0)


@pytest.mark.parametrize("f", FRAMES)
def test_frame_preserves_distances_30km(f: LocalFrame) -> None:
    bearings = np.radians(np.arange(0.0, 360.0, 30.0))
    # points about 30 km away on the ellipsoid, at various heights
    m = meridian_radius(f.lat_deg)
    lat = f.lat_deg + np.degrees(30_000.0 * np.cos(bearings) / m)
    lon = f.lon_deg + np.degrees(30_000.0 * np.sin(bearings)
                                 / (A * math.cos(math.radians(f.lat_deg))))
    h = np.linspace(-100.0, 3000.0, bearings.size)
    n, e, d = f.geodetic_to_ned(lat, lon, h)
    np.testing.assert_allclose(np.sqrt(n * n + e * e + d * d), _chord(f, lat, lon, h),
                               rtol=0, atol=1e-6)
    # and between any two points, not only from the origin
    p = np.stack(geodetic_to_ecef(lat, lon, h))
    ned = np.stack([n, e, d])
    for i, j in [(0, 6), (1, 4), (3, 11)]:
        assert np.linalg.norm(ned[:, i] - ned[:, j]) == pytest.approx(
            np.linalg.norm(p[:, i] - p[:, j]), abs=1e-6)


def test_flat_earth_is_off_by_metres_at_30km_but_we_are_not() -> None:
    f = LocalFrame(10.0, 20.0, 0.0)
    r_mean = 6371008.8
    dlat, dlon = 0.2, 0.2  # ~22 km north, ~22 km east: ~31 km
    lat, lon = f.lat_deg + dlat, f.lon_deg + dlon
    chord = float(_chord(f, lat, lon, 0.0))
    assert 29_000 < chord < 33_000
    flat_n = math.radians(dlat) * r_mean
    flat_e = math.radians(dlon) * r_mean * math.cos(math.radians(f.lat_deg))
    assert abs(math.hypot(flat_n, flat_e) - chord) > 1.0
    n, e, d = f.geodetic_to_ned(lat, lon, 0.0)
    assert math.sqrt(float(n) ** 2 + float(e) ** 2 + float(d) ** 2) == pytest.approx(
        chord, abs=1e-6)
    assert float(d) > 50.0  # ~31 km away the ellipsoid is ~75 m below the tangent plane


@pytest.mark.skipif(not hasattr(LocalFrame, "place"), reason="LocalFrame.place not present")
def test_place_gives_exact_north_east_at_height() -> None:
    f = LocalFrame(47.0, 8.0, 400.0)
    n = np.array([0.0, 1000.0, -25_000.0, 60_000.0, 3.0])
    e = np.array([0.0, -2000.0, 40_000.0, -10_000.0, 4.0])
    h = np.array([400.0, 900.0, 5000.0, 12_000.0, 0.0])
    lat, lon = f.place(n, e, h)
    n2, e2, _ = f.geodetic_to_ned(lat, lon, h)
    assert np.max(np.abs(n2 - n)) < 1e-6
    assert np.max(np.abs(e2 - e)) < 1e-6


# --- broadcasting -------------------------------------------------------------

def test_broadcasting_shapes() -> None:
    lat = np.linspace(-60, 60, 5)
    lon = np.linspace(-170, 170, 5)
    h = np.linspace(0, 1000, 5)
    for out in (geodetic_to_ecef(lat, lon, h), geodetic_to_ecef(lat, lon, 100.0),
                ecef_to_geodetic(*geodetic_to_ecef(lat, lon, h))):
        assert len(out) == 3
        assert all(np.shape(a) == (5,) for a in out)
    f = LocalFrame(10.0, 20.0, 30.0)
    for out in (f.geodetic_to_ned(lat, lon, h), f.geodetic_to_ned(lat, lon, 0.0),
                f.ned_to_geodetic(h, h, 0.0), f.ned_to_geodetic(h, 0.0, 0.0)):
        assert len(out) == 3
        assert all(np.shape(a) == (5,) for a in out)
    # element-wise, identical to the scalar call
    x, y, z = geodetic_to_ecef(lat, lon, h)
    for i in range(5):
        xi, yi, zi = geodetic_to_ecef(float(lat[i]), float(lon[i]), float(h[i]))
        assert float(x[i]) == pytest.approx(float(xi), abs=1e-6)
        assert float(y[i]) == pytest.approx(float(yi), abs=1e-6)
        assert float(z[i]) == pytest.approx(float(zi), abs=1e-6)
    n, e, d = f.geodetic_to_ned(lat, lon, h)
    n3, e3, d3 = f.geodetic_to_ned(float(lat[3]), float(lon[3]), float(h[3]))
    assert np.shape(n3) == () and float(n3) == pytest.approx(n[3], abs=1e-9)
    assert float(e3) == pytest.approx(e[3], abs=1e-9)
    assert float(d3) == pytest.approx(d[3], abs=1e-9)


def test_results_do_not_depend_on_the_batch_size() -> None:
    """Bit for bit: a point's NED (and back) is the same converted alone, in a
    batch of 50 or in any slice of it (states.parquet parts vary in size)."""
    rng = np.random.default_rng(0)
    lat = 47.0 + rng.normal(0.0, 0.05, 50)
    lon = 8.0 + rng.normal(0.0, 0.05, 50)
    alt = 400.0 + rng.uniform(0.0, 2000.0, 50)
    f = LocalFrame(47.0, 8.0, 400.0)
    batch = np.stack(f.geodetic_to_ned(lat, lon, alt))
    alone = np.stack([np.array(f.geodetic_to_ned(lat[i], lon[i], alt[i])) for i in range(50)],
                     axis=1)
    assert np.array_equal(batch, alone)
    for a, b in ((0, 7), (3, 20), (11, 50)):
        assert np.array_equal(np.stack(f.geodetic_to_ned(lat[a:b], lon[a:b], alt[a:b])),
                              batch[:, a:b])
    back = np.stack(f.ned_to_geodetic(*batch))
    back_alone = np.stack([np.array(f.ned_to_geodetic(*batch[:, i])) for i in range(50)], axis=1)
    assert np.array_equal(back, back_alone)
    placed = np.stack(f.place(batch[0], batch[1], alt))
    placed_alone = np.stack([np.array(f.place(batch[0, i], batch[1, i], alt[i]))
                             for i in range(50)], axis=1)
    assert np.array_equal(placed, placed_alone)
