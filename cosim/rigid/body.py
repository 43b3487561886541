"""The rigid body's equations of motion, as JSBSim 1.3 integrates them
(``FGPropagate``, ``FGAccelerations``, ``FGAuxiliary``), for every aircraft
of a batch at once.

The state is JSBSim's: the position and velocity in the Earth-centred
inertial frame (ft, ft/s), the attitude as the quaternion from that frame
to the body, and the body's inertial angular rates (rad/s); the Earth turns
under it at ``OMEGA_EARTH`` (the Earth position angle advances each frame).
Each frame (``propagate``):

- the attitude and the angular rates take one explicit Euler step; the
  position a third-order Adams-Bashforth step of the inertial velocity and
  the velocity a second-order one of its derivative (JSBSim's default
  integrators, with the past derivatives kept in the state);
- then the location on the rotating Earth, the local (north, east, down)
  and body matrices, the body velocity relative to the Earth ``u, v, w``,
  the rates relative to the Earth ``p, q, r`` and the Euler angles.

``accelerations`` computes the derivatives from the total force and moment
(``FGAccelerations``):

    pqri' = J^-1 (M - pqri x (J pqri))
    uvw'  = F/m - (pqr + 2 Ti2b w_e) x uvw - Ti2b (w_e x (w_e x r_i)) + Tec2b g
    v_i'  = Tb2i F/m + Tec2i g

with ``g`` the WGS84 gravity with J2 at the aircraft's position.
``auxiliary`` derives what the aerodynamics and the autopilot read
(``FGAuxiliary``, no wind): the true airspeed, angle of attack and
sideslip and their rates, dynamic pressure, Mach number, calibrated and
equivalent airspeeds, Euler rates, flight-path angle and load factors.
"""

from __future__ import annotations

import numpy as np

from cosim.rigid import atmosphere as geo
from cosim.rigid.linalg import (
    Mat,
    Quat,
    Vec,
    add,
    cross,
    euler,
    mm,
    mtv,
    mv,
    quat_dot,
    quat_from_euler,
    quat_from_matrix,
    quat_mul,
    quat_t,
    scale,
    sub,
    transpose,
)
from cosim.rigid.units import KTSTOFPS

Props = dict[str, np.ndarray]

OMEGA_EARTH = geo.OMEGA_EARTH_RAD_S
#: FGAtmosphere's standard sea-level pressure (psf) and FGJSBBase's gamma
_SHRATIO = 1.4
_RADTODEG = 57.295779513082320876798154814105

_Q = ("_eom/q0", "_eom/q1", "_eom/q2", "_eom/q3")
_QD = ("_eom/qd0", "_eom/qd1", "_eom/qd2", "_eom/qd3")
_W = ("_eom/pi", "_eom/qi", "_eom/ri")
_R = ("_eom/rx", "_eom/ry", "_eom/rz")
_V = ("_eom/vx", "_eom/vy", "_eom/vz")
_V1 = ("_eom/v1x", "_eom/v1y", "_eom/v1z")  # the inertial velocity a frame ago
_V2 = ("_eom/v2x", "_eom/v2y", "_eom/v2z")  # two frames ago
_ECEF = ("_eom/ex", "_eom/ey", "_eom/ez")  # the Earth-fixed position (ft)
_A1 = ("_eom/a1x", "_eom/a1y", "_eom/a1z")  # the inertial acceleration a frame ago
_WD = ("accelerations/pidot-rad_sec2", "accelerations/qidot-rad_sec2",
       "accelerations/ridot-rad_sec2")
_AI = ("accelerations/uidot-ft_sec2", "accelerations/vidot-ft_sec2",
       "accelerations/widot-ft_sec2")
_UVWDOT = ("accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2",
           "accelerations/wdot-ft_sec2")
