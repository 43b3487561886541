"""The atmosphere and the Earth of the rigid-body tier, computed as JSBSim 1.3
computes them, for every aircraft at once (arrays of one value per aircraft,
JSBSim's units: ft, R, psf, slug/ft^3, rad).

**The standard atmosphere** (JSBSim's ``FGStandardAtmosphere`` over
``FGAtmosphere``: the 1976 U.S. Standard Atmosphere as JSBSim implements
it). ``Atmosphere`` is a compiled part: it reads ``position/h-sl-ft`` (the
altitude above sea level, ``radius - sea-level radius``, see below) and
writes the ``atmosphere/...`` properties. With the ISA Earth radius
``r0 = 6356766 m`` the geopotential altitude of a geometric ``h`` is
``H = h r0 / (r0 + h)`` (and back: ``h = H r0 / (r0 - H)``). The
temperature is JSBSim's table of nine breakpoints in geopotential feet
(0, 36089.2388, 65616.7979, 104986.8766, 154199.4751, 167322.8346,
232939.6325, 278385.8268, 298556.4304 ft; 518.67, 389.97, 389.97, 411.57,
487.17, 487.17, 386.37, 336.5028, 336.5028 R), interpolated linearly and
held at its last value above; below sea level the first lapse rate goes on.
In layer ``b`` (base ``H_b``, base temperature ``T_b``, lapse rate
``L_b``, base pressure ``P_b``) the pressure is (the standard's equations
33a and 33b)

    P = P_b (T_b / (T_b + L_b (H - H_b)))^(g0 / (R L_b))   if L_b != 0
    P = P_b exp(-g0 (H - H_b) / (R T_b))                   if L_b == 0

with ``P_0 = 2116.228 psf`` and each ``P_b`` from the layer below at its
top; ``g0 = 9.80665 m/s^2``, ``R = R* / M_air`` (``R* = 8.31432 J/(mol
K)``, ``M_air = 28.9645 g/mol``, converted as JSBSim converts: 0.3048 m a
foot, 0.06852168 slug a kg, 1.8 R a K). Then ``rho = P / (R T)``, ``a =
sqrt(1.4 R T)``, Sutherland's viscosity ``mu = 2.269690e-8 T^1.5 / (198.72
+ T)`` and ``nu = mu / rho``, the ratios to the sea-level values (``theta``,
``delta``, ``sigma``, ``a-ratio``), and the pressure and density altitudes
(the same layer equations solved for ``H`` against the standard's pressure
and density breakpoints, then made geometric). Every operation is JSBSim's,
in its order, so the results are JSBSim's to the last bits (a few units in
the last place where numpy's ``pow``/``exp``/``log`` round differently from
the C library's).

JSBSim keeps the viscosities without properties; here they are
``_atmosphere/absolute-viscosity-lbf_s_ft2`` and
``_atmosphere/kinematic-viscosity-ft2_s`` (its Reynolds number ``aero/Re``
reads the second). ``Atmosphere(wanted)`` computes only the named outputs
(temperature, pressure and density always): the pressure and density
altitudes cost a third of the frame and few aircraft files read them. When
every aircraft is in the troposphere (the usual case) no table lookup is
made, at the same values.

Not modelled (the aircraft files do not configure them, and JSBSim's
defaults are none): a temperature bias or graded delta, a sea-level
pressure other than standard, humidity (the vapour fraction is 0, so the
gas constant is dry air's), winds, gusts and turbulence. JSBSim's floor
on the temperature (1 K) cannot be reached from a standard profile; its
floor on the pressure (1e-15 Pa, above about 900,000 ft) is kept.

**The Earth** (JSBSim's ``FGInertial`` with its default gravity model,
``simulation/gravity-model`` = 1, WGS84 with J2, and ``FGLocation``):
semimajor axis ``a = 20925646.32546 ft``, semiminor ``b = 20855486.5951
ft``, ``GM = 14.0764417572e15 ft^3/s^2``, ``J2 = 1.08262982e-3``, rotation
``7.292115e-5 rad/s``. From an ECEF position (ft):

- ``geocentric``: radius, geocentric latitude ``atan2(z, sqrt(x^2 + y^2))``
  and longitude ``atan2(y, x)``.
- ``sea_level_radius_ft``: ``a (b/a) / sqrt(1 - e^2 cos^2 lat_gc)``, and
  ``altitude_asl_ft`` = radius minus that: JSBSim's ``position/h-sl-ft``
  (not the height above the ellipsoid, which is ``position/geod-alt-ft``).
- ``ecef_to_geodetic``: geodetic latitude and height above the ellipsoid by
  Fukushima's method accelerated by Halley's (Journal of Geodesy 79, 2006),
  one iteration, as ``FGLocation`` does; ``geodetic_to_ecef`` the inverse
  (``FGLocation::SetPositionGeodetic``, closed form).
- ``tec2l``: the rotation from ECEF to the local North-East-Down frame at
  the geodetic latitude (``FGLocation::GetTec2l``; Stevens and Lewis, eqn
  1.4-13).
- ``gravity_ecef``: ``FGInertial::GetGravityJ2`` (Stevens and Lewis, eqn
  1.4-16): with ``r`` the radius and ``s`` the sine of the geocentric
  latitude, ``g_x,y = -GM/r^2 (1 + 1.5 J2 (a/r)^2 (1 - 5 s^2)) x,y / r`` and
  ``g_z = -GM/r^2 (1 + 1.5 J2 (a/r)^2 (3 - 5 s^2)) z / r``; its magnitude is
  ``accelerations/gravity-ft_sec2``.

The centre of the Earth (radius 0) is outside every function's domain.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from cosim.errors import ConfigError
from cosim.rigid import kernels

Props = dict[str, np.ndarray]

# --- JSBSim's unit conversions (FGJSBBase) --------------------------------
_FT_TO_M = 0.3048
_KG_TO_SLUG = 0.06852168
_PA_TO_PSF = 0.0208854342  # FGAtmosphere::ConvertToPSF from pascals

# --- the standard atmosphere's constants (FGAtmosphere, FGStandardAtmosphere)
#: universal gas constant, ft lbf / (R mol)
R_STAR = 8.31432 * _KG_TO_SLUG / ((_FT_TO_M * _FT_TO_M) * 1.8)
#: mean molecular weight of air, slug / mol
M_AIR = 28.9645 * _KG_TO_SLUG / 1000.0
#: dry air's gas constant, ft lbf / (slug R)
R_DRY = R_STAR / M_AIR
#: sea-level gravity of the standard (not the gravity model's), ft/s^2
G0_FT_S2 = 9.80665 / _FT_TO_M
#: ratio of specific heats
GAMMA = 1.4
#: the ISA Earth radius of the geopotential altitude, ft
ISA_EARTH_RADIUS_FT = 6356766.0 / _FT_TO_M
SUTHERLAND_R = 198.72
SUTHERLAND_BETA = 2.269690e-08
#: JSBSim's floor on the pressure, psf
MIN_PRESSURE_PSF = 1e-15 * _PA_TO_PSF

#: the temperature table: geopotential altitude (ft), temperature (R)
LAYER_H_FT = np.array([0.0, 36089.2388, 65616.7979, 104986.8766, 154199.4751,
                       167322.8346, 232939.6325, 278385.8268, 298556.4304])
LAYER_T_R = np.array([518.67, 389.97, 389.97, 411.57, 487.17, 487.17, 386.37,
                      336.5028, 336.5028])

SL_TEMPERATURE_R = float(LAYER_T_R[0])
SL_PRESSURE_PSF = 2116.228
SL_DENSITY_SLUG_FT3 = SL_PRESSURE_PSF / (R_DRY * SL_TEMPERATURE_R)
SL_SOUNDSPEED_FPS = math.sqrt(GAMMA * R_DRY * SL_TEMPERATURE_R)


def geopotential_ft(h_ft: np.ndarray) -> np.ndarray:
    """The geopotential altitude of a geometric one (ft)."""
    return (h_ft * ISA_EARTH_RADIUS_FT) / (ISA_EARTH_RADIUS_FT + h_ft)


def geometric_ft(H_ft: np.ndarray) -> np.ndarray:
    """The geometric altitude of a geopotential one (ft)."""
    return (H_ft * ISA_EARTH_RADIUS_FT) / (ISA_EARTH_RADIUS_FT - H_ft)


def _table_temperature(H: float) -> float:
    """JSBSim's temperature table at one geopotential altitude (FGTable)."""
    if H <= LAYER_H_FT[0]:
        return float(LAYER_T_R[0])
    if H >= LAYER_H_FT[-1]:
        return float(LAYER_T_R[-1])
    r = int(np.searchsorted(LAYER_H_FT, H, side="left"))
    x0 = float(LAYER_H_FT[r - 1])
    f = (H - x0) / (float(LAYER_H_FT[r]) - x0)
    return f * (float(LAYER_T_R[r]) - float(LAYER_T_R[r - 1])) + float(LAYER_T_R[r - 1])


