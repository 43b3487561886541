"""The rigid body's per-aircraft arithmetic compiled with numba: the Earth's
geometry and gravity (``FGLocation``, ``FGInertial``), the integration and
the derived state (``FGPropagate``), the accelerations (``FGAccelerations``)
and the auxiliary values (``FGAuxiliary``), each a loop over the aircraft
doing one aircraft's whole computation at a time, so the hundreds of small
operations of a frame make one pass over memory instead of one numpy call
each. ``cosim.rigid.body`` holds the equations' description and calls these;
``cosim.rigid.atmosphere``'s array functions of the Earth are loops over the
same scalar functions, so there is one implementation of each formula.

Every function here computes what the numpy form computed, operation for
operation (JSBSim's order), in float64, without fast-math: the results are
the same on every machine that runs the same numba and libm, whatever the
batch size or the split into workers (an aircraft's arithmetic never
depends on another's).
"""

from __future__ import annotations

import math

import numba
import numpy as np

# the Earth (FGInertial, FGLocation::SetEllipse)
SEMIMAJOR_FT = 20925646.32546
SEMIMINOR_FT = 20855486.5951
GM_FT3_S2 = 14.0764417572e15
J2 = 1.08262982e-03
OMEGA_EARTH_RAD_S = 0.00007292115
EC = SEMIMINOR_FT / SEMIMAJOR_FT
EC2 = EC * EC
E2 = 1.0 - EC2
C_ELL = SEMIMAJOR_FT * E2
_RADTODEG = 57.295779513082320876798154814105
_TWO_PI = 2.0 * math.pi

jit = numba.njit(cache=True, error_model="numpy", nogil=True)
#: some properties' arrays, one a row, as a tuple (a kernel reads them where
#: they are: no copy into a block)
Rows = tuple[np.ndarray, ...]


# ------------------------------------------------------------ the Earth --

@jit
def altitude_asl(x: float, y: float, z: float) -> float:
    """JSBSim's ``position/h-sl-ft``: the radius less the sea-level radius
    ``a (b/a) / sqrt(1 - e^2 cos^2 lat_gc)``, with ``cos lat_gc = rxy / r``."""
    rxy2 = x * x + y * y
    r = math.sqrt(rxy2 + z * z)
    c2 = rxy2 / (r * r)
    return r - SEMIMAJOR_FT * EC / math.sqrt(1.0 - E2 * c2)


@jit
def geodetic(x: float, y: float, z: float) -> tuple[float, float, float, float, float]:
    """FGLocation's one Fukushima-Halley step, without a trigonometric call:
    ``tan`` of the geodetic latitude (``sign s1 / cc``; infinite at a pole),
    its sine and cosine, the height above the ellipsoid and ``rxy``."""
    rxy = math.sqrt(x * x + y * y)
    sign = 1.0 if z >= 0.0 else -1.0
    s0 = abs(z)
    zc = EC * s0
    c0 = EC * rxy
    c02 = c0 * c0
    s02 = s0 * s0
    a02 = c02 + s02
    a0 = math.sqrt(a02)
    a03 = a02 * a0
    s1 = zc * a03 + C_ELL * s02 * s0
    c1 = rxy * a03 - C_ELL * c02 * c0
    cs0c0 = C_ELL * c0 * s0
    b0 = 1.5 * cs0c0 * ((rxy * s0 - zc * c0) * a0 - cs0c0)
    s1 = s1 * a03 - b0 * s0
    cc = EC * (c1 * a03 - b0 * c0)
    s12 = s1 * s1
    cc2 = cc * cc
    norm = math.sqrt(s12 + cc2)
    alt = (rxy * cc + s0 * s1 - SEMIMAJOR_FT * math.sqrt(EC2 * s12 + cc2)) / norm
    return sign * (s1 / cc), sign * s1 / norm, cc / norm, alt, rxy


