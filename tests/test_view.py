"""The live 3-D view (Rerun): a recorded view verifies and holds every
vehicle, track, target and camera; the poses it logs are the logged states
in the scenario's east-north-up frame; it never changes the simulation;
without it Rerun is not even imported; and with no display `--view` says
what to do instead of hanging."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="the view needs Rerun: pip install -e .[test]")

from cosim.errors import ConfigError  # noqa: E402
from cosim.logs import read_states  # noqa: E402
from cosim.scenario import load_scenario  # noqa: E402
from cosim.sync import run_scenario  # noqa: E402
from cosim.sync.view import ViewParticipant, enu_quaternions  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
FLYOVER = REPO / "scenarios" / "cameras" / "flyover.yaml"


pytestmark = pytest.mark.integration  # runs recorded and verified with Rerun


def _rerun_cli() -> list[str]:
    exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if exe is None:
        pytest.skip("the rerun command (installed with rerun-sdk) is not on PATH")
    return [exe]


@pytest.fixture(scope="module")
def viewed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list[dict]]:
    tmp = tmp_path_factory.mktemp("view")
    logged: list[dict] = []
    real = rr.Boxes3D

    def boxes(**kw):  # what the view hands Rerun, kept for comparison
        logged.append({k: np.asarray(v) if k != "labels" else list(v) for k, v in kw.items()
                       if k in ("centers", "quaternions", "labels")})
        return real(**kw)

    view = ViewParticipant(record=tmp / "run.rrd", rate_hz=5.0)
    mp = pytest.MonkeyPatch()
    mp.setattr(rr, "Boxes3D", boxes)
    try:
        res = run_scenario(load_scenario(FLYOVER).with_duration(4.0), tmp / "viewed",
                           backend="inline", extra_participants=[view])
    finally:
        mp.undo()
    assert res.stop_reason == "completed", res.error
    return tmp / "viewed", tmp / "run.rrd", logged


def test_the_recording_verifies_and_holds_every_part(viewed) -> None:
    out, rrd, _ = viewed
    cli = _rerun_cli()
    env = dict(os.environ, RERUN_ANALYTICS="0")
    r = subprocess.run([*cli, "rrd", "verify", str(rrd)], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([*cli, "rrd", "print", str(rrd)], capture_output=True, text=True,
                       env=env, timeout=60)
    for path in ("/world/vehicles", "/world/tracks", "/world/targets", "/cameras/uav1/belly"):
        assert path in r.stdout, path
    summary = json.loads((out / "summary.json").read_text())["view"]
    assert summary["poses_logged"] == 20  # 4 s at 5 Hz
    assert summary["frames_logged"] == 8  # 2 a second from the 10 Hz camera


def test_the_logged_poses_are_the_states_in_east_north_up(viewed) -> None:
    out, _, logged = viewed
    t = read_states(out)
    lat = np.asarray(t["lat_deg"].to_pylist())
    lon = np.asarray(t["lon_deg"].to_pylist())
    alt = np.asarray(t["alt_msl_m"].to_pylist())
    time_s = np.asarray(t["time_s"].to_pylist())
    scn = load_scenario(FLYOVER)
    lat0, lon0, h0 = scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m
    assert len(logged) == 20
    for k, entry in enumerate(logged):
        i = int(np.argmin(np.abs(time_s - k / 5.0)))
        assert abs(time_s[i] - k / 5.0) < 1e-9
        # WGS-84's radii of curvature at the origin (flat over a few hundred
        # metres: centimetres off)
        e2 = 6.69437999014e-3
        s2 = math.sin(math.radians(lat0)) ** 2
        m_radius = 6_378_137.0 * (1 - e2) / (1 - e2 * s2) ** 1.5
        n_radius = 6_378_137.0 / math.sqrt(1 - e2 * s2)
        east = math.radians(lon[i] - lon0) * n_radius * math.cos(math.radians(lat0))
        north = math.radians(lat[i] - lat0) * m_radius
        (x, y, z), = entry["centers"]
        assert (x, y) == (pytest.approx(east, abs=0.1), pytest.approx(north, abs=0.1))
        assert z == pytest.approx(alt[i] - h0, abs=0.5)
        assert entry["labels"] == ["uav1"]


@pytest.mark.parametrize("roll, pitch, yaw, body, enu", [
    (0, 0, 0, (1, 0, 0), (0, 1, 0)),    # nose north
    (0, 0, 90, (1, 0, 0), (1, 0, 0)),   # nose east
    (0, 0, 90, (0, 1, 0), (0, 1, 0)),   # left wing of an east-bound aircraft: north
    (0, 30, 0, (1, 0, 0), (0, math.cos(math.radians(30)), 0.5)),
    (90, 0, 0, (0, 1, 0), (0, 0, 1)),   # rolled right 90: the left wing points up
])
def test_box_orientation(roll: float, pitch: float, yaw: float, body: tuple, enu: tuple) -> None:
    q = enu_quaternions(np.array([roll]), np.array([pitch]), np.array([yaw]))[0]
    u, w = q[:3], q[3]
    v = np.array(body, float)
    got = v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))
    assert np.allclose(got, enu, atol=1e-9)


def test_the_view_never_changes_the_simulation(viewed, tmp_path: Path) -> None:
    out, _, _ = viewed
    res = run_scenario(load_scenario(FLYOVER).with_duration(4.0), tmp_path / "plain",
                       backend="inline")
    assert res.stop_reason == "completed"
    a, b = read_states(out), read_states(tmp_path / "plain")
    for col in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "yaw_deg", "airspeed_mps"):
        assert a[col].to_pylist() == b[col].to_pylist(), col


def test_without_a_view_rerun_is_not_imported(tmp_path: Path) -> None:
    code = ("import sys; from cosim.cli import main; "
            f"rc = main(['-q', 'run', {str(FLYOVER)!r}, '--out', {str(tmp_path / 'o')!r}, "
            "'--duration-s', '1', '--no-progress', '--backend', 'inline']); "
            "assert rc == 0, rc; assert 'rerun' not in sys.modules, 'rerun was imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_no_display_means_a_clear_message_not_a_hang(monkeypatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ConfigError, match="--record-view"):
        ViewParticipant(connect="spawn")
    with pytest.raises(ConfigError, match="view-rate-hz"):
        ViewParticipant(record=Path("x.rrd"), rate_hz=0.0)