def _layers() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each layer's lapse rate, pressure and density at its base, and the
    base temperature as ``GetPressure`` finds it (the base altitude made
    geometric and back before the table lookup), all computed once in the
    order JSBSim computes them."""
    n = len(LAYER_H_FT)
    lapse = [(float(LAYER_T_R[b + 1]) - float(LAYER_T_R[b]))
             / (float(LAYER_H_FT[b + 1]) - float(LAYER_H_FT[b])) for b in range(n - 1)]
    p = [SL_PRESSURE_PSF]
    for b in range(n - 1):
        t_b, d_h = float(LAYER_T_R[b]), float(LAYER_H_FT[b + 1]) - float(LAYER_H_FT[b])
        if lapse[b] != 0.0:
            factor = t_b / (t_b + lapse[b] * d_h)
            p.append(p[b] * math.pow(factor, G0_FT_S2 / (R_DRY * lapse[b])))
        else:
            p.append(p[b] * math.exp(-G0_FT_S2 * d_h / (R_DRY * t_b)))
    rho = [p[i] / (R_DRY * float(LAYER_T_R[i])) for i in range(n)]
    t_base = []
    for b in range(n - 1):
        hb = float(LAYER_H_FT[b])
        back = (hb * ISA_EARTH_RADIUS_FT) / (ISA_EARTH_RADIUS_FT - hb)
        t_base.append(_table_temperature((back * ISA_EARTH_RADIUS_FT)
                                         / (ISA_EARTH_RADIUS_FT + back)))
    return np.array(lapse), np.array(p), np.array(rho), np.array(t_base)


#: per layer (8): lapse rate (R/ft); per breakpoint (9): pressure (psf) and
#: density (slug/ft^3); per layer: base temperature as GetPressure uses it
LAPSE_R_FT, PRESSURE_BP_PSF, DENSITY_BP_SLUG_FT3, _T_BASE_R = _layers()

# the layer constants in the form the kernels use: a zero lapse rate's
# exponential branch is chosen by a mask, its power branch fed harmless values
_ISO = LAPSE_R_FT == 0.0
_L_SAFE = np.where(_ISO, 1.0, LAPSE_R_FT)
_EXP_P = G0_FT_S2 / (R_DRY * _L_SAFE)                                      # GetPressure
_EXP_PA = np.where(_ISO, 0.0, -R_DRY * _L_SAFE / G0_FT_S2)                 # pressure alt.
_EXP_DA = np.where(_ISO, 0.0, -1.0 / (1.0 + G0_FT_S2 / (R_DRY * _L_SAFE)))  # density alt.
_T_OVER_L = LAYER_T_R[:-1] / _L_SAFE
_FACTOR = -R_DRY * LAYER_T_R[:-1] / G0_FT_S2
_DT_R = np.diff(LAYER_T_R)  # the table's rises, as FGTable takes them

_MU = "_atmosphere/absolute-viscosity-lbf_s_ft2"
_NU = "_atmosphere/kinematic-viscosity-ft2_s"
_VISCOSITY = frozenset({_MU, _NU})
#: what Atmosphere writes each frame
FRAME_OUTPUTS = (
    "atmosphere/T-R", "atmosphere/P-psf", "atmosphere/rho-slugs_ft3", "atmosphere/a-fps",
    "atmosphere/theta", "atmosphere/delta", "atmosphere/sigma", "atmosphere/a-ratio",
    "atmosphere/pressure-altitude", "atmosphere/density-altitude",
    _MU, _NU,
)
#: the sea-level values, written once by init
SEA_LEVEL = {
    "atmosphere/T-sl-R": SL_TEMPERATURE_R,
    "atmosphere/P-sl-psf": SL_PRESSURE_PSF,
    "atmosphere/rho-sl-slugs_ft3": SL_DENSITY_SLUG_FT3,
    "atmosphere/a-sl-fps": SL_SOUNDSPEED_FPS,
}


def _altitude_from(value: np.ndarray, bp: np.ndarray, exponent: np.ndarray) -> np.ndarray:
    """The geometric altitude whose standard pressure (or density, with its
    breakpoints ``bp``) is ``value``: JSBSim's CalculatePressureAltitude and
    CalculateDensityAltitude. Layer b is the first whose top value is at or
    below ``value`` (the last one goes on up)."""
    if value.min() >= bp[1]:  # every aircraft in the first layer: no lookups
        H = _T_OVER_L[0] * ((value / bp[0]) ** exponent[0] - 1)
        return geometric_ft(LAYER_H_FT[0] + H)
    b = np.searchsorted(-bp[1:-1], -value, side="left")
    ratio = value / bp[b]
    H = LAYER_H_FT[b] + np.where(_ISO[b], _FACTOR[b] * np.log(ratio),
                                 _T_OVER_L[b] * (ratio ** exponent[b] - 1))
    return geometric_ft(H)


def _temperature_pressure(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Temperature (R) and pressure (psf) at geopotential altitudes (ft):
    FGStandardAtmosphere's GetTemperature and GetPressure."""
    if H.min() >= 0.0 and H.max() < LAYER_H_FT[1]:  # all in the troposphere
        T = (H - LAYER_H_FT[0]) / (LAYER_H_FT[1] - LAYER_H_FT[0]) * _DT_R[0] + LAYER_T_R[0]
        t_b = _T_BASE_R[0]
        P = PRESSURE_BP_PSF[0] * (t_b / (t_b + LAPSE_R_FT[0] * (H - LAYER_H_FT[0]))) ** _EXP_P[0]
        return T, P  # far above the pressure's floor
    # the temperature table, clamped above; the first lapse rate below 0
    r = np.clip(np.searchsorted(LAYER_H_FT, H, side="left"), 1, len(LAYER_H_FT) - 1)
    x0 = LAYER_H_FT[r - 1]
    f = np.minimum((H - x0) / (LAYER_H_FT[r] - x0), 1.0)
    T = np.where(H >= 0.0, f * _DT_R[r - 1] + LAYER_T_R[r - 1],
                 SL_TEMPERATURE_R + H * LAPSE_R_FT[0])
    # the pressure: layer b holds H in [H_b, H_b+1) (the last one goes on up)
    b = np.searchsorted(LAYER_H_FT[1:-1], H, side="right")
    t_b = _T_BASE_R[b]
    d_h = H - LAYER_H_FT[b]
    P = PRESSURE_BP_PSF[b] * np.where(_ISO[b], np.exp(-G0_FT_S2 * d_h / (R_DRY * t_b)),
                                      (t_b / (t_b + _L_SAFE[b] * d_h)) ** _EXP_P[b])
    return T, np.maximum(P, MIN_PRESSURE_PSF)