_UVW = ("velocities/u-fps", "velocities/v-fps", "velocities/w-fps")
_PQR = ("velocities/p-rad_sec", "velocities/q-rad_sec", "velocities/r-rad_sec")
_NED = ("velocities/v-north-fps", "velocities/v-east-fps", "velocities/v-down-fps")
_EULER = ("attitude/phi-rad", "attitude/theta-rad", "attitude/psi-rad")


def _get(props: Props, keys: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    return tuple(props[k] for k in keys)


def _put(props: Props, keys: tuple[str, ...], values: tuple[np.ndarray, ...]) -> None:
    for k, v in zip(keys, values, strict=True):
        props[k] = v


def _ti2ec(epa: np.ndarray) -> Mat:
    c, s = np.cos(epa), np.sin(epa)
    z, o = np.zeros_like(epa), np.ones_like(epa)
    return (c, s, z, -s, c, z, z, z, o)


def _omega(n: int) -> Vec:
    z = np.zeros(n)
    return (z, z, np.full(n, OMEGA_EARTH))


def _tec2l(loc: Vec, g: geo.Geodetic | None = None) -> Mat:
    m = geo.tec2l(*loc, geodetic=g)
    return (m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])


def initial_state(props: Props, loc: Vec, phi: np.ndarray, theta: np.ndarray,
                  psi: np.ndarray, uvw: Vec, pqr: Vec) -> None:
    """FGPropagate::SetInitialState: the state from an Earth-fixed position
    (ECEF, ft), the Euler angles (rad), the body velocity relative to the
    Earth (ft/s) and the body rates relative to the Earth (rad/s); the Earth
    position angle 0."""
    n = len(phi)
    for k in (*_UVWDOT, *_WD, *_AI, "_eom/bax", "_eom/bay", "_eom/baz"):
        props.setdefault(k, np.zeros(n))  # FGAccelerations::InitModel
    epa = np.zeros(n)
    ti2ec = _ti2ec(epa)
    tec2i = transpose(ti2ec)
    r_i = mv(tec2i, loc)
    ti2l = mm(_tec2l(loc), ti2ec)
    q_local = quat_from_euler(phi, theta, psi)
    q = quat_mul(quat_from_matrix(ti2l), q_local)
    ti2b = quat_t(q)
    w_i = add(pqr, mv(ti2b, _omega(n)))
    v_i = add(mtv(ti2b, uvw), cross(_omega(n), r_i))
    props["_eom/epa"] = epa
    _put(props, _Q, q)
    _put(props, _W, w_i)
    _put(props, _R, r_i)
    _put(props, _V, v_i)
    _update(props, q, w_i, r_i, v_i, epa)


def initialize_derivatives(props: Props) -> None:
    """FGPropagate::InitializeDerivatives: every past derivative is the
    present one (done once the first derivatives are known)."""
    _put(props, _V1, _get(props, _V))
    _put(props, _V2, _get(props, _V))
    _put(props, _A1, _get(props, _AI))


def propagate(props: Props, dt: float) -> None:
    """FGPropagate::Run: integrate one frame, then derive the Earth-relative state."""
    q = _get(props, _Q)
    qd = _get(props, _QD)
    q = tuple(q[k] + dt * qd[k] for k in range(4))
    rn = 1.0 / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = (q[0] * rn, q[1] * rn, q[2] * rn, q[3] * rn)
    w = _get(props, _W)
    wd = _get(props, _WD)
    w = (w[0] + dt * wd[0], w[1] + dt * wd[1], w[2] + dt * wd[2])
    # position: Adams-Bashforth 3 on the inertial velocity (before its own update)
    r = _get(props, _R)
    v0, v1, v2 = _get(props, _V), _get(props, _V1), _get(props, _V2)
    c = (1 / 12.0) * dt
    r = tuple(r[k] + c * (23.0 * v0[k] - 16.0 * v1[k] + 5.0 * v2[k]) for k in range(3))
    # velocity: Adams-Bashforth 2 on the inertial acceleration
    a0, a1 = _get(props, _AI), _get(props, _A1)
    v = tuple(v0[k] + dt * (1.5 * a0[k] - 0.5 * a1[k]) for k in range(3))
    _put(props, _V2, v1)
    _put(props, _V1, v0)
    _put(props, _A1, a0)
    epa = props["_eom/epa"] + OMEGA_EARTH * dt
    props["_eom/epa"] = epa
    _put(props, _Q, q)
    _put(props, _W, w)
    _put(props, _R, r)
    _put(props, _V, v)
    _update(props, q, w, r, v, epa)  # type: ignore[arg-type]


