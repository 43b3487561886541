"""The cameras participant: renders every camera's frames in lockstep, in its
own pool of processes, and writes the videos and ground-truth files.

A *stream* is one camera on one vehicle. Stream ``s`` belongs to render
worker ``s % n``, which renders its frames in tick order, encodes them into
``cameras/<vehicle>_<camera>.<ext>`` and appends their ground truth to
``cameras/<vehicle>_<camera>.gt.csv`` (flushed every frame). The loop only
sends the pose at the frame tick (six numbers), so rendering overlaps the
physics; at most ``max_in_flight`` frames per worker are queued before the
loop waits. ``render_workers: 0`` renders inline (the reference). Frames are a
pure function of the scenario, seed, pose and tick, hence identical for any
worker count. ``finish`` drains every queued frame and closes the files; a
worker also closes its files if the loop's process disappears. Workers are
started by ``cosim.workers.start``: Ctrl-C reaches the loop, which ends the
run and then ``finish`` closes every video, rather than the workers dying
mid-write.

Stills (the ``camera`` command: one now, every so many seconds or metres):
the still of a stream is its next video frame, written whole as
``stills/<vehicle>_<camera>_<NNNN>.png`` by the worker that renders it, with
one line per still in ``stills/stills.jsonl`` (time, tick, frame, pose,
gimbal and the frame's ground truth, the same rows as the ``.gt.csv``) and a
``still`` event; at most ``MAX_STILLS`` a run (more are counted, not taken).

Failures end the run, naming what failed: a stream that cannot be opened or
written (``RenderError``: camera, vehicle, tick, the worker's traceback), a
render worker that dies (``RenderWorkerDied``: worker, pid, signal or exit
code, its cameras), noticed at the next exchange (its process sentinel is
polled without blocking) or within ``_POLL_S`` while the loop waits for
frames, and one that is alive but silent (stopped, stuck: ``RenderWorkerTimeout``)
for the run's ``step_timeout_s`` while it has frames to render (from its start
until it is ready: at least ``_START_S``), noticed likewise; it is killed, the
others finish their frames. An error the loop did not see yet is raised by
``finish`` as ``ParticipantFailed`` with the section.
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import math
import os
import queue
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cosim.core import workers as worker_kit
from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.state import STATE_INDEX
from cosim.errors import CosimError, how_it_ended
from cosim.renderer.config import CamerasSpec
from cosim.renderer.frame import GT_COLUMNS, World, WorldSpec, render_frame
from cosim.renderer.video import EXTENSIONS, open_video
from cosim.sync.participants import ParticipantFailed, RunContext
from cosim.vehicles import get_class

log = logging.getLogger(__name__)

_POSE_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg",
                                       "pitch_deg", "yaw_deg")]
#: the most stills a run takes (more are counted in the summary, not taken)
MAX_STILLS = 10_000
#: while waiting for frames, how often the render workers' liveness is checked
_POLL_S = 0.2
#: the least time a render worker has to start (import, build its world) and
#: render its first frame
_START_S = 60.0
#: what a results thread reports when its worker's pipe ends
_EOF = ("eof",)


class RenderError(CosimError):
    """Rendering or writing a camera's frame failed (names the stream, the tick
    and the render worker's traceback)."""

    def __init__(self, vehicle: str, camera: str, tick: int | None, remote_tb: str) -> None:
        super().__init__(vehicle, camera, tick, remote_tb)
        self.vehicle, self.camera, self.tick, self.remote_traceback = (vehicle, camera, tick,
                                                                        remote_tb)

    def __str__(self) -> str:
        last = self.remote_traceback.strip().splitlines()[-1:] or ["?"]
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return (f"camera {self.camera!r} of vehicle {self.vehicle!r}{at}: {last[0]}\n"
                f"--- render traceback ---\n{self.remote_traceback.rstrip()}")


