"""The rigid-body tier's atmosphere and Earth (``cosim.rigid.atmosphere``)
against JSBSim itself: the standard atmosphere at altitudes from below sea
level through every layer of the table and above it, in flight (the
viscosity through JSBSim's Reynolds number), and the Earth's geometry and
gravity at latitudes from pole to pole, each equal to JSBSim's own value;
a perturbed constant is caught; the geodetic conversions round-trip and the
local frame points north, east and down."""

from __future__ import annotations

import jsbsim
import numpy as np
import pytest

from cosim.errors import ConfigError
from cosim.rigid import atmosphere as atm
from cosim.rigid.atmosphere import (
    FRAME_OUTPUTS,
    SEA_LEVEL,
    Atmosphere,
    altitude_asl_ft,
    ecef_to_geodetic,
    geocentric,
    geodetic_to_ecef,
    gravity_ecef,
    sea_level_radius_ft,
    tec2l,
)
from cosim.vehicles.jsb import find_model, new_fdm

#: numpy's pow, exp and log may round differently from the C library's in
#: the last place or two; every other operation is JSBSim's own, in order
RTOL = 1e-12

#: geometric altitudes (ft): below sea level, a sweep, every layer's base
#: and both sides of it (geometric 11.019 km ... 91 km), and far above, where
#: JSBSim's floor on the pressure holds
ALTITUDES_FT = np.concatenate([
    np.linspace(-5000.0, 100000.0, 43),
    [36151.80, 36151.81, 65823.90, 105518.06, 155348.07, 168676.12, 235570.77,
     282152.08, 298556.40, 160000.0, 320000.0, 400000.0, 1.0e6],
])
ATMOSPHERE_PROPS = [n for n in FRAME_OUTPUTS if not n.startswith("_")] + list(SEA_LEVEL)
EARTH_PROPS = ["position/ecef-x-ft", "position/ecef-y-ft", "position/ecef-z-ft",
               "position/lat-geod-rad", "position/geod-alt-ft", "position/lat-gc-rad",
               "position/long-gc-rad", "position/radius-to-vehicle-ft",
               "inertial/sea-level-radius_ft", "position/h-sl-ft",
               "accelerations/gravity-ft_sec2"]


@pytest.fixture(scope="module")
def fdm() -> jsbsim.FGFDMExec:
    return new_fdm(find_model("uav700"), 1 / 120)


def _at_ic(fdm, points: list[tuple[float, float, float]], names: list[str]
           ) -> dict[str, np.ndarray]:
    """JSBSim's values of ``names`` after run_ic() at each (geodetic latitude
    deg, longitude deg, h-sl-ft)."""
    out: dict[str, list[float]] = {n: [] for n in names}
    for lat, lon, h in points:
        fdm["ic/lat-geod-deg"] = lat
        fdm["ic/long-gc-deg"] = lon
        fdm["ic/h-sl-ft"] = h
        fdm.run_ic()
        for n in names:
            out[n].append(fdm[n])
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def sweep(fdm) -> dict[str, np.ndarray]:
    return _at_ic(fdm, [(30.0, -100.0, h) for h in ALTITUDES_FT],
                  ATMOSPHERE_PROPS + ["position/h-sl-ft"])


@pytest.fixture(scope="module")
def earth(fdm) -> dict[str, np.ndarray]:
    points = [(lat, lon, h)
              for lat in (-90.0, -89.99, -60.0, -45.5, -10.0, 0.0, 0.001, 23.4, 45.0, 75.0,
                          89.999, 90.0)
              for lon in (-179.9, -30.0, 0.0, 100.0, 180.0)
              for h in (-1000.0, 0.0, 3000.0, 40000.0, 100000.0)]
    return _at_ic(fdm, points, EARTH_PROPS)


def _atmosphere_of(h_sl_ft: np.ndarray) -> dict[str, np.ndarray]:
    props = {"position/h-sl-ft": h_sl_ft.copy()}
    part = Atmosphere()
    part.init(props, len(h_sl_ft))
    part.run(props, 1 / 120)
    return props