def _update(props: Props, q: Quat, w_i: Vec, r_i: Vec, v_i: Vec, epa: np.ndarray) -> None:
    """The derived state after a step: location, matrices, uvw, pqr, Euler."""
    n = len(epa)
    ti2ec = _ti2ec(epa)
    tec2i = transpose(ti2ec)
    loc = mv(ti2ec, r_i)
    g = geo.ecef_to_geodetic(*loc)
    lat, lon = g.lat_rad, g.lon_rad
    h = geo.altitude_asl_ft(*loc)
    ti2l = mm(_tec2l(loc, g), ti2ec)
    ti2b = quat_t(q)
    tl2b = mm(ti2b, transpose(ti2l))
    tec2b = mm(ti2b, tec2i)
    om = _omega(n)
    uvw = mv(ti2b, sub(v_i, cross(om, r_i)))
    pqr = sub(w_i, mv(ti2b, om))
    _put(props, _QD, quat_dot(q, w_i))
    _put(props, _UVW, uvw)
    _put(props, _PQR, pqr)
    vel = mtv(tl2b, uvw)
    _put(props, _NED, vel)
    props["velocities/h-dot-fps"] = -vel[2]
    phi, theta, psi = euler(tl2b)
    _put(props, _EULER, (phi, theta, psi))
    props["attitude/phi-deg"] = phi * _RADTODEG
    props["attitude/theta-deg"] = theta * _RADTODEG
    props["attitude/psi-deg"] = psi * _RADTODEG
    props["position/lat-geod-rad"] = lat
    props["position/lat-geod-deg"] = lat * _RADTODEG
    props["position/long-gc-rad"] = lon
    props["position/long-gc-deg"] = lon * _RADTODEG
    props["position/h-sl-ft"] = h
    props["position/h-agl-ft"] = g.alt_ft - props["position/terrain-elevation-asl-ft"]
    _put(props, _ECEF, loc)
    for i, k in enumerate(("t11", "t12", "t13", "t21", "t22", "t23", "t31", "t32", "t33")):
        props["_eom/tl2b_" + k] = tl2b[i]
        props["_eom/ti2b_" + k] = ti2b[i]
        props["_eom/tec2b_" + k] = tec2b[i]


def _mat(props: Props, name: str) -> Mat:
    return tuple(props[f"_eom/{name}_t{r}{c}"] for r in "123" for c in "123")  # type: ignore


