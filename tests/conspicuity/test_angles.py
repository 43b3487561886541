"""Critical gap and display conversions against hand-computed numbers."""

from __future__ import annotations

import pytest

from cosim.conspicuity import (
    DisplayProfile,
    angle_at_altitude_deg,
    angle_at_viewing_distance_deg,
    angle_for_gap_deg,
    critical_gap_m,
)
from cosim.errors import ConfigError


def test_critical_gap_hand_computed() -> None:
    # tan(10 deg) = 0.176327; at 0.6 m viewing distance: 0.105796 m
    assert critical_gap_m(10.0, 0.6) == pytest.approx(0.105796, abs=1e-6)
    # 45 deg at 100 m is 100 m
    assert critical_gap_m(45.0, 100.0) == pytest.approx(100.0)
    # CG 0.105796 m seen from 1.2 m: atan(0.0881635) = 5.0384 deg
    assert angle_for_gap_deg(0.105796, 1.2) == pytest.approx(5.0384, abs=1e-4)


def test_angle_at_altitude_and_inverse() -> None:
    # alpha 10 deg at d = 0.6 m -> CG 0.105796; at h = 0.3: atan(0.352654) = 19.4254 deg
    beta = angle_at_altitude_deg(10.0, 0.6, 0.3)
    assert beta == pytest.approx(19.4254, abs=1e-4)
    assert angle_at_viewing_distance_deg(beta, 0.3, 0.6) == pytest.approx(10.0, abs=1e-9)
    # round trip over several distances
    for d, h in [(0.5, 30.0), (2.0, 500.0), (1.0, 1.0)]:
        b = angle_at_altitude_deg(3.0, d, h)
        assert angle_at_viewing_distance_deg(b, h, d) == pytest.approx(3.0, rel=1e-12)


def test_critical_gap_rejects_bad_input() -> None:
    with pytest.raises(ConfigError, match=r"angle must be in \[0, 90\) degrees, got 95"):
        critical_gap_m(95, 1.0)
    with pytest.raises(ConfigError, match="distance must be a finite number > 0, got 0"):
        critical_gap_m(5, 0)


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
