"""Formations: north/east offsets (m) for ``count`` vehicles around an anchor.

``line``: abreast, perpendicular to the heading unless ``bearing_deg`` is
given; ``grid``: ``columns`` abreast, rows behind each other along the
heading; ``circle``: evenly on a circle (radius ``radius_m``, or the one
that gives ``spacing_m`` between neighbours). Every formation is centred on
its anchor.
"""

from __future__ import annotations

import math

import numpy as np

FORMATIONS = ("line", "grid", "circle")


def formation_offsets(kind: str, count: int, spacing_m: float, heading_deg: float,
                      bearing_deg: float | None = None, columns: int | None = None,
                      radius_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return (north_m, east_m) arrays of length ``count``."""
    if kind == "line":
        b = math.radians(heading_deg + 90.0 if bearing_deg is None else bearing_deg)
        s = (np.arange(count) - (count - 1) / 2.0) * spacing_m
        return s * math.cos(b), s * math.sin(b)
    if kind == "grid":
        cols = columns or math.ceil(math.sqrt(count))
        rows = math.ceil(count / cols)
        i = np.arange(count)
        across = (i % cols - (cols - 1) / 2.0) * spacing_m
        behind = (i // cols - (rows - 1) / 2.0) * spacing_m
        h = math.radians(heading_deg)
        # forward = (cos h, sin h); right = (-sin h, cos h); rows go backwards
        north = -behind * math.cos(h) - across * math.sin(h)
        east = -behind * math.sin(h) + across * math.cos(h)
        return north, east
    if kind == "circle":
        r = radius_m if radius_m is not None else (
            spacing_m / (2.0 * math.sin(math.pi / count)) if count > 1 else 0.0)
        a = 2.0 * math.pi * np.arange(count) / count
        return r * np.cos(a), r * np.sin(a)
    raise ValueError(f"unknown formation {kind!r}")
