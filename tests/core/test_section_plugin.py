"""A scenario section from another package (``examples/geofence``, installed
here with pip into a temporary folder) arrives through the ``cosim.sections``
entry point: its key is read with file:line problems, its participant runs in
the lockstep loop (events, its own output file, its part of the summary) on
every backend alike, and its CLI command joins ``cosim``'s, all without a
change to cosim. Without the package, the key is unknown."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.scenario import load_scenario
from cosim.sync import run_scenario
from tests.helpers import install_out_of_tree, plugged_in

REPO = Path(__file__).resolve().parent.parent.parent
EXAMPLE = REPO / "examples" / "geofence"


def _forget_plugins() -> None:
    from cosim.core.section import scenario_sections

    scenario_sections.cache_clear()


@pytest.fixture(scope="module")
def geofence(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The example package, installed (pip --target) and on sys.path (spawned
    workers inherit it)."""
    folder = tmp_path_factory.mktemp("geofence")
    code = (EXAMPLE / "cosim_geofence.py").read_text()
    site = install_out_of_tree(folder, "cosim-geofence", {"cosim_geofence": code},
                               {"cosim.sections": {"geofence": "cosim_geofence:GEOFENCE"}})
    with plugged_in(site, "cosim_geofence", _forget_plugins):
        yield site


def _scenario(tmp_path: Path, duration_s: int = 40) -> Path:
    p = tmp_path / "fence.yaml"
    p.write_text((EXAMPLE / "fence.yaml").read_text().replace("duration_s: 60",
                                                               f"duration_s: {duration_s}"))
    return p


def test_without_the_package_the_key_is_unknown(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"fence\.yaml:\d+: geofence: unknown key 'geofence'"):
        load_scenario(_scenario(tmp_path))


@pytest.mark.integration
def test_its_problems_carry_their_lines(geofence: Path, tmp_path: Path, capsys) -> None:
    p = _scenario(tmp_path)
    p.write_text(p.read_text().replace("[1500, -1500]]", "[1500, x]]").replace(
        "  vehicles: all", "  vehicles: nobody"))
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    line = next(i for i, t in enumerate(p.read_text().splitlines(), 1) if "area:" in t)
    assert f"fence.yaml:{line}: geofence.area[3]: expected [north_m, east_m]" in err
    assert "geofence.vehicles: 'nobody' matches no vehicle" in err


@pytest.mark.integration
def test_its_participant_runs_in_the_loop_on_every_backend(geofence: Path,
                                                           tmp_path: Path) -> None:
    scn = load_scenario(_scenario(tmp_path))
    assert "geofence" in scn.sections
    outs = {}
    for backend, workers in (("inline", None), ("process", 2)):
        res = run_scenario(scn, tmp_path / backend, backend=backend, workers=workers)
        assert res.ok, res.error
        outs[backend] = res.out_dir
    for out in outs.values():
        events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines()]
        breach = [e for e in events if e["event"] == "geofence_breach"]
        # c172-1 flies north out of the 3 km square (1500 m at 100 kt: about 29 s)
        assert [e["vehicle"] for e in breach] == ["c172-1"]
        assert 25 < breach[0]["time_s"] < 35 and breach[0]["north_m"] > 1500
        with open(out / "geofence.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        assert [(r["vehicle"], r["event"]) for r in rows] == [("c172-1", "geofence_breach")]
        summary = json.loads((out / "summary.json").read_text())
        assert summary["geofence"] == {"breaches": 1, "outside_at_end": ["c172-1"]}
    a, b = (p.read_text() for p in (outs["inline"] / "geofence.csv",
                                     outs["process"] / "geofence.csv"))
    assert a == b  # bit-identical on both backends


def test_its_command_joins_the_cli(geofence: Path, tmp_path: Path, capsys) -> None:
    scn = load_scenario(_scenario(tmp_path))
    res = run_scenario(scn, tmp_path / "run", backend="inline")
    assert res.ok
    capsys.readouterr()
    assert main(["geofence-report", str(res.out_dir)]) == 0
    assert capsys.readouterr().out.splitlines() == ["c172-1: left the area 1 time",
                                                    "1 breach(es) by 1 vehicle(s)"]
    assert main(["geofence-report", str(tmp_path)]) == 2
    assert "no geofence.csv" in capsys.readouterr().err
