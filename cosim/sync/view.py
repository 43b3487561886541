"""The live 3-D view of a run (``cosim run --view`` / ``--record-view FILE``),
drawn by Rerun (``pip install cosim[view]``, which brings ``rerun-sdk`` and its
viewer): every vehicle's pose as an oriented box with its id, its track, the
targets and obstacles, and the frames of its cameras, on a ``sim_time``
timeline so a recording scrubs by simulation time.

World coordinates are the scenario frame's in metres, east-north-up (x east,
y north, z up from the origin's ground). The view is one participant with one
job: it reads the states it is handed at the exchanges on its own rate
(``rate_hz``, default 10 Hz: one batch for all vehicles), appends each
vehicle's track once a second (the last ``TRACK_POINTS``), and logs camera
frames the cameras already rendered (their thumbnails, JPEG-encoded, at most
``FRAME_HZ`` a camera). It never changes the simulation; without ``--view``
or ``--record-view`` there is no view participant and Rerun is not imported.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.errors import ConfigError, install_extra

log = logging.getLogger(__name__)

DEFAULT_RATE_HZ = 10.0
#: the most camera frames a second each camera sends to the view
FRAME_HZ = 2.0
#: the widest camera frame the view shows (px)
FRAME_WIDTH_PX = 320
#: points kept of each vehicle's track (one a second)
TRACK_POINTS = 600
#: the size of a vehicle's box (half lengths, m: along, across, up), by class
_HALF_SIZE = {"Air+FixedWing": (6.0, 8.0, 1.0), "Air+Rotorcraft": (1.5, 1.5, 0.5),
              "Ground+Vehicle": (2.5, 1.0, 0.8)}
_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "pitch_deg",
                                  "yaw_deg")]


def _rerun() -> Any:
    try:
        import rerun
    except ImportError:
        raise ConfigError(f"the live view needs Rerun: {install_extra('view')} "
                          "(or pip install rerun-sdk)") from None
    return rerun


def enu_quaternions(roll_deg: np.ndarray, pitch_deg: np.ndarray,
                    yaw_deg: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w) turning a box's axes (x forward, y left,
    z up) into east-north-up for an attitude relative to north-east-down."""
    phi, th, psi = (np.radians(a) for a in (roll_deg, pitch_deg, yaw_deg))
    # a rotation about up by (90 deg - yaw), then about the new y (left) by -pitch,
    # then about x (forward) by roll: the FLU body in ENU
    out = np.empty((len(phi), 4))
    for i, (r, p, y) in enumerate(zip(phi, th, psi)):
        qz = _axis_angle((0.0, 0.0, 1.0), math.pi / 2 - y)
        qy = _axis_angle((0.0, 1.0, 0.0), -p)
        qx = _axis_angle((1.0, 0.0, 0.0), r)
        out[i] = _mul(_mul(qz, qy), qx)
    return out


def _axis_angle(axis: tuple[float, float, float], a: float) -> np.ndarray:
    s = math.sin(a / 2)
    return np.array([axis[0] * s, axis[1] * s, axis[2] * s, math.cos(a / 2)])


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


