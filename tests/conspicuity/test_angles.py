"""The critical gap's angles against hand-computed numbers."""

from __future__ import annotations

import pytest

from cosim.conspicuity import (
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
