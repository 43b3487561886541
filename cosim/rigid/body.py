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
from cosim.rigid import kernels as kern
from cosim.rigid.linalg import (
    Mat,
    Vec,
    add,
    cross,
    mm,
    mtv,
    mv,
    quat_from_euler,
    quat_from_matrix,
    quat_mul,
    transpose,
)
from cosim.rigid.units import KTSTOFPS

Props = dict[str, np.ndarray]

OMEGA_EARTH = geo.OMEGA_EARTH_RAD_S
_RADTODEG = 57.295779513082320876798154814105

_Q = ("_eom/q0", "_eom/q1", "_eom/q2", "_eom/q3")
_QD = ("_eom/qd0", "_eom/qd1", "_eom/qd2", "_eom/qd3")
_W = ("_eom/pi", "_eom/qi", "_eom/ri")
_R = ("_eom/rx", "_eom/ry", "_eom/rz")
_V = ("_eom/vx", "_eom/vy", "_eom/vz")
_V1 = ("_eom/v1x", "_eom/v1y", "_eom/v1z")  # the inertial velocity a frame ago
_V2 = ("_eom/v2x", "_eom/v2y", "_eom/v2z")  # two frames ago
_ECEF = ("_eom/ex", "_eom/ey", "_eom/ez")  # the Earth-fixed position (ft)
_BA = ("_eom/bax", "_eom/bay", "_eom/baz")  # the body's acceleration by forces (ft/s^2)
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


def _get(props: Props, keys: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    return tuple(props[k] for k in keys)


def _put(props: Props, keys: tuple[str, ...], values: tuple[np.ndarray, ...]) -> None:
    for k, v in zip(keys, values, strict=True):
        props[k] = v


def _rows(props: Props, keys: tuple[str, ...]) -> np.ndarray:
    """Properties as one (len(keys), n) block for a kernel."""
    return np.array([props[k] for k in keys], dtype=np.float64)


def _store(props: Props, keys: tuple[str, ...], block: np.ndarray) -> None:
    """A kernel's (len(keys), n) block into ``props``, a row a key."""
    for j, key in enumerate(keys):
        props[key] = block[j]


def block(props: Props, name: str, keys: tuple[str, ...], n: int) -> np.ndarray:
    """Where a kernel writes ``keys`` this frame: one block kept in
    ``props`` (so a frame allocates nothing) and written over in place, for
    a kernel that reads none of its rows or reads an aircraft's before
    writing that aircraft's (nothing keeps these rows across frames: the
    flight controls keep copies). A kept block whose rows are not contiguous
    (an aircraft's rows cut out of it with a mask leave it so) is replaced:
    the kernels' rows stay contiguous."""
    a = props.get(name + "0")
    if a is None or a.shape != (len(keys), n) or not _rows_contiguous(a):
        a = props[name + "0"] = _aligned((len(keys), n))
    return a


def _rows_contiguous(block: np.ndarray) -> bool:
    """Whether each row of a block is contiguous, the rows in order."""
    return block.strides[1] == block.itemsize and block.strides[0] >= block.shape[1] * 8


def _at(arr: np.ndarray) -> int:
    """An array's first byte's address."""
    return int(arr.__array_interface__["data"][0])


_SKEW = 0


def _aligned(shape: tuple[int, int]) -> np.ndarray:
    """An empty block whose start is skewed by a different number of cache
    lines for each block made, and whose rows are a cache line longer than
    the aircraft when a row would be a whole number of 4 KiB pages (a
    multiple of 512 aircraft): a kernel that writes one row and then reads
    another at the same offsets from 4 KiB-aligned starts stalls the
    processor's store forwarding ("4K aliasing", measured: the propagation
    kernel 1.6 times slower; a whole frame at 8,192 aircraft 1.5 times
    slower than at 8,000 or 8,200). The rows stay contiguous; the block is
    not C-contiguous then."""
    global _SKEW
    _SKEW = (_SKEW + 1) % 29
    skew = 8 * (_SKEW + 1)  # doubles: whole cache lines
    rows, n = shape
    stride = n + 8 if (n * 8) % 4096 == 0 else n
    flat = np.empty(rows * stride + skew)
    return flat[skew:].reshape(rows, stride)[:, :n]


def _state(props: Props, n: int) -> np.ndarray:
    """The integrated state's rows as one block: the block they are rows of
    when they all are (no copy), else a copy."""
    kept = props.get("_eom/state0")
    if kept is not None and kept.shape == (len(kern.STATE), n):
        start, step = _at(kept), kept.strides[0]
        if all(_at(props[key]) == start + j * step for j, key in enumerate(kern.STATE)):
            return kept  # the rows are this block's, in order
    return _rows(props, kern.STATE)


def _ti2ec(epa: np.ndarray) -> Mat:
    c, s = np.cos(epa), np.sin(epa)
    z, o = np.zeros_like(epa), np.ones_like(epa)
    return (c, s, z, -s, c, z, z, z, o)


def _omega(n: int) -> Vec:
    z = np.zeros(n)
    return (z, z, np.full(n, OMEGA_EARTH))


def _tec2l(loc: Vec) -> Mat:
    g = geo.ecef_to_geodetic(*loc)
    m = geo.tec2l(*loc, geodetic=g)
    return (m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])