def _check_atmosphere(sweep: dict[str, np.ndarray]) -> None:
    props = _atmosphere_of(sweep["position/h-sl-ft"])
    for name in ATMOSPHERE_PROPS:
        np.testing.assert_allclose(props[name], sweep[name], rtol=RTOL, atol=0, err_msg=name)


def test_the_atmosphere_equals_jsbsims_from_below_sea_level_to_far_above(sweep) -> None:
    _check_atmosphere(sweep)
    # the sweep went through every layer and the pressure's floor
    assert sweep["atmosphere/T-R"].min() == pytest.approx(336.5028)
    assert sweep["atmosphere/P-psf"].min() == pytest.approx(1e-15 / 47.88, rel=1e-3)
    H = atm.geopotential_ft(ALTITUDES_FT)
    assert set(np.searchsorted(atm.LAYER_H_FT, H)) == set(range(len(atm.LAYER_H_FT) + 1))


@pytest.mark.parametrize("name, factor", [
    ("ISA_EARTH_RADIUS_FT", 1 + 1e-6),   # geopotential altitude
    ("R_DRY", 1 + 1e-10),                 # the gas constant of the density
    ("SL_SOUNDSPEED_FPS", 1 + 1e-11),
])
def test_a_perturbed_constant_is_caught(sweep, monkeypatch, name: str,
                                        factor: float) -> None:
    monkeypatch.setattr(atm, name, getattr(atm, name) * factor)
    with pytest.raises(AssertionError):
        _check_atmosphere(sweep)


def test_the_atmosphere_in_flight_and_its_viscosity_through_the_reynolds_number(fdm) -> None:
    """Flown through a climb and a dive: every frame's atmosphere equals
    JSBSim's at that frame's altitude, and JSBSim's Reynolds number ``aero/Re``
    = true airspeed x chord / the kinematic viscosity."""
    fdm["ic/lat-geod-deg"] = 47.0
    fdm["ic/h-sl-ft"] = 3000
    fdm["ic/vc-kts"] = 150
    fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    names = ATMOSPHERE_PROPS + ["position/h-sl-ft", "aero/Re", "velocities/vt-fps"]
    rec: dict[str, list[float]] = {n: [] for n in names}
    for i in range(240):
        fdm["fcs/elevator-cmd-norm"] = -0.4 if i < 120 else 0.3
        fdm["fcs/throttle-cmd-norm"] = 1.0
        fdm.run()
        for n in names:
            rec[n].append(fdm[n])
    r = {k: np.array(v) for k, v in rec.items()}
    assert np.ptp(r["position/h-sl-ft"]) > 20  # it climbed and dived
    props = _atmosphere_of(r["position/h-sl-ft"])
    for name in ATMOSPHERE_PROPS:
        np.testing.assert_allclose(props[name], r[name], rtol=RTOL, atol=0, err_msg=name)
    nu = props["_atmosphere/kinematic-viscosity-ft2_s"]
    re = r["velocities/vt-fps"] * fdm["metrics/cbarw-ft"] / nu
    np.testing.assert_allclose(re, r["aero/Re"], rtol=RTOL, atol=0)
    assert not np.allclose(re * (1 + 1e-10), r["aero/Re"], rtol=RTOL, atol=0)
    assert np.all(r["aero/Re"] > 1e5)


