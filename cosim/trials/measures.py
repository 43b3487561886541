"""Conspicuity measures of a trial response, from the clip's ground truth.

Owns what a trial measures at a key press and what display profile it
accepts (``participant_display``: each value within ``SCREEN_PX_RANGE``,
``SCREEN_MM_RANGE``, ``VIEWING_DISTANCE_MM_RANGE``). The geometry from a
camera pixel to the participant's eye is the display profile's
(``cosim.core.display``): the video is drawn as large as fits the screen
with its aspect ratio kept, centred (letterboxed), the image centre on the
screen centre, where the fixation mark is; screen pixels become millimetres
through the profile's physical size (``screen_width_mm / screen_width_px``
across, ``screen_height_mm / screen_height_px`` down).

- ``onscreen_distance_mm``: from the screen centre to the target centre.
- ``eccentricity_deg = atan(onscreen_distance_mm / viewing_distance_mm)``
  (the eye on the perpendicular through the screen centre).
- ``camera_gap_deg``: the same gap seen from the camera instead of the eye:
  ``atan(gap_px / f_px)``, the camera-pixel distance between where the eyes
  are (the image centre under the fixation mark, or the tracked arrow) and
  the target centre over the camera's focal length (``Clip.focal_px``; None
  when the clip's field of view is not known). With the eyes on the
  centre it is the target's angle off the optical axis (the ground truth's
  own ``eccentricity_deg``); with them on a tracked arrow it is not the
  angle between two rays at the camera but the gap in the image plane in
  focal lengths, as an angle: its tangent is what the relation below needs.
- ``target_depth_m``: the target centre's distance along the camera's
  optical axis (``GtFrame.depth_m``: the ground truth's ``range_m *
  cos(eccentricity_deg)``; None when the ground truth does not say).
  ``target_depth_m * tan(camera_gap)`` is the distance, in the plane through
  the target perpendicular to the optical axis, between the point looked at
  and the target: for a level nadir camera the distance on the ground (at
  the height of the target's centre), the ``tan(beta) * h`` of the
  critical-gap relation (``beta`` the conspicuity angle at altitude ``h``)
  with ``h`` the camera's height above the target's centre, not above the
  ground (a truck's centre is 1.75 m up: 6 % at 30 m).
- ``target_angular_size_deg``: the visual angle of the target's on-screen
  bounding box (clipped to the image), the larger of the angles its two
  diagonals subtend at the eye (exact off axis too).

Everything here is computed on the server from the stored ground truth and
the session's display profile, never taken from the browser. Nothing here
reads files or knows about the web app.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cosim.core.display import DisplayProfile, angle_between_deg
from cosim.errors import ConfigError
from cosim.trials.study import Clip

#: what a display profile may hold (a phone to a projection wall; 0.1 to 20 m away)
SCREEN_PX_RANGE = (100, 20_000)
SCREEN_MM_RANGE = (20.0, 20_000.0)
VIEWING_DISTANCE_MM_RANGE = (100.0, 20_000.0)


def participant_display(screen_width_px: int, screen_height_px: int, screen_width_mm: float,
                        screen_height_mm: float, viewing_distance_mm: float) -> DisplayProfile:
    """The participant's screen and where their eyes are, as a trial takes
    them (a session's profile, or the page as the browser drew it): each
    value within what a trial may hold, every problem listed at once in a
    ``ConfigError``."""
    problems = []
    lo, hi = SCREEN_PX_RANGE
    for name, v in (("screen_width_px", screen_width_px),
                    ("screen_height_px", screen_height_px)):
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            problems.append(f"{name} must be a whole number in [{lo}, {hi}], got {v!r}")
    for name, f, (lo_f, hi_f) in (
            ("screen_width_mm", screen_width_mm, SCREEN_MM_RANGE),
            ("screen_height_mm", screen_height_mm, SCREEN_MM_RANGE),
            ("viewing_distance_mm", viewing_distance_mm, VIEWING_DISTANCE_MM_RANGE)):
        if (isinstance(f, bool) or not isinstance(f, (int, float))
                or not math.isfinite(f) or not lo_f <= f <= hi_f):
            problems.append(f"{name} must be a number in [{lo_f:g}, {hi_f:g}], got {f!r}")
    if problems:
        raise ConfigError([f"display profile: {p}" for p in problems])
    return DisplayProfile(viewing_distance_mm=viewing_distance_mm, width_px=screen_width_px,
                          height_px=screen_height_px, screen_width_mm=screen_width_mm,
                          screen_height_mm=screen_height_mm)


@dataclass(frozen=True)
class Measures:
    frame: int  # the ground truth's frame number
    time_s: float
    target_in_view: bool
    screen_x_mm: float | None  # target centre from the screen centre, right
    screen_y_mm: float | None  # ... and down
    onscreen_distance_mm: float | None
    eccentricity_deg: float | None
    target_angular_size_deg: float | None
    camera_gap_deg: float | None = None
    target_depth_m: float | None = None  # the target centre along the optical axis


def measures_at(clip: Clip, frame_index: int, display: DisplayProfile) -> Measures:
    """The measures at video frame ``frame_index`` of ``clip`` on ``display``."""
    if not 0 <= frame_index < len(clip.frames):
        raise ValueError(f"clip {clip.id}: frame index {frame_index} outside 0.."
                         f"{len(clip.frames) - 1}")
    g = clip.frames[frame_index]
    w, h = clip.width_px, clip.height_px
    x_mm = y_mm = dist = ecc = size = gap = None
    if g.center_px is not None:
        x_mm, y_mm = display.camera_to_screen_mm(w, h, *g.center_px)
        dist = math.hypot(x_mm, y_mm)
        ecc = display.mm_to_deg(dist)
        f = clip.focal_px
        if f is not None:
            off = math.hypot(g.center_px[0] - (w - 1) / 2, g.center_px[1] - (h - 1) / 2)
            gap = math.degrees(math.atan(off / f))
    if g.bbox_px is not None and g.in_view:
        x0, y0, x1, y1 = g.bbox_px
        x0, x1 = max(x0, -0.5), min(x1, w - 0.5)
        y0, y1 = max(y0, -0.5), min(y1, h - 0.5)
        if x1 >= x0 and y1 >= y0:
            c00 = display.camera_to_screen_mm(w, h, x0, y0)
            c11 = display.camera_to_screen_mm(w, h, x1, y1)
            c01 = display.camera_to_screen_mm(w, h, x0, y1)
            c10 = display.camera_to_screen_mm(w, h, x1, y0)
            d = display.viewing_distance_mm
            size = max(angle_between_deg(c00, c11, d), angle_between_deg(c01, c10, d))
    return Measures(frame=g.frame, time_s=g.time_s, target_in_view=g.in_view,
                    screen_x_mm=x_mm, screen_y_mm=y_mm, onscreen_distance_mm=dist,
                    eccentricity_deg=ecc, target_angular_size_deg=size, camera_gap_deg=gap,
                    target_depth_m=g.depth_m)


def arrow_offset_mm(speed_deg_s: float, elapsed_ms: float, viewing_distance_mm: float) -> float:
    """How far (mm on the screen) a ``track`` arrow has gone from the target
    after ``elapsed_ms``: its angle from the target grows at ``speed_deg_s``
    as seen from the eye in front of the target, ``D tan(speed t)`` (capped
    short of 90 degrees)."""
    a = min(math.radians(speed_deg_s * max(elapsed_ms, 0.0) / 1000.0), math.radians(89.0))
    return viewing_distance_mm * math.tan(a)


def track_measures(clip: Clip, display: DisplayProfile, direction: tuple[float, float],
                   speed_deg_s: float, elapsed_ms: float) -> Measures:
    """A ``track`` sub-trial's measures at the key press: the clip still at its
    ``still_frame``, the participant's eyes on the arrow that left the target
    ``elapsed_ms`` before in ``direction``; the eccentricity is the target's
    angle from the arrow, the on-screen distance the arrow's from the target,
    the depth the still frame's."""
    m = measures_at(clip, clip.still_frame, display)
    if m.screen_x_mm is None or m.screen_y_mm is None:
        return m
    r = arrow_offset_mm(speed_deg_s, elapsed_ms, display.viewing_distance_mm)
    target = (m.screen_x_mm, m.screen_y_mm)
    arrow = (target[0] + r * direction[0], target[1] + r * direction[1])
    gap = None
    f = clip.focal_px
    if f is not None:  # the arrow's way back in camera pixels
        s = display.scale(clip.width_px, clip.height_px)
        mx, my = display.mm_per_px
        gap = math.degrees(math.atan(
            math.hypot(r * direction[0] / (s * mx), r * direction[1] / (s * my)) / f))
    return Measures(frame=m.frame, time_s=m.time_s, target_in_view=m.target_in_view,
                    screen_x_mm=m.screen_x_mm, screen_y_mm=m.screen_y_mm,
                    onscreen_distance_mm=r,
                    eccentricity_deg=angle_between_deg(arrow, target,
                                                       display.viewing_distance_mm),
                    target_angular_size_deg=m.target_angular_size_deg, camera_gap_deg=gap,
                    target_depth_m=m.target_depth_m)
