"""The ``obstacles:`` section's polygon checks: edges that cross, against
the pairwise rule, and the work a file of the most obstacles asks for."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from cosim.scenario.reader import Reader
from cosim.world.obstacles import (
    MAX_OBSTACLES,
    MAX_VERTICES,
    _self_crossing,
    parse_obstacles,
    segments_cross,
)


class _Info:
    """The parts of a section's context the parser uses."""

    def __init__(self) -> None:
        self.msgs: list[tuple[tuple[Any, ...], str]] = []

    def err(self, path: tuple[Any, ...], msg: str) -> None:
        self.msgs.append((path, msg))

    def reader(self, d: Any, path: tuple[Any, ...], allowed: tuple[str, ...]) -> Reader:
        return Reader(self, d, path, allowed)  # type: ignore[arg-type]


def _pairwise(a: np.ndarray) -> bool:
    """Edges crossing, one pair at a time by ``segments_cross``."""
    n = len(a)
    return any(segments_cross(a[i], a[(i + 1) % n], a[j], a[(j + 1) % n])
               for i in range(n) for j in range(i + 2, n) if not (i == 0 and j == n - 1))


def test_crossing_edges_are_found_as_the_pairwise_rule_finds_them() -> None:
    rng = np.random.default_rng(5)
    found = 0
    for _ in range(300):
        n = int(rng.integers(3, 12))
        a = rng.uniform(-10, 10, (n, 2)).round(1)  # on a grid: touching and collinear too
        if rng.random() < 0.5:  # a star-shaped polygon: simple
            ang = np.sort(rng.uniform(0, 2 * math.pi, n))
            a = np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(1, 10, (n, 1))
        assert _self_crossing(a) == _pairwise(a)
        found += _self_crossing(a)
    assert 50 < found < 250


def test_the_most_obstacles_of_the_most_corners_are_checked_in_well_under_a_second() -> None:
    """1000 polygons of 64 corners: 1.95 million pairs of edges (8 s of CPU one
    pair at a time)."""
    node = [{"id": f"o{i}", "polygon": [[(i // 32) * 100.0 + 30 * math.cos(2 * math.pi * j / 64),
                                         (i % 32) * 100.0 + 30 * math.sin(2 * math.pi * j / 64)]
                                        for j in range(MAX_VERTICES)]}
            for i in range(MAX_OBSTACLES)]
    info = _Info()
    t0 = time.process_time()
    got = parse_obstacles(info, node, ("obstacles",))  # type: ignore[arg-type]
    took_s = time.process_time() - t0
    assert not info.msgs and len(got) == MAX_OBSTACLES
    assert took_s < 1.0, took_s
