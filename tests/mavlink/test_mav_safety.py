"""Commands that would crash an aircraft are refused on every command path
(``cosim.guidance.safety``): targets below the ground plus the class minimum
(20 m for a fixed-wing) and loiter radii below the minimum turn radius are
DENIED over MAVLink with a STATUSTEXT saying why, refused by the mission
protocol, refused as parameters, and are line-numbered errors in a
scenario's schedule; legal low passes still fly."""

from __future__ import annotations

import textwrap

import pytest
from mavtest import HOME_ALT_M, S, mavutil, of_type, start_of
from test_mav_commands import cint, long, one_ack

from cosim.errors import ConfigError
from cosim.guidance.commands import min_turn_radius_m
from cosim.scenario import parse_scenario
from cosim.vehicles import get_class
from cosim.vehicles.fixed_wing import DEFAULT_MIN_ALT_AGL_M

ML = mavutil.mavlink
GUIDED_FLAG = ML.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
LAT, LON = start_of(0)


def _texts(replies) -> list[str]:
    """The STATUSTEXTs, chunks of a long one put back together (by ``id``)."""
    out: list[str] = []
    chunks: dict[int, list[str]] = {}
    for m in of_type(replies, "STATUSTEXT"):
        if m.id == 0:
            out.append(m.text)
        else:
            chunks.setdefault(m.id, []).append(m.text)
    return out + ["".join(c) for c in chunks.values()]


def test_a_reposition_into_the_ground_is_denied_and_not_flown(rig) -> None:
    """The issue's case: DO_REPOSITION to 0 m MSL with the ground far above it."""
    r = rig(1)
    cmds, replies = cint(r, 1, ML.MAV_CMD_DO_REPOSITION, ML.MAV_FRAME_GLOBAL_INT, -1,
                         GUIDED_FLAG, x=int(LAT * 1e7), y=int(LON * 1e7), z=0.0)
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == ML.MAV_RESULT_DENIED
    assert cmds == []
    assert any("above the ground" in t for t in _texts(replies))
    assert r.ep.counters()["commands_unsafe"] == 1


@pytest.mark.parametrize("agl, ok", [(5.0, False), (19.0, False), (20.0, True), (30.0, True)])
def test_the_floor_is_the_class_minimum_above_the_ground(rig, agl: float, ok: bool) -> None:
    """COMMAND_LONG altitudes are relative to home (the ground here)."""
    r = rig(1)
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_REPOSITION, -1, GUIDED_FLAG, 0, 0, LAT, LON, agl)
    expect = ML.MAV_RESULT_ACCEPTED if ok else ML.MAV_RESULT_DENIED
    assert one_ack(replies, ML.MAV_CMD_DO_REPOSITION) == expect
    assert len(cmds) == (1 if ok else 0)
    if ok:
        assert cmds[0].command.alt_m == pytest.approx(HOME_ALT_M + agl)


def test_a_loiter_radius_the_aircraft_cannot_turn_is_denied(rig) -> None:
    r = rig(1)  # 37 m/s, 45 deg: about 140 m
    r_min = min_turn_radius_m(37.0, 45.0)
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, 1.0)
    assert one_ack(replies, ML.MAV_CMD_NAV_LOITER_UNLIM) == ML.MAV_RESULT_DENIED
    assert cmds == [] and any("minimum turn radius" in t for t in _texts(replies))
    cmds, replies = long(r, 1, ML.MAV_CMD_NAV_LOITER_UNLIM, 0, 0, round(r_min) + 5)
    assert one_ack(replies, ML.MAV_CMD_NAV_LOITER_UNLIM) == ML.MAV_RESULT_ACCEPTED
    assert cmds[0].command.loiter_radius_m == round(r_min) + 5


def test_position_targets_and_guided_items_below_the_floor_are_refused(rig) -> None:
    r = rig(1)
    cmds, replies = r.request(lambda: r.gcs.mav.set_position_target_global_int_send(
        0, 1, 1, ML.MAV_FRAME_GLOBAL_INT, 0b110111111000, int(LAT * 1e7), int(LON * 1e7),
        HOME_ALT_M + 3, 0, 0, 0, 0, 0, 0, 0, 0))
    assert cmds == [] and any("position target" in t for t in _texts(replies))
    cmds, replies = r.request(lambda: r.gcs.mav.mission_item_int_send(
        1, 1, 0, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ML.MAV_CMD_NAV_WAYPOINT, 2, 1, 0, 0, 0,
        0, int(LAT * 1e7), int(LON * 1e7), 2.0))
    ack, = of_type(replies, "MISSION_ACK")
    assert cmds == [] and ack.type == ML.MAV_MISSION_INVALID_PARAM7


