"""cosim.core.display: a display profile's conversions between pixels,
millimetres and visual angles, and a camera image drawn on it, against
hand-computed numbers."""

from __future__ import annotations

import math

import pytest

import cosim.conspicuity
from cosim.core.display import DisplayProfile, angle_between_deg
from cosim.errors import ConfigError


def test_display_conversions_hand_computed() -> None:
    # 24" 1920 px wide, 531.36 mm image width: pitch 0.27675 mm; viewer at 600 mm
    d = DisplayProfile(viewing_distance_mm=600, width_px=1920, height_px=1080,
                       screen_width_mm=531.36)
    assert d.pitch_mm == pytest.approx(0.27675)
    assert d.px_to_mm(200) == pytest.approx(55.35)
    # atan(55.35 / 600) = 5.27062 deg
    assert d.px_to_deg(200) == pytest.approx(5.27062, abs=1e-5)
    assert d.deg_to_px(5.27062) == pytest.approx(200, abs=1e-3)
    # 10 deg: 600 tan(10) = 105.796 mm = 382.28 px
    assert d.deg_to_mm(10) == pytest.approx(105.796, abs=1e-3)
    assert d.deg_to_px(10) == pytest.approx(382.28, abs=1e-2)


def test_camera_pixels_to_display() -> None:
    d = DisplayProfile(viewing_distance_mm=700, width_px=1920, height_px=1080,
                       pixel_pitch_mm=0.25)
    # 640x480 fitted to 1920x1080: min(3, 2.25) = 2.25 (pillarboxed)
    assert d.scale(640, 480) == pytest.approx(2.25)
    assert d.camera_px_to_display_px(100, 640, 480) == pytest.approx(225)
    # 225 px * 0.25 mm = 56.25 mm at 700 mm: atan(0.080357) = 4.59425 deg
    assert d.camera_px_to_deg(100, 640, 480) == pytest.approx(4.59425, abs=1e-5)


def test_display_profile_lists_every_problem() -> None:
    with pytest.raises(ConfigError) as e:
        DisplayProfile(viewing_distance_mm=0, width_px=0, height_px=1080)
    msg = str(e.value)
    assert "viewing_distance_mm must be > 0" in msg
    assert "width_px must be a whole number >= 1, got 0" in msg
    assert "give exactly one of pixel_pitch_mm and screen_width_mm" in msg


def test_pixels_that_are_not_square() -> None:
    # 1600 x 900 px on 400 x 180 mm: 0.25 mm across a pixel, 0.2 mm down
    d = DisplayProfile(viewing_distance_mm=500, width_px=1600, height_px=900,
                       screen_width_mm=400, screen_height_mm=180)
    assert d.mm_per_px == pytest.approx((0.25, 0.2))
    # a 320 x 240 camera image drawn min(1600 / 320, 900 / 240) = 3.75x, centred: its
    # corner (-0.5, -0.5) is 160 x 120 camera px = 600 x 450 screen px from the centre
    assert d.camera_to_screen_mm(320, 240, -0.5, -0.5) == pytest.approx((-150.0, -90.0))
    assert d.camera_to_screen_mm(320, 240, 159.5, 119.5) == (0.0, 0.0)  # the image centre
    square = DisplayProfile(viewing_distance_mm=500, width_px=1600, height_px=900,
                            pixel_pitch_mm=0.25)
    assert square.mm_per_px == (0.25, 0.25)
    assert square.camera_to_screen_mm(320, 240, -0.5, -0.5) == (-150.0, -112.5)


def test_angle_between_points_on_the_screen() -> None:
    d_mm = 600.0
    x = d_mm * math.tan(math.radians(10.0))
    # from the fixation point: the eccentricity, as mm_to_deg has it
    assert angle_between_deg((0.0, 0.0), (x, 0.0), d_mm) == pytest.approx(10.0, rel=1e-12)
    assert DisplayProfile(viewing_distance_mm=d_mm, width_px=1920, height_px=1080,
                          pixel_pitch_mm=0.25).mm_to_deg(x) == pytest.approx(10.0, rel=1e-12)
    # two points either side of the centre, up the screen: 2 atan(x / d)
    assert angle_between_deg((0.0, -x), (0.0, x), d_mm) == pytest.approx(20.0, rel=1e-12)
    # off axis the same screen distance subtends less: 10 to 20 deg off the line of sight
    far = d_mm * math.tan(math.radians(20.0))
    assert angle_between_deg((x, 0.0), (far, 0.0), d_mm) == pytest.approx(10.0, rel=1e-12)
    assert angle_between_deg((x, x), (x, x), d_mm) == 0.0


def test_screen_height_goes_with_screen_width() -> None:
    with pytest.raises(ConfigError, match="screen_height_mm goes with screen_width_mm"):
        DisplayProfile(viewing_distance_mm=600, width_px=1920, height_px=1080,
                       pixel_pitch_mm=0.25, screen_height_mm=300)
    with pytest.raises(ConfigError, match="screen_height_mm must be > 0, got 0"):
        DisplayProfile(viewing_distance_mm=600, width_px=1920, height_px=1080,
                       screen_width_mm=531, screen_height_mm=0)


def test_conspicuity_has_the_one_display_profile() -> None:
    assert cosim.conspicuity.DisplayProfile is DisplayProfile
