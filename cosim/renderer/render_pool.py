"""The render pool: every camera stream's frames rendered and written in tick
order, in render worker processes or inline.

``RenderWorker`` renders and writes the streams given to it (their
``outputs.StreamWriter``): in each worker process, which builds it from the
picklable ``WorldSpec``, or in the loop's own process (``InlinePool``, for
``render_workers: 0``: the reference). ``RenderPool`` gives stream ``s`` to
worker ``s % n`` and sends it the pose at the frame's tick (six numbers), so
rendering overlaps the physics; at most ``max_in_flight`` frames per worker
are queued before the loop waits. Each worker's results are read by a thread
of its own into one queue: a worker stopped in the middle of a message holds
up only that thread. Frames are a pure function of the scenario, seed, pose
and tick, hence identical for any worker count. Both hand each rendered
frame's thumbnail and still to ``on_frame``. ``close`` drains every queued
frame and closes the files; a worker also closes its files if the loop's
process disappears. Workers are started by ``cosim.core.workers.start``:
Ctrl-C reaches the loop, which ends the run, and then ``close`` closes every
video, rather than the workers dying mid-write.

Failures name what failed: a stream that cannot be opened or written
(``RenderError``: camera, vehicle, tick, the worker's traceback), a render
worker that dies (``RenderWorkerDied``: worker, pid, signal or exit code, its
cameras), noticed at the next exchange (its process sentinel is polled
without blocking) or within ``_POLL_S`` while the loop waits for frames, and
one that is alive but silent (stopped, stuck: ``RenderWorkerTimeout``) for
the run's ``step_timeout_s`` while it has frames to render (from its start
until it is ready: at least ``_START_S``), noticed likewise; it is killed, the
others finish their frames.

Owns the processes, their messages and their deadlines: what is written is
``outputs``', when a frame is due the participant's.
"""

from __future__ import annotations

import queue
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cosim.core import workers as worker_kit
from cosim.core.camera import camera_pose
from cosim.errors import CosimError, how_it_ended
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.outputs import Stream, StreamWriter
from cosim.renderer.sensor import Sensor

