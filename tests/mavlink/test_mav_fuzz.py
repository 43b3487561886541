"""MAVLink fuzzing: random messages of every type a vehicle handles, with
extreme and non-finite fields (NaN, +-inf, the float32 extremes, every
integer type's limits, junk text), through the endpoint's one handling path
(``inject``: exactly what arrives from a socket after decoding). Every
COMMAND_LONG/COMMAND_INT/SET_MODE gets exactly one COMMAND_ACK per vehicle
it addresses, every message whose protocol has an answer gets one, no
handler raises (``handler_errors`` stays 0), the endpoint keeps sending
telemetry, and no value reaches guidance that guidance would choke on.

Seeded and bounded: first a sweep (every numeric field of every handled
type, and of every handled command, at each of its extremes, the others
random: about 3,500 messages), then ``MESSAGES`` random ones; about 10 s.
``COSIM_FUZZ_SCALE=N`` multiplies the random ones and the ``slow`` test runs
twenty times as many.
The live version (real physics, garbage bytes too) is in test_mav_run.py.
"""

from __future__ import annotations

import math
import os
import random
import struct
from typing import Any

import numpy as np
import pytest
from mavtest import PHYSICS_HZ, mavutil, state_rows, vehicle_specs

from cosim.core.geo import LocalFrame
from cosim.mavlink import MavlinkConfig, MavlinkEndpoint
from cosim.mavlink import adapter as mav
from cosim.mavlink.handlers import Handler
from cosim.vehicles.fixed_wing.guidance import AP_CHANNELS, FixedWingGuidance
from cosim.vehicles.fixed_wing.mav_params import ARDUPLANE_PARAMS
from cosim.vehicles.fixed_wing.mavlink import ARDUPLANE

ML = mavutil.mavlink
MESSAGES = 3000  # random ones, after the sweep of every field's extremes
N_VEHICLES = 3

F32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]
FLOATS = [0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf, F32_MAX, -F32_MAX, 1e-45,
          2.0 ** 31, -(2.0 ** 31), 1e9, 21196.0, 0.5]
_INT_LIMITS = {"u1": (0, 255), "i1": (-128, 127), "<u2": (0, 65535), "<i2": (-32768, 32767),
               "<u4": (0, 2 ** 32 - 1), "<i4": (-2 ** 31, 2 ** 31 - 1),
               "<u8": (0, 2 ** 64 - 1), "<i8": (-2 ** 63, 2 ** 63 - 1)}
#: values handlers give meaning to: stream message ids, ArduPlane modes, arm/force
MEANINGFUL = [0, 1, 2, 24, 30, 33, 74, 148, 242, 245, 5, 10, 11, 12, 13, 15, 21196, 65535, -1]
_HANDLER = Handler(__import__("collections").Counter(), PHYSICS_HZ)
HANDLED = sorted(_HANDLER.by_name)
SUPPORTED = sorted(_HANDLER.commands.supported(ARDUPLANE))
COMMANDS = SUPPORTED + [0, 1, 31000, 65535, ML.MAV_CMD_DO_DIGICAM_CONTROL]
#: the message each handled one must be answered with (None: no answer in the protocol)
ANSWER = {"COMMAND_LONG": "COMMAND_ACK", "COMMAND_INT": "COMMAND_ACK",
          "SET_MODE": "COMMAND_ACK", "MISSION_REQUEST_LIST": "MISSION_COUNT",
          "MISSION_CLEAR_ALL": "MISSION_ACK", "MISSION_COUNT": ("MISSION_ACK",
                                                                "MISSION_REQUEST",
                                                                "MISSION_REQUEST_INT"),
          "MISSION_REQUEST": ("MISSION_ITEM", "MISSION_ACK"),
          "MISSION_REQUEST_INT": ("MISSION_ITEM_INT", "MISSION_ACK")}