class RenderWorkerDied(CosimError):
    """A render worker process ended without being asked to (killed, crashed)."""

    def __init__(self, worker: int, pid: int | None, exitcode: int | None,
                 cameras: list[str], tick: int | None) -> None:
        super().__init__(worker, pid, exitcode, cameras, tick)
        self.worker, self.pid, self.exitcode, self.cameras, self.tick = (
            worker, pid, exitcode, list(cameras), tick)

    @property
    def vehicle(self) -> str | None:
        """The vehicle of its first camera (for the run's error event)."""
        return self.cameras[0].split("/")[0] if self.cameras else None

    def __str__(self) -> str:
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return (f"render worker {self.worker} (pid {self.pid}) "
                f"{how_it_ended(self.exitcode)}{at}; its cameras (vehicle/camera): "
                f"{', '.join(self.cameras)}")


class RenderWorkerTimeout(RenderWorkerDied):
    """A render worker is alive but sent nothing for ``timeout_s`` while it had
    frames to render (stopped, stuck): names the frame it was on."""

    def __init__(self, worker: int, pid: int | None, cameras: list[str], tick: int | None,
                 timeout_s: float, frame: str) -> None:
        CosimError.__init__(self, worker, pid, cameras, tick, timeout_s, frame)
        self.worker, self.pid, self.exitcode, self.cameras, self.tick = (
            worker, pid, None, list(cameras), tick)
        self.timeout_s, self.frame = timeout_s, frame

    def __str__(self) -> str:
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return (f"render worker {self.worker} (pid {self.pid}) sent nothing for "
                f"{self.timeout_s:g} s while rendering {self.frame}{at} (stopped or stuck; "
                f"--step-timeout-s); its cameras (vehicle/camera): {', '.join(self.cameras)}")


@dataclass(frozen=True)
class Stream:
    index: int
    vehicle: str
    row: int  # the vehicle's row in the state array
    camera: CameraSpec
    video: str  # relative to the run folder
    ground_truth: str
    thumb_px: tuple[int, int] | None  # (w, h) of the operator view's thumbnail, if any
    #: the camera's height above the vehicle's reference point (its class's
    #: ``camera_height_m``: a car's camera is not at the road surface)
    lift_m: float = 0.0


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


def _plain(v: Any) -> Any:
    """JSON for numpy scalars in ground-truth rows."""
    return v.item() if isinstance(v, np.generic) else str(v)


class StreamWriter:
    """One stream's video and ground-truth files."""

    def __init__(self, out_dir: Path, stream: Stream, codec: str, digest: bool) -> None:
        self.s = stream
        cam = stream.camera
        self.video = open_video(str(out_dir / stream.video), codec, cam.rate_hz, cam.width_px,
                                cam.height_px)
        self.gt_file = open(out_dir / stream.ground_truth, "w", newline="")  # noqa: SIM115
        self.gt = csv.writer(self.gt_file)
        self.gt.writerow(GT_COLUMNS)
        self.gt_file.flush()
        self.frames = 0
        self.hash = hashlib.sha256() if digest else None

    def write(self, frame_no: int, time_s: float, img: np.ndarray,
              rows: list[dict[str, Any]], target_ids: list[str]) -> None:
        self.video.write(img)
        if self.hash is not None:
            self.hash.update(img.tobytes())
        head = [frame_no, f"{time_s:.6f}", self.s.vehicle, self.s.camera.name]
        self.gt.writerows([*head, tid, *[_fmt(r[c]) for c in _GT_VALUES]]
                          for tid, r in zip(target_ids, rows))
        self.gt_file.flush()
        self.frames += 1

    def close(self) -> dict[str, Any]:
        self.video.release()
        self.gt_file.close()
        return {"frames": self.frames,
                **({"frames_sha256": self.hash.hexdigest()} if self.hash is not None else {})}


_GT_VALUES = GT_COLUMNS[5:]  # the columns of a ground-truth row after its target


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4f}"
    return str(v)