def standard_atmosphere(h_sl_ft: np.ndarray, wanted: frozenset[str] = frozenset(FRAME_OUTPUTS)
                        ) -> dict[str, np.ndarray]:
    """The values of ``wanted`` (names of ``FRAME_OUTPUTS``) at the altitudes
    ``h_sl_ft`` (ft above sea level as JSBSim's ``position/h-sl-ft``)."""
    T, P = _temperature_pressure(geopotential_ft(np.asarray(h_sl_ft, dtype=np.float64)))
    rho = P / (R_DRY * T)
    out = {"atmosphere/T-R": T, "atmosphere/P-psf": P, "atmosphere/rho-slugs_ft3": rho}
    if "atmosphere/a-fps" in wanted or "atmosphere/a-ratio" in wanted:
        a = out["atmosphere/a-fps"] = np.sqrt(GAMMA * R_DRY * T)
        if "atmosphere/a-ratio" in wanted:
            out["atmosphere/a-ratio"] = a / SL_SOUNDSPEED_FPS
    if "atmosphere/theta" in wanted:
        out["atmosphere/theta"] = T / SL_TEMPERATURE_R
    if "atmosphere/delta" in wanted:
        out["atmosphere/delta"] = P / SL_PRESSURE_PSF
    if "atmosphere/sigma" in wanted:
        out["atmosphere/sigma"] = rho / SL_DENSITY_SLUG_FT3
    if "atmosphere/pressure-altitude" in wanted:
        out["atmosphere/pressure-altitude"] = _altitude_from(P, PRESSURE_BP_PSF, _EXP_PA)
    if "atmosphere/density-altitude" in wanted:
        out["atmosphere/density-altitude"] = _altitude_from(rho, DENSITY_BP_SLUG_FT3, _EXP_DA)
    if _VISCOSITY & wanted:
        mu = out[_MU] = SUTHERLAND_BETA * T ** 1.5 / (SUTHERLAND_R + T)
        out[_NU] = mu / rho
    return {k: v for k, v in out.items() if k in wanted}