def accelerations(props: Props, force: Vec, moment: Vec) -> None:
    """FGAccelerations::Run in the air (no ground friction): the body's
    angular and linear accelerations from the total force (lbs) and moment
    (lbs ft) about the centre of gravity."""
    n = len(props["_n"])
    m = props["inertia/mass-slugs"]
    ixx, iyy, izz = (props["inertia/ixx-slugs_ft2"], props["inertia/iyy-slugs_ft2"],
                     props["inertia/izz-slugs_ft2"])
    ixy, ixz, iyz = (props["inertia/ixy-slugs_ft2"], props["inertia/ixz-slugs_ft2"],
                     props["inertia/iyz-slugs_ft2"])
    j: Mat = (ixx, -ixy, -ixz, -ixy, iyy, -iyz, -ixz, -iyz, izz)
    k = [props["_mb/jinv" + s] for s in ("11", "12", "13", "22", "23", "33")]
    jinv: Mat = (k[0], k[1], k[2], k[1], k[3], k[4], k[2], k[4], k[5])
    w_i = _get(props, _W)
    ti2b = _mat(props, "ti2b")
    tec2b = _mat(props, "tec2b")
    om = _omega(n)
    wdot_i = mv(jinv, sub(moment, cross(w_i, mv(j, w_i))))  # type: ignore[arg-type]
    om_b = mv(ti2b, om)
    pqr = _get(props, _PQR)
    uvw = _get(props, _UVW)
    r_i = _get(props, _R)
    g = geo.gravity_ecef(*_get(props, _ECEF))
    accel = scale(1.0 / m, force)
    uvwdot = sub(accel, cross(add(pqr, scale(2.0, om_b)), uvw))  # type: ignore[arg-type]
    uvwdot = sub(uvwdot, mv(ti2b, cross(om, cross(om, r_i))))  # type: ignore[arg-type]
    uvwdot = add(uvwdot, mv(tec2b, g))
    tb2i = transpose(ti2b)
    tec2i = transpose(_ti2ec(props["_eom/epa"]))
    ai = add(mv(tb2i, accel), mv(tec2i, g))
    _put(props, _WD, wdot_i)
    props["accelerations/pdot-rad_sec2"], props["accelerations/qdot-rad_sec2"], \
        props["accelerations/rdot-rad_sec2"] = add(wdot_i, cross(w_i, om_b))  # type: ignore
    _put(props, _UVWDOT, uvwdot)
    _put(props, _AI, ai)
    _put(props, ("_eom/bax", "_eom/bay", "_eom/baz"), accel)
    props["accelerations/gravity-ft_sec2"] = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])


def auxiliary(props: Props) -> None:
    """FGAuxiliary::Run without wind: airspeeds, angles and their rates,
    dynamic pressure, Mach number (it reads the previous frame's accelerations,
    as JSBSim does)."""
    p, q, r = _get(props, _PQR)
    phi, tht = props["attitude/phi-rad"], props["attitude/theta-rad"]
    cphi, sphi, ctht, stht = np.cos(phi), np.sin(phi), np.cos(tht), np.sin(tht)
    props["velocities/thetadot-rad_sec"] = q * cphi - r * sphi
    with np.errstate(divide="ignore", invalid="ignore"):
        psidot = np.where(ctht != 0.0, (q * sphi + r * cphi) / ctht, 0.0)
    props["velocities/psidot-rad_sec"] = psidot
    props["velocities/phidot-rad_sec"] = np.where(ctht != 0.0, p + psidot * stht, 0.0)
    props["velocities/p-aero-rad_sec"], props["velocities/q-aero-rad_sec"] = p, q
    props["velocities/r-aero-rad_sec"] = r
    u, v, w = _get(props, _UVW)
    props["velocities/u-aero-fps"], props["velocities/v-aero-fps"] = u, v
    props["velocities/w-aero-fps"] = w
    ud, vd, wd = _get(props, _UVWDOT)
    u2, v2, w2 = u * u, v * v, w * w
    muw = u2 + w2
    vt2 = muw + v2
    vt = np.sqrt(vt2)
    moving = vt > 0.001
    uw = moving & (muw >= 1e-6)
    smuw = np.sqrt(muw)
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = np.where(moving, np.arctan2(v, smuw), 0.0)
        alpha = np.where(uw, np.arctan2(w, u), 0.0)
        vtdot = (u * ud + v * vd + w * wd) / vt
        adot = np.where(uw, (u * wd - w * ud) / muw, 0.0)
        bdot = np.where(uw, (vd * vt - v * vtdot) / (vt * smuw), 0.0)
    props["velocities/vt-fps"] = vt
    props["velocities/vtrue-kts"] = vt / KTSTOFPS
    props["aero/alpha-rad"], props["aero/beta-rad"] = alpha, beta
    props["aero/alpha-deg"], props["aero/beta-deg"] = alpha * _RADTODEG, beta * _RADTODEG
    props["aero/mag-beta-rad"] = np.abs(beta)
    props["aero/alphadot-rad_sec"], props["aero/betadot-rad_sec"] = adot, bdot
    props["aero/alphadot-deg_sec"] = adot * _RADTODEG
    rho = props["atmosphere/rho-slugs_ft3"]
    a = props["atmosphere/a-fps"]
    pres = props["atmosphere/P-psf"]
    props["aero/qbar-psf"] = 0.5 * rho * vt2
    props["aero/qbarUW-psf"] = 0.5 * rho * muw
    props["aero/qbarUV-psf"] = 0.5 * rho * (u2 + v2)
    mach = vt / a
    props["velocities/mach"] = mach
    props["velocities/machU"] = u / a
    vn, ve, vdn = _get(props, _NED)
    vg = np.sqrt(vn * vn + ve * ve)
    props["velocities/vg-fps"] = vg
    gt = np.arctan2(ve, vn)
    props["flight-path/psi-gt-rad"] = np.where(gt < 0.0, gt + 2.0 * np.pi, gt)
    gamma = np.arctan2(-vdn, vg)
    props["flight-path/gamma-rad"] = gamma
    props["flight-path/gamma-deg"] = gamma * _RADTODEG
    vcas = vcas_from_mach(mach, pres)
    props["velocities/vc-fps"] = vcas
    props["velocities/vc-kts"] = vcas / KTSTOFPS
    veas = np.sqrt(2.0 * props["aero/qbar-psf"] / props["atmosphere/rho-sl-slugs_ft3"])
    props["velocities/ve-fps"] = veas
    props["velocities/ve-kts"] = veas / KTSTOFPS
    ba = _get(props, ("_eom/bax", "_eom/bay", "_eom/baz"))
    g0 = geo.G0_FT_S2
    props["accelerations/Nx"] = ba[0] / g0
    props["accelerations/Ny"] = ba[1] / g0
    props["accelerations/Nz"] = -ba[2] / g0