def test_the_part_follows_the_contract() -> None:
    part = Atmosphere()
    assert part.inputs == {"position/h-sl-ft"}
    assert part.outputs == set(FRAME_OUTPUTS) | set(SEA_LEVEL)
    props: dict[str, np.ndarray] = {}
    part.init(props, 3)  # no altitude yet: sea level, as JSBSim's InitModel
    assert set(props) == part.outputs
    assert len({id(v) for v in props.values()}) == len(props)  # no array shared
    assert np.all(props["atmosphere/T-R"] == 518.67)
    assert np.all(props["atmosphere/P-psf"] == 2116.228)
    assert np.all(props["atmosphere/sigma"] == 1.0)
    props["position/h-sl-ft"] = np.array([0.0, 10000.0, 50000.0])
    part.run(props, 1 / 120)
    assert np.all(np.diff(props["atmosphere/rho-slugs_ft3"]) < 0)
    few = Atmosphere(["atmosphere/T-R", "atmosphere/density-altitude"])
    assert few.outputs == {"atmosphere/T-R", "atmosphere/density-altitude", *SEA_LEVEL}
    some: dict[str, np.ndarray] = {"position/h-sl-ft": np.array([5000.0, 40000.0])}
    few.init(some, 2)
    assert set(some) == few.outputs | {"position/h-sl-ft"}
    np.testing.assert_array_equal(some["atmosphere/density-altitude"],
                                  _atmosphere_of(np.array([5000.0, 40000.0]))
                                  ["atmosphere/density-altitude"])
    with pytest.raises(ConfigError, match="does not compute atmosphere/T-C; it computes "
                                          "atmosphere/T-R"):
        Atmosphere(["atmosphere/T-C"])


def test_the_earth_equals_jsbsims_from_pole_to_pole(earth) -> None:
    x, y, z = earth["position/ecef-x-ft"], earth["position/ecef-y-ft"], earth["position/ecef-z-ft"]
    geod = ecef_to_geodetic(x, y, z)
    radius, lat_gc, lon = geocentric(x, y, z)
    gx, gy, gz = gravity_ecef(x, y, z)
    ours = {
        "position/lat-geod-rad": geod.lat_rad,
        "position/geod-alt-ft": geod.alt_ft,
        "position/lat-gc-rad": lat_gc,
        "position/long-gc-rad": lon,
        "position/radius-to-vehicle-ft": radius,
        "inertial/sea-level-radius_ft": sea_level_radius_ft(lat_gc),
        "position/h-sl-ft": altitude_asl_ft(x, y, z),
        "accelerations/gravity-ft_sec2": np.sqrt(gx * gx + gy * gy + gz * gz),
    }
    for name, value in ours.items():
        # atol: the latitudes and longitudes at 0 and the altitudes at sea level
        np.testing.assert_allclose(value, earth[name], rtol=RTOL, atol=1e-12, err_msg=name)
    # h-sl-ft is the radius less the sea-level radius, not the geodetic height
    assert np.abs(earth["position/h-sl-ft"] - earth["position/geod-alt-ft"]).max() > 1e-3
    # the gravity points down and inwards, stronger at the poles
    g_up = (gx * x + gy * y + gz * z) / radius
    assert np.all(g_up / ours["accelerations/gravity-ft_sec2"] < -0.99)
    g_sl = ours["accelerations/gravity-ft_sec2"][np.abs(earth["position/h-sl-ft"]) < 1e-6]
    lat_sl = np.abs(lat_gc[np.abs(earth["position/h-sl-ft"]) < 1e-6])
    assert g_sl[lat_sl > 1.5].min() > g_sl[lat_sl < 0.01].max() + 0.05


def test_a_perturbed_earth_is_caught(earth, monkeypatch) -> None:
    """The Earth's formulas are numba kernels, which take their constants
    when compiled: the perturbed constants are given to their Python forms
    (``py_func``, which read the module's constants when called)."""
    from cosim.rigid import kernels

    x, y, z = earth["position/ecef-x-ft"], earth["position/ecef-y-ft"], earth["position/ecef-z-ft"]

    def each(f, *cols):
        return np.array([f(*v) for v in zip(*cols, strict=True)])

    g = each(kernels.gravity.py_func, x, y, z)
    np.testing.assert_allclose(np.sqrt((g * g).sum(axis=1)),
                               earth["accelerations/gravity-ft_sec2"], rtol=RTOL, atol=0)
    monkeypatch.setattr(kernels, "J2", kernels.J2 * (1 + 1e-6))
    g = each(kernels.gravity.py_func, x, y, z)
    assert not np.allclose(np.sqrt((g * g).sum(axis=1)), earth["accelerations/gravity-ft_sec2"],
                           rtol=RTOL, atol=0)
    monkeypatch.setattr(kernels, "SEMIMAJOR_FT", kernels.SEMIMAJOR_FT + 0.01)
    assert not np.allclose(each(kernels.altitude_asl.py_func, x, y, z),
                           earth["position/h-sl-ft"], rtol=RTOL, atol=1e-9)


