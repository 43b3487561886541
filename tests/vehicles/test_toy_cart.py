"""A vehicle class from another package (``examples/toy_cart``, installed
here with pip into a temporary folder) arrives through the ``cosim.vehicles``
entry point and flies beside the fixed-wing in one lockstep: its batched
model is stepped in the workers, bit-identically whatever the backend and
worker count; its own scenario key, state column, commands and MAVLink
personality all reach the run's outputs."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from cosim.logs import read_states
from cosim.scenario import load_scenario
from cosim.sync import run_scenario
from tests.helpers import install_out_of_tree, plugged_in, same_states

REPO = Path(__file__).resolve().parent.parent.parent
EXAMPLE = REPO / "examples" / "toy_cart"


pytestmark = pytest.mark.integration  # an out-of-tree package installed, flown on every backend


def _forget_plugins() -> None:
    import cosim.vehicles.registry as reg

    reg.vehicle_classes.cache_clear()


@pytest.fixture(scope="module")
def toy_cart(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The example package, installed (pip --target) and on sys.path (spawned
    workers inherit it)."""
    folder = tmp_path_factory.mktemp("toycart")
    code = (EXAMPLE / "cosim_toycart.py").read_text()
    site = install_out_of_tree(folder, "cosim-toycart", {"cosim_toycart": code},
                               {"cosim.vehicles": {"toy_cart": "cosim_toycart:TOY_CART"}})
    with plugged_in(site, "cosim_toycart", _forget_plugins):
        yield site


def _scenario(tmp_path: Path) -> Path:
    """The example scenario without its MAVLink link (runs here need no socket)."""
    text = (EXAMPLE / "carts.yaml").read_text().replace(
        'mavlink: {url: "udpin:127.0.0.1:0"}', "mavlink: {url: null}")
    p = tmp_path / "carts.yaml"
    p.write_text(text.replace("mavlink: {url: null}\n", ""))
    return p


def test_a_registered_class_is_found_and_validated(toy_cart: Path, tmp_path: Path) -> None:
    from cosim.vehicles import get_class, vehicle_classes

    assert "toy_cart" in vehicle_classes() and get_class("toy_cart").model_kind == "batched"
    scn = load_scenario(_scenario(tmp_path))
    carts = [v for v in scn.vehicles if v.vehicle_class == "toy_cart"]
    assert [v.id for v in carts] == ["cart0", "cart1", "cart2"]
    assert carts[0].class_params == {"accel_mps2": 1.5}
    assert scn.classes == ("toy_cart", "fixed_wing")
    bad = _scenario(tmp_path).read_text().replace("accel_mps2: 1.5", "accel_mps2: 99")
    (tmp_path / "bad.yaml").write_text(bad)
    from cosim.errors import ConfigError

    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+: vehicles\[0\]\.accel_mps2: must be "
                                          r"<= 10"):
        load_scenario(tmp_path / "bad.yaml")


def _cart_reference(seconds: float, hz: float = 120.0) -> list[float]:
    """The odometer of a cart (3 m/s, 8 m/s commanded from t = 5 s, 1.5 m/s^2),
    computed here with plain floats, one physics tick at a time."""
    dt, speed, dist, out = 1.0 / hz, 3.0, 0.0, [0.0]
    for tick in range(1, round(seconds * hz) + 1):
        cmd = 8.0 if tick > 600 else 3.0  # applied at the exchange of tick 600
        speed += min(max(cmd - speed, -1.5 * dt), 1.5 * dt)
        dist += speed * dt
        out.append(dist)
    return out


def test_batched_carts_fly_beside_fixed_wings_identically_on_every_backend(
        toy_cart: Path, tmp_path: Path) -> None:
    scn = load_scenario(_scenario(tmp_path))
    runs = {}
    for backend, workers in (("inline", None), ("process", 1), ("process", 2),
                             ("process", 3)):
        res = run_scenario(scn, tmp_path / f"{backend}{workers}", backend=backend,
                           workers=workers)
        assert res.stop_reason == "completed", res.error
        runs[(backend, workers)] = read_states(res.out_dir)
    ref = runs[("inline", None)]
    assert "odometer_m" in ref.column_names  # the class's own column, logged
    for key, t in runs.items():
        assert same_states(t, ref), f"{key} differs from inline"
    cart = ref.filter(np.array([v == "cart0" for v in ref["vehicle"].to_pylist()]))
    ticks = cart["tick"].to_numpy()
    expect = _cart_reference(20.0)
    assert np.array_equal(cart["odometer_m"].to_numpy(), [expect[t] for t in ticks])
    speed = cart["airspeed_mps"].to_numpy()
    assert speed[0] == 3.0 and speed[-1] == pytest.approx(8.0)
    assert cart["command"].to_pylist()[-1] == "drive 8 m/s"
    uav = ref.filter(np.array([v == "uav0" for v in ref["vehicle"].to_pylist()]))
    assert uav["yaw_deg"].to_numpy()[-1] == pytest.approx(45.0, abs=2.0)  # turned, too


def test_the_class_has_its_own_mavlink_personality(toy_cart: Path, tmp_path: Path) -> None:
    from pymavlink import mavutil

    scn = load_scenario(_scenario(tmp_path)).with_duration(3.0)
    from cosim.mavlink import MavlinkConfig

    res = run_scenario(scn, tmp_path / "m", backend="inline", mavlink=MavlinkConfig(url=None))
    assert res.stop_reason == "completed"
    types = {}
    for name in ("cart0", "uav0"):
        log = mavutil.mavlink_connection(str(tmp_path / "m" / f"{name}.tlog"),
                                         dialect="ardupilotmega")
        hb = log.recv_match(type="HEARTBEAT")
        types[name] = (hb.type, hb.custom_mode)
    assert types["cart0"] == (mavutil.mavlink.MAV_TYPE_GROUND_ROVER, 0)
    assert types["uav0"][0] == mavutil.mavlink.MAV_TYPE_FIXED_WING
    s = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert s["complete"] is True


def test_its_personality_answers_its_own_command_and_refuses_the_planes(
        toy_cart: Path, tmp_path: Path) -> None:
    from pymavlink import mavutil

    from cosim.core.state import N_STATE
    from cosim.mavlink import MavlinkConfig, MavlinkEndpoint, mav_specs
    from cosim.mavlink.adapter import make_message
    from cosim.vehicles import get_class

    ML = mavutil.mavlink
    scn = load_scenario(_scenario(tmp_path))
    ep = MavlinkEndpoint(mav_specs(scn.vehicles, get_class), 120.0, MavlinkConfig(url=None))
    try:
        states = np.zeros((len(scn.vehicles), N_STATE))

        def long(sysid: int, command: int, *params: float) -> list:
            p = list(params) + [0.0] * (7 - len(params))
            ep.inject(make_message("COMMAND_LONG", target_system=sysid, target_component=1,
                                   command=command, **{f"param{i + 1}": p[i]
                                                       for i in range(7)}))
            return ep.exchange(0, states)

        cmds = long(1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 6.5)  # cart0: its own command
        assert [(c.row, c.command.airspeed_mps) for c in cmds] == [(0, 6.5)]
        assert long(1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 99) == []  # out of its range
        assert long(1, ML.MAV_CMD_COMPONENT_ARM_DISARM, 1) == []  # ArduPlane's, not a cart's
        counts = ep.counters()
        assert counts["unsupported_commands"] == 1 and counts["commands_refused"] == 2
    finally:
        ep.close()
