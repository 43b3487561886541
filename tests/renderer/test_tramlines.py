"""Tramlines in the procedural ground's crop fields (texture._tracks): pairs of
wheel tracks along the crop rows, each as wide as it is, their pairs every
TRAMLINE_ROWS rows, darker by TRACK_DARK; box-filtered to the sample spacing."""

import numpy as np
import pytest

from cosim.renderer import noise, texture

SEED = 5


def _tram_field(seed: int) -> tuple[float, float, bool, float]:
    """A field with tramlines: its centre (north, east), whether its rows run
    along u (north) and its crop rows' period in field units."""
    colour, amp, cu, cv, tram, _, _, _ = texture._field_cells(seed, 0.05, -4, 4, -4, 4)
    k = int(np.flatnonzero(tram > 0)[0])
    i, j = divmod(k, 8)
    along = bool(cu[k] > 0)
    rows_per_unit = float(cu[k] if along else cv[k])
    return (i - 4 + 0.5) * texture.FIELD_N_M, (j - 4 + 0.5) * texture.FIELD_E_M, along, \
        rows_per_unit


def _line(seed: int, step_m: float, monkeypatch: pytest.MonkeyPatch, dark: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """The green of the ground (no trees) along 60 m across a tramline field's
    rows through its middle, every ``step_m``, with tracks ``dark``; and the
    positions (metres along the line)."""
    n0, e0, along, _ = _tram_field(seed)
    monkeypatch.setattr(texture, "TRACK_DARK", dark)
    monkeypatch.setattr(noise, "TABLES", noise.Tables(16 << 20))  # its own field tables
    s = np.arange(-30.0, 30.0, step_m)
    if along:
        n, e = (n0 + s)[:, None], np.array([[e0]])
    else:
        n, e = np.array([[n0]]), (e0 + s)[None, :]
    rgb = texture.macro_rgb(n, e, step_m, seed, with_trees=False)
    return rgb[1].ravel(), s


def test_tracks_are_pairs_of_the_gauge_every_tramline(monkeypatch: pytest.MonkeyPatch) -> None:
    step = 0.05
    dark = texture.TRACK_DARK
    _, _, along, rows_per_unit = _tram_field(SEED)
    with_tracks, s = _line(SEED, step, monkeypatch, dark)
    without, _ = _line(SEED, step, monkeypatch, 0.0)
    monkeypatch.undo()
    ratio = with_tracks / without
    # at 5 cm a sample a track covers whole samples: darker by TRACK_DARK there
    assert ratio.min() == pytest.approx(1.0 - dark, abs=0.01)
    assert ratio.max() == pytest.approx(1.0, abs=1e-4)
    inside = ratio < 1.0 - dark / 2
    starts = np.flatnonzero(inside[1:] & ~inside[:-1]) + 1
    ends = np.flatnonzero(~inside[1:] & inside[:-1]) + 1
    ends = ends[ends > starts[0]]
    starts = starts[:len(ends)]
    widths_m = (ends - starts) * step
    centres = 0.5 * (s[starts] + s[ends - 1])
    assert len(centres) >= 4  # two tramlines or more in 60 m (20 to 32 m apart)
    assert np.allclose(widths_m, texture.TRACK_M, atol=0.1)  # each track its width
    # in pairs: the gauge within a pair, the tramline spacing between pairs, in the
    # field's (warped) metres: their ratio is the gauge over TRAMLINE_ROWS rows
    gaps = np.diff(centres)
    gauge, spacing = gaps[0::2], centres[2::2] - centres[0:-2:2]
    period_m = (texture.FIELD_N_M if along else texture.FIELD_E_M) / rows_per_unit
    expected = texture.TRACK_GAUGE_M / (texture.TRAMLINE_ROWS * period_m)
    assert np.allclose(gauge[:len(spacing)] / spacing, expected, rtol=0.08)


def test_a_coarse_sample_takes_the_tracks_share(monkeypatch: pytest.MonkeyPatch) -> None:
    # at 2 m a sample (wider than both tracks) the darkening over a tramline's
    # samples sums to what its two tracks cover: TRACK_DARK x 2 x TRACK_M per
    # tramline (box-filtered, not a track drawn a sample wide); fewer than 8 m
    # a sample only (faded out beyond)
    step = 2.0
    dark = texture.TRACK_DARK
    with_tracks, s = _line(SEED, step, monkeypatch, dark)
    without, _ = _line(SEED, step, monkeypatch, 0.0)
    monkeypatch.undo()
    loss_m = float(((1.0 - with_tracks / without) * step).sum())
    tramlines = loss_m / (dark * 2 * texture.TRACK_M)
    assert abs(tramlines - round(tramlines)) < 0.25 and round(tramlines) >= 2
    cells = texture._field_cells(SEED, 8.0, -4, 4, -4, 4)
    assert not cells[4].any()  # none at 8 m a sample
