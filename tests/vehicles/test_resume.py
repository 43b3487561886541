"""A vehicle rebuilt from what a pool gathered (``cosim.vehicles.resume``)
flies on as the one it replaces: the same turn, the same attitude and rates
at the next ticks, not wings level (the ray backend rebuilds a lost
machine's vehicles this way; tests/fdm_pool/test_ray.py does it on a
cluster)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from cosim.bench.fleet import bench_specs
from cosim.core.state import STATE_INDEX, VehicleSpec
from cosim.fdm_pool.shard import Shard
from cosim.vehicles.registry import state_layout
from cosim.vehicles.resume import FIELDS, resume_spec

DT = 1 / 120
S = STATE_INDEX
ATT = [S["roll_deg"], S["pitch_deg"], S["yaw_deg"]]
#: the autopilot's setpoints: a long turn at 30 deg of bank, altitude and speed held
AP = {"cosim/ap/engage": 1.0, "cosim/ap/heading-hold": 1.0, "cosim/ap/heading-cmd-deg": 200.0,
      "cosim/ap/bank-limit-deg": 30.0, "cosim/ap/alt-hold": 1.0,
      "cosim/ap/alt-cmd-ft": 1050.0 / 0.3048, "cosim/ap/speed-hold": 1.0,
      "cosim/ap/speed-cmd-kt": 95.0, "cosim/ap/throttle-bias": 0.6,
      "position/h-sl-ft": np.nan}
CH = tuple(AP)


def _shard(specs: list[VehicleSpec]) -> tuple[Shard, np.ndarray, int]:
    """A shard gathering the ``FIELDS`` columns, its state block, the run's width."""
    names = [f.name for f in state_layout(specs)]
    shard = Shard.build(specs, DT, CH, layout_names=names + [f.name for f in FIELDS])
    out = np.zeros((len(specs), len(names) + len(FIELDS)))
    shard.write_states(out)
    return shard, out, len(names)


def _turning(model: str) -> tuple[Shard, np.ndarray, int, np.ndarray]:
    """One aircraft 3 s into a turn, and the setpoints it was sent."""
    shard, out, k = _shard(bench_specs(1, model))
    sent = np.array([list(AP.values())])
    shard.exchange(sent, 4, out)
    for _ in range(89):
        shard.exchange(None, 4, out)
    assert abs(out[0, S["roll_deg"]]) > 25  # at its bank limit
    return shard, out, k, sent[0]


@pytest.mark.parametrize("model", ["c172p", "uav700"])  # piston and turbojet, attached
def test_a_rebuilt_aircraft_turns_on_as_it_was(model: str) -> None:  # and native autopilot
    shard, out, k, sent = _turning(model)
    row = out[0].copy()
    spec = resume_spec(shard.vehicles[0].spec, row[:k], row[k:], CH, sent)
    rebuilt, out2, _ = _shard([spec])
    # where and as it was (to the rounding of m -> ft -> m), throttle included
    assert np.abs(out2[0, :k] - row[:k]).max() < 1e-6
    ticks: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(4):  # the next exchange, tick by tick
        shard.exchange(None, 1, out)
        rebuilt.exchange(None, 1, out2)
        ticks.append((out[0].copy(), out2[0].copy()))
    # what is not carried over (the engine's speed, the integrators' history)
    # changes the angular accelerations by well under 1 rad/s2: in 4 ticks (33 ms)
    # that is < 2 deg/s on a rate and < 0.03 deg on an angle; a rebuild from
    # heading and speed (trimmed wings level) was 30 deg off in roll at once
    for (want, got), (want0, got0) in zip(ticks, [(row, row)] + ticks[:-1]):
        assert np.abs(got[ATT] - want[ATT]).max() < 0.03
        rates = (got[ATT] - got0[ATT]) / DT, (want[ATT] - want0[ATT]) / DT
        assert np.abs(rates[0] - rates[1]).max() < 2.0
        assert np.abs(got[k:k + 3] - want[k:k + 3]).max() < np.radians(2.0)  # p, q, r
    for _ in range(60):  # 2 s on: the same turn
        shard.exchange(None, 4, out)
        rebuilt.exchange(None, 4, out2)
    assert abs(out2[0, S["roll_deg"]] - out[0, S["roll_deg"]]) < 1.0
    apart_m = np.hypot(out2[0, S["lat_deg"]] - out[0, S["lat_deg"]],
                       (out2[0, S["lon_deg"]] - out[0, S["lon_deg"]])
                       * np.cos(np.radians(out[0, S["lat_deg"]]))) * 111_320.0
    assert apart_m < 2.0


def test_a_value_that_moved_the_vehicle_is_not_replayed() -> None:
    shard, out, k, sent = _turning("c172p")
    sent[CH.index("position/h-sl-ft")] = 1000.0  # once put at 1000 ft, long ago
    row = out[0].copy()
    spec = resume_spec(shard.vehicles[0].spec, row[:k], row[k:], CH, sent)
    rebuilt, out2, _ = _shard([spec])
    rebuilt.exchange(None, 4, out2)
    assert abs(out2[0, S["alt_msl_m"]] - row[S["alt_msl_m"]]) < 1.0


def test_a_vehicle_without_gathered_columns_starts_from_position_heading_speed(
        specs: Callable[..., list[VehicleSpec]]) -> None:
    (spec,) = specs(1)
    row = np.zeros(len(state_layout([spec])))
    row[[S["lat_deg"], S["lon_deg"], S["alt_msl_m"], S["yaw_deg"], S["airspeed_mps"]]] = \
        [37.5, -122.1, 900.0, 370.0, 50.0]
    moved = resume_spec(spec, row, np.full(len(FIELDS), np.nan))
    assert not moved.resume and moved.trim
    assert (moved.lat_deg, moved.lon_deg, moved.alt_msl_m, moved.heading_deg,
            moved.airspeed_mps) == (37.5, -122.1, 900.0, 10.0, 50.0)
