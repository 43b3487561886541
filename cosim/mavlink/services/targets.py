"""Offboard position targets: SET_POSITION_TARGET_GLOBAL_INT and
SET_POSITION_TARGET_LOCAL_NED, taken only while the vehicle's personality
says it steers by them (``Personality.takes_targets``; ArduPlane: in
GUIDED) and never acknowledged, as in ArduPilot (a refusal that needs
explaining gets a STATUSTEXT). The local NED frame (MAV_FRAME_LOCAL_NED) is
relative to the vehicle's start; the offset frames to where it is now.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import Outcome, text, vocab
from cosim.mavlink.services.base import Context
from cosim.mavlink.vehicle import MavVehicle

log = logging.getLogger(__name__)

_LOCAL_FRAMES = (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED,
                 mav.MAV_FRAME_BODY_OFFSET_NED)


def _mask(type_mask: int) -> tuple[bool, bool] | None:
    """(horizontal position given, altitude given); None: unusable mask."""
    both = mav.POSITION_TARGET_TYPEMASK_X_IGNORE | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE
    xy = type_mask & both
    if xy not in (0, both):
        return None
    has_xy = xy == 0
    has_z = not type_mask & mav.POSITION_TARGET_TYPEMASK_Z_IGNORE
    return (has_xy, has_z) if (has_xy or has_z) else None


class TargetService:
    """SET_POSITION_TARGET_* for the vehicles of one endpoint."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.counts = ctx.counts
        self.messages = {"SET_POSITION_TARGET_GLOBAL_INT": self._global,
                         "SET_POSITION_TARGET_LOCAL_NED": self._local}

    def _ok(self, v: MavVehicle) -> bool:
        if not v.personality.takes_targets(v):
            self.counts["position_targets_ignored"] += 1
            return False
        return True

    def _command(self, v: MavVehicle, d: dict[str, Any]) -> Outcome:
        cmd = vocab(d)
        if isinstance(cmd, str):
            self.counts["position_targets_invalid"] += 1
            log.debug("position target rejected: %s", cmd)
            return Outcome()
        problem = self.ctx.unsafe(v, cmd)
        if problem is not None:  # no ACK for position targets: a STATUSTEXT says why
            self.counts["position_targets_invalid"] += 1
            return Outcome(replies=text(f"position target: {problem}"))
        return Outcome(commands=[cmd])

    def _global(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        if not self._ok(v):
            return Outcome()
        f = m.fields
        mask = _mask(int(f["type_mask"]))
        alt = self.ctx.alt(v, int(f["coordinate_frame"]), float(f["alt"]))
        if mask is None or alt is None:
            self.counts["position_targets_unsupported"] += 1
            return Outcome()
        has_xy, has_z = mask
        d: dict[str, Any] = {alt[0]: alt[1]} if has_z else {}
        if has_xy:
            d.update(lat_deg=int(f["lat_int"]) / 1e7, lon_deg=int(f["lon_int"]) / 1e7)
            return self._command(v, {"goto": d})
        return self._command(v, d)

    def _local(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        if not self._ok(v):
            return Outcome()
        f = m.fields
        mask = _mask(int(f["type_mask"]))
        frame = int(f["coordinate_frame"])
        x, y, z = float(f["x"]), float(f["y"]), float(f["z"])
        if mask is None or frame not in _LOCAL_FRAMES or not all(map(math.isfinite, (x, y, z))):
            self.counts["position_targets_unsupported"] += 1
            return Outcome()
        has_xy, has_z = mask
        row = v.row_or_raise()
        if frame == mav.MAV_FRAME_LOCAL_NED:  # relative to the vehicle's start
            alt = v.spec.start_alt_msl_m - z
            if not has_xy:
                return self._command(v, {"alt_msl_m": alt})
            goto: dict[str, Any] = {"frame": "start", "north_m": x, "east_m": y}
        else:  # offsets from where the vehicle is now
            lat0, lon0 = float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])
            alt0 = float(row[_S["alt_msl_m"]])
            alt = alt0 - z
            if not has_xy:
                return self._command(v, {"alt_msl_m": alt})
            north, east = x, y
            if frame == mav.MAV_FRAME_BODY_OFFSET_NED:  # x forward, y right
                psi = math.radians(float(row[_S["yaw_deg"]]))
                north = x * math.cos(psi) - y * math.sin(psi)
                east = x * math.sin(psi) + y * math.cos(psi)
            lat, lon = LocalFrame(lat0, lon0, alt0).place(north, east, alt0)
            goto = {"lat_deg": float(lat), "lon_deg": float(lon)}
        if has_z:
            goto["alt_msl_m"] = alt
        return self._command(v, {"goto": goto})