def _value(rng: random.Random, name: str, npt: str, length: int) -> Any:
    if npt.startswith("S"):  # char[n]
        choice = rng.randrange(4)
        if choice == 0:
            return rng.choice([p.name for p in ARDUPLANE_PARAMS])
        if choice == 1:
            return ""
        n = int(npt[1:])
        return "".join(chr(rng.randrange(32, 127)) for _ in range(rng.randrange(n + 1)))
    if length:
        return [_value(rng, name, npt, 0) for _ in range(length)]
    if npt in ("<f4", "<f8"):
        return rng.choice(FLOATS) if rng.random() < 0.7 else rng.uniform(-1e6, 1e6)
    lo, hi = _INT_LIMITS[npt]
    return rng.choice([lo, hi, 0, 1, min(hi, 2), rng.randint(lo, hi)])


def _extremes(npt: str) -> list[Any]:
    if npt in ("<f4", "<f8"):
        return FLOATS
    lo, hi = _INT_LIMITS[npt]
    return sorted({lo, hi, 0, 1, min(hi, 2), max(lo, -1)})


def sweep_messages(rng: random.Random) -> list[mav.Message]:
    """Every numeric field of every handled type (of every handled command, for
    COMMAND_LONG/INT) set to each of its extremes in turn, the other fields
    random as in ``random_message``."""
    out = []
    for name in HANDLED:
        _, _, layout = mav.wire_layout(name)
        commands = SUPPORTED if name.startswith("COMMAND") else [None]
        for command in commands:
            for fname, npt, length in layout:
                if length or npt.startswith("S") or fname in ("command", "target_system",
                                                               "target_component"):
                    continue
                for value in _extremes(npt):
                    out.append(random_message(rng, name, {fname: value, "command": command}))
    return out


def random_message(rng: random.Random, name: str | None = None,
                   force: dict[str, Any] | None = None) -> mav.Message:
    """A handled message type with extreme fields, as it arrives decoded;
    ``force``: fields set as given (None values ignored)."""
    name = name or rng.choice(HANDLED)
    _, _, layout = mav.wire_layout(name)
    fields: dict[str, Any] = {}
    for fname, npt, length in layout:
        fields[fname] = _value(rng, fname, npt, length)
    if "target_system" in fields:
        fields["target_system"] = rng.choice([0, 1, 2, 3, 99, 255])
    if "target_component" in fields:
        fields["target_component"] = rng.choice([0, 1, 1, 190])
    if "command" in fields and name.startswith("COMMAND"):
        fields["command"] = rng.choice(COMMANDS)
        if rng.random() < 0.5:  # ids, modes and flags the handlers look up
            fields["param1"] = float(rng.choice(MEANINGFUL))
        if rng.random() < 0.3:
            fields["param2"] = float(rng.choice(MEANINGFUL))
    if name == "SET_MODE" and rng.random() < 0.5:
        fields["base_mode"] = ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        fields["custom_mode"] = rng.choice(MEANINGFUL) % 2 ** 32
    if name == "FILE_TRANSFER_PROTOCOL":
        fields["payload"] = [rng.randrange(256) for _ in range(251)]
    if name in ("MISSION_ITEM", "MISSION_ITEM_INT"):
        fields["command"] = rng.choice([ML.MAV_CMD_NAV_WAYPOINT, ML.MAV_CMD_NAV_LOITER_UNLIM,
                                        ML.MAV_CMD_NAV_TAKEOFF, ML.MAV_CMD_DO_CHANGE_SPEED,
                                        ML.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 9999])
        fields["frame"] = rng.choice([0, 3, 6, 10, 5, 6, 1, 255])
        fields["current"] = rng.choice([0, 1, 2, 3, 255])
    for key, value in (force or {}).items():
        if value is not None and key in fields:
            fields[key] = value
    if force:  # a sweep addresses vehicle 1
        for key in ("target_system", "target_component"):
            if key in fields:
                fields[key] = 1
    src = rng.choice([(255, 190), (254, 1), (1, 1), (255, 0)])
    for key, value in list(fields.items()):  # what the wire carries (float32, int ranges)
        if isinstance(value, float):
            fields[key] = struct.unpack("<f", struct.pack("<f", value))[0] \
                if abs(value) <= F32_MAX or not math.isfinite(value) else value
    return mav.make_message(name, *src, **fields)


