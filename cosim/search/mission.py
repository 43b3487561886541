"""A search's plan, and each aircraft's share of it as mission waypoints.

Used twice with the same result (it is deterministic): when the scenario
is read, so that a plan that cannot be made or flown is a config error with
its file and line (``cosim validate`` included), and when the run starts,
to put the missions on board.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

#: mission waypoints are reached within this (m), as ArduPlane's WP_RADIUS, or
#: once their leg is passed; the aircraft flies on along the leg until then
ACCEPT_M = 90.0
#: turns are sampled no coarser than this to make a mission fit
MAX_TURN_STEP_M = 2000.0


def plan_search(spec: Any, starts_ne_psi: Sequence[tuple[float, float, float]]) -> Any:
    """The ``CoveragePlan`` of ``spec`` (a ``SearchSpec``) for its aircraft,
    each one's transit from where it starts (north, east, heading in
    degrees) rather than from the base, unless that would cross a no-fly
    zone. ``ValueError`` says why a plan cannot be made."""
    from shapely.geometry import LineString

    from cosim.coverage import area_polygon, plan_coverage, swath_m, turn_radius_m
    from cosim.coverage.dubins import shortest

    radius = turn_radius_m(spec.airspeed_mps, spec.bank_deg)
    zones = [area_polygon(z) for z in spec.no_fly_ne]
    plan = plan_coverage(area_polygon(spec.area_ne), len(spec.rows),
                         swath_m(spec.alt_agl_m, spec.camera.hfov_deg), radius,
                         base_ne=spec.base_ne, overlap=spec.overlap, sweep_deg=spec.sweep_deg,
                         no_fly=zones)
    for k, a in enumerate(plan.aircraft):
        if not a.lanes:
            raise ValueError(f"aircraft {k + 1} of {len(plan.aircraft)} gets no lane of the "
                             f"area: search it with fewer aircraft")
        n0, e0, psi = starts_ne_psi[k]
        (x1, y1), (x2, y2) = a.lanes[0]
        path = shortest((e0, n0, math.pi / 2 - math.radians(psi)),
                        (x1, y1, math.atan2(y2 - y1, x2 - x1)), radius)
        if zones:
            line = LineString(path.sample(20.0)[:, :2])
            if any(line.intersects(z) for z in zones):
                continue  # the planned transit, round the zones, from the base
        plan.aircraft[k] = replace(a, transit=path)
    return plan


def flight_waypoints(a: Any, step_m: float, overrun_m: float
                     ) -> tuple[list[tuple[float, float]], float]:
    """An aircraft's plan (``AircraftPlan``) as waypoints ``(north_m, east_m)``:
    the transit and turns sampled every ``step_m``, each lane by its ends, run
    ``overrun_m`` past them where the next lane is flown back the other way
    (the turn between them moved out with them); and the length that adds."""
    out: list[tuple[float, float]] = []
    added = 0.0

    def add(points: np.ndarray, shift: np.ndarray) -> None:
        out.extend((float(y + shift[1]), float(x + shift[0])) for x, y in points[:, :2])

    zero = np.zeros(2)
    if a.transit is not None:
        add(a.transit.sample(step_m)[1:-1], zero)
    lanes = [(np.array(p, dtype=float), np.array(q, dtype=float)) for p, q in a.lanes]
    units = [(q - p) / max(float(np.linalg.norm(q - p)), 1e-9) for p, q in lanes]
    back = [i + 1 < len(lanes) and float(units[i] @ units[i + 1]) < -0.999
            for i in range(len(lanes))]
    for i, (p, q) in enumerate(lanes):
        start = p - overrun_m * units[i] if i and back[i - 1] else p
        end = q + overrun_m * units[i] if back[i] else q
        added += float(np.linalg.norm(start - p) + np.linalg.norm(end - q))
        out += [(float(start[1]), float(start[0])), (float(end[1]), float(end[0]))]
        if i < len(a.turns):
            add(a.turns[i].sample(step_m)[1:-1], overrun_m * units[i] if back[i] else zero)
    return _deduplicated(out), added


def _deduplicated(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Without points within a metre of the one before (zero-length turn parts)."""
    out: list[tuple[float, float]] = []
    for p in points:
        if not out or math.dist(p, out[-1]) > 1.0:
            out.append(p)
    return out


def mission_waypoints(a: Any, step_m: float, overrun_m: float, max_items: int
                      ) -> tuple[list[tuple[float, float]], float]:
    """``flight_waypoints`` with the turns sampled more coarsely (up to
    ``MAX_TURN_STEP_M``) until they fit ``max_items`` mission items beside a
    speed item; ``ValueError`` if even that does not fit."""
    step = step_m
    while True:
        wps, extra = flight_waypoints(a, step, overrun_m)
        if len(wps) + 1 <= max_items:
            return wps, extra
        if step >= MAX_TURN_STEP_M:
            raise ValueError(f"{len(a.lanes)} lanes make {len(wps)} waypoints even with turns "
                             f"sampled every {step:.0f} m; a mission holds at most "
                             f"{max_items - 1}: search with more aircraft, higher, or a "
                             f"smaller area")
        step = min(step * 1.5, MAX_TURN_STEP_M)
