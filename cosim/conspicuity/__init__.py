"""conspicuity: measurements for the conspicuity experiments.

Owns the analysis of the renderer's per-frame ground truth (how long each
target is visible, pass by pass) and the critical-gap relation between a
conspicuity angle measured at a viewing distance and the angle at a flight
altitude; and how natural a frame is, the spectral exponent of its luminance
(``spectrum``). The display profile (on-screen distance <-> visual angle) is the
kernel's, ``cosim.core.display``, and part of this package's API. It reads
run folders; it never renders, steps an FDM or writes into a run's own files
(``cosim visibility`` adds ``visibility.csv``).
"""

from cosim.conspicuity.angles import (
    angle_at_altitude_deg,
    angle_at_viewing_distance_deg,
    angle_for_gap_deg,
    critical_gap_m,
)
from cosim.conspicuity.visibility import (
    Pass,
    TargetVisibility,
    passes,
    read_ground_truth,
    run_visibility,
    visibility,
    write_visibility_csv,
)
from cosim.core.display import DisplayProfile

__all__ = ["DisplayProfile", "Pass", "TargetVisibility", "angle_at_altitude_deg",
           "angle_at_viewing_distance_deg", "angle_for_gap_deg", "critical_gap_m", "passes",
           "read_ground_truth", "run_visibility", "visibility", "write_visibility_csv"]
