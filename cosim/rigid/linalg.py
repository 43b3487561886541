"""Small vectorised linear algebra for the rigid-body tier: a vector is a
tuple of three arrays (one value per aircraft), a matrix a tuple of nine
(row-major), a quaternion a tuple of four; every operation works on all the
aircraft at once. The quaternion conventions are JSBSim's (``FGQuaternion``:
scalar first; ``T`` is the transformation from the reference frame to the
body frame; Euler angles roll, pitch, yaw in that order of rotation)."""

from __future__ import annotations

import numpy as np

Arr = np.ndarray
Vec = tuple[Arr, Arr, Arr]
Mat = tuple[Arr, Arr, Arr, Arr, Arr, Arr, Arr, Arr, Arr]
Quat = tuple[Arr, Arr, Arr, Arr]


def mv(m: Mat, v: Vec) -> Vec:
    """m v."""
    return (m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
            m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
            m[6] * v[0] + m[7] * v[1] + m[8] * v[2])


def mtv(m: Mat, v: Vec) -> Vec:
    """m^T v."""
    return (m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
            m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
            m[2] * v[0] + m[5] * v[1] + m[8] * v[2])


def mm(a: Mat, b: Mat) -> Mat:
    """a b."""
    return (a[0] * b[0] + a[1] * b[3] + a[2] * b[6], a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
            a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
            a[3] * b[0] + a[4] * b[3] + a[5] * b[6], a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
            a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
            a[6] * b[0] + a[7] * b[3] + a[8] * b[6], a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
            a[6] * b[2] + a[7] * b[5] + a[8] * b[8])


def transpose(m: Mat) -> Mat:
    return (m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8])


def cross(a: Vec, b: Vec) -> Vec:
    """a x b."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def add(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def quat_from_euler(phi: Arr, tht: Arr, psi: Arr) -> Quat:
    """The quaternion of Euler angles (rad), FGQuaternion(phi, tht, psi)."""
    sp, cp = np.sin(0.5 * phi), np.cos(0.5 * phi)
    st, ct = np.sin(0.5 * tht), np.cos(0.5 * tht)
    ss, cs = np.sin(0.5 * psi), np.cos(0.5 * psi)
    cpct, cpst, spst, spct = cp * ct, cp * st, sp * st, sp * ct
    return (cpct * cs + spst * ss, spct * cs - cpst * ss, cpst * cs + spct * ss,
            cpct * ss - spst * cs)


def quat_from_matrix(m: Mat) -> Quat:
    """The quaternion of a transformation matrix (FGMatrix33::GetQuaternion:
    the largest of the four squared components picks the formula)."""
    t0 = 1.0 + m[0] + m[4] + m[8]
    t1 = 1.0 + m[0] - m[4] - m[8]
    t2 = 1.0 - m[0] + m[4] - m[8]
    t3 = 1.0 - m[0] - m[4] + m[8]
    big = np.argmax(np.stack([t0, t1, t2, t3]), axis=0)
    out = []
    with np.errstate(divide="ignore", invalid="ignore"):
        s0 = np.sqrt(np.maximum(t0, 0.0))
        s1 = np.sqrt(np.maximum(t1, 0.0))
        s2 = np.sqrt(np.maximum(t2, 0.0))
        s3 = np.sqrt(np.maximum(t3, 0.0))
        h0, h1, h2, h3 = 0.5 * s0, 0.5 * s1, 0.5 * s2, 0.5 * s3
        c0 = (h0, 0.25 * (m[5] - m[7]) / h0, 0.25 * (m[6] - m[2]) / h0,
              0.25 * (m[1] - m[3]) / h0)
        c1 = (0.25 * (m[5] - m[7]) / h1, h1, 0.25 * (m[1] + m[3]) / h1,
              0.25 * (m[2] + m[6]) / h1)
        c2 = (0.25 * (m[6] - m[2]) / h2, 0.25 * (m[1] + m[3]) / h2, h2,
              0.25 * (m[5] + m[7]) / h2)
        c3 = (0.25 * (m[1] - m[3]) / h3, 0.25 * (m[2] + m[6]) / h3,
              0.25 * (m[5] + m[7]) / h3, h3)
    for k in range(4):
        out.append(np.select([big == 0, big == 1, big == 2], [c0[k], c1[k], c2[k]], c3[k]))
    return (out[0], out[1], out[2], out[3])


def quat_mul(a: Quat, b: Quat) -> Quat:
    """a * b (FGQuaternion::operator*)."""
    return (a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0])