class RenderWorker:
    """Renders and writes the streams given to it (in a worker process or inline)."""

    def __init__(self, world_spec: WorldSpec, streams: list[Stream], out_dir: Path, codec: str,
                 digest: bool) -> None:
        self.world = World(world_spec)
        self.out_dir = out_dir
        self.streams = {s.index: s for s in streams}
        self.writers: dict[int, StreamWriter] = {}
        for s in streams:
            try:
                self.writers[s.index] = StreamWriter(out_dir, s, codec, digest)
            except Exception as e:  # say which stream; keep what is open closed
                self.close()
                raise StreamFailed(s.index, worker_kit.remote_traceback()) from e
        self.target_ids = [t.id for t in world_spec.targets]
        self.frames = {s.index: np.empty((s.camera.height_px, s.camera.width_px, 4), np.uint8)
                       for s in streams}  # one reused (BGRA) frame buffer per stream

    def render(self, stream: int, frame_no: int, tick: int, pose6: tuple[float, ...],
               gimbal: tuple[float, float] | None = None, still: str | None = None
               ) -> tuple[np.ndarray | None, list[dict[str, Any]] | None]:
        """One frame of ``stream`` from the vehicle's pose (lat, lon, alt, roll,
        pitch, yaw) and its gimbal's angles (None: the mount's); with ``still``
        (a path in the run folder) the frame is also written there as a still.
        Returns the operator view's thumbnail (if any) and, for a still, the
        frame's ground truth (one dict per target, with its id)."""
        s = self.streams[stream]
        la, lo, alt, roll, pitch, yaw = pose6
        pose = camera_pose(s.camera, la, lo, alt, roll, pitch, yaw, self.world.spec.ground_alt_m,
                           gimbal)
        img, rows = render_frame(self.world, s.camera, pose, tick, self.frames[stream], stream)
        self.writers[stream].write(frame_no, tick / self.world.spec.physics_hz, img, rows,
                                   self.target_ids)
        truth = None
        if still is not None:
            if not cv2.imwrite(str(self.out_dir / still), cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)):
                raise OSError(f"could not write the still {still}")
            truth = [{"target": tid, **r} for tid, r in zip(self.target_ids, rows)]
        if s.thumb_px is None:
            return None, truth
        thumb: np.ndarray = cv2.cvtColor(cv2.resize(img, s.thumb_px, interpolation=cv2.INTER_AREA),
                                         cv2.COLOR_BGRA2BGR)
        return thumb, truth

    def close(self) -> dict[int, dict[str, Any]]:
        return {i: w.close() for i, w in self.writers.items()}


class StreamFailed(Exception):
    """Opening stream ``index``'s files failed (``tb``: the traceback)."""

    def __init__(self, index: int, tb: str) -> None:
        super().__init__(index, tb)
        self.index, self.tb = index, tb


def _read_results(k: int, conn: Connection, inbox: queue.SimpleQueue[Any]) -> None:
    """A thread per render worker: its messages, in order, into ``inbox`` as
    ``(k, message)``, then ``(k, _EOF)`` when its pipe ends. A worker stopped
    in the middle of a message holds up only this thread, never the loop."""
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):  # it is gone (mid-message, perhaps)
            inbox.put((k, _EOF))
            return
        inbox.put((k, msg))


def _worker_main(world_spec: WorldSpec, streams: list[Stream], out_dir: str, codec: str,
                 digest: bool, jobs: Any, results: Connection) -> None:
    cv2.setNumThreads(1)
    try:
        w = RenderWorker(world_spec, streams, Path(out_dir), codec, digest)
    except StreamFailed as e:
        results.send(("error", e.index, None, e.tb))
        results.send(("done", {}))  # finish() need not wait for a worker that never started
        return
    except BaseException:
        results.send(("error", streams[0].index if streams else -1, None,
                      worker_kit.remote_traceback()))
        results.send(("done", {}))
        return
    results.send(("ready",))
    try:
        while True:
            try:
                job = jobs.get(timeout=1.0)
            except queue.Empty:
                if worker_kit.parent_gone():  # the loop's process is gone: keep what we have
                    break
                continue
            if job is None:
                break
            stream, frame_no, tick, pose6, gimbal, still = job
            try:
                thumb, truth = w.render(stream, frame_no, tick, pose6, gimbal, still)
            except BaseException:
                results.send(("error", stream, tick, worker_kit.remote_traceback()))
                break
            results.send(("frame", stream, frame_no, thumb, (still, truth) if still else None))
    finally:
        results.send(("done", w.close()))