#: while waiting for frames, how often the render workers' liveness is checked
_POLL_S = 0.2
#: the least time a render worker has to start (import, build its world) and
#: render its first frame
_START_S = 60.0
#: what a results thread reports when its worker's pipe ends
_EOF = ("eof",)
#: a rendered frame, to the participant: (stream, frame number, its thumbnail
#: or None, (its still's file, the frame's ground truth) or None)
OnFrame = Callable[[int, int, np.ndarray | None, tuple[str, Any] | None], None]


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
        self.sensors = {s.index: Sensor(s.camera, s.camera.sensor, world_spec.seed, s.row)
                        for s in streams if s.camera.sensor is not None}
        #: the camera each stream renders (a barrel lens's is wider: ``Sensor.source``)
        self.sources = {s.index: self.sensors[s.index].source if s.index in self.sensors
                        else s.camera for s in streams}
        self.frames = {i: np.empty((c.height_px, c.width_px, 4), np.uint8)
                       for i, c in self.sources.items()}  # one reused (BGRA) buffer a stream

    def render(self, stream: int, frame_no: int, tick: int, pose6: tuple[float, ...],
               gimbal: tuple[float, float] | None = None, still: str | None = None,
               motion: tuple[float, ...] | None = None
               ) -> tuple[np.ndarray | None, list[dict[str, Any]] | None]:
        """One frame of ``stream`` from the vehicle's pose (lat, lon, alt, roll,
        pitch, yaw) and its gimbal's angles (None: the mount's); with ``still``
        (a path in the run folder) the frame is also written there as a still.
        ``motion`` (north, east, down velocity m/s; roll, pitch, yaw rates deg/s)
        is what a sensor's exposure smears the frame by (None: at rest).
        Returns the operator view's thumbnail (if any) and, for a still, the
        frame's ground truth (one dict per target, with its id)."""
        s = self.streams[stream]
        la, lo, alt, roll, pitch, yaw = pose6
        pose = camera_pose(s.camera, la, lo, alt, roll, pitch, yaw, self.world.spec.ground_alt_m,
                           gimbal)
        src = self.sources[stream]
        img, rows = render_frame(self.world, src, pose, tick, self.frames[stream], stream)
        if stream in self.sensors:  # the camera's sensor and lens; truth from the clean render
            sensor = self.sensors[stream]
            smear = sensor.smear_px(pose6, motion, gimbal, pose, self.world.spec.ground_alt_m)
            img = sensor.apply(img, frame_no, smear)
        ids = None
        if s.camera.datalink is not None:  # the recorded frame's part of the render's
            ids = self.world.last_ids(src.height_px, src.width_px)
            mx, my = (src.width_px - img.shape[1]) // 2, (src.height_px - img.shape[0]) // 2
            ids = ids[my:my + img.shape[0], mx:mx + img.shape[1]]
        self.writers[stream].write(frame_no, tick / self.world.spec.physics_hz, img, rows,
                                   self.target_ids, ids)
        truth = None
        if still is not None:
            if not cv2.imwrite(str(self.out_dir / still), cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)):
                raise OSError(f"could not write the still {still}")
            truth = [{"target": tid, **r} for tid, r in zip(self.target_ids, rows)]
        if s.thumb_px is None:
            return None, truth
        shown = self.writers[stream].shown(img)  # with a downlink: what it delivered
        thumb: np.ndarray = cv2.cvtColor(cv2.resize(shown, s.thumb_px,
                                                    interpolation=cv2.INTER_AREA),
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
        results.send(("done", {}))  # close() need not wait for a worker that never started
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
            stream, frame_no, tick, pose6, gimbal, still, motion = job
            try:
                thumb, truth = w.render(stream, frame_no, tick, pose6, gimbal, still, motion)
            except BaseException:
                results.send(("error", stream, tick, worker_kit.remote_traceback()))
                break
            results.send(("frame", stream, frame_no, thumb, (still, truth) if still else None))
    finally:
        results.send(("done", w.close()))


class InlinePool:
    """The streams rendered and written in the loop's own process, each frame
    when it is given (``render_workers: 0``: the reference the pool matches)."""

    def __init__(self, world_spec: WorldSpec, streams: list[Stream], out_dir: Path, codec: str,
                 digest: bool, on_frame: OnFrame) -> None:
        self.streams, self.on_frame = streams, on_frame
        self.tick = 0  # the latest exchange (named in errors)
        self.failed: BaseException | None = None  # the error raised into the loop
        try:
            self.worker = RenderWorker(world_spec, streams, out_dir, codec, digest)
        except StreamFailed as e:
            st = streams[e.index]
            self.failed = RenderError(st.vehicle, st.camera.name, None, e.tb)
            raise self.failed from None

    def submit(self, s: Stream, frame_no: int, tick: int, pose6: tuple[float, ...],
               gimbal: tuple[float, float] | None, still: str | None,
               motion: tuple[float, ...] | None = None) -> None:
        """Render and write ``s``'s frame now (RenderError if that fails)."""
        try:
            thumb, truth = self.worker.render(s.index, frame_no, tick, pose6, gimbal, still,
                                              motion)
        except Exception:
            self.failed = RenderError(s.vehicle, s.camera.name, tick, traceback.format_exc())
            raise self.failed from None
        self.on_frame(s.index, frame_no, thumb, (still, truth) if still else None)

    def check(self) -> None:
        """Nothing runs apart from the loop."""

    def collect(self, block: bool) -> None:
        """Every frame is delivered when it is given."""

    def close(self) -> tuple[dict[int, dict[str, Any]], BaseException | None]:
        """What each stream's writer reports when closed, and no error."""
        return self.worker.close(), None


class RenderPool:
    """Render worker processes, each rendering and writing the streams ``s`` with
    ``s.index % n == k`` (``start``), fed with frames (``submit``) and read
    (``collect``) under the run's deadlines."""

    def __init__(self, streams: list[Stream], max_in_flight: int, step_timeout_s: float,
                 on_frame: OnFrame) -> None:
        self.streams, self.on_frame = streams, on_frame
        self.max_in_flight = max_in_flight
        self.step_timeout_s = step_timeout_s
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
        self.closed: dict[int, dict[str, Any]] = {}
        self.tick = 0  # the latest exchange (named in errors)
        self.failed: BaseException | None = None  # the error raised into the loop
        self.done: set[int] = set()  # render workers that have closed their files

    def start(self, n: int, world_spec: WorldSpec, out_dir: Path, codec: str,
              digest: bool) -> None:
        """Start ``n`` render workers, each building its world from ``world_spec``
        and writing into ``out_dir``."""
        mpc = worker_kit.context()
        for k in range(n):
            q = mpc.Queue()
            reader, writer = mpc.Pipe(duplex=False)
            mine = [s for s in self.streams if s.index % n == k]
            p = worker_kit.start(_worker_main, (world_spec, mine, str(out_dir), codec, digest, q,
                                                writer),
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

    def submit(self, s: Stream, frame_no: int, tick: int, pose6: tuple[float, ...],
               gimbal: tuple[float, float] | None, still: str | None,
               motion: tuple[float, ...] | None = None) -> None:
        """Queue ``s``'s frame for its worker; wait for results while that worker
        has ``max_in_flight`` frames queued."""
        k = s.index % len(self.procs)
        self._give(k, (s.index, frame_no, tick, pose6, gimbal, still, motion))
        self.pending[k].append((s.index, tick))
        while self.in_flight[k] >= self.max_in_flight:
            self.collect(block=True)

    def _give(self, k: int, job: tuple[Any, ...] | None) -> None:
        """Queue ``job`` for render worker ``k`` (None: finish); its silence is
        timed from now if it had nothing to do."""
        if not self.in_flight[k] and k in self.ready:
            self.heard[k] = time.monotonic()
        self.jobs[k].put(job)
        self.in_flight[k] += 1

    def _cameras_of(self, k: int) -> list[str]:
        n = len(self.procs)
        return [f"{s.vehicle}/{s.camera.name}" for s in self.streams if s.index % n == k]

    def check(self) -> None:
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
            self.on_frame(stream, frame_no, thumb, still)
        elif kind == "done":
            self.closed.update(msg[1])
            self.done.add(k)
        elif kind == "error":
            _, stream, tick, tb = msg
            s = self.streams[stream] if 0 <= stream < len(self.streams) else None
            self.failed = RenderError(s.vehicle if s else "?", s.camera.name if s else "?",
                                      tick, tb)
            raise self.failed

    def collect(self, block: bool) -> None:
        """Handle the results waiting; with ``block``, wait until at least one
        arrives (a worker that dies meanwhile is noticed within ``_POLL_S``)."""
        if not block:
            self._drain()
            return
        while True:
            try:
                item = self.inbox.get(timeout=_POLL_S)
            except queue.Empty:
                self.check()
                continue
            self._take(*item)
            self._drain()
            return

    def close(self) -> tuple[dict[int, dict[str, Any]], BaseException | None]:
        """Let every worker render what it was given and close its files, then
        stop them: what each stream's writer reported when closed, and the first
        error met meanwhile (a worker that died, failed or fell silent too long:
        the others go on)."""
        error: BaseException | None = None
        if not self.procs:
            return self.closed, error
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
        return self.closed, error