def test_geodetic_and_ecef_round_trip() -> None:
    """Fukushima's one iteration is exact to the doubles' noise at the
    Earth's surface and to 1e-7 ft up to 300,000 ft."""
    rng = np.random.default_rng(3)
    n = 20000
    lat = rng.uniform(-np.pi / 2, np.pi / 2, n)
    lon = rng.uniform(-np.pi, np.pi, n)
    h = rng.uniform(-2000.0, 300000.0, n)
    x, y, z = geodetic_to_ecef(lon, lat, h)
    g = ecef_to_geodetic(x, y, z)
    np.testing.assert_allclose(g.lat_rad, lat, rtol=0, atol=1e-13)
    np.testing.assert_allclose(g.lon_rad, lon, rtol=0, atol=1e-15)
    np.testing.assert_allclose(g.alt_ft, h, rtol=0, atol=1e-7)
    np.testing.assert_allclose(np.hypot(g.sin_lat, g.cos_lat), 1.0, rtol=1e-15)
    x2, y2, z2 = geodetic_to_ecef(g.lon_rad, g.lat_rad, g.alt_ft)
    np.testing.assert_allclose(np.stack([x2, y2, z2]), np.stack([x, y, z]), rtol=0, atol=1e-6)


def test_the_local_frame_points_north_east_and_down() -> None:
    """Each row of the ECEF-to-NED rotation is the direction in which a
    step north, east and down moves the ECEF position (finite differences
    of geodetic_to_ecef: 1e-8 is their truncation error)."""
    rng = np.random.default_rng(4)
    n = 500
    lat = rng.uniform(-1.5, 1.5, n)
    lon = rng.uniform(-np.pi, np.pi, n)
    h = rng.uniform(0.0, 50000.0, n)
    pos = np.stack(geodetic_to_ecef(lon, lat, h))
    m = tec2l(*pos)
    assert m.shape == (3, 3, n)
    np.testing.assert_allclose(np.einsum("ijn,kjn->ikn", m, m),
                               np.repeat(np.eye(3)[:, :, None], n, axis=2), atol=1e-15)
    d = 1e-7

    def direction(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> np.ndarray:
        v = np.stack(geodetic_to_ecef(*a)) - np.stack(geodetic_to_ecef(*b))
        return v / np.linalg.norm(v, axis=0)

    north = direction((lon, lat + d, h), (lon, lat - d, h))
    east = direction((lon + d, lat, h), (lon - d, lat, h))
    down = direction((lon, lat, h - 1.0), (lon, lat, h + 1.0))
    for row, want in enumerate((north, east, down)):
        np.testing.assert_allclose(m[row], want, atol=1e-8, err_msg=f"row {row}")
    # a north-east-down vector turned back to ECEF and forth again
    v = rng.normal(size=(3, n))
    back = np.einsum("jin,jn->in", m, np.einsum("ijn,jn->in", m, v))
    np.testing.assert_allclose(back, v, atol=1e-14)
    # at a pole (no longitude): FGLocation's longitude 0
    pole = tec2l(np.array([0.0]), np.array([0.0]), np.array([atm.SEMIMINOR_FT]))[:, :, 0]
    np.testing.assert_allclose(pole, [[-1, 0, 0], [0, 1, 0], [0, 0, -1]], atol=1e-15)
