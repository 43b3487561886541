"""Figures read as a person reads them: log axes in plain numbers, nothing
measured drawn off the axes, and the bench's columns explained."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from cosim.logs.figures import plain_log_axis, plain_number  # noqa: E402


def _labels(ax, which: str) -> list[str]:
    ax.figure.canvas.draw()
    ticks = ax.get_xticklabels() if which == "x" else ax.get_yticklabels()
    return [t.get_text() for t in ticks if t.get_text()]


@pytest.mark.parametrize("values,own,expect", [
    # measurements: the 1-2-5 steps, never 2x10^1 or 10^2
    ([4.48, 25.7, 193.0], False, ["5", "10", "20", "50", "100"]),
    ([0.3, 1.0, 3.5], False, ["0.5", "1", "2"]),
    # counts: the values themselves (a fleet size a point)
    ([1, 4, 8], True, ["1", "4", "8"]),
])
def test_log_axes_read_as_plain_numbers(values: list[float], own: bool,
                                        expect: list[str]) -> None:
    fig, ax = plt.subplots()
    ax.plot(values, values)
    ax.set(xscale="log", yscale="log")
    plain_log_axis(ax.yaxis, values, own_values=own)
    labels = _labels(ax, "y")
    assert all(re.fullmatch(r"\d+(\.\d+)?", t) for t in labels), labels
    assert labels == expect
    plt.close(fig)


def test_plain_numbers() -> None:
    assert [plain_number(v) for v in (0, 0.5, 20, 1500, 2e6)] == \
        ["0", "0.5", "20", "1500", "2e+06"]


def test_bench_efficiency_above_its_ceiling_is_drawn(tmp_path: Path) -> None:
    """A noisy size where the pool beat its ceiling (1.6) is inside the
    efficiency axis, not cut off at 1.2; both panels have legends."""
    from cosim.bench.plot import plot_scaling

    rows = [{"vehicles": n, "pool_rtf": 100 / n, "fraction_of_ceiling": e}
            for n, e in ((16, 0.8), (128, 1.6), (1024, 0.9))]
    captured = {}
    real_close = plt.close

    def keep(fig):  # look at the figure before it is closed
        captured["fig"] = fig
    plt.close = keep  # type: ignore[assignment]
    try:
        plot_scaling({"c172p": rows}, tmp_path / "s.png", "t")
    finally:
        plt.close = real_close  # type: ignore[assignment]
    ax1, ax2 = captured["fig"].axes
    assert ax2.get_ylim()[1] >= 1.6
    assert ax1.get_legend() is not None and ax2.get_legend() is not None
    assert "real-time factor" in ax1.get_ylabel()
    assert not any("^" in t for t in _labels(ax1, "x") + _labels(ax1, "y"))
    assert (tmp_path / "s.png").stat().st_size > 10_000
    real_close(captured["fig"])


def test_bench_says_what_its_columns_mean() -> None:
    from cosim.bench.pool import COLUMNS

    for col in ("start s", "KiB/ac", "pool st/s", "RTF", "ovh us", "serial st/s", "x serial",
                "ceil st/s", "of ceil"):
        assert f"{col}:" in COLUMNS, col
