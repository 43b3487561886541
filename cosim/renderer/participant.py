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

Failures end the run, naming what failed: a stream that cannot be opened or
written (``RenderError``: camera, vehicle, tick, the worker's traceback) and
a render worker that dies (``RenderWorkerDied``: worker, pid, signal or exit
code, its cameras), noticed at the next exchange (its process sentinel is
polled without blocking) or within ``_POLL_S`` while the loop waits for
frames. An error the loop did not see yet is raised by ``finish`` as
``ParticipantFailed`` with the section.
"""

from __future__ import annotations

import csv
import hashlib
import logging
import os
import queue
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as wait_any
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cosim import workers as worker_kit
from cosim.errors import CosimError, how_it_ended
from cosim.renderer.camera import camera_pose
from cosim.renderer.config import CameraSpec, CamerasSpec, GroundSpec
from cosim.renderer.frame import GT_COLUMNS, World, WorldSpec, render_frame
from cosim.renderer.video import EXTENSIONS, open_video
from cosim.sync.participants import ParticipantFailed, RunContext
from cosim.vehicles import get_class
from cosim.vehicles.spec import STATE_INDEX

log = logging.getLogger(__name__)

_POSE_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg",
                                       "pitch_deg", "yaw_deg")]
_RESULT_TIMEOUT_S = 60.0
#: while waiting for frames, how often the render workers' liveness is checked
_POLL_S = 0.2


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
               gimbal: tuple[float, float] | None = None) -> np.ndarray | None:
        """One frame of ``stream`` from the vehicle's pose (lat, lon, alt, roll,
        pitch, yaw) and its gimbal's angles (None: the mount's)."""
        s = self.streams[stream]
        la, lo, alt, roll, pitch, yaw = pose6
        pose = camera_pose(s.camera, la, lo, alt, roll, pitch, yaw, self.world.spec.ground_alt_m,
                           gimbal)
        img, rows = render_frame(self.world, s.camera, pose, tick, self.frames[stream], stream)
        self.writers[stream].write(frame_no, tick / self.world.spec.physics_hz, img, rows,
                                   self.target_ids)
        if s.thumb_px is None:
            return None
        thumb: np.ndarray = cv2.cvtColor(cv2.resize(img, s.thumb_px, interpolation=cv2.INTER_AREA),
                                         cv2.COLOR_BGRA2BGR)
        return thumb

    def close(self) -> dict[int, dict[str, Any]]:
        return {i: w.close() for i, w in self.writers.items()}


class StreamFailed(Exception):
    """Opening stream ``index``'s files failed (``tb``: the traceback)."""

    def __init__(self, index: int, tb: str) -> None:
        super().__init__(index, tb)
        self.index, self.tb = index, tb


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
            stream, frame_no, tick, pose6, gimbal = job
            try:
                thumb = w.render(stream, frame_no, tick, pose6, gimbal)
            except BaseException:
                results.send(("error", stream, tick, worker_kit.remote_traceback()))
                break
            results.send(("frame", stream, frame_no, thumb))
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
        #: one pipe of results per render worker, read only here: a worker that
        #: dies mid-message is an end of file, never a read waiting forever
        self.results: list[Connection] = []
        self.in_flight: list[int] = []
        self.closed: dict[int, dict[str, Any]] = {}
        self.operator: Any = None
        self.finished = False
        self.tick = 0  # the latest exchange (named in errors)
        self.failed: BaseException | None = None  # the error raised into the loop
        self.done: set[int] = set()  # render workers that have closed their files
        #: each gimbal stream's current (pitch_deg, yaw_deg), set by commands
        self.gimbal: dict[int, tuple[float, float]] = {}
        self.gimbal_moves: list[tuple[Stream, str]] = []

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
        for i, (cam, row) in enumerate(streams):
            base = f"cameras/{ctx.ids[row]}_{cam.name}"
            show = tiles is not None and i < OperatorView.MAX_TILES
            lift = get_class(ctx.scenario.vehicles[row].vehicle_class).camera_height_m
            self.streams.append(Stream(i, ctx.ids[row], row, cam, f"{base}.{ext}",
                                       f"{base}.gt.csv", tiles if show else None, lift))
        self.gimbal = {s.index: (s.camera.pitch_deg, s.camera.yaw_deg) for s in self.streams
                       if s.camera.mount == "gimbal"}
        if ctx.commander is not None:
            ctx.commander.observers.append(self.point_gimbal)
        scn = ctx.scenario
        ws = WorldSpec(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m,
                       int(scn.seed), float(ctx.physics_hz),
                       scn.sections.get("ground") or GroundSpec(),
                       tuple(scn.sections.get("targets") or ()),
                       tuple(scn.sections.get("obstacles") or ()))
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
            self.in_flight.append(0)
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

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        self.tick = tick
        for s, source in self.gimbal_moves:
            pitch, yaw = self.gimbal[s.index]
            self.ctx.events.emit("gimbal", tick, vehicle=s.vehicle, camera=s.camera.name,
                                 pitch_deg=pitch, yaw_deg=yaw, source=source)
        self.gimbal_moves.clear()
        if self.procs:
            self._check_workers()
        for s in self.streams:
            every = s.camera.frame_every
            if tick % every:
                continue
            pose6 = tuple(float(x) for x in states[s.row, _POSE_COLS])
            if s.lift_m:
                pose6 = pose6[:2] + (pose6[2] + s.lift_m,) + pose6[3:]
            gimbal = self.gimbal.get(s.index)
            frame_no = tick // every
            if self.inline is not None:
                try:
                    thumb = self.inline.render(s.index, frame_no, tick, pose6, gimbal)
                except Exception:
                    self.failed = RenderError(s.vehicle, s.camera.name, tick,
                                              traceback.format_exc())
                    raise self.failed from None
                if self.operator is not None:
                    self.operator.thumb(s.index, frame_no, thumb)
            else:
                k = s.index % len(self.procs)
                self.jobs[k].put((s.index, frame_no, tick, pose6, gimbal))
                self.in_flight[k] += 1
                while self.in_flight[k] >= self.spec.max_in_flight:
                    self._collect(block=True)
        if self.operator is not None:
            self.operator.at_exchange(tick, states)
        if self.procs:
            self._collect(block=False)

    def _cameras_of(self, k: int) -> list[str]:
        n = len(self.procs)
        return [f"{s.vehicle}/{s.camera.name}" for s in self.streams if s.index % n == k]

    def _check_workers(self) -> None:
        """Raise for a render worker that has ended (without blocking): first
        whatever it reported (a failure at start), else ``RenderWorkerDied``."""
        ended = worker_kit.ended(self.procs)
        if ended:
            self._drain()  # a worker that failed says why before it exits
            self._died(ended[0])

    def _died(self, k: int) -> None:
        p = self.procs[k]
        p.join(1.0)
        self.failed = RenderWorkerDied(k, p.pid, p.exitcode, self._cameras_of(k), self.tick)
        raise self.failed

    def _read(self, k: int) -> None:
        """Handle one message from worker ``k`` (its pipe is readable)."""
        try:
            msg = self.results[k].recv()
        except (EOFError, OSError):  # the worker is gone (mid-message, perhaps)
            if k in self.done:  # it said goodbye first: a normal end
                self.results[k].close()
                return
            self._died(k)
        self._handle(k, msg)

    def _drain(self) -> None:
        """Handle every result waiting now (raises a reported error)."""
        for k, conn in enumerate(self.results):
            while not conn.closed and conn.poll(0):
                self._read(k)

    def _handle(self, k: int, msg: tuple[Any, ...]) -> None:
        kind = msg[0]
        if kind == "frame":
            _, stream, frame_no, thumb = msg
            self.in_flight[stream % len(self.procs)] -= 1
            if self.operator is not None and thumb is not None:
                self.operator.thumb(stream, frame_no, thumb)
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
            ready = wait_any(self.results, timeout=_POLL_S)
            if ready:
                self._drain()
                return
            self._check_workers()

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        if self.finished:
            return None
        self.finished = True
        self.tick = tick
        raised = self.failed  # an error the loop has ended on already: said once
        error: BaseException | None = None
        if self.inline is not None:
            self.closed = self.inline.close()
        elif self.procs:
            for q in self.jobs:
                q.put(None)
            deadline = time.monotonic() + _RESULT_TIMEOUT_S
            waiting = set(range(len(self.procs))) - self.done  # may still send
            while waiting:
                if time.monotonic() > deadline:
                    error = error or RenderError("?", "?", tick, f"render workers did not "
                                                 f"finish in {_RESULT_TIMEOUT_S:g} s")
                    break
                for conn in wait_any([self.results[k] for k in waiting], timeout=_POLL_S):
                    k = self.results.index(conn)  # type: ignore[arg-type]
                    try:
                        self._read(k)
                    except RenderWorkerDied as e:
                        waiting.discard(k)
                        error = error or e
                    except RenderError as e:
                        error = error or e
                waiting -= self.done
            worker_kit.stop(self.procs, 10.0)
            for q in self.jobs:  # the workers are gone: nothing left to deliver at exit
                q.cancel_join_thread()
                q.close()
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
        if raised is not None:
            out["error"] = str(raised).splitlines()[0]
        elif error is not None:
            out["error"] = str(error).splitlines()[0]
            raise ParticipantFailed(error, out)
        return out

    def after_run(self, out_dir: Path) -> None:
        return None