def initial_state(props: Props, loc: Vec, phi: np.ndarray, theta: np.ndarray,
                  psi: np.ndarray, uvw: Vec, pqr: Vec) -> None:
    """FGPropagate::SetInitialState: the state from an Earth-fixed position
    (ECEF, ft), the Euler angles (rad), the body velocity relative to the
    Earth (ft/s) and the body rates relative to the Earth (rad/s); the Earth
    position angle 0."""
    n = len(phi)
    for key in kern.ACCELERATIONS:  # the body's acceleration by forces among them
        props.setdefault(key, np.zeros(n))  # FGAccelerations::InitModel
    epa = np.zeros(n)
    ti2ec = _ti2ec(epa)
    tec2i = transpose(ti2ec)
    r_i = mv(tec2i, loc)
    ti2l = mm(_tec2l(loc), ti2ec)
    q_local = quat_from_euler(phi, theta, psi)
    q = quat_mul(quat_from_matrix(ti2l), q_local)
    ti2b = tuple(kern.ti2b_arrays(np.array(q)))
    w_i = add(pqr, mv(ti2b, _omega(n)))
    v_i = add(mtv(ti2b, uvw), cross(_omega(n), r_i))
    props["_eom/epa"] = epa
    _put(props, _Q, q)
    _put(props, _W, w_i)
    _put(props, _R, r_i)
    _put(props, _V, v_i)
    for key in (*_V1, *_V2, *_A1):
        props.setdefault(key, np.zeros(n))
    ce, se = np.cos(epa), np.sin(epa)
    der = np.empty((len(kern.DERIVED), n))
    kern.derive(np.array(q), np.array(w_i), np.array(r_i), np.array(v_i), ce, se,
                props["position/terrain-elevation-asl-ft"], der)
    _store(props, kern.DERIVED, der)
    _angles(props)


def initialize_derivatives(props: Props) -> None:
    """FGPropagate::InitializeDerivatives: every past derivative is the
    present one (done once the first derivatives are known)."""
    for old, now in ((_V1, _V), (_V2, _V), (_A1, _AI)):
        _put(props, old, tuple(props[key].copy() for key in now))


def propagate(props: Props, dt: float) -> None:
    """FGPropagate::Run: integrate one frame, then derive the Earth-relative
    state (``kernels.propagate``)."""
    epa = props["_eom/epa"] + OMEGA_EARTH * dt
    n = len(epa)
    new = block(props, "_eom/state", kern.STATE, n)  # the state's own rows, mostly
    der = block(props, "_eom/derived", kern.DERIVED, n)
    kern.propagate(dt, _state(props, n), _rows(props, _QD), _rows(props, _WD),
                   _rows(props, _AI), epa, props["position/terrain-elevation-asl-ft"],
                   new, der)
    props["_eom/epa"] = epa
    _store(props, kern.STATE, new)
    _store(props, kern.DERIVED, der)
    _angles(props)


def _angles(props: Props) -> None:
    """The angles of the derived state, with numpy's vectorised trigonometry:
    the Euler angles of Tl2b (FGMatrix33::GetEuler, without its gimbal-lock
    branch: at exactly +-90 deg of pitch roll comes from the same formula),
    the geodetic latitude and the longitude."""
    t = props
    theta = np.arcsin(np.clip(-t["_eom/tl2b_t13"], -1.0, 1.0))
    phi = np.arctan2(t["_eom/tl2b_t23"], t["_eom/tl2b_t33"])
    psi = np.arctan2(t["_eom/tl2b_t12"], t["_eom/tl2b_t11"])
    psi = np.where(psi < 0.0, psi + 2.0 * np.pi, psi)
    lat = np.arctan(t["_eom/tanlat"])
    lon = np.arctan2(t["_eom/ey"], t["_eom/ex"])
    for name, rad in (("attitude/phi", phi), ("attitude/theta", theta), ("attitude/psi", psi),
                      ("position/lat-geod", lat)):
        props[name + "-rad"] = rad
        props[name + "-deg"] = rad * _RADTODEG
    props["position/long-gc-rad"] = lon
    props["position/long-gc-deg"] = lon * _RADTODEG


