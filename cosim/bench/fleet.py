"""The fleet every bench measures: N aircraft in a grid at 1000 m, 100 kt,
built as ``cosim run`` builds them (``bench_specs``), and the rates'
check."""

from __future__ import annotations

from cosim.core.geo import LocalFrame
from cosim.core.state import VehicleSpec
from cosim.core.units import KT_TO_MPS
from cosim.scenario.formation import formation_offsets
from cosim.vehicles import DEFAULT_CLASS
from cosim.vehicles.jsb import find_model
from cosim.vehicles.registry import get_class
from cosim.world.model import World

#: where the benchmark's fleets fly
ORIGIN = (37.4, -122.0, 0.0)


def bench_specs(n: int, model: str = "c172p", spacing_m: float = 300.0,
                vehicle_class: str | None = None) -> list[VehicleSpec]:
    """N vehicles in a grid at 1000 m, 100 kt, heading north, of the model's
    own class or ``vehicle_class`` (a batched class gets what of the world it
    needs, as a scenario would give it)."""
    m = find_model(model)
    cls = vehicle_class or m.profile.get("class", DEFAULT_CLASS)
    vc = get_class(cls)
    if vc.model_kind == "batched":
        vc.resolve_model(model, ())  # refuses a model the class cannot fly
    north, east = formation_offsets("grid", n, spacing_m, 0.0)
    lat, lon, _ = LocalFrame(*ORIGIN).ned_to_geodetic(north, east, 0.0)
    specs = [VehicleSpec(id=f"b{i:04d}", model=m.name, aircraft_dir=m.aircraft_dir,
                         model_source=m.source, lat_deg=float(lat[i]), lon_deg=float(lon[i]),
                         alt_msl_m=1000.0, heading_deg=0.0, airspeed_mps=100 * KT_TO_MPS,
                         random_seed=i, profile=m.profile, vehicle_class=cls)
             for i in range(n)]
    return [vc.with_world(v, World(), {}, ORIGIN) for v in specs]


def check_rates(physics_hz: float, control_hz: float) -> int:
    """Physics ticks per exchange; ``ValueError`` quoting both rates unless
    ``control_hz`` divides ``physics_hz``."""
    q = physics_hz / control_hz
    if not (abs(q - round(q)) < 1e-9 and round(q) >= 1):
        raise ValueError(f"control_hz {control_hz:g} must divide physics_hz {physics_hz:g} "
                         f"(a whole number of physics ticks per exchange)")
    return round(q)
