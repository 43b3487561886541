"""The cameras participant: every camera's frames rendered in lockstep with the
loop, from the vehicles' states at the frame ticks.

At its start it makes one stream per camera and vehicle (``outputs.Stream``)
and hands them to the render pool (``render_pool``: worker processes, or
inline for ``render_workers: 0``) and, if asked, the operator view. At each
exchange it sends the frames due, those between the last exchange and this
one from the states the run gathered in between (``watch_requests``), and
takes what the pool has rendered: thumbnails for the operator view and the
frame taps (``--video``), stills for their record. Commands point gimbal
cameras (a ``gimbal`` event): at angles, or at a point they keep in the
image's centre (``look_at``: the angles recomputed from the vehicle's pose
for every frame, within the gimbal's limits); they also trigger stills (the
``camera`` command: one now, every so many seconds or metres, at most a
count). ``finish`` renders what is still due, closes the pool and the files
and returns the ``cameras`` section of the summary; an error the loop did
not see yet is raised there as ``ParticipantFailed`` with the section.

Owns the loop hooks and when frames and stills are due: the processes are the
pool's, the files ``outputs``', the pixels ``frame``'s.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.camera import CameraSpec, look_at_angles
from cosim.core.state import STATE_INDEX
from cosim.guidance.commands import GIMBAL_PITCH_DEG, GIMBAL_YAW_DEG, Point
from cosim.renderer.config import CamerasSpec
from cosim.renderer.frame import WorldSpec
from cosim.renderer.outputs import Stills, Stream, summary
from cosim.renderer.render_pool import InlinePool, RenderError, RenderPool
from cosim.renderer.video import EXTENSIONS
from cosim.sync.participants import ParticipantFailed, RunContext
from cosim.vehicles import get_class

log = logging.getLogger(__name__)

_POSE_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg",
                                       "pitch_deg", "yaw_deg")]
_ATT_COLS = [STATE_INDEX[c] for c in ("roll_deg", "pitch_deg", "yaw_deg")]
_VEL_COLS = [STATE_INDEX[c] for c in ("vn_mps", "ve_mps", "vd_mps")]


@dataclass
class _Trigger:
    """One vehicle's still triggering (``camera`` commands)."""

    shoot: bool = False
    interval_ticks: int | None = None
    next_tick: int | None = None
    distance_m: float | None = None
    flown_m: float = 0.0
    last: tuple[float, float] | None = None
    left: int | None = None  # stills still to take (None: until stopped)
    source: str = ""


def _tap_size(cam: CameraSpec, widths: list[int | None]) -> tuple[int, int]:
    """A frame's size for the taps: the widest any asks for (None: full size)."""
    w = cam.width_px if None in widths else min(cam.width_px, max(w for w in widths if w))
    return w, max(1, round(cam.height_px * w / cam.width_px))