_INERTIA = ("inertia/ixx-slugs_ft2", "inertia/iyy-slugs_ft2", "inertia/izz-slugs_ft2",
            "inertia/ixy-slugs_ft2", "inertia/ixz-slugs_ft2", "inertia/iyz-slugs_ft2")
_JINV = tuple("_mb/jinv" + s for s in ("11", "12", "13", "22", "23", "33"))
#: the forces (lbs) and moments (lbs ft) summed into the total
_LOADS = tuple(f"forces/fb{a}-{s}-lbs" for s in ("aero", "prop") for a in "xyz") + tuple(
    f"moments/{a}-{s}-lbsft" for s in ("aero", "prop") for a in "lmn")


def accelerations(props: Props) -> None:
    """FGAccelerations::Run in the air (no ground friction): the body's
    angular and linear accelerations from the total force (lbs) and moment
    (lbs ft) about the centre of gravity, the aerodynamics' and the
    propulsion's (``kernels.accelerations``; it writes the total force)."""
    out = block(props, "_eom/accelerations", kern.ACCELERATIONS, len(props["_n"]))
    kern.accelerations(props["inertia/mass-slugs"], _get(props, _INERTIA), _get(props, _JINV),
                       _get(props, _W), _get(props, _Q), props["_eom/ce"], props["_eom/se"],
                       _get(props, _PQR), _get(props, _UVW), _get(props, _R),
                       _get(props, _ECEF), _get(props, _LOADS), out)
    _store(props, kern.ACCELERATIONS, out)


def auxiliary(props: Props, wanted: frozenset[str] = frozenset()) -> None:
    """FGAuxiliary::Run without wind: airspeeds, angles and their rates,
    dynamic pressure, Mach number (it reads the previous frame's accelerations,
    as JSBSim does; ``kernels.auxiliary``). The calibrated airspeed and the
    flight path's angles are computed only when in ``wanted`` (their cost is
    a third of the rest's)."""
    phi, theta = props["attitude/phi-rad"], props["attitude/theta-rad"]
    u, v, w = _get(props, _UVW)
    out = block(props, "_eom/auxiliary", kern.AUXILIARY, len(phi))
    kern.auxiliary(_get(props, _PQR), phi, theta, _get(props, _UVW), np.arctan2(w, u),
                   np.arctan2(v, np.sqrt(u * u + w * w)), _get(props, _UVWDOT),
                   props["atmosphere/rho-slugs_ft3"], props["atmosphere/a-fps"],
                   _get(props, _NED), props["atmosphere/rho-sl-slugs_ft3"],
                   _get(props, _BA), geo.G0_FT_S2, KTSTOFPS, out)
    _store(props, kern.AUXILIARY, out)
    # no wind, no turbulence: the air-relative rates and velocities are the body's
    for a, b in zip(("velocities/p-aero-rad_sec", "velocities/q-aero-rad_sec",
                     "velocities/r-aero-rad_sec", "velocities/u-aero-fps",
                     "velocities/v-aero-fps", "velocities/w-aero-fps"), (*_PQR, *_UVW),
                    strict=True):
        props[a] = props[b]
    if wanted & {"velocities/vc-fps", "velocities/vc-kts"}:
        vc = kern.vcas_arrays(props["velocities/mach"], props["atmosphere/P-psf"],
                              geo.SL_PRESSURE_PSF, geo.SL_SOUNDSPEED_FPS)
        props["velocities/vc-fps"], props["velocities/vc-kts"] = vc, vc / KTSTOFPS
    if wanted & {"flight-path/gamma-rad", "flight-path/gamma-deg", "flight-path/psi-gt-rad"}:
        vn, ve, vd = _get(props, _NED)
        gt = np.arctan2(ve, vn)
        props["flight-path/psi-gt-rad"] = np.where(gt < 0.0, gt + 2.0 * np.pi, gt)
        gamma = np.arctan2(-vd, props["velocities/vg-fps"])
        props["flight-path/gamma-rad"], props["flight-path/gamma-deg"] = \
            gamma, gamma * _RADTODEG


__all__ = ["accelerations", "auxiliary", "initial_state", "initialize_derivatives",
           "propagate"]
