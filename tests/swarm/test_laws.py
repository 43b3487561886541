"""The consensus laws on tiny hand-worked cases (numbers in the comments)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.swarm import laws


def test_centroid_and_distances() -> None:
    # (0,0), (400,0), (0,300), (400,300): centroid (200, 150); every vehicle
    # is sqrt(200^2 + 150^2) = 250 m from it
    p = np.array([[0.0, 0.0], [400.0, 0.0], [0.0, 300.0], [400.0, 300.0]])
    assert laws.centroid(p).tolist() == [200.0, 150.0]
    assert laws.distances_to_centroid_m(p).tolist() == [250.0, 250.0, 250.0, 250.0]


def test_rendezvous_goal_and_speed() -> None:
    # p = (0,0), (1000,0), (0,2000): c = (333.33, 666.67)
    # mu = 0.5: g_0 = 0.5 (c - p_0) + p_0 = (166.67, 333.33)
    # ||p_0 - c|| = sqrt(333.33^2 + 666.67^2) = 745.36; k_s = 0.04 -> 29.81 m/s
    # ||p_2 - c|| = sqrt(333.33^2 + 1333.33^2) = 1374.37 -> 54.97 m/s
    # ||p_1 - c|| = sqrt(666.67^2 + 666.67^2) = 942.81 -> 37.71, but stall 40 wins
    p = np.array([[0.0, 0.0], [1000.0, 0.0], [0.0, 2000.0]])
    goal, speed = laws.rendezvous(p, 0.5, 0.04, [20.0, 40.0, 20.0])
    assert goal[0] == pytest.approx([500 / 3, 1000 / 3])
    assert goal[1] == pytest.approx([1000 - 1000 / 3, 1000 / 3])
    assert speed == pytest.approx([29.814, 40.0, 54.975], abs=1e-3)
    # mu = 1: every goal is the centroid
    goal, _ = laws.rendezvous(p, 1.0, 0.04, [0.0] * 3)
    assert np.allclose(goal, [[1000 / 3, 2000 / 3]] * 3)


def test_anti_rendezvous_goal_and_speed() -> None:
    # p = (0,0), (300,0), (0,0), (0,900)... use a line: (0,0), (100,0), (400,0)
    # c = (166.67, 0); d = 166.67, 66.67, 233.33; max = 233.33
    # mu = -1: g_i = p_i - (c - p_i) = 2 p_i - c: (-166.67,0), (33.33,0), (633.33,0)
    # speed = k_s (max - d_i) with k_s = 0.3: 20, 50, 0 -> stall 25 floors the last
    p = np.array([[0.0, 0.0], [100.0, 0.0], [400.0, 0.0]])
    goal, speed = laws.anti_rendezvous(p, -1.0, 0.3, [25.0, 25.0, 25.0])
    assert goal[:, 0] == pytest.approx([-500 / 3, 100 / 3, 1900 / 3])
    assert goal[:, 1].tolist() == [0.0, 0.0, 0.0]
    assert speed == pytest.approx([25.0, 50.0, 25.0])  # 20 -> stall 25; 50; 0 -> 25
    # the nearest to the centre flies fastest
    assert speed[1] == speed.max()


def test_flocking_goal_and_speed() -> None:
    # p = (0,0), (0,200): c = (0,100); mu = 0.5: rendezvous goals (0,50), (0,150)
    # q = 1000 m at bearing 90 (east) = (0, 1000): goals (0,1050), (0,1150)
    # ||p_0 - g_0|| = 1050, ||p_1 - g_1|| = 950; k_s = 0.05 -> 52.5, 47.5 m/s
    q = laws.q_vector_ne_m(90.0, 1000.0)
    assert q == pytest.approx([0.0, 1000.0])
    p = np.array([[0.0, 0.0], [0.0, 200.0]])
    goal, speed = laws.flocking(p, 0.5, 0.05, q, [30.0, 30.0])
    assert goal == pytest.approx(np.array([[0.0, 1050.0], [0.0, 1150.0]]))
    assert speed == pytest.approx([52.5, 47.5])
    # q as north/east at bearing 45, 100 m: (70.71, 70.71)
    assert laws.q_vector_ne_m(45.0, 100.0) == pytest.approx([70.7107, 70.7107], abs=1e-4)


def test_stall_speed_from_bank() -> None:
    # s_s = k / sqrt(cos phi): 20 level; 20 / sqrt(0.5) = 28.28 at 60 deg;
    # 89.9 deg: 20 / sqrt(0.0017453) = 478.73; beyond 90 deg no lift at all: infinite
    s = laws.stall_speed_mps([20.0] * 5, [0.0, math.radians(60), math.radians(-60),
                                          math.radians(89.9), math.radians(100)])
    assert s[:4] == pytest.approx([20.0, 28.2843, 28.2843, 478.731], abs=1e-3)
    assert s[4] == math.inf


def test_level_stall_constant_from_model_numbers() -> None:
    # uav700: 40 kg, 1.2 m2, CL_max 1.3; sea level rho 1.225:
    # sqrt(2 * 40 * 9.80665 / (1.225 * 1.2 * 1.3)) = sqrt(784.53 / 1.911) = 20.26 m/s (39.4 kt)
    assert float(laws.level_stall_constant_mps(40.0, 1.2, 1.3, 0.0)) == pytest.approx(
        20.262, abs=1e-3)


def test_clip_speed_stall_wins_over_envelope_minimum() -> None:
    # envelope 26..123; stall 30 > 26: the floor is 30; 200 -> 123; 50 stays
    out = laws.clip_speed_mps([10.0, 200.0, 50.0], [30.0, 30.0, 30.0], 26.0, 123.0)
    assert out.tolist() == [30.0, 123.0, 50.0]


def test_float32_speed_never_rounds_below() -> None:
    x = np.array([26.3, 31.1, 40.0, 0.1])
    f = laws.float32_at_least(x)
    assert (f.astype(np.float64) >= x).all()
    assert (f.astype(np.float64) - x < 1e-5).all()
