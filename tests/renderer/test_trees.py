"""The procedural ground's trees are drawn whole: a hedgerow's or a wood's tree is
there or not as a whole, never cut by the edge of its wood, its hedgerow band, its
field or its cell."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.renderer import texture

SEED = 7  # scenarios/cameras/flyover.yaml's


def _trees(n0: float, n1: float, e0: float, e1: float) -> tuple[np.ndarray, ...]:
    """Every tree cell's centre (north, east), radius and tone inside the box."""
    kn = np.arange(np.floor(n0 / texture.TREE_M), np.ceil(n1 / texture.TREE_M))[:, None]
    ke = np.arange(np.floor(e0 / texture.TREE_M), np.ceil(e1 / texture.TREE_M))[None, :]
    tn, te, r, tone = texture._tree_cells(kn, ke, SEED)[2:6]
    inside = (tn > n0) & (tn < n1) & (te > e0) & (te < e1)
    return tn[inside], te[inside], r[inside], tone[inside]


# the hedgerows along the field edge the flyover's camera crosses; a wood's edge
@pytest.mark.parametrize("south_m, west_m", [(-160.0, -60.0), (330.0, -60.0)])
@pytest.mark.parametrize("step_m", [0.1, 0.25])
def test_every_tree_is_drawn_whole(south_m: float, west_m: float, step_m: float) -> None:
    side_m = 120.0
    n = -np.arange(-south_m - side_m, -south_m, step_m)[:, None]  # north descending
    e = np.arange(west_m, west_m + side_m, step_m)[None, :]
    rgb = texture.macro_rgb(n, e, step_m, SEED)
    # a sample a step inside a tree's outline has a tree's colour: the tree colour
    # times a tone, and no field, road or (where another lies over it) other tree's
    ratio = rgb / texture._TREE[:, None, None]
    tree_coloured = (np.ptp(ratio, axis=0) < 1e-3) & (ratio[0] > 0.7) & (ratio[0] < 1.3)
    drawn = 0
    for tn, te, r, tone in zip(*_trees(south_m + 5, south_m + side_m - 5, west_m + 5,
                                       west_m + side_m - 5)):
        rows = slice(int((-tn - r + south_m + side_m) / step_m),
                     int((-tn + r + south_m + side_m) / step_m) + 2)
        cols = slice(int((te - r - west_m) / step_m), int((te + r - west_m) / step_m) + 2)
        inner = np.hypot(n[rows] - tn, e[:, cols] - te) < r - step_m
        own = np.abs(ratio[0][rows, cols] - tone) < 1e-3
        if not (inner & own).any():  # not drawn (or under others)
            continue
        drawn += 1
        share = (tree_coloured[rows, cols] & inner).sum() / inner.sum()
        assert share == 1.0, f"tree at north {tn:.1f}, east {te:.1f} (r {r:.1f} m) cut: " \
                             f"{share:.0%} of its disc drawn"
    assert drawn >= 5


@pytest.mark.parametrize("step_m", [0.25, 3.2])
def test_overlapping_crowns_are_laid_alike_whatever_the_grid(step_m: float) -> None:
    # the same samples in a grid and in a part of it (two tiles over one wood) get
    # the same trees, the same coverage and the same shade, bit for bit
    n = 375.0 - (np.arange(-200, 200) + 0.5) * step_m  # about a wood's edge, north 375 m
    e = (np.arange(-200, 200) + 0.5) * step_m
    whole = np.zeros((2, len(n) * len(e)), np.float32)
    got = texture._trees(n, e, step_m, SEED, lambda: np.zeros((len(n), len(e))))
    assert got is not None and len(got[0]) > 500
    whole[:, got[0]] = got[1:]
    whole = whole.reshape(2, len(n), len(e))[:, 130:290, 70:330]
    part = np.zeros((2, 160 * 260), np.float32)
    got = texture._trees(n[130:290], e[70:330], step_m, SEED,
                         lambda: np.zeros((160, 260)))
    assert got is not None
    part[:, got[0]] = got[1:]
    assert np.array_equal(part.reshape(whole.shape), whole)


def test_noise_at_scattered_points_is_the_value_noise() -> None:
    from cosim.renderer.noise import value_noise, value_noise_at

    rng = np.random.default_rng(3)
    x, y = rng.uniform(-900.0, 900.0, 5000), rng.uniform(-40.0, 60.0, 5000)
    a, b = value_noise_at(x, y, 17, 18)
    assert np.array_equal(a, value_noise(x, y, 17)) and np.array_equal(b, value_noise(x, y, 18))