def test_a_mission_item_below_the_floor_is_refused_alone_and_never_flown(rig) -> None:
    r = rig(1)
    items = [(ML.MAV_CMD_NAV_WAYPOINT, 100.0), (ML.MAV_CMD_NAV_WAYPOINT, 10.0),
             (ML.MAV_CMD_NAV_WAYPOINT, 120.0)]
    cmds, replies = r.request(lambda: r.gcs.mav.mission_count_send(1, 1, len(items) + 1, 0))
    seen = list(replies)
    for seq in range(len(items) + 1):
        command, alt = (ML.MAV_CMD_NAV_WAYPOINT, 0.0) if seq == 0 else items[seq - 1]
        cmds, replies = r.request(lambda s=seq, c=command, a=alt: r.gcs.mav.mission_item_int_send(
            1, 1, s, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, c, 0, 1, 0, 0, 0, 0,
            int(LAT * 1e7), int(LON * 1e7) + s * 10_000, a, 0))
        seen += replies
    ack, = of_type(seen, "MISSION_ACK")
    assert ack.type == ML.MAV_MISSION_ACCEPTED
    assert any("Mission item 2" in t and "above the ground refused" in t
               and "MAV_MISSION_INVALID_PARAM7" in t for t in _texts(seen))
    assert r.ep.vehicles[0].mission.refused == {2: ML.MAV_MISSION_INVALID_PARAM7}
    assert r.ep.counters()["commands_unsafe"] == 1
    cmds, _ = r.request(lambda: r.gcs.mav.set_mode_send(1, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                                        10))
    r.states[0, S["lat_deg"]] = LAT
    r.states[0, S["lon_deg"]] = (int(LON * 1e7) + 10_000) / 1e7
    cmds = r.step(4)  # item 1 reached: item 2 is skipped, item 3 flown
    assert cmds[0].command.alt_m == pytest.approx(HOME_ALT_M + 120.0)


@pytest.mark.parametrize("name, value, ok", [
    ("TKOFF_ALT", 5, False), ("TKOFF_ALT", 40, True),
    ("ALT_HOLD_RTL", 1000, False), ("ALT_HOLD_RTL", -1, True), ("ALT_HOLD_RTL", 5000, True),
    ("WP_LOITER_RAD", 1, False), ("WP_LOITER_RAD", -2, False), ("WP_LOITER_RAD", 0, True),
    ("WP_LOITER_RAD", 500, True), ("RTL_RADIUS", 10, False),
])
def test_parameters_that_would_crash_a_later_command_are_refused(rig, name: str, value: float,
                                                                 ok: bool) -> None:
    r = rig(1)
    before = r.ep.vehicles[0].params[name]
    cmds, replies = r.request(lambda: r.gcs.mav.param_set_send(
        1, 1, name.encode(), value, ML.MAV_PARAM_TYPE_INT32))
    pv, = of_type(replies, "PARAM_VALUE")
    assert pv.param_value == (value if ok else before)
    assert bool(_texts(replies)) != ok


SCHEDULE = """\
schema_version: 1
origin: {lat_deg: 47.0, lon_deg: 8.0, ground_alt_m: 1000}
duration_s: 20
vehicles:
  - {id: a, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 300, heading_deg: 0,
                                  airspeed_kt: 100}}
schedule:
  - {at_s: 1, vehicles: a, command: COMMAND}
"""


@pytest.mark.parametrize("command, fragment", [
    ("{goto: {north_m: 1000, east_m: 0, alt_msl_m: 0}}", "-1000 m above the ground"),
    ("{alt_agl_m: 5}", "5 m above the ground (at 1000 m); a must stay at least 20 m"),
    ("{waypoints: [{north_m: 1000, east_m: 0}, {north_m: 0, east_m: 1000, alt_msl_m: 1010}]}",
     "10 m above the ground"),
    ("{loiter: {radius_m: 1}}", "loiter radius 1 m is below the minimum turn radius of a"),
])
def test_the_schedule_refuses_the_same_commands_with_a_line(command: str,
                                                            fragment: str) -> None:
    with pytest.raises(ConfigError) as ei:
        parse_scenario(SCHEDULE.replace("COMMAND", command), "s.yaml")
    assert any(p.startswith("s.yaml:8: schedule[0].command: ") and fragment in p
               for p in ei.value.problems), ei.value.problems


def test_a_legal_low_pass_is_still_accepted() -> None:
    low = DEFAULT_MIN_ALT_AGL_M + 10
    scn = parse_scenario(SCHEDULE.replace("COMMAND", f"{{alt_agl_m: {low:g}, heading_deg: 0}}"),
                         "s.yaml")
    assert scn.schedule[0].command is not None
    assert scn.schedule[0].command.alt_m == low


def test_a_profile_may_set_its_own_minimum(tmp_path) -> None:
    from cosim.mavlink import mav_specs

    scn = parse_scenario(SCHEDULE.replace("COMMAND", "{alt_agl_m: 30}"), "s.yaml")
    assert mav_specs(scn.vehicles, get_class)[0].min_alt_agl_m == DEFAULT_MIN_ALT_AGL_M
    plane = tmp_path / "planes"
    src = scn.vehicles[0].aircraft_dir
    import shutil

    shutil.copytree(f"{src}/uav700", plane / "uav700", symlinks=True)
    prof = plane / "uav700" / "cosim.yaml"
    prof.write_text(prof.read_text() + "\nmin_alt_agl_m: 50\n")
    text = SCHEDULE.replace("COMMAND", "{alt_agl_m: 30}").replace(
        "duration_s: 20", f"duration_s: 20\naircraft_path: {plane}")
    with pytest.raises(ConfigError, match="must stay at least 50 m above it"):
        parse_scenario(textwrap.dedent(text), str(tmp_path / "s.yaml"))
