"""A toy vehicle class for cosim: carts that drive straight ahead on the
ground at a commanded speed. It shows everything a class supplies, in one
small file: a batched model (all carts of a worker advanced by one numpy
call per substep), its own scenario key (``accel_mps2``), a state column of
its own (``odometer_m``), a command vocabulary (``airspeed_mps``/
``airspeed_kt``: the cart's speed) with its guidance, and a MAVLink
personality (a ground rover, in mode 0 "DRIVE", that takes DO_CHANGE_SPEED).

Scenario (``carts.yaml`` beside this file)::

    vehicles:
      - {id: cart, class: toy_cart, model: cart, accel_mps2: 1.5,
         init: {north_m: 0, east_m: 0, alt_agl_m: 0, heading_deg: 90, airspeed_mps: 3}}
    schedule:
      - {at_s: 5, vehicles: cart, command: {airspeed_mps: 8}}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX, StateField, VehicleSpec, VehicleStatus
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import CommandRequest, Outcome, text, vocab
from cosim.mavlink.personality import CommandFn, Personality
from cosim.mavlink.services.base import Context
from cosim.vehicles import GuidanceEvent, ModelChoice, VehicleClass

SPEED_CMD = "toy_cart/speed-cmd-mps"  # the setpoint channel its guidance writes
_S = STATE_INDEX


class CartModel:
    """Every cart of one worker: positions along each cart's heading, speeds
    moving toward the commanded speed at ``accel_mps2``; only +, -, *, /
    inside the vectorised step, so a cart's state never depends on how many
    carts share its batch."""

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                 columns: Sequence[str]) -> None:
        self.dt_s = dt_s
        self.odometer = list(columns).index("odometer_m")
        self.col = list(channels).index(SPEED_CMD) if SPEED_CMD in channels else None
        self.frames = [LocalFrame(s.lat_deg, s.lon_deg, s.terrain_alt_m) for s in specs]
        self.alt_m = np.array([s.terrain_alt_m for s in specs])
        heading = [math.radians(s.heading_deg) for s in specs]
        self.heading_deg = np.array([s.heading_deg for s in specs])
        self.cos_h = np.array([math.cos(h) for h in heading])
        self.sin_h = np.array([math.sin(h) for h in heading])
        self.accel = np.array([float(s.class_params.get("accel_mps2", 1.0)) for s in specs])
        self.speed = np.array([s.airspeed_mps for s in specs])
        self.cmd = self.speed.copy()
        self.dist = np.zeros(len(specs))  # metres driven from the start

    def apply(self, setpoints: np.ndarray) -> None:
        if self.col is not None:
            v = setpoints[:, self.col]
            self.cmd = np.where(np.isnan(v), self.cmd, v)

    def step(self, nsub: int) -> None:
        for _ in range(nsub):
            dv = np.clip(self.cmd - self.speed, -self.accel * self.dt_s, self.accel * self.dt_s)
            self.speed = self.speed + dv
            self.dist = self.dist + self.speed * self.dt_s

    def write_states(self, out: np.ndarray) -> None:
        out[:] = 0.0
        for j, frame in enumerate(self.frames):  # one cart at a time: exact, batch-free
            lat, lon = frame.place(float(self.dist[j] * self.cos_h[j]),
                                   float(self.dist[j] * self.sin_h[j]), float(self.alt_m[j]))
            out[j, _S["lat_deg"]], out[j, _S["lon_deg"]] = float(lat), float(lon)
        out[:, _S["alt_msl_m"]] = self.alt_m
        out[:, _S["yaw_deg"]] = self.heading_deg
        out[:, _S["vn_mps"]] = self.speed * self.cos_h
        out[:, _S["ve_mps"]] = self.speed * self.sin_h
        out[:, _S["airspeed_mps"]] = self.speed
        out[:, _S["status"]] = VehicleStatus.ACTIVE
        out[:, self.odometer] = self.dist  # the class's own column


class CartGuidance:
    """Commands to setpoints: a speed, held."""

    def __init__(self, n: int, channel_index: Mapping[str, int]) -> None:
        self.col = channel_index[SPEED_CMD]
        self.labels = [""] * n

    def command(self, rows: list[int], cmd: Command, states: np.ndarray,
                sp: np.ndarray) -> None:
        if cmd.airspeed_mps is not None:
            sp[rows, self.col] = cmd.airspeed_mps
            for r in rows:
                self.labels[r] = f"drive {cmd.airspeed_mps:g} m/s"

    def update(self, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]:
        return []


class Rover(Personality):
    """How a cart looks on MAVLink: a ground rover in one mode, DRIVE, that
    takes one command, DO_CHANGE_SPEED (param2: m/s). The services answer
    the rest (one COMMAND_ACK each, UNSUPPORTED for what it lacks)."""

    mav_type = mav.MAV_TYPE_GROUND_ROVER
    autopilot = True
    modes = {0: "DRIVE"}

    def command_handler(self, number: int) -> CommandFn | None:
        return self._change_speed if number == mav.MAV_CMD_DO_CHANGE_SPEED else None

    def supported_commands(self) -> frozenset[int]:
        return frozenset({mav.MAV_CMD_DO_CHANGE_SPEED})

    @staticmethod
    def _change_speed(ctx: Context, v: Any, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        cmd = vocab({"airspeed_mps": req.p[1]})
        if isinstance(cmd, str) or not 0 <= req.p[1] <= 30:
            out.replies.extend(text("change speed: a toy cart drives at 0..30 m/s"))
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED


class ToyCart(VehicleClass):
    name = "toy_cart"
    description = "a toy cart driving straight ahead on the ground (batched; an example)"
    model_kind = "batched"
    vehicle_keys = ("accel_mps2",)
    state_columns = (StateField("odometer_m", None),)
    default_camera_mount = "forward"
    contact_is_impact = False
    channels = (SPEED_CMD,)
    mavlink = Rover()

    def resolve_model(self, model: str | None, aircraft_path: tuple[str, ...]
                      ) -> ModelChoice:
        if model not in (None, "cart"):
            raise ConfigError(f"toy_cart has one model, 'cart'; got {model!r}")
        return ModelChoice("cart")

    def parse_vehicle(self, entry: Any, path: tuple[Any, ...]) -> dict[str, Any]:
        accel = entry.num("accel_mps2", 1.0, lo=0.0, lo_open=True, hi=10.0)
        return {"accel_mps2": accel if accel is not None else 1.0}

    def make_batch(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                   columns: Sequence[str]) -> CartModel:
        return CartModel(specs, dt_s, channels, columns)

    @property
    def commandable(self) -> bool:
        return True

    def make_guidance(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                      channel_index: Mapping[str, int], specs: Sequence[VehicleSpec] = ()
                      ) -> CartGuidance:
        return CartGuidance(len(start_ne), channel_index)

    def command_problems(self, cmd: Command, spec: VehicleSpec, limits: Limits) -> list[str]:
        if cmd.airspeed_mps is None or cmd.nav or cmd.alt_m is not None \
                or cmd.heading_deg is not None:
            return [f"{spec.id}: a toy cart takes only a speed (airspeed_mps or airspeed_kt)"]
        if not 0 <= cmd.airspeed_mps <= 30:
            return [f"{spec.id}: a toy cart drives at 0..30 m/s"]
        return []


TOY_CART = ToyCart()