def _addressed(m: mav.Message, n: int) -> int:
    """How many vehicles ``m`` addresses (and whose component it reaches)."""
    if m.target_component not in (None, 0, 1):
        return 0
    t = m.target_system
    return n if t == 0 else (1 if t is not None and 1 <= t <= n else 0)


def fuzz(tmp_path: Any, count: int, seed: int) -> dict[str, int]:
    rng = random.Random(seed)
    ep = MavlinkEndpoint(vehicle_specs(N_VEHICLES), PHYSICS_HZ, MavlinkConfig(url=None),
                         tlog_dir=tmp_path)
    got: list[mav.Message] = []
    ep.subscribe(got.append)
    states = state_rows(N_VEHICLES)
    frame = LocalFrame(47.0, 8.0, 400.0)
    guidance = FixedWingGuidance(N_VEHICLES, frame, np.zeros((N_VEHICLES, 2)),
                                 {c: i for i, c in enumerate(AP_CHANNELS)})
    setpoints = np.full((N_VEHICLES, len(AP_CHANNELS)), np.nan)
    tick = 0
    stats = {"messages": 0, "acks": 0, "answers": 0, "commands": 0}
    try:
        messages = sweep_messages(rng) + [random_message(rng) for _ in range(count)]
        for m in messages:
            ep.inject(m)
            got.clear()
            tick += 4
            for vc in ep.exchange(tick, states):
                guidance.command([vc.row], vc.command, states, setpoints)  # never raises
                stats["commands"] += 1
            guidance.update(states, setpoints)
            assert np.isfinite(setpoints[~np.isnan(setpoints)]).all()
            stats["messages"] += 1
            n = _addressed(m, N_VEHICLES)
            answer = ANSWER.get(m.name)
            if answer is None or n == 0:
                continue
            kinds = (answer,) if isinstance(answer, str) else answer
            replies = [g for g in got if g.name in kinds
                       and (g.fields.get("target_system") in (None, m.src_system))]
            if m.name in ("COMMAND_LONG", "COMMAND_INT", "SET_MODE"):
                acks = [g for g in replies if g.name == "COMMAND_ACK"]
                assert len(acks) == n, (m, acks)  # exactly one per vehicle addressed
                stats["acks"] += len(acks)
            else:
                assert replies, (m, got)
                stats["answers"] += 1
        c = ep.counters()
        assert c["handler_errors"] == 0, c
        # every vehicle still answers (its streams may have been turned off:
        # SET_MESSAGE_INTERVAL -1 is a legal request)
        got.clear()
        ep.inject(mav.make_message("COMMAND_LONG", target_system=0, target_component=1,
                                   command=ML.MAV_CMD_REQUEST_MESSAGE, param1=0))
        ep.exchange(tick + 4, states)
        assert {g.src_system for g in got if g.name == "HEARTBEAT"} == {1, 2, 3}
    finally:
        ep.close()
    return stats


@pytest.mark.integration
def test_random_extreme_messages_of_every_handled_type(tmp_path) -> None:
    scale = int(os.environ.get("COSIM_FUZZ_SCALE", "1"))
    stats = fuzz(tmp_path, MESSAGES * scale, seed=13)
    assert stats["messages"] > MESSAGES * scale + 3000  # the sweep, then the random ones
    # the fuzz reaches the handlers' working paths too, not only their refusals
    assert stats["acks"] > 500 and stats["answers"] > 100 and stats["commands"] > 20, stats


@pytest.mark.slow
def test_random_extreme_messages_long(tmp_path) -> None:
    fuzz(tmp_path, MESSAGES * 20, seed=1313)