class CameraParticipant:
    name = "cameras"

    def __init__(self, scenario: Any) -> None:
        self.scn = scenario
        self.spec: CamerasSpec = scenario.sections["cameras"]
        self.streams: list[Stream] = []
        self.pool: InlinePool | RenderPool | None = None
        self.operator: Any = None
        self.finished = False
        self.failed: BaseException | None = None  # a failure to start, raised into the loop
        #: each gimbal stream's current (pitch_deg, yaw_deg), set by commands
        self.gimbal: dict[int, tuple[float, float]] = {}
        self.gimbal_before: dict[int, tuple[float, float]] = {}  # as of the last exchange
        #: the gimbal streams that track a point (``look_at``): its lat_deg,
        #: lon_deg, alt_msl_m; and as of the last exchange
        self.look_at: dict[int, tuple[float, float, float]] = {}
        self.look_at_before: dict[int, tuple[float, float, float]] = {}
        #: streams whose tracking an angle command ended at this exchange: the
        #: point, and the command's pitch and yaw (None: where tracking left it)
        self.released: dict[int, tuple[tuple[float, float, float], float | None,
                                       float | None]] = {}
        #: gimbal commands for this exchange's events: the stream, the source
        #: and the point tracked (north_m, east_m, alt_msl_m; None: angles)
        self.gimbal_moves: list[tuple[Stream, str, dict[str, float] | None]] = []
        #: still triggering per vehicle row (``camera`` commands) and the streams
        #: whose next frame is a still (stream index -> the command's source)
        self.triggers: dict[int, _Trigger] = {}
        self.still_due: dict[int, str] = {}
        #: per stream whose sensor has an exposure: its last frame's tick and attitude
        self.last_attitude: dict[int, tuple[int, np.ndarray]] = {}
        self.stills: Stills | None = None

    # --- lifecycle -------------------------------------------------------------------
    def start(self, ctx: RunContext) -> None:
        from cosim.renderer.operator import OperatorView

        self.ctx = ctx
        out = ctx.out_dir / "cameras"
        out.mkdir(parents=True, exist_ok=True)
        ext = EXTENSIONS[self.spec.codec]
        streams = [(cam, row) for cam in self.spec.views for row in cam.vehicles]
        tiles = OperatorView.tile_size(self.spec, len(streams)) if self.spec.operator_view \
            else None
        self.taps = [tap for tap, _ in ctx.frame_taps or ()]
        widths = [w for _, w in ctx.frame_taps or ()]
        for i, (cam, row) in enumerate(streams):
            base = f"cameras/{ctx.ids[row]}_{cam.name}"
            show = tiles is not None and i < OperatorView.MAX_TILES
            thumb = tiles if show else _tap_size(cam, widths) if self.taps else None
            lift = get_class(ctx.scenario.vehicles[row].vehicle_class).camera_height_m
            self.streams.append(Stream(i, ctx.ids[row], row, cam, f"{base}.{ext}",
                                       f"{base}.gt.csv", thumb, lift))
        self.gimbal = {s.index: (s.camera.pitch_deg, s.camera.yaw_deg) for s in self.streams
                       if s.camera.mount == "gimbal"}
        self.stills = Stills(ctx.out_dir, ctx.physics_hz, ctx.events)
        self._stream_of = {(s.vehicle, s.camera.name): s.index for s in self.streams}
        ctx.gimbal_angles = self.gimbal_angles
        if ctx.commander is not None:
            ctx.commander.observers.append(self.point_gimbal)
            ctx.commander.observers.append(self.trigger_camera)
        scn = ctx.scenario
        ws = WorldSpec(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m,
                       int(scn.seed), float(ctx.physics_hz), scn.world.ground,
                       scn.world.targets, scn.world.obstacles, scn.world.sun,
                       atmosphere=scn.world.atmosphere)
        n = self.spec.render_workers
        if n is None:
            n = min(len(self.streams), os.cpu_count() or 1)
        n = min(n, len(self.streams))
        if self.spec.operator_view:
            self.operator = OperatorView(self.spec, self.streams, ws, ctx, ext)
        if n == 0:
            try:
                self.pool = InlinePool(ws, self.streams, ctx.out_dir, self.spec.codec,
                                       self.spec.digest, self._rendered)
            except RenderError as e:
                self.failed = e
                raise
            return
        self.pool = RenderPool(self.streams, self.spec.max_in_flight, ctx.step_timeout_s,
                               self._rendered)
        self.pool.start(n, ws, ctx.out_dir, self.spec.codec, self.spec.digest)
        log.info("cameras: %d stream(s) on %d render worker(s)", len(self.streams), n)

    def gimbal_angles(self, vehicle: str, camera: str) -> tuple[float, float] | None:
        """Camera ``camera`` of ``vehicle``: its gimbal's ``(pitch_deg, yaw_deg)``
        as of the last exchange (None: not a camera on a gimbal)."""
        i = self._stream_of.get((vehicle, camera))
        return None if i is None else self.gimbal.get(i)

    def point_gimbal(self, row: int, cmd: Any, source: str) -> None:
        """A command's gimbal angles, or the point to track (``look_at``), for
        the vehicle's gimbal cameras from this exchange's frame on (a
        ``gimbal`` event); ignored, with a warning, by a vehicle without one.
        Angles, or a hold (``look_at: null``), end tracking (an angle not
        given stays where tracking left it at this exchange)."""
        if not cmd.points_gimbal:
            return
        moved = [s for s in self.streams if s.row == row and s.index in self.gimbal]
        if not moved:
            log.warning("vehicle %s has no camera on a gimbal: gimbal command (%s) ignored",
                        self.ctx.ids[row], source)
            return
        at = None if cmd.gimbal_look_at is None else self._resolve(cmd.gimbal_look_at, row)
        p_cmd, y_cmd = cmd.gimbal_pitch_deg, cmd.gimbal_yaw_deg
        for s in moved:
            i = s.index
            if at is not None:
                self.look_at[i] = at[0]
                self.released.pop(i, None)
            elif i in self.look_at or i in self.released:  # the angles at this exchange's pose
                point, p0, y0 = self.released.get(i) or (self.look_at.pop(i), None, None)
                self.released[i] = (point, p0 if p_cmd is None else p_cmd,
                                    y0 if y_cmd is None else y_cmd)
            else:
                pitch, yaw = self.gimbal[i]
                self.gimbal[i] = (pitch if p_cmd is None else p_cmd,
                                  yaw if y_cmd is None else y_cmd)
        # events at this exchange's tick
        self.gimbal_moves += [(s, source, None if at is None else at[1]) for s in moved]

    def _resolve(self, p: Point, row: int
                 ) -> tuple[tuple[float, float, float], dict[str, float]]:
        """A look_at point for vehicle ``row``: its (lat_deg, lon_deg,
        alt_msl_m), and its north_m, east_m, alt_msl_m in the scenario frame
        (for the event). Its height: the ground's (the scenario origin's)
        unless given."""
        ground_m = float(self.scn.origin.ground_alt_m)
        alt_m = ground_m if p.alt_m is None else p.alt_m + (ground_m if p.alt_agl else 0.0)
        frame = self.ctx.frame
        if p.frame == "geodetic":
            lat, lon = p.a, p.b
            ned = frame.geodetic_to_ned(lat, lon, alt_m)
            n, e = float(ned[0]), float(ned[1])
        else:
            n, e = (p.a, p.b) if p.frame == "local" else (
                float(self.ctx.start_ned_m[row, 0]) + p.a,
                float(self.ctx.start_ned_m[row, 1]) + p.b)
            la, lo = frame.place(n, e, alt_m)
            lat, lon = float(la), float(lo)
        return (lat, lon, alt_m), {"north_m": round(n, 3), "east_m": round(e, 3),
                                   "alt_msl_m": round(alt_m, 3)}

    def _aim(self, s: Stream, pose6: tuple[float, ...], at: tuple[float, float, float]
             ) -> tuple[float, float]:
        """Stream ``s``'s gimbal angles that keep the point ``at`` (lat, lon,
        alt MSL) in its image's centre from the camera's pose ``pose6``,
        clamped to the gimbal's limits."""
        lat, lon, alt_m, roll, pitch, yaw = pose6
        pitch, yaw = look_at_angles(s.camera, lat, lon, alt_m, roll, pitch, yaw,
                                    float(self.scn.origin.ground_alt_m), *at)
        return (min(max(pitch, GIMBAL_PITCH_DEG[0]), GIMBAL_PITCH_DEG[1]),
                min(max(yaw, GIMBAL_YAW_DEG[0]), GIMBAL_YAW_DEG[1]))

    def trigger_camera(self, row: int, cmd: Any, source: str) -> None:
        """A ``camera`` command: stills of the vehicle's cameras from this
        exchange on; ignored, with a warning, by a vehicle without a camera."""
        trig = cmd.camera
        if trig is None:
            return
        if not any(s.row == row for s in self.streams):
            log.warning("vehicle %s has no camera: camera command (%s) ignored",
                        self.ctx.ids[row], source)
            return
        if trig.stop:
            t = self.triggers.get(row)
            if t is not None:
                t.interval_ticks = t.distance_m = None
            return
        t = self.triggers.setdefault(row, _Trigger())
        t.source = source
        if trig.shoot:
            t.shoot = True
            return
        t.left = trig.count
        if trig.interval_s is not None:
            t.interval_ticks = max(1, round(trig.interval_s * self.ctx.physics_hz))
            t.distance_m = None
            t.next_tick = None  # the first at this exchange
        else:
            t.distance_m = trig.distance_m
            t.interval_ticks = None
            t.flown_m, t.last = 0.0, None
            t.shoot = True  # the first where it starts, as ArduPilot's camera does

    def _due_stills(self, tick: int, states: np.ndarray) -> None:
        """Which vehicles take a still now: their streams' next frames are stills."""
        for row, t in self.triggers.items():
            due = t.shoot
            t.shoot = False
            if t.interval_ticks is not None:
                if t.next_tick is None:
                    t.next_tick = tick
                if tick >= t.next_tick:
                    due = True
                    t.next_tick += t.interval_ticks * ((tick - t.next_tick) // t.interval_ticks
                                                       + 1)
            if t.distance_m is not None:
                lat, lon = float(states[row, _POSE_COLS[0]]), float(states[row, _POSE_COLS[1]])
                if t.last is not None:
                    dn = math.radians(lat - t.last[0]) * 6_371_000.0
                    de = math.radians(lon - t.last[1]) * 6_371_000.0 * math.cos(
                        math.radians(lat))
                    t.flown_m += math.hypot(dn, de)
                t.last = (lat, lon)
                if t.flown_m >= t.distance_m:
                    due = True
                    t.flown_m -= t.distance_m * (t.flown_m // t.distance_m)
            if not due:
                continue
            if t.left is not None and (t.interval_ticks is not None or t.distance_m is not None):
                t.left -= 1
                if t.left <= 0:
                    t.interval_ticks = t.distance_m = None
            for s in self.streams:
                if s.row == row:
                    self.still_due.setdefault(s.index, t.source)
    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        assert self.pool is not None
        self.pool.tick = tick
        if self.triggers:
            self._due_stills(tick, states)
        for s in self.streams:  # tracking: the angles from this exchange's pose
            at = self.look_at.get(s.index)
            if at is not None:
                self.gimbal[s.index] = self._aim(s, self._pose6(s, states[s.row]), at)
            elif s.index in self.released:  # ended here: held where it was, but for the
                point, p_cmd, y_cmd = self.released.pop(s.index)  # angles commanded
                pitch, yaw = self._aim(s, self._pose6(s, states[s.row]), point)
                self.gimbal[s.index] = (pitch if p_cmd is None else p_cmd,
                                        yaw if y_cmd is None else y_cmd)
        for s, source, looked_at in self.gimbal_moves:
            pitch, yaw = self.gimbal[s.index]
            extra = {} if looked_at is None else {"look_at": looked_at}
            self.ctx.events.emit("gimbal", tick, vehicle=s.vehicle, camera=s.camera.name,
                                 pitch_deg=pitch, yaw_deg=yaw, source=source, **extra)
        self.gimbal_moves.clear()
        self.pool.check()
        self._between(tick)
        for s in self.streams:
            every = s.camera.frame_every
            if tick % every:
                continue
            self._frame(s, tick, states[s.row], self.gimbal.get(s.index), stills=True)
        # the angles the frames until the next exchange were taken with (a
        # command at that exchange moves the gimbal only from its own tick)
        self.gimbal_before = dict(self.gimbal)
        self.look_at_before = dict(self.look_at)
        if self.operator is not None:
            self.operator.at_exchange(tick, states)
        self.pool.collect(block=False)

    def watch_requests(self) -> list[tuple[int, int]]:
        """(vehicle row, ticks per frame) of the cameras whose frames fall
        between exchanges: the run gathers those vehicles' states that often
        (``RunContext.watched``)."""
        k = self.scn.rates.control_every
        return [(row, cam.frame_every) for cam in self.spec.views for row in cam.vehicles
                if 0 < cam.frame_every < k]

    def _between(self, tick: int) -> None:
        """The frames due between the last exchange and ``tick``, from the
        states the run gathered in between."""
        w = self.ctx.watched
        if w is None or not w.ticks:
            return
        pos = {r: j for j, r in enumerate(w.rows)}
        for c, t in enumerate(w.ticks):
            if t >= tick:
                break
            for s in self.streams:
                if s.row in pos and t % s.camera.frame_every == 0:
                    row = w.states[c, pos[s.row]]
                    at = self.look_at_before.get(s.index)
                    gimbal = self.gimbal_before.get(s.index) if at is None else \
                        self._aim(s, self._pose6(s, row), at)
                    self._frame(s, t, row, gimbal, stills=False)

    def _frame(self, s: Stream, tick: int, row: np.ndarray,
               gimbal: tuple[float, float] | None, stills: bool) -> None:
        """Render stream ``s``'s frame at ``tick`` from its vehicle's state
        ``row`` with the gimbal at ``gimbal`` (and a still with it when one is
        due and ``stills``)."""
        assert self.pool is not None and self.stills is not None
        every = s.camera.frame_every
        pose6 = self._pose6(s, row)
        frame_no = tick // every
        still = self.stills.name(s, frame_no, tick, pose6, gimbal, self.still_due.pop(s.index)) \
            if stills and s.index in self.still_due else None
        sensor = s.camera.sensor
        motion = self._motion(s, tick, row) if sensor is not None and sensor.exposure_ms else None
        self.pool.submit(s, frame_no, tick, pose6, gimbal, still, motion)

    @staticmethod
    def _pose6(s: Stream, row: np.ndarray) -> tuple[float, ...]:
        """Stream ``s``'s camera pose (lat, lon, alt MSL, roll, pitch, yaw) from
        its vehicle's state ``row``: lifted by the class's camera height."""
        pose6 = tuple(float(x) for x in row[_POSE_COLS])
        if s.lift_m:
            pose6 = pose6[:2] + (pose6[2] + s.lift_m,) + pose6[3:]
        return pose6

    def _motion(self, s: Stream, tick: int, row: np.ndarray) -> tuple[float, ...]:
        """What the exposure of stream ``s``'s frame at ``tick`` sees move: the
        vehicle's velocity (north, east, down, m/s) from its state ``row`` and
        its attitude's rates (roll, pitch, yaw, deg/s) since the stream's last
        frame (0 at its first)."""
        att = row[_ATT_COLS].astype(float)
        before = self.last_attitude.get(s.index)
        self.last_attitude[s.index] = (tick, att)
        rates = np.zeros(3)
        if before is not None and tick > before[0]:
            d = (att - before[1] + 180.0) % 360.0 - 180.0  # the short way round
            rates = d * self.ctx.physics_hz / (tick - before[0])
        return tuple(float(x) for x in row[_VEL_COLS]) + tuple(float(x) for x in rates)

    def _rendered(self, stream: int, frame_no: int, thumb: np.ndarray | None,
                  still: tuple[str, Any] | None) -> None:
        """A frame the pool has rendered: its still's record, its thumbnail to the
        operator view and the taps."""
        assert self.stills is not None
        self.stills.done(still)
        if thumb is None:
            return
        if self.operator is not None:
            self.operator.thumb(stream, frame_no, thumb)
        if self.taps:
            s = self.streams[stream]
            t = frame_no * s.camera.frame_every / self.ctx.physics_hz
            for tap in self.taps:
                tap(s.vehicle, s.camera.name, t, thumb)

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        if self.finished:
            return None
        self.finished = True
        pool = self.pool
        if pool is not None:
            pool.tick = tick
        # an error the loop has ended on already: said once
        raised = self.failed or (pool.failed if pool is not None else None)
        error: BaseException | None = None
        if raised is None and reason == "completed" and hasattr(self, "ctx"):
            try:  # the frames due after the last exchange, gathered in its step
                self._between(tick)
            except Exception as e:
                error = e
        closed: dict[int, dict[str, Any]] = {}
        if pool is not None:
            closed, failed = pool.close()
            error = error or failed
        operator = self.operator.close() if self.operator is not None else None
        if self.stills is not None:
            self.stills.close()
        out = summary(self.streams, closed, self.spec.codec, operator,
                      self.stills.summary() if self.stills is not None else None)
        if raised is not None:
            out["error"] = str(raised).splitlines()[0]
        elif error is not None:
            out["error"] = str(error).splitlines()[0]
            raise ParticipantFailed(error, out)
        return out

    def after_run(self, out_dir: Path) -> None:
        return None
