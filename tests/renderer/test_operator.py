"""The operator view's map explains itself: a legend with each symbol it draws,
a scale bar of a round length whose pixels match the map's scale, a title and
a north arrow, at the sizes the operator view gives it."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.renderer.operator import (
    AIRCRAFT_BGR,
    BACKGROUND,
    LEGEND,
    TARGET_BGR,
    map_panel,
    scale_bar,
)


def _has(img: np.ndarray, bgr: tuple[int, int, int]) -> bool:
    return bool((img == np.array(bgr, np.uint8)).all(axis=-1).any())


def _light(part: np.ndarray) -> int:
    """Pixels light in every channel: text and lines."""
    return int((part.min(axis=-1) > 150).sum())


@pytest.mark.parametrize("w, h", [(480, 360), (240, 180)])  # one camera; nine
def test_the_map_has_a_legend_scale_bar_title_and_north_arrow(w: int, h: int) -> None:
    # a vehicle and a target in the top right quarter: the corners hold only the map's keys
    vehicles = np.array([[400.0, 300.0], [420.0, 330.0]])
    targets = np.array([[380.0, 380.0]])
    img = map_panel(w, h, vehicles, targets, ["uav1", "uav2"])
    assert img.shape == (h, w, 3)
    assert {s for s, _, _ in LEGEND} == {"dot", "cross"}  # every symbol the map draws
    legend = img[h // 2:, : w // 3]  # bottom left
    assert _has(legend, AIRCRAFT_BGR) and _has(legend, TARGET_BGR)
    assert _light(img[: h // 8, : w // 3]) > 20  # the title
    assert _light(img[: h // 5, -w // 6:]) > 10  # N and its arrow
    assert _light(img[-h // 8:, -w // 3:]) > 20  # the scale bar and its length
    assert (img[h // 3: 2 * h // 3, : w // 4] == BACKGROUND).all()  # nothing stray elsewhere


def test_the_scale_bar_is_a_round_length_at_the_map_scale() -> None:
    for px_per_m in (0.01, 0.37, 1.0, 2.9, 40.0):
        for width in (160, 240, 480):
            metres, px = scale_bar(px_per_m, width)
            mantissa = metres / 10 ** np.floor(np.log10(metres))
            assert round(mantissa, 9) in (1.0, 2.0, 5.0)
            assert abs(px - metres * px_per_m) <= 0.5
            assert width / 10 <= px <= width / 4 + 0.5
