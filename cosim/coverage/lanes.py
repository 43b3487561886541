"""Lanes: how a searchable area becomes an aircraft's lanes, and their order.

The area, turned so that the lanes run along +u (v across them), is cut
across v into one strip per aircraft, each of the same area (cut positions
found by bisection on the clipped area; a fleet larger than the rows of lanes
shares each row's strip along the lanes instead). Each strip is flown as a
lawnmower (boustrophedon): parallel rows of lanes, spaced no wider than the
camera's swath less the overlap, each lane as long as the strip's band
around it so that the swaths cover the strip to its edges. The rows of lane
pieces are grouped into cells (consecutive rows of one piece each, as in a
boustrophedon decomposition); the cells are flown in order of the nearest,
each in the row order and way that is shortest from where the aircraft is:
one row after another, or, where lanes are closer together than a U-turn
(twice the radius), interleaved (0, k, 1, k + 1, ...) so the turns need not
loop; consecutive lanes are joined by the shortest Dubins turns.

Plane geometry only: this module knows nothing of no-fly zones (``airspace``
cuts the rows it makes and adds cells of its own), and nothing of the plan's
types (``planner``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from shapely import affinity
from shapely.geometry import box
from shapely.geometry.base import BaseGeometry

from cosim.coverage.dubins import DubinsPath, shortest

_BISECT_TOL = 1e-9  # relative area error of a cut

Pose = tuple[float, float, float]
Lane = tuple[tuple[float, float], tuple[float, float]]
Piece = tuple[float, float, float]  # a lane in a rotated frame: u_start, u_end, v


def _clip_v(poly: BaseGeometry, v0: float, v1: float) -> BaseGeometry:
    minx, _, maxx, _ = poly.bounds
    return poly.intersection(box(minx - 1.0, v0, maxx + 1.0, v1))


def strip_shares(rot: BaseGeometry, n: int, spacing: float, tiles: bool
                 ) -> list[tuple[BaseGeometry, float, float]]:
    """Each aircraft's share of ``rot`` (lanes along u) as (polygon, v0, v1)
    of equal area: strips across v, or, when there are more aircraft than
    lanes across the area (and ``tiles``), a strip per lane row cut along the
    lanes into as many pieces as aircraft share it, so that a large fleet
    flies shorter lanes rather than narrower strips (which only overlap)."""
    _, vmin, _, vmax = rot.bounds
    rows = max(1, math.ceil((vmax - vmin) / spacing - 1e-9))
    if not tiles or n <= rows:
        cuts = equal_area_cuts(rot, n)
        return [(_clip_v(rot, cuts[k], cuts[k + 1]), cuts[k], cuts[k + 1]) for k in range(n)]
    per = [n // rows + (1 if s < n % rows else 0) for s in range(rows)]
    cuts = equal_area_cuts(rot, rows, weights=per)
    out = []
    for s, k in enumerate(per):
        strip = _clip_v(rot, cuts[s], cuts[s + 1])
        # cut along u: the same bisection on the strip turned a quarter turn
        turned = affinity.rotate(strip, 90.0, origin=(0, 0))  # (u, v) -> (-v, u)
        ucuts = equal_area_cuts(turned, k)
        for j in range(k):
            piece = affinity.rotate(_clip_v(turned, ucuts[j], ucuts[j + 1]), -90.0,
                                    origin=(0, 0))
            out.append((piece, cuts[s], cuts[s + 1]))
    return out


def equal_area_cuts(poly: BaseGeometry, n: int, weights: Sequence[int] | None = None
                     ) -> list[float]:
    """v positions splitting ``poly`` into ``n`` bands of equal area (or of
    areas in proportion to ``weights``)."""
    _, miny, _, maxy = poly.bounds
    total = poly.area
    share = [1] * n if weights is None else list(weights)
    cuts = [miny]
    for k in range(1, n):
        want = total * sum(share[:k]) / sum(share)
        lo, hi = cuts[-1], maxy
        for _ in range(200):
            mid = (lo + hi) / 2.0
            if _clip_v(poly, miny, mid).area < want:
                lo = mid
            else:
                hi = mid
            if hi - lo <= _BISECT_TOL * max(1.0, maxy - miny):
                break
        cuts.append((lo + hi) / 2.0)
    cuts.append(maxy)
    return cuts


def lane_rows(strip: BaseGeometry, v0: float, v1: float, spacing: float
              ) -> list[tuple[int, list[Piece]]]:
    """Per lane row (v ascending; with its index, empty rows left out), the
    lane pieces ``(u_start, u_end, v)``: rows centred in equal sub-bands no
    wider than ``spacing``; each piece spans its sub-band's part of the
    strip, so the swaths reach its edges."""
    if strip.is_empty or v1 <= v0:
        return []
    m = max(1, math.ceil((v1 - v0) / spacing - 1e-9))
    width = (v1 - v0) / m
    minx, _, maxx, _ = strip.bounds
    rows = []
    for i in range(m):
        a, b = v0 + i * width, v0 + (i + 1) * width
        band = strip.intersection(box(minx - 1.0, a, maxx + 1.0, b))
        parts = list(band.geoms) if hasattr(band, "geoms") else [band]
        pieces = sorted((p.bounds[0], p.bounds[2]) for p in parts
                        if not p.is_empty and p.area > 0)
        if pieces:
            rows.append((i, [(u0, u1, (a + b) / 2.0) for u0, u1 in pieces]))
    return rows


def side_rows(region: BaseGeometry, v_side: float, offset: float, spacing: float,
              swath: float) -> list[tuple[int, list[Piece]]]:
    """Rows of lanes along a zone's side at ``v = v_side`` over ``region``
    (on one side of it): the first ``offset`` from the side, then a
    ``spacing`` apart until the swaths reach across ``region``; each lane
    spans the part of ``region`` its band holds."""
    minx, v0, maxx, v1 = region.bounds
    up = (v0 + v1) / 2.0 >= v_side
    far = (v1 - v_side) if up else (v_side - v0)
    rows = []
    i = 0
    while offset + i * spacing - swath / 2.0 < far and i < 1000:
        d = offset + i * spacing
        v = v_side + d if up else v_side - d
        band = region.intersection(box(minx - 1.0, v - spacing / 2.0, maxx + 1.0,
                                       v + spacing / 2.0))
        parts = [g for g in getattr(band, "geoms", [band]) if not g.is_empty and g.area > 0]
        if parts:
            rows.append((i, sorted((g.bounds[0], g.bounds[2], v) for g in parts)))
        i += 1
    return rows


def group_cells(rows: list[tuple[int, list[Piece]]]) -> list[list[Piece]]:
    """The pieces grouped into cells: a piece continues the cell of the one
    piece of the row before that it overlaps along the lanes, when that one
    overlaps no other (a boustrophedon decomposition); each cell one piece
    a row, rows consecutive."""
    cells: list[list[Piece]] = []
    prev: list[tuple[int, Piece]] = []
    prev_i = None
    for i, pieces in rows:
        cur = []
        for p in pieces:
            cid = None
            if prev_i == i - 1:
                over = [(c, q) for c, q in prev if q[0] < p[1] and p[0] < q[1]]
                if len(over) == 1:
                    q = over[0][1]
                    if sum(1 for r in pieces if q[0] < r[1] and r[0] < q[1]) == 1:
                        cid = over[0][0]
            if cid is None:
                cells.append([])
                cid = len(cells) - 1
            cells[cid].append(p)
            cur.append((cid, p))
        prev, prev_i = cur, i
    return cells


def unrotate(cell: list[Piece], phi: float) -> list[Lane]:
    """A cell's pieces as lanes (each its +u way) in the (east, north) frame."""
    return [(rotate_xy((u0, v), phi), rotate_xy((u1, v), phi)) for u0, u1, v in cell]


