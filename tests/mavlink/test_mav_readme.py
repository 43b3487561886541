"""The README's ground-station walkthrough is true: its pymavlink script,
run as written (only the port changed) against the scenario it names,
prints the reposition's acknowledgement; the mission file its MAVProxy
steps load exists and is a QGC WPL file (tests/mavlink/test_mavproxy.py
uploads it and flies it in AUTO)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

mavutil = pytest.importorskip("pymavlink.mavutil")

from tests.mavlink.mavtest import free_udp_port  # noqa: E402
from tests.mavlink.test_mav_run import _stop_sim  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
README = (REPO / "README.md").read_text()
ML = mavutil.mavlink


def _section(title: str) -> str:
    start = README.index(f"\n## {title}\n")
    return README[start:README.index("\n## ", start + 1)]


@pytest.mark.integration
def test_the_readme_pymavlink_script_prints_the_repositions_ack(tmp_path: Path) -> None:
    text = _section("Ground stations")
    script = re.search(r"\*\*pymavlink script\*\*:\n\n```python\n(.*?)```", text, re.S)
    assert script is not None, "the README's pymavlink script is gone"
    scn = re.search(r"cosim run (scenarios/\S+\.yaml) --realtime\n", text)
    assert scn is not None
    port = free_udp_port()
    code = script.group(1)
    assert code.count("14550") == 1
    station = subprocess.Popen([sys.executable, "-c", code.replace("14550", str(port))],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sim = subprocess.Popen(
        [sys.executable, "-m", "cosim", "-q", "run", str(REPO / scn.group(1)), "--out",
         str(tmp_path / "run"), "--realtime", "--no-progress", "--duration-s", "120",
         "--mavlink", f"udpout:127.0.0.1:{port}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = station.communicate(timeout=60)
    finally:
        if station.poll() is None:
            station.kill()
            station.wait()
        _stop_sim(sim)
    assert station.returncode == 0, err
    ack = re.fullmatch(r"COMMAND_ACK \{command : (\d+), result : (\d+),.*\}\n", out)
    assert ack is not None, out
    assert (int(ack[1]), int(ack[2])) == (ML.MAV_CMD_DO_REPOSITION, ML.MAV_RESULT_ACCEPTED)


def test_the_mission_file_the_walkthrough_loads_exists() -> None:
    loads = re.findall(r"^\s*wp load (\S+)", _section("Ground stations"), re.M)
    assert loads, "the MAVProxy walkthrough loads no mission"
    for name in loads:
        path = REPO / name
        assert path.is_file(), f"README: wp load {name}: no such file in the checkout"
        from pymavlink import mavwp

        wp = mavwp.MAVWPLoader()
        assert wp.load(str(path)) == 6  # home, the square's four corners, DO_JUMP
        assert wp.wp(5).command == ML.MAV_CMD_DO_JUMP