class CameraParticipant:
    name = "cameras"

    def __init__(self, scenario: Any) -> None:
        self.scn = scenario
        self.spec: CamerasSpec = scenario.sections["cameras"]
        self.streams: list[Stream] = []
        self.inline: RenderWorker | None = None
        self.procs: list[Any] = []
        self.jobs: list[Any] = []
        #: one pipe of results per render worker, each read by a thread of its own
        #: into ``inbox`` (a worker that dies mid-message is an end of file; one
        #: stopped mid-message holds up its thread only), the pipes that have ended
        self.results: list[Connection] = []
        self.readers: list[threading.Thread] = []
        self.inbox: queue.SimpleQueue[tuple[int, tuple[Any, ...]]] = queue.SimpleQueue()
        self.eof: set[int] = set()
        self.in_flight: list[int] = []
        #: per render worker: (stream, tick) of each frame sent and not yet back,
        #: when it was last heard from (or given work while idle), whether it is ready
        self.pending: list[deque[tuple[int, int]]] = []
        self.heard: list[float] = []
        self.ready: set[int] = set()
        self.step_timeout_s = 60.0
        self.closed: dict[int, dict[str, Any]] = {}
        self.operator: Any = None
        self.finished = False
        self.tick = 0  # the latest exchange (named in errors)
        self.failed: BaseException | None = None  # the error raised into the loop
        self.done: set[int] = set()  # render workers that have closed their files
        #: each gimbal stream's current (pitch_deg, yaw_deg), set by commands
        self.gimbal: dict[int, tuple[float, float]] = {}
        self.gimbal_before: dict[int, tuple[float, float]] = {}  # as of the last exchange
        self.gimbal_moves: list[tuple[Stream, str]] = []
        #: still triggering per vehicle row (``camera`` commands) and the streams
        #: whose next frame is a still (stream index -> the command's source)
        self.triggers: dict[int, _Trigger] = {}
        self.still_due: dict[int, str] = {}
        self.stills_taken = 0
        self.stills_refused = 0
        #: what each still was taken at (its file -> the record without ground truth)
        self.still_meta: dict[str, dict[str, Any]] = {}
        self.stills_log: Any = None

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
        if ctx.commander is not None:
            ctx.commander.observers.append(self.point_gimbal)
            ctx.commander.observers.append(self.trigger_camera)
        scn = ctx.scenario
        ws = WorldSpec(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m,
                       int(scn.seed), float(ctx.physics_hz), scn.world.ground,
                       scn.world.targets, scn.world.obstacles)
        n = self.spec.render_workers
        if n is None:
            n = min(len(self.streams), os.cpu_count() or 1)
        n = min(n, len(self.streams))
        if self.spec.operator_view:
            self.operator = OperatorView(self.spec, self.streams, ws, ctx, ext)
        if n == 0:
            try:
                self.inline = RenderWorker(ws, self.streams, ctx.out_dir, self.spec.codec,
                                           self.spec.digest)
            except StreamFailed as e:
                st = self.streams[e.index]
                self.failed = RenderError(st.vehicle, st.camera.name, None, e.tb)
                raise self.failed from None
            return
        mpc = worker_kit.context()
        self.step_timeout_s = ctx.step_timeout_s
        for k in range(n):
            q = mpc.Queue()
            reader, writer = mpc.Pipe(duplex=False)
            mine = [s for s in self.streams if s.index % n == k]
            p = worker_kit.start(_worker_main, (ws, mine, str(ctx.out_dir), self.spec.codec,
                                             self.spec.digest, q, writer),
                              name=f"cosim-render-{k}")
            writer.close()  # the worker holds the only writing end
            self.procs.append(p)
            self.jobs.append(q)
            self.results.append(reader)
            t = threading.Thread(target=_read_results, args=(k, reader, self.inbox),
                                 name=f"cosim-render-{k}-results", daemon=True)
            t.start()
            self.readers.append(t)
            self.in_flight.append(0)
            self.pending.append(deque())
            self.heard.append(time.monotonic())
        log.info("cameras: %d stream(s) on %d render worker(s)", len(self.streams), n)

    def point_gimbal(self, row: int, cmd: Any, source: str) -> None:
        """A command's gimbal angles, for the vehicle's gimbal cameras from this
        exchange's frame on (a ``gimbal`` event); ignored, with a warning, by a
        vehicle without one."""
        if not cmd.points_gimbal:
            return
        moved = []
        for s in self.streams:
            if s.row == row and s.index in self.gimbal:
                pitch, yaw = self.gimbal[s.index]
                self.gimbal[s.index] = (
                    pitch if cmd.gimbal_pitch_deg is None else cmd.gimbal_pitch_deg,
                    yaw if cmd.gimbal_yaw_deg is None else cmd.gimbal_yaw_deg)
                moved.append(s)
        if not moved:
            log.warning("vehicle %s has no camera on a gimbal: gimbal command (%s) ignored",
                        self.ctx.ids[row], source)
            return
        self.gimbal_moves += [(s, source) for s in moved]  # events at this exchange's tick

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

    def _still_name(self, s: Stream, frame_no: int, tick: int, pose6: tuple[float, ...],
                    gimbal: tuple[float, float] | None) -> str | None:
        """The file of a still taken at this frame of ``s`` (None: the limit)."""
        source = self.still_due.pop(s.index)
        if self.stills_taken >= MAX_STILLS:
            self.stills_refused += 1
            if self.stills_refused == 1:
                log.warning("cameras: %d stills taken, the most a run takes; more are counted "
                            "(stills_refused in summary.json), not taken", MAX_STILLS)
            return None
        if self.stills_log is None:
            (self.ctx.out_dir / "stills").mkdir(exist_ok=True)
            self.stills_log = open(self.ctx.out_dir / "stills" / "stills.jsonl", "a")  # noqa: SIM115
        self.stills_taken += 1
        name = f"stills/{s.vehicle}_{s.camera.name}_{self.stills_taken:04d}.png"
        time_s = tick / self.ctx.physics_hz
        self.still_meta[name] = {
            "file": name, "vehicle": s.vehicle, "camera": s.camera.name, "frame": frame_no,
            "tick": tick, "time_s": time_s,
            "pose": dict(zip(("lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "pitch_deg",
                              "yaw_deg"), pose6)),
            "gimbal": None if gimbal is None else {"pitch_deg": gimbal[0], "yaw_deg": gimbal[1]}}
        self.ctx.events.emit("still", tick, vehicle=s.vehicle, camera=s.camera.name,
                             file=name, frame=frame_no, source=source)
        return name

    def _still_done(self, still: tuple[str, list[dict[str, Any]] | None] | None) -> None:
        """A still's line in stills.jsonl, once its frame is rendered."""
        if still is None:
            return
        name, truth = still
        record = self.still_meta.pop(name)
        record["targets"] = truth
        self.stills_log.write(json.dumps(record, default=_plain) + "\n")
        self.stills_log.flush()

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        self.tick = tick
        if self.triggers:
            self._due_stills(tick, states)
        for s, source in self.gimbal_moves:
            pitch, yaw = self.gimbal[s.index]
            self.ctx.events.emit("gimbal", tick, vehicle=s.vehicle, camera=s.camera.name,
                                 pitch_deg=pitch, yaw_deg=yaw, source=source)
        self.gimbal_moves.clear()
        if self.procs:
            self._check_workers()
        self._between(tick)
        for s in self.streams:
            every = s.camera.frame_every
            if tick % every:
                continue
            self._frame(s, tick, states[s.row], self.gimbal.get(s.index), stills=True)
        # the angles the frames until the next exchange were taken with (a
        # command at that exchange moves the gimbal only from its own tick)
        self.gimbal_before = dict(self.gimbal)
        if self.operator is not None:
            self.operator.at_exchange(tick, states)
        if self.procs:
            self._collect(block=False)

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
                    self._frame(s, t, w.states[c, pos[s.row]], self.gimbal_before.get(s.index),
                                stills=False)

    def _frame(self, s: Stream, tick: int, row: np.ndarray,
               gimbal: tuple[float, float] | None, stills: bool) -> None:
        """Render stream ``s``'s frame at ``tick`` from its vehicle's state
        ``row`` with the gimbal at ``gimbal`` (and a still with it when one is
        due and ``stills``)."""
        every = s.camera.frame_every
        pose6 = tuple(float(x) for x in row[_POSE_COLS])
        if s.lift_m:
            pose6 = pose6[:2] + (pose6[2] + s.lift_m,) + pose6[3:]
        frame_no = tick // every
        still = self._still_name(s, frame_no, tick, pose6, gimbal) \
            if stills and s.index in self.still_due else None
        if self.inline is not None:
            try:
                thumb, truth = self.inline.render(s.index, frame_no, tick, pose6, gimbal,
                                                  still)
            except Exception:
                self.failed = RenderError(s.vehicle, s.camera.name, tick,
                                          traceback.format_exc())
                raise self.failed from None
            self._still_done((still, truth) if still else None)
            self._thumb(s.index, frame_no, thumb)
        else:
            k = s.index % len(self.procs)
            self._give(k, (s.index, frame_no, tick, pose6, gimbal, still))
            self.pending[k].append((s.index, tick))
            while self.in_flight[k] >= self.spec.max_in_flight:
                self._collect(block=True)

    def _give(self, k: int, job: tuple[Any, ...] | None) -> None:
        """Queue ``job`` for render worker ``k`` (None: finish); its silence is
        timed from now if it had nothing to do."""
        if not self.in_flight[k] and k in self.ready:
            self.heard[k] = time.monotonic()
        self.jobs[k].put(job)
        self.in_flight[k] += 1

    def _thumb(self, stream: int, frame_no: int, thumb: np.ndarray | None) -> None:
        """A rendered frame's thumbnail: to the operator view and the taps."""
        if self.operator is not None:
            self.operator.thumb(stream, frame_no, thumb)
        if thumb is not None and self.taps:
            s = self.streams[stream]
            t = frame_no * s.camera.frame_every / self.ctx.physics_hz
            for tap in self.taps:
                tap(s.vehicle, s.camera.name, t, thumb)

    def _cameras_of(self, k: int) -> list[str]:
        n = len(self.procs)
        return [f"{s.vehicle}/{s.camera.name}" for s in self.streams if s.index % n == k]

    def _check_workers(self) -> None:
        """Raise for a render worker that has ended (without blocking): first
        whatever it reported (a failure at start), else ``RenderWorkerDied``;
        then for one silent too long with frames to render (``RenderWorkerTimeout``)."""
        ended = [k for k in worker_kit.ended(self.procs) if k not in self.done]
        if ended:  # a worker that failed says why before it exits: read to its end
            k = ended[0]
            deadline = time.monotonic() + 1.0
            while k not in self.eof and (left := deadline - time.monotonic()) > 0:
                try:
                    self._take(*self.inbox.get(timeout=left))
                except queue.Empty:
                    break
            self._died(k)
        self._drain()  # what has arrived counts as heard
        for k in range(len(self.procs)):
            if self.in_flight[k]:
                self._check_silence(k)

    def _check_silence(self, k: int) -> None:
        """``RenderWorkerTimeout`` if worker ``k`` has been silent longer than the
        run allows (before it is ready: at least ``_START_S``); it is killed
        (a stopped process ends only so)."""
        limit = self.step_timeout_s if k in self.ready else max(self.step_timeout_s, _START_S)
        if time.monotonic() - self.heard[k] <= limit:
            return
        stream, tick = self.pending[k][0] if self.pending[k] else (-1, self.tick)
        s = self.streams[stream] if 0 <= stream < len(self.streams) else None
        frame = f"the frame at tick {tick} of {s.vehicle}/{s.camera.name}" if s else \
            "its first frame"
        p = self.procs[k]
        self.failed = RenderWorkerTimeout(k, p.pid, self._cameras_of(k), self.tick, limit, frame)
        self.done.add(k)  # nothing more is waited for from it
        p.kill()
        raise self.failed

    def _died(self, k: int) -> None:
        p = self.procs[k]
        p.join(1.0)
        self.failed = RenderWorkerDied(k, p.pid, p.exitcode, self._cameras_of(k), self.tick)
        raise self.failed

    def _take(self, k: int, msg: tuple[Any, ...]) -> None:
        """Handle one message from worker ``k``, or the end of its pipe."""
        if msg == _EOF:
            self.eof.add(k)
            if k not in self.done:  # gone without saying goodbye
                self._died(k)
            return
        self._handle(k, msg)

    def _drain(self) -> None:
        """Handle every result waiting now (raises a reported error)."""
        while True:
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                return
            self._take(*item)

    def _handle(self, k: int, msg: tuple[Any, ...]) -> None:
        kind = msg[0]
        self.heard[k] = time.monotonic()
        if kind == "ready":
            self.ready.add(k)
        elif kind == "frame":
            _, stream, frame_no, thumb, still = msg
            self.in_flight[k] -= 1
            if self.pending[k]:
                self.pending[k].popleft()
            self._still_done(still)
            if thumb is not None:
                self._thumb(stream, frame_no, thumb)
        elif kind == "done":
            self.closed.update(msg[1])
            self.done.add(k)
        elif kind == "error":
            _, stream, tick, tb = msg
            s = self.streams[stream] if 0 <= stream < len(self.streams) else None
            self.failed = RenderError(s.vehicle if s else "?", s.camera.name if s else "?",
                                      tick, tb)
            raise self.failed

    def _collect(self, block: bool) -> None:
        """Handle the results waiting; with ``block``, wait until at least one
        arrives (a worker that dies meanwhile is noticed within ``_POLL_S``)."""
        if not block:
            self._drain()
            return
        while True:
            try:
                item = self.inbox.get(timeout=_POLL_S)
            except queue.Empty:
                self._check_workers()
                continue
            self._take(*item)
            self._drain()
            return

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        if self.finished:
            return None
        self.finished = True
        self.tick = tick
        raised = self.failed  # an error the loop has ended on already: said once
        error: BaseException | None = None
        if raised is None and reason == "completed" and hasattr(self, "ctx"):
            try:  # the frames due after the last exchange, gathered in its step
                self._between(tick)
            except Exception as e:
                error = e
        if self.inline is not None:
            self.closed = self.inline.close()
        elif self.procs:
            for k in range(len(self.jobs)):
                self._give(k, None)  # the goodbye is work too: its silence is timed
            waiting = set(range(len(self.procs))) - self.done - self.eof  # may still send
            while waiting:
                try:
                    k, msg = self.inbox.get(timeout=_POLL_S)
                    self._take(k, msg)
                except queue.Empty:
                    pass
                except RenderWorkerDied as e:
                    waiting.discard(k)
                    error = error or e
                except RenderError as e:
                    error = error or e
                for k in waiting - self.done:  # silent too long: killed, the others go on
                    try:
                        self._check_silence(k)
                    except RenderWorkerTimeout as e:
                        error = error or e
                waiting -= self.done | self.eof
            worker_kit.stop(self.procs, 10.0)
            for q in self.jobs:  # the workers are gone: nothing left to deliver at exit
                q.cancel_join_thread()
                q.close()
            for t in self.readers:  # their pipes have ended with the workers
                t.join(1.0)
            for conn in self.results:
                conn.close()
        out: dict[str, Any] = {"streams": [], "codec": self.spec.codec}
        for s in self.streams:
            c = s.camera
            out["streams"].append({
                "vehicle": s.vehicle, "camera": c.name, "video": s.video,
                "ground_truth": s.ground_truth, "rate_hz": c.rate_hz, "width_px": c.width_px,
                "height_px": c.height_px, "hfov_deg": c.hfov_deg, "vfov_deg": c.vfov_deg,
                "mount": c.mount, "pitch_deg": c.pitch_deg,
                **self.closed.get(s.index, {"frames": None})})
        if self.operator is not None:
            out["operator"] = self.operator.close()
        if self.stills_log is not None:
            self.stills_log.close()
        if self.stills_taken or self.stills_refused:
            out["stills"] = {"taken": self.stills_taken, "refused": self.stills_refused,
                             "log": "stills/stills.jsonl"}
        if raised is not None:
            out["error"] = str(raised).splitlines()[0]
        elif error is not None:
            out["error"] = str(error).splitlines()[0]
            raise ParticipantFailed(error, out)
        return out

    def after_run(self, out_dir: Path) -> None:
        return None
