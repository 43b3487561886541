"""coverage: planning the search of an area by a fixed-wing fleet.

``planner`` splits a search area among the aircraft and lays out each one's
lawnmower lanes, turns no tighter than the aircraft can fly (``dubins``)
and its transit from the base. Geometry only: it owns no simulation state
and sends nothing.
"""

from cosim.coverage.dubins import DubinsPath, shortest
from cosim.coverage.planner import (
    AircraftPlan,
    CoveragePlan,
    area_polygon,
    completion_s,
    max_alt_for_detection_m,
    min_fleet,
    plan_coverage,
    swath_m,
    turn_radius_m,
)

__all__ = ["AircraftPlan", "CoveragePlan", "DubinsPath", "area_polygon", "completion_s",
           "max_alt_for_detection_m", "min_fleet", "plan_coverage", "shortest", "swath_m",
           "turn_radius_m"]
