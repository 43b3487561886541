"""One simulated vehicle as a MAVLink vehicle (as its class's personality
says): identity, mode and arming state, parameters, telemetry built from its
state row, and the per-message schedule.

Telemetry is stamped from SIMULATION time only (``SimClock``): boot is tick
0, ``time_boot_ms`` counts simulated milliseconds, and unix times are a
wall-clock anchor plus simulated time. Nothing here reads the wall clock.

Streams are scheduled on integer ticks: each message has a period of
``max(1, round(physics_hz / rate_hz))`` ticks and a next-due tick; at an
exchange a message is sent once if it is due, and its next-due tick moves on
by whole periods, so the long-run rate is exactly ``physics_hz / period``
whatever the exchange interval (never more than once per exchange).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from cosim.core.state import STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.guidance.commands import Command
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink.mission import Mission
from cosim.mavlink.params import ParamTable
from cosim.mavlink.personality import Personality

_S = STATE_INDEX


_CONTROL = (mav.SENSOR_RATE_CONTROL | mav.SENSOR_ATTITUDE_CONTROL | mav.SENSOR_YAW_CONTROL
            | mav.SENSOR_Z_CONTROL | mav.SENSOR_XY_CONTROL)

#: messages a vehicle can produce on request or as a stream
STREAMABLE: tuple[str, ...] = (
    "HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD", "SYS_STATUS", "GPS_RAW_INT",
    "SYSTEM_TIME", "HOME_POSITION", "EXTENDED_SYS_STATE", "AUTOPILOT_VERSION",
    "MISSION_CURRENT")
#: default stream rates (Hz); streamable messages not listed are sent on request only
DEFAULT_RATES_HZ: Mapping[str, float] = {
    "HEARTBEAT": 1.0, "GLOBAL_POSITION_INT": 5.0, "ATTITUDE": 5.0, "VFR_HUD": 2.0,
    "SYS_STATUS": 1.0, "GPS_RAW_INT": 1.0, "SYSTEM_TIME": 1.0, "MISSION_CURRENT": 1.0}

#: system ids a vehicle may take (0 is broadcast; 251..255 are left to ground stations)
SYSID_RANGE = (1, 250)

#: a class's command-safety rule (``cosim.guidance.safety``): why ``command``
#: would fly the vehicle into the ground or ask for what it cannot do, given
#: what it can fly now and who it is; empty: it may fly it
SafetyRule = Callable[[Command, Limits, str], list[str]]


class MavClass(Protocol):
    """What a vehicle's class hands down to put its vehicles on MAVLink (the
    classes of ``cosim.vehicles`` are such): how they look (``mavlink``, a
    ``Personality``; None: the base one), how low above the ground a
    command may send them, and the safety rule of their commands."""

    mavlink: Personality | None

    def min_alt_agl_m(self, profile: Mapping[str, Any]) -> float: ...

    def safety_problems(self, cmd: Command, limits: Limits, who: str) -> list[str]: ...


def check_rates(rates_hz: Mapping[str, float]) -> list[str]:
    """Problems with a stream-rate mapping (message name -> Hz, 0 = off)."""
    problems = []
    for name, hz in rates_hz.items():
        if name not in STREAMABLE:
            problems.append(f"{name!r} is not a message cosim streams; streamable: "
                            f"{', '.join(STREAMABLE)}")
        elif isinstance(hz, bool) or not isinstance(hz, (int, float)) or not math.isfinite(hz) \
                or hz < 0:
            problems.append(f"{name}: rate must be a number >= 0 (Hz, 0 = off), got {hz!r}")
    return problems


def period_ticks(rate_hz: float, physics_hz: float) -> int | None:
    """Stream period in ticks for a rate (None: off)."""
    if rate_hz <= 0:
        return None
    return max(1, round(physics_hz / rate_hz))


@dataclass(frozen=True)
class SimClock:
    """Simulation time for MAVLink: boot at tick 0, unix time = anchor + sim time."""

    physics_hz: float
    anchor_unix_us: int

    def sim_us(self, tick: int) -> int:
        return int(tick * 1_000_000 // self.physics_hz)

    def boot_ms(self, tick: int) -> int:
        return (self.sim_us(tick) // 1000) % 2 ** 32

    def unix_us(self, tick: int) -> int:
        return self.anchor_unix_us + self.sim_us(tick)


@dataclass(frozen=True)
class MavVehicleSpec:
    """How one simulated vehicle appears on MAVLink.

    ``row`` is its row in the state array (and the index commands are
    returned with); ``home_alt_msl_m`` the ground under its start (ArduPilot's
    home is where it armed on the ground). ``mode`` None: GUIDED with an
    autopilot (outside guidance drives it), MANUAL without one.
    """

    row: int
    sysid: int
    name: str
    start_lat_deg: float
    start_lon_deg: float
    start_alt_msl_m: float
    home_alt_msl_m: float
    armed: bool = True
    mode: int | None = None
    params: Mapping[str, float] = field(default_factory=dict)
    #: how its class appears on MAVLink (None: the base personality, no modes)
    personality: Personality | None = None
    #: the class minimum height above the ground commands may ask for
    min_alt_agl_m: float = 0.0
    #: its class's safety rule, asked of every command (None: none)
    safety: SafetyRule | None = None

    @property
    def has_autopilot(self) -> bool:
        """Whether it takes commands (its personality's autopilot)."""
        return self.personality is not None and self.personality.autopilot


def mav_specs(vehicles: Sequence[VehicleSpec], classes: Callable[[str], MavClass],
              first_sysid: int = 1, first_row: int = 0,
              rows: Sequence[int] | None = None) -> list[MavVehicleSpec]:
    """MAVLink identities for scenario vehicles: system ids ``first_sysid``
    upwards; from each vehicle's class (``classes``: class name -> what the
    class hands down, e.g. ``cosim.vehicles.get_class``) its personality,
    command floor and safety rule, and the parameter values its personality
    derives from the vehicle (e.g. airspeed limits); their state rows
    ``first_row`` upwards, or ``rows``."""
    out = []
    for k, v in enumerate(vehicles):
        cls = classes(v.vehicle_class)
        personality = cls.mavlink or Personality()
        params = personality.spec_params(v)
        out.append(MavVehicleSpec(row=first_row + k if rows is None else rows[k],
                                  sysid=first_sysid + k, name=v.id,
                                  start_lat_deg=v.lat_deg, start_lon_deg=v.lon_deg,
                                  start_alt_msl_m=v.alt_msl_m, home_alt_msl_m=v.terrain_alt_m,
                                  params=params, personality=cls.mavlink,
                                  min_alt_agl_m=cls.min_alt_agl_m(v.profile),
                                  safety=cls.safety_problems))
    return out


def _i(x: float, lo: int, hi: int, nan: int = 0) -> int:
    """Round into an integer field's range (NaN -> ``nan``)."""
    if x != x:
        return nan
    return int(min(max(round(x), lo), hi))


ATTITUDE_COLUMNS = [_S["roll_deg"], _S["pitch_deg"], _S["yaw_deg"]]


def body_rates(prev_deg: np.ndarray, cur_deg: np.ndarray, dt_s: float) -> np.ndarray:
    """Body rates p, q, r (rad/s) from two samples of (roll, pitch, yaw) in
    degrees ``dt_s`` apart, per row (vectorised; non-finite results are 0)."""
    prev = np.radians(prev_deg)
    cur = np.radians(cur_deg)
    d = cur - prev
    d[:, 0] = np.remainder(d[:, 0] + np.pi, 2 * np.pi) - np.pi
    d[:, 2] = np.remainder(d[:, 2] + np.pi, 2 * np.pi) - np.pi
    dphi, dtheta, dpsi = (d / dt_s).T
    phi, theta = cur[:, 0], cur[:, 1]
    sphi, cphi, ctheta = np.sin(phi), np.cos(phi), np.cos(theta)
    pqr = np.stack([dphi - dpsi * np.sin(theta),
                    dtheta * cphi + dpsi * sphi * ctheta,
                    -dtheta * sphi + dpsi * cphi * ctheta], axis=1)
    return np.where(np.isfinite(pqr), pqr, 0.0)


def safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "vehicle"


class StateFrame:
    """The state rows of an exchange, shared by the vehicles of an endpoint:
    each vehicle reads its own row only when something needs it (no
    per-vehicle work per exchange). ``rows``: (n, N_STATE) float64 in vehicle
    order; ``rates``: (n, 3) body rates p, q, r in rad/s."""

    def __init__(self) -> None:
        self.rows: np.ndarray | None = None
        self._rates: np.ndarray | Callable[[], np.ndarray] | None = None
        self.version = 0
        self._attitude: np.ndarray | None = None  # the previous exchange's
        self._tick: int | None = None

    def update(self, rows: np.ndarray,
               rates: np.ndarray | Callable[[], np.ndarray]) -> None:
        """New rows; ``rates`` may be a function computing them on first use."""
        self.rows, self._rates = rows, rates
        self.version += 1

    def observe(self, rows: np.ndarray, tick: int, physics_hz: float) -> None:
        """The rows of the exchange at ``tick``, with the body rates from the
        attitude change since the previous exchange's (computed on first
        use); at the first exchange, or the same tick again, the rates stand."""
        att = rows[:, ATTITUDE_COLUMNS]
        prev_att, prev_tick = self._attitude, self._tick
        self._attitude, self._tick = att, tick
        if prev_att is not None and prev_tick is not None and tick > prev_tick:
            dt_s = (tick - prev_tick) / physics_hz
            self.update(rows, lambda: body_rates(prev_att, att, dt_s))
        else:
            self.update(rows, self.latest_rates(len(rows)))

    @property
    def rates(self) -> np.ndarray | None:
        r = self._rates
        if callable(r):
            r = self._rates = r()
        return r

    def latest_rates(self, n: int) -> np.ndarray:
        """The body rates of the latest rows (zeros for ``n`` vehicles before
        the second exchange)."""
        r = self.rates
        return np.zeros((n, 3)) if r is None else r


class MavVehicle:
    """Mutable MAVLink-side state of one vehicle.

    ``frame``/``index``: where its state row comes from (an endpoint's shared
    ``StateFrame``); without them it has its own.
    """

    def __init__(self, spec: MavVehicleSpec, clock: SimClock,
                 rates_hz: Mapping[str, float], frame: StateFrame | None = None,
                 index: int = 0) -> None:
        lo, hi = SYSID_RANGE
        if not lo <= spec.sysid <= hi:
            raise ValueError(f"vehicle {spec.name!r}: system id must be {lo}..{hi}, "
                             f"got {spec.sysid}")
        self.spec = spec
        self.row = spec.row
        self.sysid = spec.sysid
        self.clock = clock
        self.packer = mav.Packer(spec.sysid)
        self.personality = spec.personality or Personality()
        self.params = ParamTable(self.personality.param_defs, spec.params)
        if "SYSID_THISMAV" in self.params:
            self.params.force("SYSID_THISMAV", spec.sysid)
        self.armed = spec.armed
        self.mode = self.personality.default_mode() if spec.mode is None else int(spec.mode)
        self.home = (spec.start_lat_deg, spec.start_lon_deg, spec.home_alt_msl_m)
        self.period: dict[str, int | None] = {
            n: period_ticks(rates_hz.get(n, DEFAULT_RATES_HZ.get(n, 0.0)), clock.physics_hz)
            for n in STREAMABLE}
        self.next_due: dict[str, int | None] = {n: None for n in STREAMABLE}
        self.frame = frame if frame is not None else StateFrame()
        self.index = index
        self._seen = -1  # the frame version the cached row is from
        self._row: list[float] | None = None
        #: called with (vehicle, message name) when a stream's period changes
        self.on_period_change: Callable[[MavVehicle, str], None] | None = None
        self.mission = Mission()
        #: VIDEO_STREAM_INFORMATION fields of its streamed cameras (``cosim run --video``)
        self.video: list[dict[str, Any]] = []

    # -- state -------------------------------------------------------------
    @property
    def row_values(self) -> list[float] | None:
        """The latest state row as Python floats (None before any)."""
        f = self.frame
        if f.version != self._seen:
            self._seen = f.version
            self._row = None if f.rows is None else f.rows[self.index].tolist()
        return self._row

    @property
    def status(self) -> int:
        row = self.row_values
        if row is None:
            return int(VehicleStatus.ACTIVE)
        st = row[_S["status"]]
        return int(st) if st == st else int(VehicleStatus.DIVERGED)

    def in_air(self) -> bool:
        row = self.row_values
        return (row is not None and self.status == VehicleStatus.ACTIVE
                and self.personality.in_air(row))

    def prearm_ok(self) -> bool:
        return self.status == VehicleStatus.ACTIVE

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode (the personality's rule)."""
        return self.personality.base_mode(self.mode, self.armed)

    def system_status(self) -> int:
        if self.status != VehicleStatus.ACTIVE:
            return mav.MAV_STATE_EMERGENCY
        return mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY

    # -- schedule ----------------------------------------------------------
    def due(self, tick: int) -> list[str]:
        """Streams due at ``tick``; advances their next-due ticks."""
        out = []
        for name, p in self.period.items():
            if p is None:
                continue
            nd = self.next_due[name]
            if nd is None:
                nd = tick
            if tick >= nd:
                out.append(name)
                nd += p * ((tick - nd) // p + 1)
            self.next_due[name] = nd
        return out

    def set_period(self, name: str, period: int | None, tick: int) -> None:
        self.period[name] = period
        self.next_due[name] = tick  # starts at the next telemetry pass
        if self.on_period_change is not None:
            self.on_period_change(self, name)

    # -- telemetry ---------------------------------------------------------
    def fields(self, name: str, tick: int) -> dict[str, Any]:
        """The fields of a streamable message at ``tick`` (needs a state row,
        except for HEARTBEAT, SYSTEM_TIME and AUTOPILOT_VERSION)."""
        build = STATE_COLUMNS.get(name)
        if build is not None:
            if name != "SYSTEM_TIME":
                self.row_or_raise()
            cols = build(self.frame.rows[self.index:self.index + 1]
                         if self.frame.rows is not None else np.zeros((1, 0)),
                         self.frame.rates[self.index:self.index + 1]
                         if self.frame.rates is not None else np.zeros((1, 3)),
                         np.array([self.home[2]]), self.clock, tick)
            return {k: _scalar(v) for k, v in cols.items()}
        fields: dict[str, Any] = getattr(self, "_f_" + name.lower())(tick)
        return fields

    def row_or_raise(self) -> list[float]:
        """The latest state row; RuntimeError if there is none yet."""
        row = self.row_values
        if row is None:
            raise RuntimeError(f"vehicle {self.spec.name!r}: no state observed yet")
        return row

    def _f_heartbeat(self, tick: int) -> dict[str, Any]:
        p = self.personality
        return {"type": p.mav_type, "autopilot": p.autopilot_type,
                "base_mode": self.base_mode(), "custom_mode": self.mode,
                "system_status": self.system_status(), "mavlink_version": 3}

    def sensors_present(self) -> int:
        """What SYS_STATUS says the vehicle has: the position (GPS) and attitude
        (AHRS) it reports, its class's extra sensors (an airspeed sensor), motor
        outputs, and with an autopilot its control loops, pre-arm checks and,
        once a fence is uploaded, the geofence. No gyro, accelerometer,
        magnetometer or barometer: the simulation reports the flight model's
        state, not sensor readings."""
        present = (mav.SENSOR_GPS | mav.SENSOR_AHRS | mav.SENSOR_MOTOR_OUTPUTS
                   | self.personality.extra_sensors)
        if self.spec.has_autopilot:
            present |= _CONTROL | mav.SENSOR_PREARM_CHECK
            if self.mission.fence:
                present |= mav.SENSOR_GEOFENCE
        return present

    def _f_sys_status(self, tick: int) -> dict[str, Any]:
        present = self.sensors_present()
        enabled = present
        if self.personality.manual(self.mode) or not self.spec.has_autopilot:
            enabled &= ~_CONTROL
        if not self.armed:
            enabled &= ~mav.SENSOR_MOTOR_OUTPUTS
        # the geofence is healthy unless breached, with or without a fence, as
        # ArduPilot reports it: stations read a clear bit as a breach
        health = present | mav.SENSOR_GEOFENCE
        if not self.prearm_ok():
            health &= ~(mav.SENSOR_PREARM_CHECK | mav.SENSOR_AHRS)
        if self.mission.breached:
            health &= ~mav.SENSOR_GEOFENCE
        return {"onboard_control_sensors_present": present,
                "onboard_control_sensors_enabled": enabled,
                "onboard_control_sensors_health": health,
                "load": 0, "voltage_battery": 65535, "current_battery": -1,
                "battery_remaining": -1, "drop_rate_comm": 0, "errors_comm": 0,
                "errors_count1": 0, "errors_count2": 0, "errors_count3": 0, "errors_count4": 0}

    def _f_home_position(self, tick: int) -> dict[str, Any]:
        lat, lon, alt = self.home
        return {"latitude": _i(lat * 1e7, -900_000_000, 900_000_000),
                "longitude": _i(lon * 1e7, -1_800_000_000, 1_800_000_000),
                "altitude": _i(alt * 1000.0, -2 ** 31, 2 ** 31 - 1),
                # local frame = the vehicle's start (docs/physics.md, Coordinates): home is below it
                "x": 0.0, "y": 0.0, "z": float(self.spec.start_alt_msl_m - alt),
                "q": [1.0, 0.0, 0.0, 0.0], "approach_x": 0.0, "approach_y": 0.0,
                "approach_z": 0.0, "time_usec": self.clock.sim_us(tick)}

    def _f_extended_sys_state(self, tick: int) -> dict[str, Any]:
        return {"vtol_state": mav.MAV_VTOL_STATE_UNDEFINED,
                "landed_state": mav.MAV_LANDED_STATE_IN_AIR if self.in_air()
                else mav.MAV_LANDED_STATE_ON_GROUND}

    def _f_mission_current(self, tick: int) -> dict[str, Any]:
        self.mission.reported_current = self.mission.current
        return self.mission.state(self.mode == self.personality.auto_mode)

    def _f_autopilot_version(self, tick: int) -> dict[str, Any]:
        p = self.personality
        return {"capabilities": p.capability_flags(), "flight_sw_version": p.flight_sw_version,
                "middleware_sw_version": 0, "os_sw_version": 0, "board_version": 0,
                "flight_custom_version": list(b"cosim\0\0\0"),
                "middleware_custom_version": [0] * 8, "os_custom_version": [0] * 8,
                "vendor_id": 0, "product_id": 0, "uid": self.sysid}


# -- telemetry from state rows, vectorised over vehicles ------------------------
def _iv(x: np.ndarray, lo: int, hi: int, nan: int = 0) -> np.ndarray:
    """Round half to even into an integer field's range (NaN -> ``nan``)."""
    with np.errstate(invalid="ignore"):
        out = np.clip(np.rint(x), lo, hi)
    return np.where(np.isnan(x), nan, out).astype(np.int64)


def _cdeg_v(deg: np.ndarray) -> np.ndarray:
    """Angles in centidegrees 0..35999 (65535: unknown)."""
    ok = np.isfinite(deg)
    with np.errstate(invalid="ignore"):
        c = np.rint(np.mod(np.where(ok, deg, 0.0), 360.0) * 100.0) % 36000
    return np.where(ok, c, 65535).astype(np.int64)


_I32 = (-2 ** 31, 2 ** 31 - 1)
ColumnBuilder = Callable[[np.ndarray, np.ndarray, np.ndarray, SimClock, int],
                         dict[str, Any]]


def _c_global_position_int(r: np.ndarray, pqr: np.ndarray, home_alt: np.ndarray,
                           clock: SimClock, tick: int) -> dict[str, Any]:
    alt = r[:, _S["alt_msl_m"]]
    return {"time_boot_ms": clock.boot_ms(tick),
            "lat": _iv(r[:, _S["lat_deg"]] * 1e7, -900_000_000, 900_000_000),
            "lon": _iv(r[:, _S["lon_deg"]] * 1e7, -1_800_000_000, 1_800_000_000),
            "alt": _iv(alt * 1000.0, *_I32),
            "relative_alt": _iv((alt - home_alt) * 1000.0, *_I32),
            "vx": _iv(r[:, _S["vn_mps"]] * 100.0, -32768, 32767),
            "vy": _iv(r[:, _S["ve_mps"]] * 100.0, -32768, 32767),
            "vz": _iv(r[:, _S["vd_mps"]] * 100.0, -32768, 32767),
            "hdg": _cdeg_v(r[:, _S["yaw_deg"]])}


def _c_attitude(r: np.ndarray, pqr: np.ndarray, home_alt: np.ndarray, clock: SimClock,
                tick: int) -> dict[str, Any]:
    yaw = np.radians(r[:, _S["yaw_deg"]])
    return {"time_boot_ms": clock.boot_ms(tick),
            "roll": np.radians(r[:, _S["roll_deg"]]),
            "pitch": np.radians(r[:, _S["pitch_deg"]]),
            # -pi..pi as IEEE remainder (exact), like ArduPilot reports it
            "yaw": np.array([math.remainder(y, math.tau) for y in yaw.tolist()]),
            "rollspeed": pqr[:, 0], "pitchspeed": pqr[:, 1], "yawspeed": pqr[:, 2]}


def _c_vfr_hud(r: np.ndarray, pqr: np.ndarray, home_alt: np.ndarray, clock: SimClock,
               tick: int) -> dict[str, Any]:
    yaw = r[:, _S["yaw_deg"]]
    ok = np.isfinite(yaw)
    heading = np.where(ok, np.floor(np.mod(np.where(ok, yaw, 0.0), 360.0)) % 360, 0)
    return {"airspeed": r[:, _S["airspeed_mps"]],
            "groundspeed": np.hypot(r[:, _S["vn_mps"]], r[:, _S["ve_mps"]]),
            "heading": heading.astype(np.int64),
            "throttle": _iv(r[:, _S["throttle"]] * 100.0, 0, 100),
            "alt": r[:, _S["alt_msl_m"]], "climb": -r[:, _S["vd_mps"]]}


def _c_gps_raw_int(r: np.ndarray, pqr: np.ndarray, home_alt: np.ndarray, clock: SimClock,
                   tick: int) -> dict[str, Any]:
    vn, ve = r[:, _S["vn_mps"]], r[:, _S["ve_mps"]]
    gs = np.hypot(vn, ve)
    with np.errstate(invalid="ignore"):
        moving = gs > 0.1
    cog = np.where(moving, _cdeg_v(np.degrees(np.arctan2(ve, vn))), 65535)
    alt_mm = _iv(r[:, _S["alt_msl_m"]] * 1000.0, *_I32)
    return {"time_usec": clock.sim_us(tick), "fix_type": mav.GPS_FIX_TYPE_3D_FIX,
            "lat": _iv(r[:, _S["lat_deg"]] * 1e7, -900_000_000, 900_000_000),
            "lon": _iv(r[:, _S["lon_deg"]] * 1e7, -1_800_000_000, 1_800_000_000),
            "alt": alt_mm, "eph": 100, "epv": 100, "vel": _iv(gs * 100.0, 0, 65534),
            "cog": cog, "satellites_visible": 12,
            # cosim has no geoid: heights are ellipsoidal throughout (cosim.core.geo)
            "alt_ellipsoid": alt_mm, "h_acc": 500, "v_acc": 800, "vel_acc": 100,
            "hdg_acc": 0, "yaw": 0}


def _c_system_time(r: np.ndarray, pqr: np.ndarray, home_alt: np.ndarray, clock: SimClock,
                   tick: int) -> dict[str, Any]:
    return {"time_unix_usec": clock.unix_us(tick), "time_boot_ms": clock.boot_ms(tick)}


#: messages built from state rows for many vehicles at once: name -> builder of
#: columns (arrays over the rows given, or one value for all)
STATE_COLUMNS: dict[str, ColumnBuilder] = {
    "GLOBAL_POSITION_INT": _c_global_position_int, "ATTITUDE": _c_attitude,
    "VFR_HUD": _c_vfr_hud, "GPS_RAW_INT": _c_gps_raw_int, "SYSTEM_TIME": _c_system_time}


def _scalar(v: Any) -> Any:
    """One row's value of a column as a plain Python number."""
    if isinstance(v, np.ndarray):
        v = v[0]
    return v.item() if isinstance(v, np.generic) else v
