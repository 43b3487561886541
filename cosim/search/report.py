"""``cosim search-plan``: the plan of a scenario's search, the smallest fleet
that finishes it before a deadline, and how that fleet changes with the
altitude flown (the camera's swath against the pixels a fire still gets)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from cosim.search.spec import SearchSpec


@dataclass(frozen=True)
class FleetRow:
    alt_agl_m: float
    swath_m: float
    fire_px: float  # pixels on the smallest fire, flat on the ground
    fleet: int | None  # None: no fleet up to the limit makes the deadline
    done_s: float | None
    note: str = ""


def fire_pixels(spec: SearchSpec, alt_agl_m: float) -> float:
    """Pixels a square fire of the smallest size covers, seen from straight
    above at ``alt_agl_m`` (its ground patch alone)."""
    size = min((f.size_m for f in spec.fires), default=8.0)
    return (size * spec.camera.fx_px / alt_agl_m) ** 2


def fleet_table(spec: SearchSpec, deadline_s: float, altitudes: Sequence[float],
                max_aircraft: int = 2000) -> list[FleetRow]:
    """The minimum fleet at each altitude (and the scenario's own first)."""
    from cosim.coverage import area_polygon, completion_s, min_fleet, swath_m

    area = area_polygon(spec.area_ne)
    zones = [area_polygon(z) for z in spec.no_fly_ne]
    out = []
    for alt in [spec.alt_agl_m, *[a for a in altitudes if a != spec.alt_agl_m]]:
        sw = swath_m(alt, spec.camera.hfov_deg)
        note = ""
        px = fire_pixels(spec, alt)
        if px < spec.detection.min_pixels:
            note = f"below the {spec.detection.min_pixels:g} px detection needs"
        try:
            plan = min_fleet(area, spec.airspeed_mps, spec.bank_deg, sw, deadline_s,
                             base_ne=spec.base_ne, overlap=spec.overlap,
                             max_aircraft=max_aircraft, no_fly=zones)
            out.append(FleetRow(alt, sw, px, len(plan.aircraft),
                                completion_s(plan, spec.airspeed_mps), note))
        except ValueError as e:
            out.append(FleetRow(alt, sw, px, None, None, note or str(e)))
    return out


def format_report(spec: SearchSpec, scenario: Any, rows: Sequence[FleetRow],
                  deadline_s: float) -> str:
    from cosim.coverage import turn_radius_m

    area_km2 = _searchable_km2(spec)
    r = turn_radius_m(spec.airspeed_mps, spec.bank_deg)
    cam = spec.camera
    lines = [
        f"{scenario.name}: {area_km2:.1f} km2 to search, base at north {spec.base_ne[0]:.0f} m, "
        f"east {spec.base_ne[1]:.0f} m",
        f"{spec.airspeed_kt:g} kt, {spec.bank_deg:g} deg of bank (turns of {r:.0f} m); camera "
        f"{cam.width_px} x {cam.height_px} px, {cam.hfov_deg:.0f} x {cam.vfov_deg:.0f} deg; "
        f"detection needs {spec.detection.min_pixels:g} px on a "
        f"{min((f.size_m for f in spec.fires), default=8.0):g} m fire",
        f"aircraft in the scenario: {len(spec.rows)}",
        "",
        f"smallest fleet that covers the area within {deadline_s:g} s:",
        f"{'altitude (m AGL)':>17} {'swath (m)':>10} {'fire (px)':>10} {'fleet':>6} "
        f"{'plan done (s)':>14}",
    ]
    for k, row in enumerate(rows):
        alt = f"{row.alt_agl_m:.0f}" + (" (this)" if k == 0 else "")
        fleet = "-" if row.fleet is None else str(row.fleet)
        done = "-" if row.done_s is None else f"{row.done_s:.0f}"
        lines.append(f"{alt:>17} {row.swath_m:>10.0f} {row.fire_px:>10.0f} {fleet:>6} "
                     f"{done:>14}" + (f"  ({row.note})" if row.note else ""))
    return "\n".join(lines)


def _searchable_km2(spec: SearchSpec) -> float:
    from cosim.coverage import area_polygon

    a = area_polygon(spec.area_ne)
    for z in spec.no_fly_ne:
        a = a.difference(area_polygon(z))
    return float(a.area) / 1e6


def default_altitudes(spec: SearchSpec) -> list[float]:
    """Altitudes either side of the scenario's: from a quarter to twice it."""
    base = spec.alt_agl_m
    return sorted({round(base * f / 10.0) * 10.0 for f in (0.25, 0.5, 0.75, 1.5, 2.0)
                   if base * f >= 30.0} | ({150.0, 300.0} if base > 300 else set()))

