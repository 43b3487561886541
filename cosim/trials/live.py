"""A live-console trial's run: its scenario paced at real time, its feeds
handed to the participant's page.

Owns the three pieces between a run and the browsers: ``FeedTap``, a run
participant (``cosim.sync.runner.Run(..., extra_participants=[...])``) that
takes the frames the cameras render anyway (``RunContext.frame_taps``),
JPEG-encodes those of the condition's feeds with their feed number and
frame number (also written in rows below the picture, ``with_counter``, for
the page to read back from what it decoded), and the aircraft's positions
a few times a second; where the
scenario sets a ``datalink:`` a feed is its delivered frames (each
``every``-th, as the downlink decoded it, numbered as the ground truth
numbers it) handed on its ``latency_ms`` later;
``Hub``, which fans each message out to every page watching the session
without ever waiting for one (a page that does not keep up loses its oldest
messages, and its dropped frames are counted); and ``LiveRun``, the run in
its own thread, into the session's own run folder, stopped when the
session ends or the server shuts down; where the condition allows tasking,
the run has a ``cosim.sync.inbox.CommandInbox`` through which the
participant's map commands (``command_spec``) reach the aircraft by the one
command path, each applied at the next exchange and logged in the run
folder's ``commands.jsonl``. It does not serve HTTP
(``live_routes``), parse the study (``live_study``) or store reports
(``store``).

The tap never changes the simulation: it reads the frames and states it is
handed and returns; the run's states are those of the same scenario run
without it.
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.errors import ConfigError
from cosim.trials.live_study import TASKING_ACTIONS, LiveCondition

log = logging.getLogger(__name__)

#: JPEG quality of the frames sent to the page
JPEG_QUALITY = 80
#: how often the map's positions are sent (Hz of simulated time)
MAP_RATE_HZ = 4.0
#: messages waiting for one page before its oldest are dropped
MAX_PENDING = 32
#: pages watching one session at once
MAX_WATCHERS = 4
#: rows below each frame sent that carry its number (``with_counter``)
COUNTER_ROWS = 32
_POS_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "yaw_deg")]
_POSE_COLS = [STATE_INDEX[c] for c in ("lat_deg", "lon_deg", "alt_msl_m", "roll_deg",
                                       "pitch_deg", "yaw_deg")]
#: how far (m, horizontally) a footprint's corner above the horizon is drawn
FOOTPRINT_RANGE_M = 2000.0


class Watcher:
    """One page's queue of messages (only ever touched in the event loop).
    Full: the oldest message goes, and a frame among them counts as dropped."""

    def __init__(self, max_pending: int = MAX_PENDING) -> None:
        self.max_pending = max_pending
        self.pending: deque[tuple[str, str]] = deque()
        self.ready = asyncio.Event()
        self.sent_frames = 0
        self.dropped_frames = 0
        self.closed = False

    def put(self, kind: str, text: str) -> None:
        if len(self.pending) >= self.max_pending:
            old, _ = self.pending.popleft()
            if old == "frame":
                self.dropped_frames += 1
        self.pending.append((kind, text))
        self.ready.set()

    async def get(self) -> tuple[str, str]:
        """The next message; ("end", ...) once the session's run is over and
        nothing is left."""
        while not self.pending:
            if self.closed:
                return "end", "{}"
            self.ready.clear()
            await self.ready.wait()
        kind, text = self.pending.popleft()
        if kind == "frame":
            self.sent_frames += 1
        return kind, text


class Hub:
    """The messages of one live session, fanned out to its watchers. ``publish``
    may be called from any thread and never blocks (the run's thread calls it);
    the watchers live in the event loop ``loop``."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.watchers: list[Watcher] = []
        self.published_frames = 0
        #: the messages a page needs on arrival: the feeds, the map's last positions
        self.hello: str = "{}"
        self.last_states: str | None = None
        self.ended = False
        #: frames dropped for pages that have gone
        self.dropped_gone = 0
        #: each feed's last frame number sent to the watchers
        self.last_frame: dict[int, int] = {}
        #: each aircraft's last map command (a ``command`` message), for pages arriving
        self.last_commands: dict[str, str] = {}

    def publish(self, kind: str, payload: dict[str, Any], delay_s: float = 0.0) -> None:
        """Send ``payload`` to every watcher, ``delay_s`` from now (a
        datalink's latency); a ``frame`` payload has its ``feed`` and ``frame``."""
        text = json.dumps(payload, separators=(",", ":"))
        if kind == "frame":
            self.published_frames += 1
        try:
            self.loop.call_soon_threadsafe(self._later, delay_s, kind, text,
                                           payload.get("feed"), payload.get("frame"))
        except RuntimeError:  # the loop is closed: the server is going
            pass

    def _later(self, delay_s: float, *args: Any) -> None:
        if delay_s > 0:
            self.loop.call_later(delay_s, self._fan, *args)
        else:
            self._fan(*args)

    def end(self, delay_s: float = 0.0) -> None:
        """No more messages (after those published up to ``delay_s`` from now)."""
        try:
            self.loop.call_soon_threadsafe(self._later, delay_s, "end", "", None, None)
        except RuntimeError:
            pass

    def _fan(self, kind: str, text: str, feed: int | None, frame: int | None) -> None:
        if kind == "end":
            self._end()
            return
        if kind == "states":
            self.last_states = text
        elif kind == "frame" and feed is not None and frame is not None:
            self.last_frame[feed] = frame
        for w in self.watchers:
            w.put(kind, text)

    def command(self, payload: dict[str, Any]) -> None:
        """A map command taken (in the event loop): to every page, and kept as
        its aircraft's last for pages that come later (a reload)."""
        text = json.dumps(payload, separators=(",", ":"))
        self.last_commands[str(payload["vehicle"])] = text
        for w in self.watchers:
            w.put("command", text)

    def _end(self) -> None:
        self.ended = True
        for w in self.watchers:
            w.closed = True
            w.ready.set()

    def watch(self, max_pending: int = MAX_PENDING) -> Watcher:
        """A new watcher (in the event loop), primed with the feeds and the map."""
        if len(self.watchers) >= MAX_WATCHERS:
            raise ConfigError(f"{MAX_WATCHERS} pages already watch this session")
        w = Watcher(max_pending)
        w.put("hello", self.hello)
        if self.last_states is not None:
            w.put("states", self.last_states)
        for text in self.last_commands.values():
            w.put("command", text)
        w.closed = self.ended
        self.watchers.append(w)
        return w

    def leave(self, w: Watcher) -> None:
        if w in self.watchers:
            self.watchers.remove(w)
            self.dropped_gone += w.dropped_frames

    @property
    def dropped_frames(self) -> int:
        """Frames dropped for slow pages, those still watching and those gone."""
        return self.dropped_gone + sum(w.dropped_frames for w in self.watchers)


def with_counter(bgr: np.ndarray, frame_no: int) -> np.ndarray:
    """The frame (BGR) with ``COUNTER_ROWS`` rows below it that carry its
    number (mod 2**16) for the page to read back from what it decoded: bit
    ``b`` is white (1) or black (0) in block ``b % 8`` (each ``width // 8``
    px wide) of band ``b // 8`` (each 16 rows). The page draws the frame
    without them."""
    h, w = bgr.shape[:2]
    out = np.zeros((h + COUNTER_ROWS, w, 3), np.uint8)
    out[:h] = bgr[:, :, :3]
    bw = w // 8
    for b in range(16):
        if (frame_no >> b) & 1:
            band, col = divmod(b, 8)
            out[h + 16 * band:h + 16 * (band + 1), col * bw:(col + 1) * bw] = 255
    return out


def read_counter(img: np.ndarray) -> int:
    """The number ``with_counter`` wrote into ``img`` (its last
    ``COUNTER_ROWS`` rows; BGR or grey), each block read at its centre."""
    strip = img[-COUNTER_ROWS:]
    bw = strip.shape[1] // 8
    value = 0
    for b in range(16):
        band, col = divmod(b, 8)
        px = strip[16 * band + 8, col * bw + bw // 2]
        if float(np.mean(px)) >= 128:
            value |= 1 << b
    return value


class FeedTap:
    """The run participant that hands the condition's feeds and the aircraft's
    positions to a ``Hub`` (see the module docstring)."""

    name = "live_console"

    def __init__(self, condition: LiveCondition, hub: Hub) -> None:
        self.condition, self.hub = condition, hub
        self.index = {(f.vehicle, f.camera): k for k, f in enumerate(condition.feeds)}
        self.frames_sent = 0
        #: each downlinked feed's (every how many rendered frames one is
        #: delivered, its latency in s)
        self.links: dict[int, tuple[int, float]] = {}
        self.encode_s = 0.0
        self.every = 1

    def prepare(self, ctx: Any) -> None:
        """Before any participant starts: every camera's frames, at full size."""
        if ctx.frame_taps is not None:
            ctx.frame_taps.append((self.frame, None))

    def start(self, ctx: Any) -> None:
        self.ctx = ctx
        # a whole number of exchanges (the ticks on_exchange sees)
        self.every = ctx.control_every * max(1, round(ctx.physics_hz / MAP_RATE_HZ
                                                      / ctx.control_every))
        self.ground_m = ctx.scenario.origin.ground_alt_m
        self.ids = list(ctx.ids)
        from cosim.vehicles import get_class

        scn = ctx.scenario
        row = {v.id: i for i, v in enumerate(scn.vehicles)}
        cam_of = {c.name: c for c in scn.sections["cameras"].views}
        #: each feed's vehicle row, camera and the camera's height above the vehicle's
        self.feed_cams = [(row[f.vehicle], cam_of[f.camera],
                           get_class(scn.vehicles[row[f.vehicle]].vehicle_class).camera_height_m)
                          for f in self.condition.feeds]
        cams = {c.name: c for c in ctx.scenario.sections["cameras"].views}
        for k, f in enumerate(self.condition.feeds):
            link = cams[f.camera].datalink
            if link is not None:
                self.links[k] = (int(link.every), float(link.latency_ms) / 1000.0)

    def frame(self, vehicle: str, camera: str, time_s: float, bgr: np.ndarray) -> None:
        k = self.index.get((vehicle, camera))
        if k is None:
            return
        import cv2

        feed = self.condition.feeds[k]
        frame_no = round(time_s * feed.rate_hz)
        every, latency_s = self.links.get(k, (1, 0.0))
        if frame_no % every:  # between a downlink's deliveries: its last frame held
            return
        t0 = time.perf_counter()
        ok, jpg = cv2.imencode(".jpg", with_counter(bgr, frame_no),
                               [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        self.encode_s += time.perf_counter() - t0
        if not ok:
            log.warning("feed %s: frame at %.2f s could not be JPEG-encoded", feed.name, time_s)
            return
        self.hub.publish("frame", {"feed": k, "frame": frame_no, "time_s": round(time_s, 6),
                                   "made_ms": round(time.time() * 1000.0, 1),
                                   "jpeg": base64.b64encode(jpg.tobytes()).decode()},
                         delay_s=latency_s)
        self.frames_sent += 1

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        if tick % self.every:
            return
        s = states[:, _POS_COLS]
        ok = np.isfinite(s[:, 0]) & np.isfinite(s[:, 1])
        frame = self.ctx.frame
        n, e, _ = frame.geodetic_to_ned(np.where(ok, s[:, 0], frame.lat_deg),
                                        np.where(ok, s[:, 1], frame.lon_deg),
                                        np.where(ok, s[:, 2], frame.alt_m))
        msg: dict[str, Any] = {
            "time_s": round(tick / self.ctx.physics_hz, 6),
            "vehicles": [{"id": self.ids[i], "north_m": round(float(n[i]), 2),
                          "east_m": round(float(e[i]), 2),
                          "alt_agl_m": round(float(s[i, 2]) - self.ground_m, 2),
                          "yaw_deg": round(float(s[i, 3]), 1)}
                         for i in np.flatnonzero(ok).tolist()]}
        if "footprints" in self.condition.map_layers:
            msg["footprints"] = self._footprints(states, n, e, ok)
        self.hub.publish("states", msg)

    def _footprints(self, states: np.ndarray, n: np.ndarray, e: np.ndarray,
                    ok: np.ndarray) -> list[dict[str, Any]]:
        """Each feed's ground footprint (its image's corners on flat ground,
        north/east m in the scenario frame; a gimbal camera's as the cameras
        posed it at this exchange: its commanded angles, or a ``look_at``'s)."""
        from cosim.core.camera import camera_pose, footprint

        out = []
        angles_of = self.ctx.gimbal_angles
        for k, (r, cam, lift_m) in enumerate(self.feed_cams):
            if not ok[r]:
                continue
            la, lo, alt, roll, pitch, yaw = (float(x) for x in states[r, _POSE_COLS])
            feed = self.condition.feeds[k]
            gimbal = None if angles_of is None else angles_of(feed.vehicle, feed.camera)
            pose = camera_pose(cam, la, lo, alt + lift_m, roll, pitch, yaw, self.ground_m,
                               gimbal=gimbal)
            ne = footprint(cam, pose, FOOTPRINT_RANGE_M) + [float(n[r]), float(e[r])]
            out.append({"feed": k, "corners_ne_m": np.round(ne, 1).tolist()})
        return out

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        return {"feeds": [f.name for f in self.condition.feeds], "frames_sent": self.frames_sent,
                "jpeg_encode_s": round(self.encode_s, 3)}

    def after_run(self, out_dir: Path) -> None:
        return None


def _targets(scn: Any) -> list[dict[str, Any]]:
    """The scenario's targets where they start (north/east m in its frame)."""
    frame = scn.origin.frame
    out = []
    for t in scn.world.targets:
        if t.north_m is None:
            n, e, _ = frame.geodetic_to_ned(t.lat_deg, t.lon_deg, scn.origin.ground_alt_m)
        else:
            n, e = t.north_m, t.east_m
        out.append({"id": t.id, "north_m": round(float(n), 2), "east_m": round(float(e), 2)})
    return out


def command_spec(action: str, north_m: float, east_m: float,
                 orbit_radius_m: float) -> dict[str, Any]:
    """The command (the vocabulary of ``cosim.guidance.commands``, as a
    schedule item's ``command:``) of a map action at a point (north/east m
    in the scenario frame): ``go`` flies there, ``orbit`` circles it at
    ``orbit_radius_m``, ``look`` points the gimbal cameras at it (on the
    ground)."""
    at = {"north_m": float(north_m), "east_m": float(east_m)}
    if action == "go":
        return {"goto": at}
    if action == "orbit":
        return {"loiter": {"center": at, "radius_m": float(orbit_radius_m)}}
    if action == "look":
        return {"gimbal": {"look_at": at}}
    raise ConfigError(f"action: expected one of {', '.join(TASKING_ACTIONS)}, got {action!r}")


class LiveRun:
    """One session's live run: the condition's scenario, paced at ``realtime``
    (1.0: real time), into ``out_dir``, in a thread of its own. ``stop`` ends
    it early; ``wait`` waits for it (both safe to call twice). Where the
    condition allows tasking, ``command`` hands a map command to the run
    (``on_applied(entry)`` is called from the run's thread with each
    command's log entry once applied)."""

    def __init__(self, condition: LiveCondition, out_dir: Path, hub: Hub, *,
                 realtime: float = 1.0, backend: str = "process",
                 workers: int | None = None,
                 on_applied: Callable[[dict[str, Any]], None] | None = None) -> None:
        from cosim.scenario import load_scenario
        from cosim.sync.runner import Run

        scn = load_scenario(condition.scenario)
        if condition.duration_s is not None:
            scn = scn.with_duration(condition.duration_s)
        self.condition, self.out_dir, self.hub = condition, out_dir, hub
        self.tap = FeedTap(condition, hub)
        hub.hello = json.dumps({"condition": condition.id, "duration_s": scn.duration_s,
                                "map": list(condition.map_layers),
                                "targets": _targets(scn) if "targets" in condition.map_layers
                                else [],
                                "feeds": [{"feed": k, "name": f.name, "width_px": f.width_px,
                                           "height_px": f.height_px, "rate_hz": f.rate_hz}
                                          for k, f in enumerate(condition.feeds)],
                                "vehicles": [v.id for v in scn.vehicles],
                                "tasking": {"actions": list(condition.tasking),
                                            "vehicles": list(condition.taskable),
                                            "look_vehicles": list(condition.lookers),
                                            "orbit_radius_m": condition.orbit_radius_m}})
        extra: list[Any] = [self.tap]
        #: the participant's commands' way into the run (None: no tasking)
        self.inbox: Any = None
        if condition.tasking:
            from cosim.sync.inbox import CommandInbox

            self.inbox = CommandInbox(source="operator", on_applied=on_applied)
            extra.append(self.inbox)
        self.run = Run(scn, out_dir, backend=backend, workers=workers, realtime=realtime,
                       extra_participants=extra)
        self.result: Any = None
        self.error: BaseException | None = None
        #: the last timing the participant's page reported (``live_routes``)
        self.page_timing: dict[str, Any] | None = None
        self.started_s = time.time()
        self._thread = threading.Thread(target=self._main, name=f"live-{out_dir.name}",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _main(self) -> None:
        try:
            self.result = self.run.run()
            if self.result.error is not None:
                self.error = self.result.error
                log.error("live run %s ended: %s", self.out_dir, self.result.error)
        except Exception as e:  # noqa: BLE001 - said on the experimenter's page
            self.error = e
            log.exception("live run %s failed", self.out_dir)
        finally:  # after the frames still held back by a downlink's latency
            self.hub.end(max((lat for _, lat in self.tap.links.values()), default=0.0))

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def command(self, vehicle: str, action: str, north_m: float, east_m: float) -> int:
        """Hand the run the map command ``action`` for ``vehicle`` at a point
        (north/east m in the scenario frame); its sequence number. A
        ``ConfigError`` if the condition does not allow it, or the inbox
        refuses it (an unknown vehicle, a full queue, a run that is over)."""
        c = self.condition
        if self.inbox is None or action not in c.tasking:
            allowed = ", ".join(c.tasking) or "none"
            raise ConfigError(f"action: {str(action)[:40]!r} is not allowed in condition "
                              f"{c.id!r} (allowed: {allowed})")
        if vehicle not in c.taskable:
            raise ConfigError(f"vehicle: {str(vehicle)[:40]!r} cannot be tasked in condition "
                              f"{c.id!r} (it may task: {', '.join(c.taskable)[:400]})")
        if action == "look" and vehicle not in c.lookers:
            raise ConfigError(f"vehicle: {vehicle} has no camera on a gimbal to point (those "
                              f"that do: {', '.join(c.lookers)[:400]})")
        seq: int = self.inbox.submit(vehicle, command_spec(action, north_m, east_m,
                                                           c.orbit_radius_m))
        return seq

    def stop(self, reason: str = "session_ended") -> None:
        self.run.stop(reason)

    def wait(self, timeout_s: float | None = None) -> bool:
        """True once the run is over (within ``timeout_s``)."""
        if self._thread.ident is None:
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def status(self) -> dict[str, Any]:
        r = self.result
        return {"running": self.running, "out_dir": str(self.out_dir),
                # held by Run.pause (a SAGAT freeze waiting for its answers)
                "paused": self.running and self.run.paused,
                "stop_reason": r.stop_reason if r is not None else None,
                "error": str(self.error)[:500] if self.error is not None else None,
                "frames_published": self.hub.published_frames,
                "frames_dropped": self.hub.dropped_frames,
                "watchers": len(self.hub.watchers), "page_timing": self.page_timing}
