"""The search's figures explain what they draw: a title, axes with units, a
legend entry for every kind of line and mark (coverage.png, coverage_map.png,
the sweep's fleet-size curve), and a log axis labelled with plain numbers
(the fleet sizes 6, 12, 23, ...; or 5, 10, 20, 50, 100), never 10^1 or 2x10^1."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest

from cosim.logs.figures import plain_log_axis
from cosim.search import sweep
from cosim.search.coverage_map import NEVER
from cosim.search.plot import coverage_figure, coverage_map_figure


def _part() -> Any:
    """What the figures read of a finished search: a 4 x 4 km area, two
    aircraft's plans, a fire found at 6.8 min and two decoys (one found)."""
    first = np.full((40, 40), NEVER, np.int64)
    first[:, :30] = np.arange(30)[None, :] * 20
    inside = np.ones((40, 40), np.uint8)
    cmap = SimpleNamespace(first=first, inside=inside, fraction=0.75,
                           extent_ne=lambda: (-2000.0, 2000.0, -2000.0, 2000.0))
    lanes = [np.column_stack([np.full(20, e), np.linspace(-1900, 1900, 20)])
             for e in (-1000.0, 1000.0)]
    plan = SimpleNamespace(aircraft=[SimpleNamespace(path=lambda step_m, p=p: p) for p in lanes])
    spec = SimpleNamespace(area_ne=[(-2000.0, -2000.0), (-2000.0, 2000.0), (2000.0, 2000.0),
                                    (2000.0, -2000.0)],
                           no_fly_ne=[[(500.0, 500.0), (500.0, 900.0), (900.0, 900.0),
                                       (900.0, 500.0)]],
                           base_ne=(0.0, 0.0), airspeed_kt=200.0, alt_agl_m=1386.0)
    found = {"fire": {"time_s": 408.0, "decoy": False, "reported_north_m": 300.0,
                      "reported_east_m": -400.0},
             "decoy1": {"time_s": 90.0, "decoy": True, "reported_north_m": -800.0,
                        "reported_east_m": 700.0}}
    return SimpleNamespace(spec=spec, cmap=cmap, plan=plan, cov_every=120,
                           ctx=SimpleNamespace(physics_hz=120.0), rows=[0, 1],
                           fire_specs=[0, 1, 2],
                           fire_ne=np.array([[300.0, -400.0], [-800.0, 700.0], [1500, 1500]]),
                           decoy=np.array([False, True, True]), first=found,
                           curve=[(float(t), min(1.0, t / 560.0)) for t in range(0, 601, 5)],
                           planned_s=572.6)


def _legend(ax: Any) -> list[str]:
    leg = ax.get_legend()
    assert leg is not None, "no legend"
    return [t.get_text() for t in leg.get_texts()]


def _style(line: Any) -> tuple[Any, ...]:
    return (matplotlib.colors.to_hex(line.get_color()), line.get_linestyle(), line.get_marker())


def test_coverage_over_time_names_every_line() -> None:
    fig = coverage_figure(_part())
    ax = fig.axes[0]
    names = _legend(ax)
    assert names == ["area covered", "plan done (9.5 min)", "deadline (10 min)",
                     "decoy found (1)", "fire found (6.8 min)"]
    # every line drawn looks like one of the legend's
    shown = {_style(h) for h in ax.get_legend().legend_handles}
    assert {_style(line) for line in ax.lines} <= shown
    assert "fire found at 408 s" in ax.get_title() and "75% covered" in ax.get_title()
    assert "(min)" in ax.get_xlabel() and "%" in ax.get_ylabel()
    plt.close(fig)


def test_the_coverage_map_names_every_mark() -> None:
    fig = coverage_map_figure(_part())
    ax = fig.axes[0]
    assert _legend(ax) == ["never seen (25% of the area)", "search area", "no-fly zone",
                           "planned tracks", "base", "fire (the target)", "decoy fire",
                           "first report's position"]
    assert fig.axes[1].get_ylabel() == "first seen (minutes after the start)"  # the colour bar
    assert "(km)" in ax.get_xlabel() and "(km)" in ax.get_ylabel() and ax.get_title()
    plt.close(fig)


@pytest.mark.parametrize("values, ticks", [
    ([6, 12, 23, 32, 64, 128, 64, 6], ["6", "12", "23", "32", "64", "128"]),
    ([12, 23, 64], ["12", "23", "64"]),
    (range(3, 501), ["3", "5", "10", "20", "50", "100", "200", "500"]),
    (range(1, 1001, 7), ["1", "2", "5", "10", "20", "50", "100", "200", "500", "995"]),
    ([30, 32, 100], ["30", "100"]),  # too near to label both
])
def test_log_axes_are_labelled_with_plain_numbers(values: list[int], ticks: list[str]) -> None:
    fig, ax = plt.subplots()
    ax.plot(values, values)
    ax.set_xscale("log")
    plain_log_axis(ax.xaxis, values)
    fig.canvas.draw()
    assert [t.get_text() for t in ax.get_xticklabels()] == ticks
    assert not [t for t in ax.get_xticklabels(minor=True) if t.get_text()]
    plt.close(fig)


def test_the_fleet_curve_has_plain_ticks_a_title_and_a_legend(tmp_path: Path,
                                                             monkeypatch) -> None:
    rows = [{"tier": tier, "seed": seed, "aircraft": n,
             "time_to_detect_s": None if n == 6 and seed == 2 else 3000.0 / n + 60 * seed,
             "plan_completion_s": 12000.0 / n, "sim_time_s": max(600.0, 15000.0 / n)}
            for tier in ("fixed_wing", "fixed_wing_batched") for seed in (1, 2)
            for n in (6, 12, 23, 32, 64, 128) if tier == "fixed_wing_batched" or n <= 32]
    kept: list[Any] = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    sweep.plot_curve(rows, ["tier"], tmp_path / "search_curve.png")
    assert (tmp_path / "search_curve.png").stat().st_size > 0
    ax = kept[0].axes[0]
    kept[0].canvas.draw()
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels == ["6", "12", "23", "32", "64", "128"], labels
    assert all(re.fullmatch(r"\d+", t) for t in labels)
    names = _legend(ax)
    for tier in ("fixed_wing", "fixed_wing_batched"):
        assert f"tier={tier}: fire found (mean, range over the runs)" in names
        assert f"tier={tier}: plan done (area covered)" in names
    assert "tier=fixed_wing: fire not found by the run's end" in names
    assert names[-1] == "deadline (10 min)"
    assert ax.get_title().startswith("Time to find the fire against the fleet size (20 runs")
    assert "(min)" in ax.get_ylabel() and "aircraft" in ax.get_xlabel()