def _pitot_total(mach: np.ndarray, pres: np.ndarray | float) -> np.ndarray:
    """FGAuxiliary::PitotTotalPressure (isentropic below Mach 1, Rayleigh above)."""
    g = _SHRATIO
    a, b = (g - 1.0) / 2.0, g / (g - 1.0)
    c, d = 2.0 * b, 1.0 / (g - 1.0)
    coeff = (0.5 * (g + 1.0)) ** b * ((g + 1.0) / (g - 1.0)) ** d
    m = np.maximum(mach, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sup = pres * coeff * m ** c / (c * m * m - 1.0) ** d
    return np.where(mach < 0, pres, np.where(mach < 1, pres * (1.0 + a * m * m) ** b, sup))


def _mach_from_impact(qc: np.ndarray, pres: float) -> np.ndarray:
    """FGAuxiliary::MachFromImpactPressure (ten fixed-point steps above Mach 1)."""
    g = _SHRATIO
    a, b = 2.0 / (g - 1.0), (g - 1.0) / g
    c, d = 2.0 / b, 0.5 * a
    coeff = (0.5 * (g + 1.0)) ** (-0.25 * c) * (0.5 * (g + 1.0) / g) ** (-0.5 * d)
    big_a = qc / pres + 1
    m = np.sqrt(a * (big_a ** b - 1.0))
    sup = m > 1.0
    if np.any(sup):
        ms = m[sup]
        for _ in range(10):
            ms = coeff * np.sqrt(big_a[sup] * (1 - 1.0 / (c * ms * ms)) ** d)
        m = m.copy()
        m[sup] = ms
    return m


def vcas_from_mach(mach: np.ndarray, pres: np.ndarray) -> np.ndarray:
    """The calibrated airspeed (ft/s), FGAuxiliary::VcalibratedFromMach; 0 at rest."""
    qc = _pitot_total(mach, pres) - pres
    return np.where(np.abs(mach) > 0.0,
                    geo.SL_SOUNDSPEED_FPS * _mach_from_impact(qc, geo.SL_PRESSURE_PSF), 0.0)


__all__ = ["accelerations", "auxiliary", "initial_state", "initialize_derivatives",
           "propagate"]
