"""The spectral exponent's estimator against images of known exponent."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.conspicuity.spectrum import luminance, noise_image, spectral_exponent
from cosim.errors import ConfigError


@pytest.mark.parametrize("a", [1.0, 2.0, 3.0])
def test_recovers_the_exponent_of_random_phase_noise(a: float) -> None:
    # one 640 x 480 image's estimate scatters by about 0.075: the mean of 8 by 0.03
    got = [spectral_exponent(noise_image((480, 640), a, seed)).exponent for seed in range(8)]
    assert abs(float(np.mean(got)) - a) < 0.1, got


def test_the_window_keeps_the_edges_out() -> None:
    # a steep spectrum in a frame whose opposite edges do not match: without the
    # window the edges' own f**-2 would flatten it towards 2
    img = noise_image((480, 640), 3.0, 1)[:400, :500]
    assert abs(spectral_exponent(img).exponent - 3.0) < 0.2


def test_luminance_is_rec709_of_linear_srgb() -> None:
    grey = np.full((2, 2, 3), 128, np.uint8)
    assert luminance(grey)[0, 0] == pytest.approx(0.2158605, abs=1e-6)
    green = np.zeros((1, 1, 3), np.uint8)
    green[..., 1] = 255
    assert luminance(green)[0, 0] == pytest.approx(0.7152)


def test_a_flat_image_has_no_exponent() -> None:
    sp = spectral_exponent(np.full((256, 256), 0.3))
    assert np.isnan(sp.exponent)


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"expected an \(H, W, 3\) RGB image"):
        luminance(np.zeros((4, 4)))
    with pytest.raises(ConfigError, match="expected a 2-D luminance image"):
        spectral_exponent(np.zeros((4, 4, 3)))
    with pytest.raises(ConfigError, match="must span at least 1.5 octaves"):
        spectral_exponent(np.zeros((16, 16)))
