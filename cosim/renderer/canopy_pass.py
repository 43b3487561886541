"""The trees' outlines, compiled: each crown's, sunlit cap's and trunk's
outline in pixels (``outline_pixels``, the arithmetic of ``canopy.outlines``
and the projection), and a run of convex polygons painted in order into the
frame, clearing the target-id image under those that hide what is behind
them (``fill_polygons``).

A pixel (centred on whole numbers) is filled when the polygon reaches into
its square: on each row, the span the polygon covers within the row's band
of height one, widened to the pixels it reaches into. Like OpenCV's fill of
a convex polygon, which adds the pixels its outline crosses, this draws a
polygon thinner than a pixel (a far trunk) as a line, not as nothing, and
does it without a call per polygon. Compiled by numba on first use in a
process (kept in numba's cache beside this file after that). Owns nothing
but the arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, boundscheck=False)
def _fill(img: np.ndarray, ids: np.ndarray, polys: np.ndarray, counts: np.ndarray,
          bgr: np.ndarray, clear: np.ndarray, lo: int, hi: int
          ) -> None:  # pragma: no cover (compiled)
    h, w = ids.shape
    x_lo = np.empty(h + 2)  # per row: the polygon's span within the row's band
    x_hi = np.empty(h + 2)
    for m in range(lo, hi):
        n = counts[m]
        if n < 3:
            continue
        y_lo, y_hi = polys[m, 0, 1], polys[m, 0, 1]
        for k in range(1, n):
            y_lo = min(y_lo, polys[m, k, 1])
            y_hi = max(y_hi, polys[m, k, 1])
        # the rows of the pixels whose square the polygon overlaps, within the image
        r0 = max(0, int(math.floor(y_lo - 0.5)) + 1)
        r1 = min(h - 1, int(math.ceil(y_hi + 0.5)) - 1)
        if r1 < r0:
            continue
        x_lo[r0:r1 + 1] = np.inf
        x_hi[r0:r1 + 1] = -np.inf
        for k in range(n):  # a row's span: its vertices, and its edges at its band's edges
            ax, ay = polys[m, k, 0], polys[m, k, 1]
            bx, by = polys[m, (k + 1) % n, 0], polys[m, (k + 1) % n, 1]
            r = int(math.floor(ay + 0.5))
            if r0 <= r <= r1:
                x_lo[r], x_hi[r] = min(x_lo[r], ax), max(x_hi[r], ax)
            if ay == by:
                continue
            e_lo, e_hi = min(ay, by), max(ay, by)
            for j in range(max(r0, int(math.ceil(e_lo - 0.5))),
                           min(r1 + 1, int(math.floor(e_hi - 0.5)) + 1)):
                x = ax + (j + 0.5 - ay) * (bx - ax) / (by - ay)  # at y = j + 1/2
                x_lo[j], x_hi[j] = min(x_lo[j], x), max(x_hi[j], x)
                if j + 1 <= r1:
                    x_lo[j + 1], x_hi[j + 1] = min(x_lo[j + 1], x), max(x_hi[j + 1], x)
            if e_lo <= r0 - 0.5 <= e_hi:  # the first row's top, if the polygon reaches above
                x = ax + (r0 - 0.5 - ay) * (bx - ax) / (by - ay)
                x_lo[r0], x_hi[r0] = min(x_lo[r0], x), max(x_hi[r0], x)
        b, g, r = bgr[m, 0], bgr[m, 1], bgr[m, 2]
        for y in range(r0, r1 + 1):
            if x_hi[y] < x_lo[y]:
                continue
            c0 = max(0, int(math.floor(x_lo[y] - 0.5)) + 1)
            c1 = min(w - 1, int(math.ceil(x_hi[y] + 0.5)) - 1)
            for x in range(c0, c1 + 1):
                img[y, x, 0] = b
                img[y, x, 1] = g
                img[y, x, 2] = r
                if clear[m]:
                    ids[y, x] = 0


@njit(cache=True, nogil=True, boundscheck=False)
def _ring(centre: np.ndarray, semi: np.ndarray, shift: np.ndarray, scale: float,
          m: np.ndarray, rho: float, axis: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray,
          pts: np.ndarray, at: int) -> None:  # pragma: no cover (compiled)
    """``pts[at + k] = centre + semi (shift + scale (m + rho (cos_k u + sin_k v)))``:
    a circle about ``axis`` where the crown is the unit sphere (``canopy._circle``)."""
    n = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    a0, a1, a2 = axis[0] / n, axis[1] / n, axis[2] / n
    h0, h1, h2 = (1.0, 0.0, 0.0) if abs(a2) > 0.9 else (0.0, 0.0, 1.0)
    u0, u1, u2 = a1 * h2 - a2 * h1, a2 * h0 - a0 * h2, a0 * h1 - a1 * h0
    un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    u0, u1, u2 = u0 / un, u1 / un, u2 / un
    v0, v1, v2 = a1 * u2 - a2 * u1, a2 * u0 - a0 * u2, a0 * u1 - a1 * u0
    for k in range(cos_t.shape[0]):
        c, s = cos_t[k], sin_t[k]
        pts[at + k, 0] = centre[0] + semi[0] * (shift[0] + scale * (m[0] + rho * (c * u0 + s * v0)))
        pts[at + k, 1] = centre[1] + semi[1] * (shift[1] + scale * (m[1] + rho * (c * u1 + s * v1)))
        pts[at + k, 2] = centre[2] + semi[2] * (shift[2] + scale * (m[2] + rho * (c * u2 + s * v2)))


@njit(cache=True, nogil=True, boundscheck=False)
def _outlines(centre: np.ndarray, semi: np.ndarray, sun: np.ndarray, cam: np.ndarray,
              R: np.ndarray, K: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray, lit: float,
              half_trunk_m: float, near_m: float, out: np.ndarray, counts: np.ndarray,
              depth: np.ndarray, state: np.ndarray) -> None:  # pragma: no cover (compiled)
    S = cos_t.shape[0]
    pts = np.empty((4 + 2 * S, 3))
    c = np.empty(3)
    m = np.empty(3)
    sh = np.zeros(3)
    for i in range(centre.shape[0]):
        for j in range(3):
            c[j] = (cam[j] - centre[i, j]) / semi[i, j]
        d2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        if d2 <= 1.0 + 1e-6:
            state[i] = 2  # the camera inside the crown
            continue
        for j in range(3):
            m[j] = c[j] / d2
            sh[j] = 0.0
        _ring(centre[i], semi[i], sh, 1.0, m, math.sqrt(1.0 - 1.0 / d2), c, cos_t, sin_t,
              pts, 4)
        # the cap: the unit sphere shrunk by lit, moved lit toward the sunniest point
        sn = math.sqrt((semi[i, 0] * sun[0]) ** 2 + (semi[i, 1] * sun[1]) ** 2
                       + (semi[i, 2] * sun[2]) ** 2)
        for j in range(3):
            sh[j] = lit * semi[i, j] * sun[j] / sn
        cc = (c - sh) / (1.0 - lit)
        e2 = max(cc[0] * cc[0] + cc[1] * cc[1] + cc[2] * cc[2], 1.0 + 1e-6)
        _ring(centre[i], semi[i], sh, 1.0 - lit, cc / e2, math.sqrt(1.0 - 1.0 / e2), cc,
              cos_t, sin_t, pts, 4 + S)
        # the trunk: foot to the crown's centre, across the horizontal line of sight
        ln, le = centre[i, 0] - cam[0], centre[i, 1] - cam[1]
        norm = math.sqrt(ln * ln + le * le)
        an, ae = (-le / norm * half_trunk_m, ln / norm * half_trunk_m) if norm > 1e-6 \
            else (0.0, half_trunk_m)
        for k, (sgn, z) in enumerate(((-1.0, 0.0), (1.0, 0.0), (1.0, centre[i, 2]),
                                      (-1.0, centre[i, 2]))):
            pts[k, 0], pts[k, 1], pts[k, 2] = centre[i, 0] + sgn * an, centre[i, 1] + sgn * ae, z
        # into the camera, then pixels
        state[i] = 0
        mx, my, mz = 0.0, 0.0, 0.0
        for k in range(4 + 2 * S):
            x0, x1, x2 = pts[k, 0] - cam[0], pts[k, 1] - cam[1], pts[k, 2] - cam[2]
            px = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2
            py = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2
            pz = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2
            if 4 <= k < 4 + S:
                mx, my, mz = mx + px, my + py, mz + pz
            if pz < near_m:
                state[i] = 1  # across the near plane
                continue
            part, at = (0, k) if k < 4 else ((1, k - 4) if k < 4 + S else (2, k - 4 - S))
            out[i, part, at, 0] = K[0, 0] * px / pz + K[0, 2]
            out[i, part, at, 1] = K[1, 1] * py / pz + K[1, 2]
        depth[i] = math.sqrt(mx * mx + my * my + mz * mz) / S
        if state[i] != 0:
            continue
        # a trunk whose foot lies inside the crown's inscribed circle is hidden
        cx, cy = 0.0, 0.0
        for k in range(S):
            cx, cy = cx + out[i, 1, k, 0] / S, cy + out[i, 1, k, 1] / S
        inner = np.inf
        for k in range(S):
            inner = min(inner, math.hypot(out[i, 1, k, 0] - cx, out[i, 1, k, 1] - cy))
        fx = 0.5 * (out[i, 0, 0, 0] + out[i, 0, 1, 0]) - cx
        fy = 0.5 * (out[i, 0, 0, 1] + out[i, 0, 1, 1]) - cy
        counts[i, 0] = 4 if math.hypot(fx, fy) > inner * math.cos(math.pi / S) else 0
        counts[i, 1] = counts[i, 2] = S


def outline_pixels(centre: np.ndarray, semi: np.ndarray, sun_l: np.ndarray, camera_l: np.ndarray,
                   R_cl: np.ndarray, K: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray,
                   lit: float, trunk_m: float, near_m: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``canopy.outlines`` of the crowns (``centre``, ``semi``: N x 3, L axes) seen
    from ``camera_l`` in pixels (``R_cl``, ``K``): (N, 3, k, 2) trunk, crown and
    cap (``cos_t``, ``sin_t``: the outline's k angles), how many vertices each
    has (the trunk's 0 where the crown hides it), each crown's centre's depth,
    and each tree's state: 0 drawn, 1 across the near plane (not filled in:
    clip it), 2 the camera inside the crown."""
    n, k = len(centre), len(cos_t)
    out = np.zeros((n, 3, k + 2, 2))
    counts = np.zeros((n, 3), np.int64)
    depth, state = np.zeros(n), np.zeros(n, np.int64)
    _outlines(np.ascontiguousarray(centre, dtype=np.float64),
              np.ascontiguousarray(semi, dtype=np.float64), np.asarray(sun_l, np.float64),
              np.asarray(camera_l, np.float64), np.ascontiguousarray(R_cl, dtype=np.float64),
              np.ascontiguousarray(K, dtype=np.float64), cos_t, sin_t, lit, 0.5 * trunk_m,
              near_m, out, counts, depth, state)
    return out, counts, depth, state


def fill_polygons(img: np.ndarray, ids: np.ndarray, polys: np.ndarray, counts: np.ndarray,
                  bgr: np.ndarray, clear: np.ndarray, lo: int, hi: int) -> None:
    """Fill polygons ``lo .. hi - 1`` in order into ``img`` (h x w x 4 BGRA uint8;
    alpha left as it is): polygon ``m`` is the convex ``polys[m, :counts[m]]``
    (pixels, x and y; float64), in colour ``bgr[m]`` (uint8), and where
    ``clear[m]`` it sets ``ids`` (h x w uint16) to 0 under it."""
    if not (polys.ndim == 3 and polys.shape[2] == 2 and len(counts) == len(bgr) == len(clear)
            == len(polys) and img.shape[:2] == ids.shape and 0 <= lo <= hi <= len(polys)):
        raise ValueError(f"fill_polygons: polygons {polys.shape}, {len(counts)} counts, "
                         f"{len(bgr)} colours, {len(clear)} flags, image {img.shape}, ids "
                         f"{ids.shape}, range {lo}..{hi}")
    _fill(img, ids, polys, counts, bgr, clear, lo, hi)
