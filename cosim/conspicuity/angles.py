"""Visual angles of the critical gap. Beyond a threshold viewing distance the
conspicuity measured as a distance stays constant, so

    CG = tan(alpha) * d = tan(beta) * h

relates the conspicuity angle ``alpha`` measured at viewing distance ``d``
to the angle ``beta`` at altitude ``h``: one measurement predicts the
others. ``d``, ``h`` and ``CG`` share one length unit (metres here).

Scalars in, scalars out. Distances on a screen and their visual angles are
the display profile's (``cosim.core.display``); the critical gap fitted to
trial responses is ``cosim.trials.critical_gap``.
"""

from __future__ import annotations

import math

from cosim.errors import ConfigError


def critical_gap_m(angle_deg: float, distance_m: float) -> float:
    """CG = tan(angle) * distance: the gap a conspicuity angle measured at
    ``distance_m`` (a viewing distance or an altitude) stands for."""
    _check_angle(angle_deg)
    _check_distance(distance_m)
    return math.tan(math.radians(angle_deg)) * distance_m


def angle_for_gap_deg(cg_m: float, distance_m: float) -> float:
    """The angle under which the critical gap ``cg_m`` is seen from ``distance_m``."""
    if not cg_m >= 0:
        raise ConfigError(f"critical gap must be >= 0, got {cg_m!r}")
    _check_distance(distance_m)
    return math.degrees(math.atan(cg_m / distance_m))


def angle_at_altitude_deg(alpha_deg: float, viewing_distance_m: float, alt_m: float) -> float:
    """Predict the conspicuity angle at altitude ``alt_m`` from the angle
    ``alpha_deg`` measured at ``viewing_distance_m``: beta = atan(tan(alpha) d / h)."""
    return angle_for_gap_deg(critical_gap_m(alpha_deg, viewing_distance_m), alt_m)


def angle_at_viewing_distance_deg(beta_deg: float, alt_m: float,
                                  viewing_distance_m: float) -> float:
    """The inverse: the angle at ``viewing_distance_m`` from ``beta_deg`` at ``alt_m``."""
    return angle_for_gap_deg(critical_gap_m(beta_deg, alt_m), viewing_distance_m)


def _check_angle(angle_deg: float) -> None:
    if not 0 <= angle_deg < 90:
        raise ConfigError(f"conspicuity angle must be in [0, 90) degrees, got {angle_deg!r}")


def _check_distance(distance_m: float) -> None:
    if not (distance_m > 0 and math.isfinite(distance_m)):
        raise ConfigError(f"distance must be a finite number > 0, got {distance_m!r}")
