"""Visual angles: the critical gap and on-screen distance <-> visual angle.

**Critical gap** (DESIGN.md 3.5). Beyond a threshold viewing distance the
conspicuity measured as a distance stays constant, so

    CG = tan(alpha) * d = tan(beta) * h

relates the conspicuity angle ``alpha`` measured at viewing distance ``d``
to the angle ``beta`` at altitude ``h``: one measurement predicts the
others. ``d``, ``h`` and ``CG`` share one length unit (metres here).

**Display profile.** An angle on the screen is measured from the observer's
eye, looking straight at the fixation point (the screen centre) from
``viewing_distance_mm``: a point ``s`` mm from the fixation point lies
``atan(s / d)`` off the line of sight. Pixels become millimetres through the
pixel pitch (given directly, or as the screen's width in mm over its width in
pixels). A camera image shown scaled to fit the display (aspect kept) maps
camera pixels to display pixels by one factor, ``min(W/w, H/h)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


@dataclass(frozen=True)
class DisplayProfile:
    """A screen and where the observer sits.

    Give the pixel pitch as ``pixel_pitch_mm``, or ``screen_width_mm`` (the
    visible image width) from which pitch = screen_width_mm / width_px.
    """

    viewing_distance_mm: float
    width_px: int
    height_px: int
    pixel_pitch_mm: float | None = None
    screen_width_mm: float | None = None

    def __post_init__(self) -> None:
        problems = []
        if not (self.viewing_distance_mm > 0 and math.isfinite(self.viewing_distance_mm)):
            problems.append(f"viewing_distance_mm must be > 0, got {self.viewing_distance_mm!r}")
        for name in ("width_px", "height_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                problems.append(f"{name} must be a whole number >= 1, got {v!r}")
        if (self.pixel_pitch_mm is None) == (self.screen_width_mm is None):
            problems.append("give exactly one of pixel_pitch_mm and screen_width_mm")
        for name in ("pixel_pitch_mm", "screen_width_mm"):
            v = getattr(self, name)
            if v is not None and not (v > 0 and math.isfinite(v)):
                problems.append(f"{name} must be > 0, got {v!r}")
        if problems:
            raise ConfigError([f"display profile: {p}" for p in problems])

    @property
    def pitch_mm(self) -> float:
        """Millimetres per display pixel."""
        if self.pixel_pitch_mm is not None:
            return self.pixel_pitch_mm
        assert self.screen_width_mm is not None
        return self.screen_width_mm / self.width_px

    # --- distance on the screen <-> visual angle (from the fixation point) ---
    def px_to_mm(self, px: float) -> float:
        return px * self.pitch_mm

    def mm_to_px(self, mm: float) -> float:
        return mm / self.pitch_mm

    def mm_to_deg(self, mm: float) -> float:
        """Angle off the line of sight of a point ``mm`` from the fixation point."""
        return math.degrees(math.atan(mm / self.viewing_distance_mm))

    def deg_to_mm(self, deg: float) -> float:
        if not -90 < deg < 90:
            raise ConfigError(f"angle must be in (-90, 90) degrees, got {deg!r}")
        return math.tan(math.radians(deg)) * self.viewing_distance_mm

    def px_to_deg(self, px: float) -> float:
        """Angle of a point ``px`` display pixels from the fixation point."""
        return self.mm_to_deg(self.px_to_mm(px))

    def deg_to_px(self, deg: float) -> float:
        return self.mm_to_px(self.deg_to_mm(deg))

    # --- camera image shown on the display ---
    def scale(self, camera_width_px: int, camera_height_px: int) -> float:
        """Display pixels per camera pixel when the image is scaled to fit
        (aspect ratio kept, letterboxed): min(W / w, H / h)."""
        if camera_width_px < 1 or camera_height_px < 1:
            raise ConfigError(f"camera image size must be >= 1 px, got "
                              f"{camera_width_px} x {camera_height_px}")
        return min(self.width_px / camera_width_px, self.height_px / camera_height_px)

    def camera_px_to_display_px(self, px: float, camera_width_px: int,
                                camera_height_px: int) -> float:
        return px * self.scale(camera_width_px, camera_height_px)

    def camera_px_to_deg(self, px: float, camera_width_px: int, camera_height_px: int) -> float:
        """Visual angle of a point ``px`` camera pixels from the image centre
        (e.g. the ground truth's ``eccentricity_px``) on this display."""
        return self.px_to_deg(self.camera_px_to_display_px(px, camera_width_px,
                                                           camera_height_px))
