"""coverage: planning the search of an area by a fixed-wing fleet.

``planner`` splits a search area among the aircraft and lays out each one's
lawnmower lanes (``lanes``), turns no tighter than the aircraft can fly
(``dubins``) and its transit from the base, detouring around no-fly zones
(``airspace``). Geometry only: it owns no simulation state and sends
nothing.
"""

from cosim.coverage.dubins import DubinsChain, DubinsPath, Flight, candidates, shortest
from cosim.coverage.planner import (
    AircraftPlan,
    CoveragePlan,
    area_polygon,
    completion_s,
    max_alt_for_detection_m,
    min_fleet,
    no_fly_polygon,
    plan_coverage,
    swath_m,
    turn_radius_m,
)

__all__ = ["AircraftPlan", "CoveragePlan", "DubinsChain", "DubinsPath", "Flight", "area_polygon",
           "candidates", "completion_s", "max_alt_for_detection_m", "min_fleet", "no_fly_polygon",
           "plan_coverage", "shortest", "swath_m", "turn_radius_m"]