class ViewParticipant:
    """See the module docstring. ``record``: an .rrd file to write; ``connect``:
    a viewer's gRPC URL, or "spawn" to start a viewer here."""

    name = "view"

    def __init__(self, record: Path | None = None, connect: str | None = None,
                 rate_hz: float = DEFAULT_RATE_HZ) -> None:
        if record is None and connect is None:
            raise ConfigError("the view needs --view or --record-view FILE")
        if not (math.isfinite(rate_hz) and 0 < rate_hz <= 1000):
            raise ConfigError(f"--view-rate-hz must be > 0 and at most 1000, got {rate_hz:g}")
        if connect == "spawn" and not (os.environ.get("DISPLAY")
                                       or os.environ.get("WAYLAND_DISPLAY")):
            raise ConfigError("--view: no display to open the viewer on; record with "
                              "--record-view FILE and open it with `rerun FILE`, or run "
                              "`rerun` elsewhere and give its address: --view "
                              "rerun+http://HOST:9876/proxy")
        self.rr = _rerun()
        self.record, self.connect, self.rate_hz = record, connect, rate_hz
        self.every = 1
        self.logged = 0
        self.frames_logged = 0
        self.next_track_s = 0.0
        self.tracks: list[list[tuple[float, float, float]]] = []
        self.last_frame_s: dict[tuple[str, str], float] = {}

    # -- lifecycle ---------------------------------------------------------------------
    def start(self, ctx: Any) -> None:
        rr = self.rr
        self.ctx = ctx
        scn = ctx.scenario
        self.frame = ctx.frame
        self.ground = scn.origin.ground_alt_m
        self.ids = list(ctx.ids)
        self.every = max(1, round(ctx.physics_hz / self.rate_hz))
        from cosim.vehicles import get_class

        kinds = [get_class(v.vehicle_class).display_type for v in scn.vehicles]
        self.half = np.array([_HALF_SIZE.get(k, (2.0, 2.0, 1.0)) for k in kinds])
        self.tracks = [[] for _ in self.ids]
        self.rec = rr.RecordingStream("cosim", recording_id=f"{scn.name}-{ctx.out_dir.name}")
        sinks: list[Any] = []
        if self.record is not None:
            self.record.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(self.record)))
        if self.connect == "spawn":
            self.rec.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        elif self.connect is not None:
            sinks.append(rr.GrpcSink(self.connect))
        self.rec.set_sinks(*sinks)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._static_world(scn)

    def prepare(self, ctx: Any) -> None:
        """Before any participant starts: ask the cameras for their frames."""
        if ctx.frame_taps is not None:
            ctx.frame_taps.append((self.camera_frame, FRAME_WIDTH_PX))

    def _static_world(self, scn: Any) -> None:
        rr = self.rr
        targets = scn.world.targets
        if targets:
            where = []
            for t in targets:
                if t.north_m is None:
                    n, e, _ = self.frame.geodetic_to_ned(t.lat_deg, t.lon_deg, self.ground)
                    where.append([float(e), float(n), 0.0])
                else:
                    where.append([t.east_m, t.north_m, 0.0])
            self.rec.log("world/targets", rr.Points3D(where, radii=3.0,
                labels=[t.id for t in targets], colors=[[230, 60, 40]]), static=True)
        obstacles = scn.world.obstacles
        if obstacles:
            strips = []
            for o in obstacles:
                ring = [(e, n) for n, e in o.polygon] + [(o.polygon[0][1], o.polygon[0][0])]
                strips.append([[x, y, 0.0] for x, y in ring])
                strips.append([[x, y, o.height_m] for x, y in ring])
            self.rec.log("world/obstacles", rr.LineStrips3D(strips, colors=[[120, 120, 120]]),
                         static=True)

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        if tick % self.every:
            return
        rr = self.rr
        t = tick / self.ctx.physics_hz
        s = states[:, _COLS]
        ok = np.isfinite(s[:, 0]) & np.isfinite(s[:, 1]) & np.isfinite(s[:, 2])
        n, e, d = self.frame.geodetic_to_ned(np.where(ok, s[:, 0], self.frame.lat_deg),
                                             np.where(ok, s[:, 1], self.frame.lon_deg),
                                             np.where(ok, s[:, 2], self.frame.alt_m))
        enu = np.stack([e, n, -np.asarray(d)], axis=1)
        self.rec.set_time("sim_time", duration=t)
        q = enu_quaternions(np.nan_to_num(s[:, 3]), np.nan_to_num(s[:, 4]),
                            np.nan_to_num(s[:, 5]))
        keep = np.flatnonzero(ok)
        self.rec.log("world/vehicles", rr.Boxes3D(
            centers=enu[keep], half_sizes=self.half[keep], quaternions=q[keep],
            labels=[self.ids[i] for i in keep], fill_mode="solid"))
        self.logged += 1
        if t >= self.next_track_s:
            self.next_track_s = t + 1.0
            for i in keep.tolist():
                tr = self.tracks[i]
                tr.append(tuple(enu[i]))
                if len(tr) > TRACK_POINTS:
                    del tr[0]
            strips = [tr for tr in self.tracks if len(tr) > 1]
            if strips:
                self.rec.log("world/tracks", rr.LineStrips3D(strips, radii=0.5))

    def camera_frame(self, vehicle: str, camera: str, time_s: float, bgr: np.ndarray) -> None:
        """A camera frame the cameras rendered (a thumbnail): JPEG to the view,
        at most ``FRAME_HZ`` a camera."""
        key = (vehicle, camera)
        last = self.last_frame_s.get(key)
        if last is not None and time_s - last < 1.0 / FRAME_HZ - 1e-9:
            return
        self.last_frame_s[key] = time_s
        import cv2

        ok, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 75])
        if not ok:
            return
        self.rec.set_time("sim_time", duration=time_s)
        self.rec.log(f"cameras/{vehicle}/{camera}", self.rr.EncodedImage(
            contents=jpg.tobytes(), media_type="image/jpeg"))
        self.frames_logged += 1

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        try:
            self.rec.flush(timeout_sec=10.0)
        finally:
            self.rec.disconnect()
        out: dict[str, Any] = {"poses_logged": self.logged, "frames_logged": self.frames_logged,
                               "rate_hz": self.rate_hz}
        if self.record is not None:
            out["recording"] = str(self.record)
        return out

    def after_run(self, out_dir: Path) -> None:
        return None