class Atmosphere:
    """The standard atmosphere as a compiled part: reads ``position/h-sl-ft``,
    writes ``wanted`` (every name of ``FRAME_OUTPUTS`` unless told fewer)
    every frame and the sea-level values (``SEA_LEVEL``) at init. A plan
    holds no state: everything lives in ``props``."""

    inputs = frozenset({"position/h-sl-ft"})

    def __init__(self, wanted: Iterable[str] = FRAME_OUTPUTS) -> None:
        wanted = frozenset(wanted)
        unknown = sorted(wanted - set(FRAME_OUTPUTS))
        if unknown:
            raise ConfigError(f"the standard atmosphere does not compute {', '.join(unknown)}; "
                              f"it computes {', '.join(FRAME_OUTPUTS)}")
        self.wanted = wanted
        self.outputs = wanted | frozenset(SEA_LEVEL)

    def init(self, props: Props, n: int) -> None:
        """The sea-level values for ``n`` aircraft, and the atmosphere at
        ``position/h-sl-ft`` (at sea level, as JSBSim's InitModel, when the
        altitude is not in ``props`` yet)."""
        for name, value in SEA_LEVEL.items():
            props[name] = np.full(n, value)
        h = props.get("position/h-sl-ft")
        props.update(standard_atmosphere(np.zeros(n) if h is None else h, self.wanted))

    def run(self, props: Props, dt_s: float) -> None:
        """One frame: the atmosphere at each aircraft's ``position/h-sl-ft``."""
        props.update(standard_atmosphere(props["position/h-sl-ft"], self.wanted))


