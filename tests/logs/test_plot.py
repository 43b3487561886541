"""``cosim plot``: every vehicle drawn unless the user chooses, what was drawn
said in the figure and on the terminal, a legend, units on every axis, and
the ground vehicles' speed where the aircraft have their altitude."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.collections import LineCollection

from cosim.cli import main
from cosim.logs import read_states
from tests.helpers import finished_run

SCENARIO = """\
schema_version: 1
name: mixed_fleet
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
rates: {physics_hz: 120, control_hz: 10, log_hz: 10}
duration_s: 5
vehicles:
  - {id: quad, model: F450, init: {north_m: 0, east_m: 50, alt_agl_m: 20}}
  - {id: car, class: ground, max_speed_mps: 6, init: {north_m: 0, east_m: 100, heading_deg: 0}}
  - {id: b, class: fixed_wing_batched, model: uav700, count: 58,
     formation: {type: grid, spacing_m: 100, columns: 10},
     init: {north_m: 500, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}
obstacles:
  - {id: block, height_m: 8, polygon: [[40, 80], [40, 90], [50, 90], [50, 80]]}
schedule:
  - {at_s: 0, vehicles: car, command: {airspeed_mps: 5, waypoints: [{north_m: 5, east_m: 100},
                                                                     {north_m: 12, east_m: 100}]}}
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """60 vehicles: a quadrotor, a car (a waypoint reached) and 58 batched fixed-wings."""
    return finished_run(SCENARIO, tmp_path_factory.mktemp("plot"))


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The figures ``plot_run`` draws, kept open to look at."""
    kept: list[Any] = []
    monkeypatch.setattr("matplotlib.pyplot.close", kept.append)
    return kept


def _axes(fig: Any) -> dict[str, Any]:
    return {ax.get_title(): ax for ax in fig.axes}


def _legend(fig: Any) -> list[str]:
    return [t.get_text() for t in fig.legends[0].get_texts()]


def _lines(ax: Any) -> list[np.ndarray]:
    (tracks,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    return tracks.get_segments()


def test_every_vehicle_is_drawn_and_the_figure_and_terminal_say_so(
        run: Path, tmp_path: Path, figures: list[Any], capsys) -> None:
    png = tmp_path / "all.png"
    assert main(["plot", str(run), "--out", str(png)]) == 0
    assert capsys.readouterr().out.strip() == f"{png} (60 of 60 vehicles drawn: all)"
    (fig,) = figures
    assert fig._suptitle.get_text() == "mixed_fleet: 60 of 60 vehicles drawn (all)"
    axes = _axes(fig)
    assert len(_lines(axes["ground tracks"])) == 60
    legend = _legend(fig)
    assert legend[0] == "60 vehicles, one line each (colours repeat)"
    assert {"start", "waypoint reached", "obstacle"} <= set(legend)
    for ax in fig.axes:  # units on every axis
        assert re.search(r"\((m|s|m/s|m above the WGS-84 ellipsoid)\)$", ax.get_xlabel())
        assert re.search(r"\((m|s|m/s|m above the WGS-84 ellipsoid)\)$", ax.get_ylabel())
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ground_vehicles_have_their_speed_where_aircraft_have_their_altitude(
        run: Path, tmp_path: Path, figures: list[Any]) -> None:
    assert main(["plot", str(run), "--out", str(tmp_path / "p.png")]) == 0
    axes = _axes(figures[0])
    air, ground = axes["altitude of the aircraft (59)"], axes["speed of the ground vehicles (1)"]
    assert len(_lines(air)) == 59 and ground.get_ylabel() == "ground speed (m/s)"
    (car,) = _lines(ground)
    t = read_states(run)
    is_car = np.array(t["vehicle"].to_pylist()) == "car"
    speed = np.hypot(t["vn_mps"].to_numpy(), t["ve_mps"].to_numpy())[is_car]
    assert np.array_equal(car[:, 0], t["time_s"].to_numpy()[is_car])
    assert np.array_equal(car[:, 1], speed) and speed.max() > 4.0


def test_the_user_chooses_which_vehicles(run: Path, tmp_path: Path, figures: list[Any],
                                         capsys) -> None:
    png = str(tmp_path / "p.png")
    assert main(["plot", str(run), "--out", png, "--max-vehicles", "5"]) == 0
    assert capsys.readouterr().out.strip().endswith(
        "(5 of 60 vehicles drawn: the first 5: --max-vehicles 5, in the scenario's order)")
    assert len(_lines(_axes(figures[-1])["ground tracks"])) == 5
    assert main(["plot", str(run), "--out", png, "--vehicles", "car,b0*"]) == 0
    assert "(11 of 60 vehicles drawn: --vehicles car,b0*)" in capsys.readouterr().out
    assert _legend(figures[-1])[:3] == ["car", "b00", "b01"]  # a line each, named
    assert main(["plot", str(run), "--out", png, "--vehicles", "quad,nope*"]) == 2
    assert re.search(r"--vehicles: no vehicle of the run matches 'nope\*' \(its vehicles: "
                     r"quad, car, b00, .* \(60 in all\)\)", capsys.readouterr().err)
    assert main(["plot", str(run), "--out", png, "--max-vehicles", "0"]) == 2
    assert "--max-vehicles must be >= 1, got 0" in capsys.readouterr().err
