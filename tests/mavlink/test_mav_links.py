"""More than 240 vehicles: one link per 240, system ids 1..240 on each, the
next port for the next link."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from mavtest import ANCHOR_US, PHYSICS_HZ, GroundStation, of_type, state_rows

from cosim.core.state import VehicleSpec
from cosim.errors import ConfigError
from cosim.mavlink import MavlinkConfig, MavlinkLinks, link_specs
from cosim.mavlink.links import link_urls
from cosim.vehicles import get_class


def _vehicles(n: int) -> list[VehicleSpec]:
    return [VehicleSpec(id=f"v{i:03d}", model="uav700", aircraft_dir="", model_source="cosim",
                        lat_deg=47.0 + 1e-4 * i, lon_deg=8.0, alt_msl_m=1000.0,
                        heading_deg=0.0, airspeed_mps=40.0, terrain_alt_m=400.0,
                        profile={"class": "fixed_wing"}, vehicle_class="fixed_wing")
            for i in range(n)]


def test_specs_and_urls_per_link() -> None:
    specs = link_specs(_vehicles(500), get_class)
    assert [len(s) for s in specs] == [240, 240, 20]
    assert [(s[0].sysid, s[-1].sysid) for s in specs] == [(1, 240), (1, 240), (1, 20)]
    assert [(s[0].row, s[-1].row) for s in specs] == [(0, 239), (240, 479), (480, 499)]
    assert link_urls("udpout:127.0.0.1:14550", 3) == [
        "udpout:127.0.0.1:14550", "udpout:127.0.0.1:14551", "udpout:127.0.0.1:14552"]
    assert link_urls("udpin:127.0.0.1:0", 2) == ["udpin:127.0.0.1:0"] * 2
    assert link_urls(None, 2) == [None, None]
    with pytest.raises(ConfigError, match="65535"):
        link_urls("udpin:127.0.0.1:65535", 2)


def test_second_link_serves_vehicles_241_on_with_their_own_system_ids(tmp_path: Path) -> None:
    n = 250
    links = MavlinkLinks(_vehicles(n), get_class, PHYSICS_HZ,
                         MavlinkConfig(url="udpin:127.0.0.1:0"),
                         tlog_dir=tmp_path, clock_anchor_unix_us=ANCHOR_US)
    (_, p0), (_, p1) = links.local_addresses
    assert p0 != p1
    gcs = GroundStation(f"udpout:127.0.0.1:{p1}")
    heard: list = []
    got_in_process: list[tuple[int, int]] = []
    links.subscribe(lambda m, link: got_in_process.append((link, m.src_system)))
    try:
        states = state_rows(n)
        gcs.hello()
        deadline = time.monotonic() + 5
        tick = 0
        while not of_type(heard, "HEARTBEAT") and time.monotonic() < deadline:
            links.exchange(tick, states)
            heard += gcs.drain(0.05)
        assert {m.get_srcSystem() for m in of_type(heard, "HEARTBEAT")} == set(range(1, 11))
        assert sorted(set(got_in_process)) == [(0, s) for s in range(1, 241)] + [
            (1, s) for s in range(1, 11)]
        # a command to system 3 of the second link reaches row 242
        gcs.mav.command_long_send(3, 1, 17, 0, 0, 0, 0, 0, 0, 0, 0)  # NAV_LOITER_UNLIM
        cmds = []
        deadline = time.monotonic() + 5
        while not cmds and time.monotonic() < deadline:
            tick += 4
            cmds = links.exchange(tick, states)
        assert [c.row for c in cmds] == [242]
        c = links.counters()
        assert c["links"] == 2 and c["peers"] == 1 and c["packets_out"] > 250
    finally:
        gcs.close()
        links.close()
    assert len(list(tmp_path.glob("*.tlog"))) == n


def test_an_outside_controller_drives_one_link_only() -> None:
    with pytest.raises(ConfigError, match="at most 240"):
        MavlinkLinks(_vehicles(241), get_class, PHYSICS_HZ,
                     MavlinkConfig(url="udpin:127.0.0.1:0", lockstep_sysid=245))


def test_only_the_vehicles_chosen_are_on_mavlink(tmp_path: Path) -> None:
    """mavlink.vehicles: the chosen rows (here 250 of 1000) get the links and
    system ids, in vehicle order; a command from elsewhere to a vehicle off
    MAVLink passes through untouched; no tlog for the others."""
    from cosim.guidance.commands import Command

    n = 1000
    rows = tuple(range(0, n, 4))
    links = MavlinkLinks(_vehicles(n), get_class, PHYSICS_HZ,
                         MavlinkConfig(url=None, rows=rows), tlog_dir=tmp_path,
                         clock_anchor_unix_us=ANCHOR_US)
    try:
        assert [len(s) for s in links.specs] == [240, 10]
        assert [v.row for s in links.specs for v in s] == list(rows)
        assert (links.specs[1][0].sysid, links.specs[1][0].row) == (1, 960)
        heard: list[tuple[int, int]] = []
        links.subscribe(lambda m, link: heard.append((link, m.src_system)))
        links.exchange(0, state_rows(n))
        assert len(set(heard)) == 250
        cmd = Command(heading_deg=90.0)
        assert links.local_command(1, cmd) is cmd  # row 1: not on MAVLink
        links.local_command(4, cmd)  # row 4: system 2 of link 0 follows it
    finally:
        links.close()
    assert len(list(tmp_path.glob("*.tlog"))) == 250
    with pytest.raises(ConfigError, match="selects no vehicle"):
        MavlinkLinks(_vehicles(3), get_class, PHYSICS_HZ, MavlinkConfig(url=None, rows=()))


def test_the_scenario_chooses_its_mavlink_vehicles(tmp_path: Path) -> None:
    """mavlink: {vehicles: PATTERNS} resolves to rows; a pattern matching no
    vehicle is an error with its line; a swarm vehicle left off is refused."""
    from cosim.scenario import parse_scenario

    head = """schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 400}
duration_s: 5
vehicles:
  - {id: lead, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}
  - {id: fleet, class: fixed_wing_batched, model: uav700, count: 30,
     formation: {type: grid, spacing_m: 300},
     init: {north_m: 3000, east_m: 0, alt_agl_m: 300, airspeed_kt: 100}}
"""
    scn = parse_scenario(head + "mavlink: {url: 'udpin:127.0.0.1:0', vehicles: [lead, fleet01]}\n",
                         str(tmp_path / "a.yaml"), check_properties=False)
    cfg = MavlinkConfig.of_scenario(scn.mavlink, [v.id for v in scn.vehicles])
    assert cfg is not None and cfg.rows == (0, 2)
    with pytest.raises(ConfigError) as ei:
        parse_scenario(head + "mavlink: {vehicles: nobody*}\n", str(tmp_path / "b.yaml"),
                       check_properties=False)
    assert "b.yaml:9: mavlink.vehicles: 'nobody*' matches no vehicle" in ei.value.problems[0]
    swarm = """swarm:
  groups:
    - {name: g, vehicles: "fleet*", phases: [{behaviour: rendezvous, radius_m: 400}]}
"""
    with pytest.raises(ConfigError) as ei:
        parse_scenario(head + "mavlink: {vehicles: lead}\n" + swarm, str(tmp_path / "c.yaml"),
                       check_properties=False)
    assert any("are not in mavlink.vehicles" in p for p in ei.value.problems)