@jit
def tec2l(x: float, y: float, rxy: float, sin_lat: float, cos_lat: float
          ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """FGLocation::GetTec2l, row-major: ECEF to local north-east-down."""
    if rxy == 0.0:
        sin_lon, cos_lon = 0.0, 1.0
    else:
        sin_lon, cos_lon = y / rxy, x / rxy
    return (-cos_lon * sin_lat, -sin_lon * sin_lat, cos_lat,
            -sin_lon, cos_lon, 0.0,
            -cos_lon * cos_lat, -sin_lon * cos_lat, -sin_lat)


@jit
def gravity(x: float, y: float, z: float) -> tuple[float, float, float]:
    """FGInertial::GetGravityJ2 (ECEF, ft/s^2), with ``sin lat_gc = z / r``."""
    r = math.sqrt(x * x + y * y + z * z)
    s = z / r
    s2 = s * s
    adivr = SEMIMAJOR_FT / r
    pre = 1.5 * J2 * adivr * adivr
    g_r2 = -GM_FT3_S2 / (r * r)
    xy = 1.0 + pre * (1.0 - 5.0 * s2)
    return g_r2 * (xy * x / r), g_r2 * (xy * y / r), g_r2 * ((1.0 + pre * (3.0 - 5.0 * s2)) * z / r)


@jit
def geodetic_arrays(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``geodetic`` for arrays: rows tan lat, sin lat, cos lat, alt, rxy."""
    out = np.empty((5, len(x)))
    for i in range(len(x)):
        out[0, i], out[1, i], out[2, i], out[3, i], out[4, i] = geodetic(x[i], y[i], z[i])
    return out


@jit
def altitude_asl_arrays(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    out = np.empty(len(x))
    for i in range(len(x)):
        out[i] = altitude_asl(x[i], y[i], z[i])
    return out


@jit
def gravity_arrays(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    out = np.empty((3, len(x)))
    for i in range(len(x)):
        out[0, i], out[1, i], out[2, i] = gravity(x[i], y[i], z[i])
    return out


@jit
def tec2l_arrays(x: np.ndarray, y: np.ndarray, rxy: np.ndarray, sin_lat: np.ndarray,
                 cos_lat: np.ndarray) -> np.ndarray:
    out = np.empty((3, 3, len(x)))
    for i in range(len(x)):
        m = tec2l(x[i], y[i], rxy[i], sin_lat[i], cos_lat[i])
        for k in range(9):
            out[k // 3, k % 3, i] = m[k]
    return out


# ------------------------------------------------------------- the body --

#: the rows of the derived-state block ``derive`` fills; the angles that
#: need a trigonometric call are made from them by ``body`` with numpy's
#: vectorised functions (several times faster than one C call an aircraft)
DERIVED = ("velocities/u-fps", "velocities/v-fps", "velocities/w-fps",
           "velocities/p-rad_sec", "velocities/q-rad_sec", "velocities/r-rad_sec",
           "velocities/v-north-fps", "velocities/v-east-fps", "velocities/v-down-fps",
           "velocities/h-dot-fps", "_eom/tanlat", "position/h-sl-ft", "position/h-agl-ft",
           "_eom/qd0", "_eom/qd1", "_eom/qd2", "_eom/qd3", "_eom/ex", "_eom/ey", "_eom/ez",
           *(f"_eom/tl2b_t{r}{c}" for r in "123" for c in "123"), "_eom/ce", "_eom/se")


@jit
def ti2b(q0: float, q1: float, q2: float, q3: float
         ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """The body's matrix from the inertial frame (row-major) of the attitude
    quaternion, normalised first (FGQuaternion::GetT)."""
    rn = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    a0, a1, a2, a3 = rn * q0, rn * q1, rn * q2, rn * q3
    a00, a11, a22, a33 = a0 * a0, a1 * a1, a2 * a2, a3 * a3
    a01, a02, a03 = a0 * a1, a0 * a2, a0 * a3
    a12, a13, a23 = a1 * a2, a1 * a3, a2 * a3
    return (a00 + a11 - a22 - a33, 2.0 * (a12 + a03), 2.0 * (a13 - a02),
            2.0 * (a12 - a03), a00 - a11 + a22 - a33, 2.0 * (a23 + a01),
            2.0 * (a13 + a02), 2.0 * (a23 - a01), a00 - a11 - a22 + a33)


@jit
def ti2b_arrays(q: np.ndarray) -> np.ndarray:
    """``ti2b`` for a (4, n) block of quaternions: its nine rows."""
    out = np.empty((9, q.shape[1]))
    for i in range(q.shape[1]):
        b = ti2b(q[0, i], q[1, i], q[2, i], q[3, i])
        for k in range(9):
            out[k, i] = b[k]
    return out


@jit
def _derive(out: np.ndarray, i: int, q0: float, q1: float, q2: float, q3: float,
            wi0: float, wi1: float, wi2: float, rx: float, ry: float, rz: float,
            vx: float, vy: float, vz: float, ce: float, se: float, terrain: float) -> None:
    """FGPropagate after the integration, for aircraft ``i``: location,
    matrices, uvw, pqr, quaternion rate (into ``out[:, i]``); ``ce``, ``se``:
    the cosine and sine of the Earth position angle."""
    # Ti2ec = [[ce, se, 0], [-se, ce, 0], [0, 0, 1]]
    lx, ly, lz = ce * rx + se * ry, -se * rx + ce * ry, rz
    tanlat, slat, clat, galt, rxy = geodetic(lx, ly, lz)
    e = tec2l(lx, ly, rxy, slat, clat)
    # Ti2l = Tec2l Ti2ec
    il = (e[0] * ce - e[1] * se, e[0] * se + e[1] * ce, e[2],
          e[3] * ce - e[4] * se, e[3] * se + e[4] * ce, e[5],
          e[6] * ce - e[7] * se, e[6] * se + e[7] * ce, e[8])
    b = ti2b(q0, q1, q2, q3)
    # Tl2b = Ti2b Ti2l^T
    t = (b[0] * il[0] + b[1] * il[1] + b[2] * il[2], b[0] * il[3] + b[1] * il[4] + b[2] * il[5],
         b[0] * il[6] + b[1] * il[7] + b[2] * il[8],
         b[3] * il[0] + b[4] * il[1] + b[5] * il[2], b[3] * il[3] + b[4] * il[4] + b[5] * il[5],
         b[3] * il[6] + b[4] * il[7] + b[5] * il[8],
         b[6] * il[0] + b[7] * il[1] + b[8] * il[2], b[6] * il[3] + b[7] * il[4] + b[8] * il[5],
         b[6] * il[6] + b[7] * il[7] + b[8] * il[8])
    om = OMEGA_EARTH_RAD_S
    # uvw = Ti2b (v_i - w_e x r_i), w_e x r = (-om ry, om rx, 0); pqr = w_i - Ti2b w_e
    dx, dy, dz = vx + om * ry, vy - om * rx, vz
    u = b[0] * dx + b[1] * dy + b[2] * dz
    v = b[3] * dx + b[4] * dy + b[5] * dz
    w = b[6] * dx + b[7] * dy + b[8] * dz
    out[0, i], out[1, i], out[2, i] = u, v, w
    out[3, i], out[4, i], out[5, i] = wi0 - b[2] * om, wi1 - b[5] * om, wi2 - b[8] * om
    vn = t[0] * u + t[3] * v + t[6] * w
    ve = t[1] * u + t[4] * v + t[7] * w
    vd = t[2] * u + t[5] * v + t[8] * w
    out[6, i], out[7, i], out[8, i], out[9, i] = vn, ve, vd, -vd
    out[10, i] = tanlat
    out[11, i] = altitude_asl(lx, ly, lz)
    out[12, i] = galt - terrain
    # the quaternion's rate for the inertial body rates (FGQuaternion::GetQDot)
    out[13, i] = -0.5 * (q1 * wi0 + q2 * wi1 + q3 * wi2)
    out[14, i] = 0.5 * (q0 * wi0 - q3 * wi1 + q2 * wi2)
    out[15, i] = 0.5 * (q3 * wi0 + q0 * wi1 - q1 * wi2)
    out[16, i] = 0.5 * (-q2 * wi0 + q1 * wi1 + q0 * wi2)
    out[17, i], out[18, i], out[19, i] = lx, ly, lz
    for k in range(9):
        out[20 + k, i] = t[k]
    out[29, i], out[30, i] = ce, se


@jit
def derive(q: np.ndarray, wi: np.ndarray, ri: np.ndarray, vi: np.ndarray, ce: np.ndarray,
           se: np.ndarray, terrain: np.ndarray, out: np.ndarray) -> None:
    """The derived state (into ``out``'s rows ``DERIVED``) of states given as
    (k, n) blocks."""
    n = len(ce)
    for i in range(n):
        _derive(out, i, q[0, i], q[1, i], q[2, i], q[3, i], wi[0, i], wi[1, i], wi[2, i],
                ri[0, i], ri[1, i], ri[2, i], vi[0, i], vi[1, i], vi[2, i], ce[i], se[i],
                terrain[i])


#: the rows of the integrated-state block ``propagate`` returns
STATE = ("_eom/q0", "_eom/q1", "_eom/q2", "_eom/q3", "_eom/pi", "_eom/qi", "_eom/ri",
         "_eom/rx", "_eom/ry", "_eom/rz", "_eom/vx", "_eom/vy", "_eom/vz",
         "_eom/v1x", "_eom/v1y", "_eom/v1z", "_eom/v2x", "_eom/v2y", "_eom/v2z",
         "_eom/a1x", "_eom/a1y", "_eom/a1z")


@jit
def propagate(dt: float, st: np.ndarray, qd: np.ndarray, wd: np.ndarray, ai: np.ndarray,
              epa: np.ndarray, terrain: np.ndarray, new: np.ndarray, der: np.ndarray) -> None:
    """One frame of FGPropagate::Run: the attitude and the inertial rates an
    Euler step, the position an Adams-Bashforth-3 step of the inertial
    velocity (before its own update), the velocity an Adams-Bashforth-2 step
    of the inertial acceleration; then ``_derive`` at the Earth's new angle
    ``epa`` (its cosine and sine libm's, as numpy 2's). ``st``: the rows
    ``STATE``; the new ``STATE`` into ``new``, which may be ``st`` itself
    (an aircraft's state is read before it is written), and ``DERIVED``
    into ``der`` (which may share no memory with an input)."""
    n = st.shape[1]
    c = (1 / 12.0) * dt
    for i in range(n):
        q0 = st[0, i] + dt * qd[0, i]
        q1 = st[1, i] + dt * qd[1, i]
        q2 = st[2, i] + dt * qd[2, i]
        q3 = st[3, i] + dt * qd[3, i]
        rn = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0, q1, q2, q3 = q0 * rn, q1 * rn, q2 * rn, q3 * rn
        w0 = st[4, i] + dt * wd[0, i]
        w1 = st[5, i] + dt * wd[1, i]
        w2 = st[6, i] + dt * wd[2, i]
        for k in range(3):
            v0, v1 = st[10 + k, i], st[13 + k, i]
            new[7 + k, i] = st[7 + k, i] + c * (23.0 * v0 - 16.0 * v1 + 5.0 * st[16 + k, i])
            new[10 + k, i] = v0 + dt * (1.5 * ai[k, i] - 0.5 * st[19 + k, i])
            new[16 + k, i] = v1
            new[13 + k, i] = v0
            new[19 + k, i] = ai[k, i]
        new[0, i], new[1, i], new[2, i], new[3, i] = q0, q1, q2, q3
        new[4, i], new[5, i], new[6, i] = w0, w1, w2
        _derive(der, i, q0, q1, q2, q3, w0, w1, w2, new[7, i], new[8, i], new[9, i],
                new[10, i], new[11, i], new[12, i], math.cos(epa[i]), math.sin(epa[i]),
                terrain[i])


#: the rows ``accelerations`` returns
ACCELERATIONS = ("accelerations/pidot-rad_sec2", "accelerations/qidot-rad_sec2",
                 "accelerations/ridot-rad_sec2", "accelerations/pdot-rad_sec2",
                 "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2",
                 "accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2",
                 "accelerations/wdot-ft_sec2", "accelerations/uidot-ft_sec2",
                 "accelerations/vidot-ft_sec2", "accelerations/widot-ft_sec2",
                 "_eom/bax", "_eom/bay", "_eom/baz", "accelerations/gravity-ft_sec2",
                 "forces/fbx-total-lbs", "forces/fby-total-lbs", "forces/fbz-total-lbs")


@jit
def accelerations(mass: np.ndarray, inertia: Rows, jinv: Rows, wi: Rows, q: Rows,
                  ce: np.ndarray, se: np.ndarray, pqr: Rows, uvw: Rows, ri: Rows,
                  ecef: Rows, loads: Rows, out: np.ndarray) -> None:
    """FGAccelerations::Run in the air for every aircraft (rows
    ``ACCELERATIONS``). ``inertia``: rows Ixx, Iyy, Izz, Ixy, Ixz, Iyz (the
    products as JSBSim's properties give them); ``jinv``: rows 11, 12, 13,
    22, 23, 33 of the inverse; the total force (lbs) and moment (lbs ft) are
    the aerodynamics' plus the propulsion's (``loads``: their forces x, y,
    z, then their moments l, m, n), the force kept in the last three rows; ``q``: the attitude
    quaternion's rows (the body's matrices are made from it and the Earth's
    angle ``ce``, ``se`` again here, the same arithmetic as ``_derive``'s,
    rather than kept as eighteen rows a frame writes and reads back)."""
    n = len(mass)
    om = OMEGA_EARTH_RAD_S
    for i in range(n):
        ixx, iyy, izz = inertia[0][i], inertia[1][i], inertia[2][i]
        ixy, ixz, iyz = inertia[3][i], inertia[4][i], inertia[5][i]
        j = (ixx, -ixy, -ixz, -ixy, iyy, -iyz, -ixz, -iyz, izz)
        k11, k12, k13 = jinv[0][i], jinv[1][i], jinv[2][i]
        k22, k23, k33 = jinv[3][i], jinv[4][i], jinv[5][i]
        w0, w1, w2 = wi[0][i], wi[1][i], wi[2][i]
        jw0 = j[0] * w0 + j[1] * w1 + j[2] * w2
        jw1 = j[3] * w0 + j[4] * w1 + j[5] * w2
        jw2 = j[6] * w0 + j[7] * w1 + j[8] * w2
        fx = loads[0][i] + loads[3][i]
        fy = loads[1][i] + loads[4][i]
        fz = loads[2][i] + loads[5][i]
        out[16, i], out[17, i], out[18, i] = fx, fy, fz
        m0 = (loads[6][i] + loads[9][i]) - (w1 * jw2 - w2 * jw1)
        m1 = (loads[7][i] + loads[10][i]) - (w2 * jw0 - w0 * jw2)
        m2 = (loads[8][i] + loads[11][i]) - (w0 * jw1 - w1 * jw0)
        d0 = k11 * m0 + k12 * m1 + k13 * m2
        d1 = k12 * m0 + k22 * m1 + k23 * m2
        d2 = k13 * m0 + k23 * m1 + k33 * m2
        b = ti2b(q[0][i], q[1][i], q[2][i], q[3][i])
        # the Earth's rate in the body: Ti2b (0, 0, om)
        ob0 = b[0] * 0.0 + b[1] * 0.0 + b[2] * om
        ob1 = b[3] * 0.0 + b[4] * 0.0 + b[5] * om
        ob2 = b[6] * 0.0 + b[7] * 0.0 + b[8] * om
        out[0, i], out[1, i], out[2, i] = d0, d1, d2
        out[3, i] = d0 + (w1 * ob2 - w2 * ob1)
        out[4, i] = d1 + (w2 * ob0 - w0 * ob2)
        out[5, i] = d2 + (w0 * ob1 - w1 * ob0)
        gx, gy, gz = gravity(ecef[0][i], ecef[1][i], ecef[2][i])
        inv_m = 1.0 / mass[i]
        ax, ay, az = inv_m * fx, inv_m * fy, inv_m * fz
        c0, c1, c2 = pqr[0][i] + 2.0 * ob0, pqr[1][i] + 2.0 * ob1, pqr[2][i] + 2.0 * ob2
        u, v, w = uvw[0][i], uvw[1][i], uvw[2][i]
        ud = ax - (c1 * w - c2 * v)
        vd = ay - (c2 * u - c0 * w)
        wd = az - (c0 * v - c1 * u)
        # centripetal: w_e x (w_e x r_i) = (-om^2 rx, -om^2 ry, 0)
        rx, ry, rz = ri[0][i], ri[1][i], ri[2][i]
        cx, cy, cz = 0.0 * rz - om * ry, om * rx - 0.0 * rz, 0.0 * ry - 0.0 * rx
        i0 = 0.0 * cz - om * cy
        i1 = om * cx - 0.0 * cz
        i2 = 0.0 * cy - 0.0 * cx
        ud -= b[0] * i0 + b[1] * i1 + b[2] * i2
        vd -= b[3] * i0 + b[4] * i1 + b[5] * i2
        wd -= b[6] * i0 + b[7] * i1 + b[8] * i2
        # Tec2b = Ti2b Tec2i (Tec2i = Ti2ec^T = [[ce, -se, 0], [se, ce, 0], [0, 0, 1]])
        c, sn = ce[i], se[i]
        e = (b[0] * c + b[1] * sn, -b[0] * sn + b[1] * c, b[2],
             b[3] * c + b[4] * sn, -b[3] * sn + b[4] * c, b[5],
             b[6] * c + b[7] * sn, -b[6] * sn + b[7] * c, b[8])
        ud += e[0] * gx + e[1] * gy + e[2] * gz
        vd += e[3] * gx + e[4] * gy + e[5] * gz
        wd += e[6] * gx + e[7] * gy + e[8] * gz
        out[6, i], out[7, i], out[8, i] = ud, vd, wd
        # the inertial acceleration: Tb2i F/m + Tec2i g
        out[9, i] = (b[0] * ax + b[3] * ay + b[6] * az) + (ce[i] * gx + (-se[i]) * gy + 0.0 * gz)
        out[10, i] = (b[1] * ax + b[4] * ay + b[7] * az) + (se[i] * gx + ce[i] * gy + 0.0 * gz)
        out[11, i] = (b[2] * ax + b[5] * ay + b[8] * az) + (0.0 * gx + 0.0 * gy + 1.0 * gz)
        out[12, i], out[13, i], out[14, i] = ax, ay, az
        out[15, i] = math.sqrt(gx * gx + gy * gy + gz * gz)


_SHR = 1.4  # FGJSBBase::SHRatio


@jit
def _pitot_total(mach: float, pres: float) -> float:
    """FGAuxiliary::PitotTotalPressure (isentropic below Mach 1, Rayleigh above)."""
    a, b = (_SHR - 1.0) / 2.0, _SHR / (_SHR - 1.0)
    c, d = 2.0 * b, 1.0 / (_SHR - 1.0)
    if mach < 0:
        return pres
    if mach < 1:
        return pres * (1.0 + a * mach * mach) ** b
    coeff = (0.5 * (_SHR + 1.0)) ** b * ((_SHR + 1.0) / (_SHR - 1.0)) ** d
    return pres * coeff * mach ** c / (c * mach * mach - 1.0) ** d


@jit
def _mach_from_impact(qc: float, pres: float) -> float:
    """FGAuxiliary::MachFromImpactPressure (ten fixed-point steps above Mach 1)."""
    a, b = 2.0 / (_SHR - 1.0), (_SHR - 1.0) / _SHR
    c, d = 2.0 / b, 0.5 * a
    big_a = qc / pres + 1
    m = math.sqrt(a * (big_a ** b - 1.0))
    if m > 1.0:
        coeff = (0.5 * (_SHR + 1.0)) ** (-0.25 * c) * (0.5 * (_SHR + 1.0) / _SHR) ** (-0.5 * d)
        for _ in range(10):
            m = coeff * math.sqrt(big_a * (1 - 1.0 / (c * m * m)) ** d)
    return m


@jit
def vcas(mach: float, pres: float, sl_pres: float, sl_a: float) -> float:
    """FGAuxiliary::VcalibratedFromMach (ft/s); 0 at rest."""
    if not abs(mach) > 0.0:
        return 0.0
    return sl_a * _mach_from_impact(_pitot_total(mach, pres) - pres, sl_pres)


@jit
def vcas_arrays(mach: np.ndarray, pres: np.ndarray, sl_pres: float, sl_a: float) -> np.ndarray:
    out = np.empty(len(mach))
    for i in range(len(mach)):
        out[i] = vcas(mach[i], pres[i], sl_pres, sl_a)
    return out


@jit
def pitot_total_arrays(mach: np.ndarray, pres: np.ndarray) -> np.ndarray:
    """``_pitot_total`` for every aircraft (an engine's intake pressure)."""
    out = np.empty(len(mach))
    for i in range(len(mach)):
        out[i] = _pitot_total(mach[i], pres[i])
    return out


@jit
def atan2_arrays(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """libm's ``atan2`` for every aircraft (numpy's rounds differently in
    about one case in a hundred)."""
    out = np.empty(len(y))
    for i in range(len(y)):
        out[i] = math.atan2(y[i], x[i])
    return out


#: the rows ``auxiliary`` returns
AUXILIARY = ("velocities/thetadot-rad_sec", "velocities/psidot-rad_sec",
             "velocities/phidot-rad_sec", "velocities/vt-fps", "velocities/vtrue-kts",
             "aero/alpha-rad", "aero/beta-rad", "aero/alpha-deg", "aero/beta-deg",
             "aero/mag-beta-rad", "aero/alphadot-rad_sec", "aero/betadot-rad_sec",
             "aero/alphadot-deg_sec", "aero/qbar-psf", "aero/qbarUW-psf", "aero/qbarUV-psf",
             "velocities/mach", "velocities/machU", "velocities/vg-fps",
             "velocities/ve-fps", "velocities/ve-kts",
             "accelerations/Nx", "accelerations/Ny", "accelerations/Nz")


@jit
def auxiliary(pqr: Rows, phi: np.ndarray, theta: np.ndarray, uvw: Rows,
              alpha_uw: np.ndarray, beta_v: np.ndarray, uvwdot: Rows, rho: np.ndarray,
              a_snd: np.ndarray, ned: Rows, rho_sl: np.ndarray, body_accel: Rows, g0: float,
              ktstofps: float, out: np.ndarray) -> None:
    """FGAuxiliary::Run without wind for every aircraft (rows ``AUXILIARY``):
    it reads the previous frame's accelerations, as JSBSim does. The
    roll's and pitch's cosines and sines are libm's here (numpy 2 computes
    float64 sines and cosines with libm too: the same doubles);
    ``atan2(w, u)`` and ``atan2(v, sqrt(u^2 + w^2))`` come in from numpy's
    vectorised atan2, which rounds differently from libm's (used where
    JSBSim computes them: a true airspeed above 0.001 ft/s, and ``u^2 +
    w^2`` at least 1e-6 for the angle of attack)."""
    n = len(phi)
    for i in range(n):
        p, q, r = pqr[0][i], pqr[1][i], pqr[2][i]
        cphi, sphi = math.cos(phi[i]), math.sin(phi[i])
        ctht, stht = math.cos(theta[i]), math.sin(theta[i])
        out[0, i] = q * cphi - r * sphi
        if ctht != 0.0:
            psidot = (q * sphi + r * cphi) / ctht
            out[1, i], out[2, i] = psidot, p + psidot * stht
        else:
            out[1, i], out[2, i] = 0.0, 0.0
        u, v, w = uvw[0][i], uvw[1][i], uvw[2][i]
        ud, vd, wd = uvwdot[0][i], uvwdot[1][i], uvwdot[2][i]
        u2, v2, w2 = u * u, v * v, w * w
        muw = u2 + w2
        vt2 = muw + v2
        vt = math.sqrt(vt2)
        alpha = beta = adot = bdot = 0.0
        if vt > 0.001:
            beta = beta_v[i]
            if muw >= 1e-6:
                alpha = alpha_uw[i]
                vtdot = (u * ud + v * vd + w * wd) / vt
                adot = (u * wd - w * ud) / muw
                bdot = (vd * vt - v * vtdot) / (vt * math.sqrt(muw))
        out[3, i], out[4, i] = vt, vt / ktstofps
        out[5, i], out[6, i] = alpha, beta
        out[7, i], out[8, i] = alpha * _RADTODEG, beta * _RADTODEG
        out[9, i] = abs(beta)
        out[10, i], out[11, i], out[12, i] = adot, bdot, adot * _RADTODEG
        qbar = 0.5 * rho[i] * vt2
        out[13, i] = qbar
        out[14, i] = 0.5 * rho[i] * muw
        out[15, i] = 0.5 * rho[i] * (u2 + v2)
        out[16, i], out[17, i] = vt / a_snd[i], u / a_snd[i]
        vn, ve = ned[0][i], ned[1][i]
        out[18, i] = math.sqrt(vn * vn + ve * ve)
        ve_ = math.sqrt(2.0 * qbar / rho_sl[i])
        out[19, i], out[20, i] = ve_, ve_ / ktstofps
        out[21, i] = body_accel[0][i] / g0
        out[22, i] = body_accel[1][i] / g0
        out[23, i] = -body_accel[2][i] / g0


#: the rows ``aero_forces`` writes (the last three with wind axes only)
AERO_FORCES = ("forces/fbx-aero-lbs", "forces/fby-aero-lbs", "forces/fbz-aero-lbs",
               "moments/l-aero-lbsft", "moments/m-aero-lbsft", "moments/n-aero-lbsft",
               "forces/fwx-aero-lbs", "forces/fwy-aero-lbs", "forces/fwz-aero-lbs")


@jit
def aero_forces(f0: np.ndarray, f1: np.ndarray, f2: np.ndarray, alpha: np.ndarray,
                beta: np.ndarray, m0: np.ndarray, m1: np.ndarray, m2: np.ndarray,
                cgx: np.ndarray, cgy: np.ndarray, cgz: np.ndarray, rpx: float, rpy: float,
                rpz: float, inch_to_ft: float, wind: bool, out: np.ndarray) -> None:
    """FGAerodynamics' forces and moments from the axes' sums (rows
    ``AERO_FORCES``). ``wind``: ``f0, f1, f2`` are the DRAG, SIDE and LIFT
    sums (drag and lift act against their axes), turned into body axes
    through the angle of attack and the sideslip (FGAuxiliary::GetTw2b; the
    angles' cosines and sines libm's, as numpy 2's); else they are the X, Y
    and Z sums. The moment about the centre of gravity is that of the body
    force at the reference point (structural frame, in: ``rp``; JSBSim's
    ``inch_to_ft``) plus the axes' moments ``m0, m1, m2``."""
    for i in range(len(alpha)):
        if wind:
            fd, fs, fl = -f0[i], f1[i], -f2[i]
            ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
            cb, sb = math.cos(beta[i]), math.sin(beta[i])
            out[6, i], out[7, i], out[8, i] = fd, fs, fl
            fx = ca * cb * fd - ca * sb * fs - sa * fl
            fy = sb * fd + cb * fs
            fz = sa * cb * fd - sa * sb * fs + ca * fl
        else:
            fx, fy, fz = f0[i], f1[i], f2[i]
        out[0, i], out[1, i], out[2, i] = fx, fy, fz
        # FGMassBalance::StructuralToBody: x aft and z up to x forward and z down, ft
        rx = inch_to_ft * (cgx[i] - rpx)
        ry = inch_to_ft * (rpy - cgy[i])
        rz = inch_to_ft * (cgz[i] - rpz)
        out[3, i] = (ry * fz - rz * fy) + m0[i]
        out[4, i] = (rz * fx - rx * fz) + m1[i]
        out[5, i] = (rx * fy - ry * fx) + m2[i]


@jit
def any_low_or_not_finite(agl: np.ndarray, reach: float, a: np.ndarray, b: np.ndarray,
                          c: np.ndarray, d: np.ndarray, e: np.ndarray, f: np.ndarray) -> bool:
    """Whether some aircraft is below ``reach`` above the terrain or has a
    value of ``a`` .. ``f`` that is not finite (one pass; the frame's usual
    answer is no)."""
    for i in range(len(agl)):
        if not agl[i] >= reach:  # below, or NaN
            return True
        if not (math.isfinite(a[i]) and math.isfinite(b[i]) and math.isfinite(c[i])
                and math.isfinite(d[i]) and math.isfinite(e[i]) and math.isfinite(f[i])):
            return True
    return False


# ----------------------------------------------------------- the tables --

@jit
def _segment(bp: np.ndarray, key: float) -> tuple[int, float]:
    """FGTable's lookup of one breakpoint list: the upper breakpoint's index
    (1 .. len - 1: numpy's ``searchsorted`` 'left', clamped) and the factor
    clamped to [0, 1] (a key beyond an end takes the end's value)."""
    m = len(bp)
    r = 0
    while r < m and bp[r] < key:
        r += 1
    if key != key:  # NaN sorts last
        r = m
    r = min(max(r, 1), m - 1)
    lo = bp[r - 1]
    f = (key - lo) / (bp[r] - lo)
    return r, min(max(f, 0.0), 1.0) if f == f else f


@jit
def table1(bp: np.ndarray, val: np.ndarray, key: np.ndarray) -> np.ndarray:
    """A table of one dimension for every aircraft."""
    out = np.empty(len(key))
    for i in range(len(key)):
        r, f = _segment(bp, key[i])
        out[i] = f * (val[r] - val[r - 1]) + val[r - 1]
    return out


@jit
def table2(rbp: np.ndarray, cbp: np.ndarray, data: np.ndarray, rkey: np.ndarray,
           ckey: np.ndarray) -> np.ndarray:
    """A table of two dimensions for every aircraft (rows, then columns)."""
    out = np.empty(len(rkey))
    for i in range(len(rkey)):
        r, rf = _segment(rbp, rkey[i])
        c, cf = _segment(cbp, ckey[i])
        col1 = rf * (data[r, c - 1] - data[r - 1, c - 1]) + data[r - 1, c - 1]
        col2 = rf * (data[r, c] - data[r - 1, c]) + data[r - 1, c]
        out[i] = col1 + cf * (col2 - col1)
    return out