# --- the Earth (FGInertial, FGLocation) -------------------------------------
SEMIMAJOR_FT = kernels.SEMIMAJOR_FT
SEMIMINOR_FT = kernels.SEMIMINOR_FT
GM_FT3_S2 = kernels.GM_FT3_S2
J2 = kernels.J2
OMEGA_EARTH_RAD_S = kernels.OMEGA_EARTH_RAD_S
# FGLocation::SetEllipse
_EC = SEMIMINOR_FT / SEMIMAJOR_FT
_EC2 = _EC * _EC
_E2 = 1.0 - _EC2
_C = SEMIMAJOR_FT * _E2


class Geodetic(NamedTuple):
    """A position's geodetic coordinates, with the sines and cosines
    ``tec2l`` is built from."""

    lat_rad: np.ndarray
    lon_rad: np.ndarray
    alt_ft: np.ndarray   # above the ellipsoid
    sin_lat: np.ndarray
    cos_lat: np.ndarray


def _radius_latitude(x: np.ndarray, y: np.ndarray, z: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """FGLocation's radius and geocentric latitude."""
    xy2 = x * x + y * y
    return np.sqrt(xy2 + z * z), np.arctan2(z, np.sqrt(xy2))


def geocentric(x_ft: np.ndarray, y_ft: np.ndarray, z_ft: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radius (ft), geocentric latitude and longitude (rad) of ECEF positions."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x_ft, y_ft, z_ft))
    return (*_radius_latitude(x, y, z), np.arctan2(y, x))


def sea_level_radius_ft(lat_gc_rad: np.ndarray) -> np.ndarray:
    """The ellipsoid's radius at a geocentric latitude (``inertial/sea-level-radius_ft``)."""
    c = np.cos(lat_gc_rad)
    return SEMIMAJOR_FT * _EC / np.sqrt(1.0 - _E2 * c * c)


def _f64(*arrays: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(np.atleast_1d(np.asarray(v, dtype=np.float64)))
            for v in arrays]


def altitude_asl_ft(x_ft: np.ndarray, y_ft: np.ndarray, z_ft: np.ndarray) -> np.ndarray:
    """JSBSim's ``position/h-sl-ft``: the radius less the sea-level radius
    (``kernels.altitude_asl``)."""
    return kernels.altitude_asl_arrays(*_f64(x_ft, y_ft, z_ft))


def ecef_to_geodetic(x_ft: np.ndarray, y_ft: np.ndarray, z_ft: np.ndarray) -> Geodetic:
    """Geodetic latitude, longitude and height above the ellipsoid of ECEF
    positions (ft), by FGLocation's one Fukushima-Halley iteration
    (``kernels.geodetic``)."""
    x, y, z = _f64(x_ft, y_ft, z_ft)
    tan_lat, sin_lat, cos_lat, alt, _ = kernels.geodetic_arrays(x, y, z)
    return Geodetic(np.arctan(tan_lat), np.arctan2(y, x), alt, sin_lat, cos_lat)


def geodetic_to_ecef(lon_rad: np.ndarray, lat_rad: np.ndarray, alt_ft: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF positions (ft) of geodetic longitudes, latitudes and heights above
    the ellipsoid (FGLocation::SetPositionGeodetic)."""
    slat = np.sin(lat_rad)
    clat = np.cos(lat_rad)
    rn = SEMIMAJOR_FT / np.sqrt(1.0 - _E2 * slat * slat)
    rh = (rn + alt_ft) * clat
    return rh * np.cos(lon_rad), rh * np.sin(lon_rad), ((1 - _E2) * rn + alt_ft) * slat


def tec2l(x_ft: np.ndarray, y_ft: np.ndarray, z_ft: np.ndarray,
          geodetic: Geodetic | None = None) -> np.ndarray:
    """The rotation from ECEF to local North-East-Down at each position
    (FGLocation::GetTec2l), shape (3, 3, n): ``m[i, j]`` is row ``i``,
    column ``j`` for every aircraft, so ``np.einsum("ijn,jn->in", m, v)``
    turns ECEF vectors ``v`` (3, n) into NED ones. ``geodetic``: the
    positions' ``ecef_to_geodetic`` when already computed."""
    x, y, z = _f64(x_ft, y_ft, z_ft)
    g = ecef_to_geodetic(x, y, z) if geodetic is None else geodetic
    return kernels.tec2l_arrays(x, y, np.sqrt(x * x + y * y), *_f64(g.sin_lat, g.cos_lat))


def gravity_ecef(x_ft: np.ndarray, y_ft: np.ndarray, z_ft: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The WGS84 gravitation with J2 in ECEF (ft/s^2) at ECEF positions (ft):
    FGInertial::GetGravityJ2 (``kernels.gravity``)."""
    g = kernels.gravity_arrays(*_f64(x_ft, y_ft, z_ft))
    return g[0], g[1], g[2]