def route(cells: list[list[Lane]], start: tuple[float, float], radius: float, jump: int
          ) -> tuple[list[Lane], list[DubinsPath | None]]:
    """The cells' lanes in flying order, and the turns between them (None
    between cells): from ``start``, the cell with the nearest end next; each
    cell flown in the row order (plain or interleaved) and way that is
    shortest from where the aircraft is."""
    left = list(range(len(cells)))
    lanes: list[Lane] = []
    joins: list[DubinsPath | None] = []
    pos = start
    while left:
        gaps = [_gap(cells[c], pos) for c in left]
        ci = left[gaps.index(min(gaps))]
        left.remove(ci)
        best: tuple[float, list[Lane], list[DubinsPath]] | None = None
        for seq in _sequences(len(cells[ci]), jump):
            ls = _orient(cells[ci], seq, pos)
            ts = [shortest((a[1][0], a[1][1], heading(a)), (b[0][0], b[0][1], heading(b)),
                           radius) for a, b in zip(ls, ls[1:])]
            cost = math.dist(pos, ls[0][0]) + sum(t.length_m for t in ts)
            if best is None or cost < best[0]:
                best = (cost, ls, ts)
        assert best is not None
        if lanes:
            joins.append(None)
        lanes += best[1]
        joins += best[2]
        pos = lanes[-1][1]
    return lanes, joins


def _gap(cell: list[Lane], at: tuple[float, float]) -> float:
    """How far ``at`` is from the nearest end of a cell's first or last lane."""
    return min(math.dist(at, p) for p in (*cell[0], *cell[-1]))


def _orient(cell: list[Lane], seq: list[int], pos: tuple[float, float]) -> list[Lane]:
    """The cell's lanes in the order ``seq`` (or its reverse), alternating
    direction; of the four ways (either end of ``seq``, starting either way
    along the lanes) the one whose first lane starts nearest ``pos``."""
    best: list[Lane] = []
    best_d = math.inf
    for order in (seq, seq[::-1]):
        for forward in (True, False):
            lanes = []
            fwd = forward
            for r in order:
                a, b = cell[r]
                lanes.append((a, b) if fwd else (b, a))
                fwd = not fwd
            d = math.dist(pos, lanes[0][0])
            if d < best_d:
                best, best_d = lanes, d
    return best


def _sequences(m: int, jump: int) -> list[list[int]]:
    """Orders of ``m`` rows to try: one after another; and, where lanes are
    closer than a U-turn, interleaved in blocks of ``2 * jump`` rows (0,
    jump, 1, jump + 1, ...: every turn but one a block spans ``jump`` or
    ``jump - 1`` rows, wide enough not to loop)."""
    out = [list(range(m))]
    if jump > 1 and m > 2:
        seq: list[int] = []
        for b in range(0, m, 2 * jump):
            size = min(2 * jump, m - b)
            h = (size + 1) // 2
            low, high = range(b, b + h), range(b + h, b + size)
            for i in range(h):
                seq.append(low[i])
                if i < len(high):
                    seq.append(high[i])
        out.append(seq)
    return out


def heading(lane: Lane) -> float:
    """A lane's direction, radians counter-clockwise from +x."""
    (x0, y0), (x1, y1) = lane
    return math.atan2(y1 - y0, x1 - x0)


def rotate_xy(p: tuple[float, float], a: float) -> tuple[float, float]:
    """``p`` turned by ``a`` radians counter-clockwise about the origin."""
    c, s = math.cos(a), math.sin(a)
    return (c * p[0] - s * p[1], s * p[0] + c * p[1])
