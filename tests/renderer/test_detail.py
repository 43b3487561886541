"""The ground's fine detail (cosim.renderer.detail): its spectrum is the natural
f**-2 law over the octaves it spans, its litter is tinted by kind, it repeats
seamlessly, it is a pure function of the seed and it leaves the scales above
its high-pass to the macro brightness."""

import numpy as np

from cosim.conspicuity.spectrum import luminance, spectral_exponent
from cosim.renderer import detail
from cosim.renderer.texture import ProceduralTiles

REC709 = np.array([0.2126, 0.7152, 0.0722])


def test_spectral_exponent_over_its_octaves_is_natural() -> None:
    # 32 px to 4 px at the base level (1.6 m to 20 cm at 5 cm a pixel), inside the
    # span of the litter (ellipses 2 to 24 px across) and the growth octaves; the
    # smoothed value-noise octaves of the earlier texture gave 2.7 to 2.8 here
    for seed in (0, 7):
        base = detail.detail_pyramid(seed)[0].astype(np.float64) @ REC709
        got = spectral_exponent(base, lo_cpi=16, hi_nyquist=0.5)
        assert abs(got.exponent - 2.0) < 0.25, (seed, got.exponent)
        assert got.r2 > 0.95
        assert 0.1 < base.std() < 0.3  # a visible texture, a multiplier about 1
        assert abs(base.mean() - 1.0) < 0.02


def test_a_level_0_tile_has_the_natural_exponent_at_fine_scales() -> None:
    # the detail as the ground's tiles carry it (macro colour times the detail):
    # 32 px to 4 px of a 5 cm level-0 tile, where the macro colour (a 0.5 m lattice)
    # has little power; the version 8 texture's tiles gave 2.7 to 3.0 here
    tiles = ProceduralTiles(0, 0.05, 256)
    out = np.empty((256, 256, 4), np.uint8)
    for ti, tj in ((0, 0), (3, 5), (-7, 2)):
        lum = luminance(tiles.make(0, ti, tj, out)[..., 2::-1])
        got = spectral_exponent(lum, lo_cpi=8, hi_nyquist=0.5).exponent
        assert abs(got - 2.0) < 0.3, ((ti, tj), got)


def test_litter_is_tinted_by_kind() -> None:
    # each kind's tint changes the hue, not the luminance; the texture's channels
    # then differ where straw and soil (warmer) or leaves (greener) lie, and not
    # elsewhere: a grey texture fails
    for _, tint in detail.LITTER_KINDS.values():
        assert abs(float(np.array(tint) @ REC709) - 1.0) < 0.01
    d = detail.detail_pyramid(0)[0].astype(np.float64)
    assert np.allclose(d.mean(axis=(0, 1)), 1.0, atol=0.02)
    warm = d[..., 0] - d[..., 2]  # red over blue
    assert 0.02 < warm.std() < 0.1
    assert (warm > 0.05).mean() > 0.1  # straw and soil over a tenth of the ground


def test_no_litter_narrower_than_two_pixels() -> None:
    # band-limited at the base level as every feature of the ground: an ellipse's
    # minor semi-axis at least 1 px, its radii as drawn (r**-3 from 1 to 12 px)
    _, _, major, minor, _, _ = detail.litter_ellipses(0)
    assert minor.min() >= 1.0 - 1e-9
    r = np.sqrt(major * minor)
    assert r.min() >= 1.0 - 1e-9 and r.max() <= 12.0 + 1e-9
    assert 0.45 < (r < np.sqrt(2.0)).mean() < 0.55  # half of them below sqrt(2) px
    assert (major / minor).max() > 3.9  # elongated where wide enough


def test_repeats_seamlessly() -> None:
    # across the texture's edge the detail changes no more than between any two
    # neighbouring pixels (an ellipse cut at the edge would show as a seam)
    d = detail.detail_pyramid(0)[0]
    inside = np.abs(np.diff(d, axis=0)).mean()
    assert np.abs(d[0] - d[-1]).mean() < 1.2 * inside
    assert np.abs(d[:, 0] - d[:, -1]).mean() < 1.2 * inside


def test_pure_function_of_the_seed() -> None:
    a = detail.detail_pyramid(0)
    detail.detail_pyramid.cache_clear()
    b = detail.detail_pyramid(0)
    assert b is not a and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], detail.detail_pyramid(7)[0])
    assert not a[0].flags.writeable


def test_no_scales_above_the_highpass() -> None:
    # the texture repeats every DETAIL_PX pixels: at 32 base pixels a pixel (level
    # 5) it is nearly flat, the larger scales being the macro brightness's
    levels = detail.detail_pyramid(7)
    assert levels[5].shape == (16, 16, 3)
    assert levels[5].std() < 0.2 * levels[0].std()
    assert len(levels) == 10 and levels[-1].shape == (1, 1, 3)
