"""The one module that imports pymavlink.

Everything else in ``cosim.mavlink`` sees MAVLink through this module only:

- ``Packer``: encodes messages for ONE vehicle (its own system id,
  component 1 and its own sequence numbers), MAVLink 2 framing,
  ``ardupilotmega`` dialect (a superset of ``common``).
- ``Decoder``: turns one received UDP datagram into typed ``Message``
  values. It never raises: garbage, bad CRCs, truncated or malformed
  packets and unknown message ids are dropped and counted.
- ``Message``: a decoded message as plain Python values (no pymavlink
  types leak out), also constructible directly so in-process callers can use
  the same handling path as the network.
- MAVLink 2 signing: ``signing_key`` (MAVProxy's passphrase -> key),
  ``Packer.enable_signing`` (sign every outgoing packet) and
  ``SignatureChecker`` (verify received packets, reject replays).
- The protocol constants the rest of the package uses, as typed ints.

pymavlink ships no type information, so its objects stay inside this module.
The dialect module is imported directly (not through ``mavutil``), so the
``MAVLINK20``/``MAVLINK_DIALECT`` environment variables that ``mavutil``
reads do not change what cosim sends.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Final

from pymavlink.dialects.v20 import ardupilotmega as _d

#: MAVLink protocol version spoken (framing); v1 packets are still decoded
WIRE_PROTOCOL_VERSION: Final[str] = str(_d.WIRE_PROTOCOL_VERSION)

# -- constants ---------------------------------------------------------------
MAV_COMP_ID_AUTOPILOT1: Final[int] = int(_d.MAV_COMP_ID_AUTOPILOT1)
MAV_COMP_ID_ALL: Final[int] = int(_d.MAV_COMP_ID_ALL)
MAV_TYPE_GENERIC: Final[int] = int(_d.MAV_TYPE_GENERIC)
MAV_TYPE_FIXED_WING: Final[int] = int(_d.MAV_TYPE_FIXED_WING)
MAV_TYPE_QUADROTOR: Final[int] = int(_d.MAV_TYPE_QUADROTOR)
MAV_TYPE_GROUND_ROVER: Final[int] = int(_d.MAV_TYPE_GROUND_ROVER)
MAV_TYPE_GCS: Final[int] = int(_d.MAV_TYPE_GCS)
MAV_AUTOPILOT_ARDUPILOTMEGA: Final[int] = int(_d.MAV_AUTOPILOT_ARDUPILOTMEGA)
MAV_AUTOPILOT_GENERIC: Final[int] = int(_d.MAV_AUTOPILOT_GENERIC)

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final[int] = int(_d.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
MAV_MODE_FLAG_GUIDED_ENABLED: Final[int] = int(_d.MAV_MODE_FLAG_GUIDED_ENABLED)
MAV_MODE_FLAG_STABILIZE_ENABLED: Final[int] = int(_d.MAV_MODE_FLAG_STABILIZE_ENABLED)
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED: Final[int] = int(_d.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED)
MAV_MODE_FLAG_SAFETY_ARMED: Final[int] = int(_d.MAV_MODE_FLAG_SAFETY_ARMED)

MAV_STATE_STANDBY: Final[int] = int(_d.MAV_STATE_STANDBY)
MAV_STATE_ACTIVE: Final[int] = int(_d.MAV_STATE_ACTIVE)
MAV_STATE_EMERGENCY: Final[int] = int(_d.MAV_STATE_EMERGENCY)

MAV_RESULT_ACCEPTED: Final[int] = int(_d.MAV_RESULT_ACCEPTED)
MAV_RESULT_TEMPORARILY_REJECTED: Final[int] = int(_d.MAV_RESULT_TEMPORARILY_REJECTED)
MAV_RESULT_DENIED: Final[int] = int(_d.MAV_RESULT_DENIED)
MAV_RESULT_UNSUPPORTED: Final[int] = int(_d.MAV_RESULT_UNSUPPORTED)
MAV_RESULT_FAILED: Final[int] = int(_d.MAV_RESULT_FAILED)

MAV_CMD_NAV_WAYPOINT: Final[int] = int(_d.MAV_CMD_NAV_WAYPOINT)
MAV_CMD_DO_SET_MISSION_CURRENT: Final[int] = int(_d.MAV_CMD_DO_SET_MISSION_CURRENT)
MAV_CMD_NAV_LOITER_UNLIM: Final[int] = int(_d.MAV_CMD_NAV_LOITER_UNLIM)
MAV_CMD_NAV_RETURN_TO_LAUNCH: Final[int] = int(_d.MAV_CMD_NAV_RETURN_TO_LAUNCH)
MAV_CMD_NAV_TAKEOFF: Final[int] = int(_d.MAV_CMD_NAV_TAKEOFF)
MAV_CMD_NAV_LAND: Final[int] = int(_d.MAV_CMD_NAV_LAND)
MAV_CMD_DO_SET_MODE: Final[int] = int(_d.MAV_CMD_DO_SET_MODE)
MAV_CMD_DO_CHANGE_SPEED: Final[int] = int(_d.MAV_CMD_DO_CHANGE_SPEED)
MAV_CMD_DO_REPOSITION: Final[int] = int(_d.MAV_CMD_DO_REPOSITION)
MAV_CMD_COMPONENT_ARM_DISARM: Final[int] = int(_d.MAV_CMD_COMPONENT_ARM_DISARM)
MAV_CMD_GET_HOME_POSITION: Final[int] = int(_d.MAV_CMD_GET_HOME_POSITION)
MAV_CMD_GET_MESSAGE_INTERVAL: Final[int] = int(_d.MAV_CMD_GET_MESSAGE_INTERVAL)
MAV_CMD_SET_MESSAGE_INTERVAL: Final[int] = int(_d.MAV_CMD_SET_MESSAGE_INTERVAL)
MAV_CMD_REQUEST_MESSAGE: Final[int] = int(_d.MAV_CMD_REQUEST_MESSAGE)
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: Final[int] = int(
    _d.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES)
MAV_CMD_NAV_LOITER_TURNS: Final[int] = int(_d.MAV_CMD_NAV_LOITER_TURNS)
MAV_CMD_NAV_LOITER_TIME: Final[int] = int(_d.MAV_CMD_NAV_LOITER_TIME)
MAV_CMD_NAV_LOITER_TO_ALT: Final[int] = int(_d.MAV_CMD_NAV_LOITER_TO_ALT)
MAV_CMD_DO_JUMP: Final[int] = int(_d.MAV_CMD_DO_JUMP)
MAV_CMD_DO_SET_HOME: Final[int] = int(_d.MAV_CMD_DO_SET_HOME)
MAV_CMD_CONDITION_DELAY: Final[int] = int(_d.MAV_CMD_CONDITION_DELAY)
MAV_CMD_CONDITION_DISTANCE: Final[int] = int(_d.MAV_CMD_CONDITION_DISTANCE)
MAV_CMD_DO_SET_ROI: Final[int] = int(_d.MAV_CMD_DO_SET_ROI)
MAV_CMD_DO_SET_ROI_LOCATION: Final[int] = int(_d.MAV_CMD_DO_SET_ROI_LOCATION)
MAV_CMD_DO_SET_ROI_NONE: Final[int] = int(_d.MAV_CMD_DO_SET_ROI_NONE)
MAV_CMD_DO_SET_CAM_TRIGG_DIST: Final[int] = int(_d.MAV_CMD_DO_SET_CAM_TRIGG_DIST)
MAV_CMD_IMAGE_START_CAPTURE: Final[int] = int(_d.MAV_CMD_IMAGE_START_CAPTURE)
MAV_CMD_IMAGE_STOP_CAPTURE: Final[int] = int(_d.MAV_CMD_IMAGE_STOP_CAPTURE)
MAV_CMD_DO_DIGICAM_CONTROL: Final[int] = int(_d.MAV_CMD_DO_DIGICAM_CONTROL)
MAV_CMD_MISSION_START: Final[int] = int(_d.MAV_CMD_MISSION_START)
MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION: Final[int] = int(
    _d.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION)
VIDEO_STREAM_TYPE_RTPUDP: Final[int] = int(_d.VIDEO_STREAM_TYPE_RTPUDP)
VIDEO_STREAM_TYPE_MPEG_TS: Final[int] = int(_d.VIDEO_STREAM_TYPE_MPEG_TS)
VIDEO_STREAM_STATUS_FLAGS_RUNNING: Final[int] = int(_d.VIDEO_STREAM_STATUS_FLAGS_RUNNING)
VIDEO_STREAM_ENCODING_H264: Final[int] = int(_d.VIDEO_STREAM_ENCODING_H264)
MAV_CMD_DO_ORBIT: Final[int] = int(_d.MAV_CMD_DO_ORBIT)
MAV_CMD_NAV_FENCE_RETURN_POINT: Final[int] = int(_d.MAV_CMD_NAV_FENCE_RETURN_POINT)
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION: Final[int] = int(
    _d.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION)
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION: Final[int] = int(
    _d.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION: Final[int] = int(_d.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION)
MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION: Final[int] = int(_d.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)
MAV_CMD_NAV_RALLY_POINT: Final[int] = int(_d.MAV_CMD_NAV_RALLY_POINT)

MAV_DO_REPOSITION_FLAGS_CHANGE_MODE: Final[int] = int(_d.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)

MAV_FRAME_GLOBAL: Final[int] = int(_d.MAV_FRAME_GLOBAL)
MAV_FRAME_GLOBAL_INT: Final[int] = int(_d.MAV_FRAME_GLOBAL_INT)
MAV_FRAME_GLOBAL_RELATIVE_ALT: Final[int] = int(_d.MAV_FRAME_GLOBAL_RELATIVE_ALT)
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: Final[int] = int(_d.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
MAV_FRAME_GLOBAL_TERRAIN_ALT: Final[int] = int(_d.MAV_FRAME_GLOBAL_TERRAIN_ALT)
MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: Final[int] = int(_d.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
MAV_FRAME_LOCAL_NED: Final[int] = int(_d.MAV_FRAME_LOCAL_NED)
MAV_FRAME_MISSION: Final[int] = int(_d.MAV_FRAME_MISSION)
MAV_FRAME_LOCAL_OFFSET_NED: Final[int] = int(_d.MAV_FRAME_LOCAL_OFFSET_NED)
MAV_FRAME_BODY_OFFSET_NED: Final[int] = int(_d.MAV_FRAME_BODY_OFFSET_NED)

POSITION_TARGET_TYPEMASK_X_IGNORE: Final[int] = int(_d.POSITION_TARGET_TYPEMASK_X_IGNORE)
POSITION_TARGET_TYPEMASK_Y_IGNORE: Final[int] = int(_d.POSITION_TARGET_TYPEMASK_Y_IGNORE)
POSITION_TARGET_TYPEMASK_Z_IGNORE: Final[int] = int(_d.POSITION_TARGET_TYPEMASK_Z_IGNORE)

MAV_MISSION_TYPE_MISSION: Final[int] = int(_d.MAV_MISSION_TYPE_MISSION)
MAV_MISSION_TYPE_ALL: Final[int] = int(_d.MAV_MISSION_TYPE_ALL)
MAV_MISSION_TYPE_FENCE: Final[int] = int(_d.MAV_MISSION_TYPE_FENCE)
MAV_MISSION_TYPE_RALLY: Final[int] = int(_d.MAV_MISSION_TYPE_RALLY)
MAV_MISSION_ACCEPTED: Final[int] = int(_d.MAV_MISSION_ACCEPTED)
MAV_MISSION_ERROR: Final[int] = int(_d.MAV_MISSION_ERROR)
MAV_MISSION_UNSUPPORTED_FRAME: Final[int] = int(_d.MAV_MISSION_UNSUPPORTED_FRAME)
MAV_MISSION_UNSUPPORTED: Final[int] = int(_d.MAV_MISSION_UNSUPPORTED)
MAV_MISSION_NO_SPACE: Final[int] = int(_d.MAV_MISSION_NO_SPACE)
MAV_MISSION_INVALID_PARAM1: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM1)
MAV_MISSION_INVALID_PARAM2: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM2)
MAV_MISSION_INVALID_PARAM3: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM3)
MAV_MISSION_INVALID_PARAM5_X: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM5_X)
MAV_MISSION_INVALID_PARAM6_Y: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM6_Y)
MAV_MISSION_INVALID_PARAM7: Final[int] = int(_d.MAV_MISSION_INVALID_PARAM7)
MAV_MISSION_INVALID_SEQUENCE: Final[int] = int(_d.MAV_MISSION_INVALID_SEQUENCE)
MAV_MISSION_DENIED: Final[int] = int(_d.MAV_MISSION_DENIED)
MAV_MISSION_OPERATION_CANCELLED: Final[int] = int(_d.MAV_MISSION_OPERATION_CANCELLED)

MAV_PARAM_TYPE_INT8: Final[int] = int(_d.MAV_PARAM_TYPE_INT8)
MAV_PARAM_TYPE_INT16: Final[int] = int(_d.MAV_PARAM_TYPE_INT16)
MAV_PARAM_TYPE_INT32: Final[int] = int(_d.MAV_PARAM_TYPE_INT32)
MAV_PARAM_TYPE_REAL32: Final[int] = int(_d.MAV_PARAM_TYPE_REAL32)

MAV_SEVERITY_CRITICAL: Final[int] = int(_d.MAV_SEVERITY_CRITICAL)
MAV_SEVERITY_WARNING: Final[int] = int(_d.MAV_SEVERITY_WARNING)
MAV_SEVERITY_INFO: Final[int] = int(_d.MAV_SEVERITY_INFO)

GPS_FIX_TYPE_3D_FIX: Final[int] = int(_d.GPS_FIX_TYPE_3D_FIX)
MAV_VTOL_STATE_UNDEFINED: Final[int] = int(_d.MAV_VTOL_STATE_UNDEFINED)
MAV_LANDED_STATE_ON_GROUND: Final[int] = int(_d.MAV_LANDED_STATE_ON_GROUND)
MAV_LANDED_STATE_IN_AIR: Final[int] = int(_d.MAV_LANDED_STATE_IN_AIR)

#: SYS_STATUS sensor/subsystem bits cosim reports (present, enabled, health)
SENSOR_GYRO: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_3D_GYRO)
SENSOR_ACCEL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_3D_ACCEL)
SENSOR_MAG: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_3D_MAG)
SENSOR_ABS_PRESSURE: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE)
SENSOR_DIFF_PRESSURE: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE)
SENSOR_GPS: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_GPS)
SENSOR_RATE_CONTROL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL)
SENSOR_ATTITUDE_CONTROL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION)
SENSOR_YAW_CONTROL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_YAW_POSITION)
SENSOR_Z_CONTROL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL)
SENSOR_XY_CONTROL: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL)
SENSOR_MOTOR_OUTPUTS: Final[int] = int(_d.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
SENSOR_GEOFENCE: Final[int] = int(_d.MAV_SYS_STATUS_GEOFENCE)
SENSOR_AHRS: Final[int] = int(_d.MAV_SYS_STATUS_AHRS)
SENSOR_PREARM_CHECK: Final[int] = int(_d.MAV_SYS_STATUS_PREARM_CHECK)

CAP_MAVLINK2: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
CAP_COMMAND_INT: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_COMMAND_INT)
CAP_PARAM_ENCODE_C_CAST: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
CAP_MISSION_INT: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_MISSION_INT)
CAP_MISSION_FLOAT: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT)
CAP_PARAM_FLOAT: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT)
CAP_MISSION_FENCE: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE)
CAP_MISSION_RALLY: Final[int] = int(_d.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)
CAP_SET_POSITION_TARGET_GLOBAL_INT: Final[int] = int(
    _d.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT)
CAP_SET_POSITION_TARGET_LOCAL_NED: Final[int] = int(
    _d.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED)

FIRMWARE_VERSION_TYPE_OFFICIAL: Final[int] = int(_d.FIRMWARE_VERSION_TYPE_OFFICIAL)

_F32 = struct.Struct("<f")

#: CRC-16/MCRF4XX of bytes from an initial value, in C when pymavlink has
#: fastcrc (its dependency), else None (callers fall back to their own)
crc16_mcrf4xx: Any = getattr(_d, "mcrf4xx", None)

# -- message ids -------------------------------------------------------------
_CLASS_BY_NAME: dict[str, Any] = {cls.msgname: cls for cls in _d.mavlink_map.values()}
_NAME_BY_ID: dict[int, str] = {int(i): cls.msgname for i, cls in _d.mavlink_map.items()}
_CHAR_FIELDS: dict[str, frozenset[str]] = {
    name: frozenset(f for f, t in zip(cls.fieldnames, cls.fieldtypes) if t == "char")
    for name, cls in _CLASS_BY_NAME.items()}


def msg_id(name: str) -> int:
    """The numeric id of a message name (``"HEARTBEAT"`` -> 0); KeyError if unknown."""
    return int(_CLASS_BY_NAME[name].id)


def msg_name(msgid: int) -> str | None:
    """The name of a message id, or None if the dialect does not define it."""
    return _NAME_BY_ID.get(msgid)


def command_name(cmd: int) -> str:
    """The name of a MAV_CMD value (``"MAV_CMD_NAV_TAKEOFF"``), or ``"MAV_CMD <n>"``."""
    entry = _d.enums.get("MAV_CMD", {}).get(cmd)
    return str(entry.name) if entry is not None else f"MAV_CMD {cmd}"


def enum_entry(enum: str, value: int) -> str | None:
    """The name of ``value`` in MAVLink enum ``enum`` (None: not in it)."""
    entry = _d.enums.get(enum, {}).get(value)
    return str(entry.name) if entry is not None else None


_FLOAT32_FIELDS: dict[str, tuple[str, ...]] = {}  # filled on first use per message


def wire_values(name: str, fields: dict[str, Any]) -> dict[str, Any]:
    """``fields`` with every scalar ``float`` field rounded to float32, as a
    receiver decodes them from the wire (in-place; returns ``fields``). Integer
    fields are already exact; arrays and chars are left alone."""
    names = _FLOAT32_FIELDS.get(name)
    if names is None:
        cls = _message_class(name)
        names = _FLOAT32_FIELDS[name] = tuple(
            f for f, t, n in zip(cls.fieldnames, cls.fieldtypes, _array_lengths(cls))
            if t == "float" and not n)
    for f in names:
        v = fields.get(f)
        if v is not None:
            fields[f] = _F32.unpack(_F32.pack(v))[0]
    return fields


_NP_TYPES = {"uint8_t": "u1", "int8_t": "i1", "uint16_t": "<u2", "int16_t": "<i2",
             "uint32_t": "<u4", "int32_t": "<i4", "uint64_t": "<u8", "int64_t": "<i8",
             "float": "<f4", "double": "<f8", "char": "S1"}


def wire_layout(name: str) -> tuple[int, int, list[tuple[str, str, int]]]:
    """(message id, CRC extra, fields in wire order as (name, numpy type, array
    length or 0)) of a message: what a batch encoder needs to lay out payloads."""
    cls = _message_class(name)
    types = dict(zip(cls.fieldnames, cls.fieldtypes))
    fields = []
    for f, n in zip(cls.ordered_fieldnames, cls.array_lengths):
        t = _NP_TYPES[types[f]]
        if t == "S1" and n:
            t, n = f"S{n}", 0
        fields.append((str(f), t, int(n)))
    return int(cls.id), int(cls.crc_extra), fields


def field_names(name: str) -> tuple[str, ...]:
    """The field names of a message, in declaration order."""
    return tuple(_CLASS_BY_NAME[name].fieldnames)


# -- messages ----------------------------------------------------------------
@dataclass(frozen=True)
class Message:
    """One decoded (or in-process) MAVLink message as plain values.

    ``fields`` holds every field by its MAVLink name (char arrays as ``str``,
    arrays as lists of numbers); ``raw`` is the packet exactly as received
    (empty for in-process messages), written to tlogs.
    """

    name: str
    src_system: int
    src_component: int
    fields: Mapping[str, Any]
    raw: bytes = b""
    signed: bool = False

    @property
    def target_system(self) -> int | None:
        v = self.fields.get("target_system")
        return None if v is None else int(v)

    @property
    def target_component(self) -> int | None:
        v = self.fields.get("target_component")
        return None if v is None else int(v)


def make_message(name: str, src_system: int = 255, src_component: int = 190,
                 **fields: Any) -> Message:
    """A ``Message`` built in-process, exactly as it would arrive from the
    network: omitted fields take the dialect's zero values and every value is
    rounded to its wire type (float32 params, integer ranges) by encoding and
    decoding it. ``raw`` stays empty (it was never on a link). Unknown fields
    or values that do not fit raise ``ValueError``."""
    cls = _message_class(name)
    names = list(cls.fieldnames)
    extra = set(fields) - set(names)
    if extra:
        raise ValueError(f"{name} has no field(s) {sorted(extra)}; fields: {', '.join(names)}")
    full: dict[str, Any] = {}
    for fname, ftype, alen in zip(names, cls.fieldtypes, _array_lengths(cls)):
        if fname in fields:
            full[fname] = fields[fname]
        elif ftype == "char":
            full[fname] = ""
        elif alen:
            full[fname] = [0] * alen
        else:
            full[fname] = 0
    decoded = Decoder().decode(Packer(src_system, src_component).pack(name, **full))
    if len(decoded) != 1:
        raise ValueError(f"{name} with {fields!r} does not survive encoding")
    return replace(decoded[0], raw=b"")


def _array_lengths(cls: Any) -> list[int]:
    """Array length per field in ``fieldnames`` order (0: scalar)."""
    by_wire = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    return [int(by_wire[f]) for f in cls.fieldnames]


def _message_class(name: str) -> Any:
    try:
        return _CLASS_BY_NAME[name]
    except KeyError:
        raise ValueError(f"unknown MAVLink message {name!r} (dialect ardupilotmega)") from None


class Packer:
    """Encodes messages from one vehicle: its own system id, component and
    sequence numbers (one pymavlink ``MAVLink`` instance per vehicle)."""

    def __init__(self, system_id: int, component_id: int = MAV_COMP_ID_AUTOPILOT1) -> None:
        if not 1 <= system_id <= 255:
            raise ValueError(f"MAVLink system id must be 1..255, got {system_id}")
        self._mav = _d.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.system_id = system_id
        self.component_id = component_id
        self.packets = 0

    @property
    def seq(self) -> int:
        """The sequence number the next packet will carry."""
        return int(self._mav.seq)

    @seq.setter
    def seq(self, value: int) -> None:
        """Set by a batch encoder that sent packets for this vehicle."""
        self._mav.seq = int(value) % 256

    @property
    def signing(self) -> bool:
        """Whether packets are signed (``enable_signing`` was called)."""
        return bool(self._mav.signing.sign_outgoing)

    def enable_signing(self, key: bytes, link_id: int = 0) -> None:
        """Sign every packet from now on (MAVLink 2 signing) with the 32-byte
        ``key`` and ``link_id``; timestamps come from ``advance_signing_time``."""
        if len(key) != SIGNING_KEY_LEN:
            raise ValueError(f"MAVLink signing key must be {SIGNING_KEY_LEN} bytes, "
                             f"got {len(key)}")
        if not 0 <= link_id <= 255:
            raise ValueError(f"MAVLink signing link id must be 0..255, got {link_id}")
        s = self._mav.signing
        s.secret_key = bytes(key)
        s.link_id = link_id
        s.sign_outgoing = True

    @property
    def signing_timestamp(self) -> int:
        """The signature timestamp the next packet will carry (10 us units since 2015)."""
        return int(self._mav.signing.timestamp)

    def advance_signing_time(self, timestamp: int) -> None:
        """Move the signature timestamp up to ``timestamp`` (never back: every
        signed packet carries a timestamp greater than the previous one)."""
        s = self._mav.signing
        s.timestamp = max(int(s.timestamp), int(timestamp))

    def pack(self, message: str, /, **fields: Any) -> bytes:
        """Encode one message; ``str`` values of char fields are ASCII-encoded.

        A wrong field name or a value that does not fit its field raises
        ``ValueError`` naming the message (a bug in the caller, not bad input).
        """
        _message_class(message)
        chars = _CHAR_FIELDS[message]
        for k in chars & fields.keys():
            v = fields[k]
            if isinstance(v, str):
                fields[k] = v.encode("ascii", errors="replace")
        try:
            msg = getattr(self._mav, message.lower() + "_encode")(**fields)
            buf = bytes(msg.pack(self._mav))
        except Exception as e:  # TypeError (fields), struct.error (ranges)
            raise ValueError(f"cannot encode {message} from system {self.system_id} with "
                             f"{fields!r}: {e}") from e
        self._mav.seq = (self._mav.seq + 1) % 256
        self.packets += 1
        return buf


# -- signing -----------------------------------------------------------------
SIGNING_KEY_LEN: Final[int] = 32
#: the MAVLink 2 signing epoch, 2015-01-01T00:00:00Z, in unix microseconds
SIGNING_EPOCH_UNIX_US: Final[int] = 1_420_070_400 * 1_000_000
_IFLAG_SIGNED: Final[int] = int(_d.MAVLINK_IFLAG_SIGNED)
_SIGNATURE_LEN: Final[int] = int(_d.MAVLINK_SIGNATURE_BLOCK_LEN)
_V2_MARKER: Final[int] = int(_d.PROTOCOL_MARKER_V2)


def signing_key(passphrase: str) -> bytes:
    """The 32-byte MAVLink 2 signing key of a passphrase, as MAVProxy's
    ``signing key PASSPHRASE`` (and ``signing setup``) derive it: SHA-256 of
    the ASCII passphrase. ``ValueError`` if it is not ASCII."""
    return hashlib.sha256(passphrase.encode("ascii")).digest()


def signing_timestamp(unix_us: int) -> int:
    """A MAVLink 2 signature timestamp (10 us units since 2015-01-01) for a
    unix time in microseconds (0 before 2015)."""
    return max(0, (int(unix_us) - SIGNING_EPOCH_UNIX_US) // 10)


def wall_signing_timestamp() -> int:
    """The wall clock now as a MAVLink 2 signature timestamp."""
    return signing_timestamp(time.time_ns() // 1000)


#: a new stream whose first timestamp is further behind the local timestamp
#: than this (10 us units: one minute) is refused, as the MAVLink 2 signing
#: specification, pymavlink and ArduPilot do
NEW_STREAM_WINDOW: Final[int] = 6_000_000

#: ``SignatureChecker.check`` verdicts
SIG_OK: Final[str] = "ok"
SIG_MAVLINK1: Final[str] = "mavlink1"
SIG_UNSIGNED: Final[str] = "unsigned"
SIG_BAD: Final[str] = "bad_signature"
SIG_REPLAY: Final[str] = "replay"
SIG_STALE: Final[str] = "stale_stream"
SIG_OWN: Final[str] = "own_stream"

Stream = tuple[int, int, int]  # (link id, system, component)


class SignatureChecker:
    """Verifies the MAVLink 2 signature of received packets against one key.

    ``check(raw)`` (``raw``: one packet exactly as received, ``Message.raw``)
    returns ``SIG_OK``, ``SIG_MAVLINK1`` (a MAVLink 1 packet: it cannot carry
    a signature), ``SIG_UNSIGNED``, ``SIG_BAD`` (wrong key or tampered),
    ``SIG_OWN`` (a correct signature on one of the streams this side signs
    with, ``own``: our own packet sent back), ``SIG_REPLAY`` (a correct
    signature whose timestamp is not newer than the last accepted one of the
    same stream: link id, system, component) or ``SIG_STALE`` (the first
    packet of a stream, stamped more than a minute behind the local
    timestamp). The local timestamp is the latest of the wall clock,
    ``timestamp`` (what was accepted or sent before, in this run or,
    restored by the caller, in earlier ones) and every accepted packet's
    stamp. The signature is checked before the timestamp, and only an
    accepted packet advances anything, so forged packets cannot block a
    stream. ``streams`` (the last accepted timestamp of each) and
    ``timestamp`` may be given from an earlier run, or merged in later
    (``merge``) from other runs: a packet accepted there is a replay here.

    ``check`` is ``verify`` (the signature) then ``admit`` (the stream's
    timestamps), which a caller sharing the state with other processes runs
    apart: verify first, then admit under its lock.
    """

    def __init__(self, key: bytes, timestamp: int = 0,
                 streams: Mapping[Stream, int] | None = None) -> None:
        if len(key) != SIGNING_KEY_LEN:
            raise ValueError(f"MAVLink signing key must be {SIGNING_KEY_LEN} bytes, "
                             f"got {len(key)}")
        self._key = bytes(key)
        self.timestamp = int(timestamp)
        self.last_timestamp: dict[Stream, int] = dict(streams or {})
        #: the streams this side signs with: never accepted from the network
        self.own: set[Stream] = set()

    def local_timestamp(self) -> int:
        """The latest of the wall clock and everything accepted or restored."""
        self.timestamp = max(self.timestamp, wall_signing_timestamp())
        return self.timestamp

    def merge(self, timestamp: int, streams: Mapping[Stream, int]) -> None:
        """Take in what others accepted: the maximum of every timestamp."""
        self.timestamp = max(self.timestamp, int(timestamp))
        last = self.last_timestamp
        for s, t in streams.items():
            if t > last.get(s, -1):
                last[s] = t

    def verify(self, raw: bytes) -> tuple[str, Stream, int]:
        """The signature alone: (``SIG_OK`` if it is correct, else the verdict;
        the packet's stream; its timestamp). Changes nothing."""
        if not raw or raw[0] != _V2_MARKER:
            return SIG_MAVLINK1, (0, 0, 0), 0
        if len(raw) < 10 + 2 + _SIGNATURE_LEN or not raw[2] & _IFLAG_SIGNED:
            return SIG_UNSIGNED, (0, 0, 0), 0
        body, sig = raw[:-6], raw[-6:]
        expect = hashlib.sha256(self._key + body).digest()[:6]
        if not hmac.compare_digest(expect, sig):
            return SIG_BAD, (0, 0, 0), 0
        stream = (int(raw[-_SIGNATURE_LEN]), int(raw[5]), int(raw[6]))
        return SIG_OK, stream, int.from_bytes(raw[-12:-6], "little")

    def admit(self, stream: Stream, timestamp: int, remember: bool = True) -> str:
        """Whether a correctly signed packet of ``stream`` stamped
        ``timestamp`` goes on: ``SIG_OK`` (remembered, unless not
        ``remember``), ``SIG_OWN``, ``SIG_REPLAY`` or ``SIG_STALE``."""
        if stream in self.own:
            return SIG_OWN
        last = self.last_timestamp.get(stream)
        if last is not None:
            if timestamp <= last:
                return SIG_REPLAY
        elif timestamp + NEW_STREAM_WINDOW < self.local_timestamp():
            return SIG_STALE
        if remember:
            self.last_timestamp[stream] = timestamp
            self.timestamp = max(self.timestamp, timestamp)
        return SIG_OK

    def check(self, raw: bytes) -> str:
        verdict, stream, timestamp = self.verify(raw)
        return verdict if verdict != SIG_OK else self.admit(stream, timestamp)


#: Decoder counters (keys always present)
DECODE_COUNTERS: tuple[str, ...] = ("datagrams", "messages", "garbage", "bad_crc", "truncated",
                                    "malformed", "unknown_message", "decoder_errors")


class Decoder:
    """Decodes received datagrams into ``Message`` values; never raises.

    Each datagram is parsed on its own (a truncated packet at the end of one
    datagram cannot swallow the start of the next). Problems are counted in
    ``counts``: ``garbage`` (runs of bytes that do not start a packet),
    ``bad_crc``, ``truncated`` (a datagram ending inside a packet),
    ``malformed`` (bad length or flags), ``unknown_message`` (an id this
    dialect does not define: its CRC cannot be checked), ``decoder_errors``
    (pymavlink raised anyway).
    """

    def __init__(self) -> None:
        self._mav = _d.MAVLink(None, srcSystem=0, srcComponent=0)
        self._mav.robust_parsing = True
        self.counts: Counter[str] = Counter({k: 0 for k in DECODE_COUNTERS})

    def _reset(self) -> None:
        m = self._mav
        m.buf = bytearray()
        m.buf_index = 0
        m.expected_length = _d.HEADER_LEN_V1 + 2
        m.have_prefix_error = False

    def decode(self, datagram: bytes) -> list[Message]:
        """All valid messages in one datagram, in order."""
        self.counts["datagrams"] += 1
        self._reset()
        try:
            parsed = self._mav.parse_buffer(datagram) or []
        except Exception:  # robust parsing should not raise; count it if it does
            self.counts["decoder_errors"] += 1
            parsed = []
        out: list[Message] = []
        for pm in parsed:
            kind = pm.get_type()
            if kind == "BAD_DATA":
                reason = str(getattr(pm, "reason", ""))
                if reason.startswith("Bad prefix"):
                    self.counts["garbage"] += 1
                elif "CRC" in reason:
                    self.counts["bad_crc"] += 1
                else:
                    self.counts["malformed"] += 1
                continue
            if kind.startswith("UNKNOWN_"):
                self.counts["unknown_message"] += 1
                continue
            try:
                fields = {n: getattr(pm, n) for n in pm.get_fieldnames()}
                out.append(Message(kind, int(pm.get_srcSystem()), int(pm.get_srcComponent()),
                                   fields, bytes(pm.get_msgbuf()), bool(pm.get_signed())))
            except Exception:
                self.counts["decoder_errors"] += 1
        if self._mav.buf_len() > 0:
            self.counts["truncated"] += 1
        self._reset()
        self.counts["messages"] += len(out)
        return out

