"""Display geometry: a screen's pixels and millimetres, and the visual angle
under which an eye in front of it sees them.

A display profile (``DisplayProfile``) is a screen and where the observer
sits: ``viewing_distance_mm`` from the screen, the eye on the perpendicular
through the screen centre, looking at the fixation point there. Pixels
become millimetres through the pixel pitch: given directly
(``pixel_pitch_mm``, square pixels), or as the screen's width in mm over its
width in pixels (``screen_width_mm``), and its height over its height in
pixels (``screen_height_mm``) when the pixels are not square.

- A point ``s`` mm from the fixation point lies ``atan(s / d)`` off the
  line of sight: its eccentricity (``mm_to_deg``, and back ``deg_to_mm``).
- A camera image drawn as large as fits the screen, aspect ratio kept and
  centred (letterboxed), maps camera pixels to display pixels by one factor,
  ``min(W / w, H / h)`` (``scale``). Camera pixel coordinates put pixel
  centres at integers (the image spans ``[-0.5, w - 0.5]``,
  ``cosim.core.camera``), so the image centre ``((w - 1) / 2, (h - 1) / 2)``
  is the screen centre (``camera_to_screen_mm``: the on-screen distance
  from the fixation point).
- Two points on the screen subtend at the eye the angle between the rays to
  them (``angle_between_deg``, exact off axis too: a target's angular size
  from the diagonals of its box).

Numbers in, numbers out: nothing here knows a trial, a clip, its ground
truth or a file. What displays a trial accepts is the trial server's
(``cosim.trials.measures``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cosim.errors import ConfigError


@dataclass(frozen=True)
class DisplayProfile:
    """A screen and where the observer sits.

    Give the pixel pitch as ``pixel_pitch_mm``, or ``screen_width_mm`` (the
    visible image width) from which pitch = screen_width_mm / width_px; with
    ``screen_width_mm``, ``screen_height_mm`` (the visible image height) when
    the pixels are not square: the pitch down the screen is then
    screen_height_mm / height_px. Distances in pixels without a direction
    (``px_to_mm``, ``px_to_deg``, ``camera_px_to_deg`` and their inverses) are
    along a row.
    """

    viewing_distance_mm: float
    width_px: int
    height_px: int
    pixel_pitch_mm: float | None = None
    screen_width_mm: float | None = None
    screen_height_mm: float | None = None

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
        if self.screen_height_mm is not None and self.screen_width_mm is None:
            problems.append("screen_height_mm goes with screen_width_mm (pixel_pitch_mm is "
                            "for square pixels)")
        for name in ("pixel_pitch_mm", "screen_width_mm", "screen_height_mm"):
            v = getattr(self, name)
            if v is not None and not (v > 0 and math.isfinite(v)):
                problems.append(f"{name} must be > 0, got {v!r}")
        if problems:
            raise ConfigError([f"display profile: {p}" for p in problems])

    @property
    def pitch_mm(self) -> float:
        """Millimetres per display pixel (across)."""
        if self.pixel_pitch_mm is not None:
            return self.pixel_pitch_mm
        assert self.screen_width_mm is not None
        return self.screen_width_mm / self.width_px

    @property
    def mm_per_px(self) -> tuple[float, float]:
        """Millimetres per display pixel across and down."""
        if self.screen_height_mm is None:
            return self.pitch_mm, self.pitch_mm
        return self.pitch_mm, self.screen_height_mm / self.height_px

    # --- distance on the screen <-> visual angle (from the fixation point) ---
    def px_to_mm(self, px: float) -> float:
        return px * self.pitch_mm

    def mm_to_px(self, mm: float) -> float:
        return mm / self.pitch_mm

    def mm_to_deg(self, mm: float) -> float:
        """Angle off the line of sight of a point ``mm`` from the fixation
        point: its eccentricity."""
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

    def camera_to_screen_mm(self, camera_width_px: int, camera_height_px: int, u_px: float,
                            v_px: float) -> tuple[float, float]:
        """Camera pixel (u, v) -> millimetres right of and below the screen
        centre, the image drawn as large as fits (``scale``) and centred."""
        s = self.scale(camera_width_px, camera_height_px)
        mx, my = self.mm_per_px
        return ((u_px - (camera_width_px - 1) / 2) * s * mx,
                (v_px - (camera_height_px - 1) / 2) * s * my)


def angle_between_deg(a_mm: tuple[float, float], b_mm: tuple[float, float],
                      viewing_distance_mm: float) -> float:
    """Visual angle between two points on the screen (mm from its centre)
    seen from ``viewing_distance_mm`` in front of the centre."""
    d = viewing_distance_mm
    ax, ay = a_mm
    bx, by = b_mm
    dot = ax * bx + ay * by + d * d
    cross = math.sqrt((ay * d - d * by) ** 2 + (d * bx - ax * d) ** 2 + (ax * by - ay * bx) ** 2)
    return math.degrees(math.atan2(cross, dot))
