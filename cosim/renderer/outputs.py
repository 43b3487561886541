"""What the cameras write into the run folder.

A *stream* (``Stream``) is one camera on one vehicle; its ``StreamWriter``
encodes its frames into ``cameras/<vehicle>_<camera>.<ext>`` and appends their
ground truth to ``cameras/<vehicle>_<camera>.gt.csv`` (flushed every frame),
with a sha256 of the raw frames when ``digest`` asks for one. The stills of
the ``camera`` command (``Stills``): the still of a stream is its next video
frame, written whole as ``stills/<vehicle>_<camera>_<NNNN>.png`` by whoever
renders it, with one line per still in ``stills/stills.jsonl`` (time, tick,
frame, pose, gimbal and the frame's ground truth, the same rows as the
``.gt.csv``) and a ``still`` event; at most ``MAX_STILLS`` a run (more are
counted, not taken). ``summary`` is the ``cameras`` section of
``summary.json``.

Owns these files and their formats: it renders nothing, starts no process and
decides no frame's time.
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.camera import CameraSpec
from cosim.renderer.datalink import DELIVERED_COLUMNS, Downlink
from cosim.renderer.truth import GT_COLUMNS, delivered
from cosim.renderer.video import open_video

log = logging.getLogger(__name__)

#: the most stills a run takes (more are counted in the summary, not taken)
MAX_STILLS = 10_000


@dataclass(frozen=True)
class Stream:
    """One camera on one vehicle: stream ``index`` of the run, its files."""

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


def _plain(v: Any) -> Any:
    """JSON for numpy scalars in ground-truth rows."""
    return v.item() if isinstance(v, np.generic) else str(v)


class StreamWriter:
    """One stream's video and ground-truth files."""

    def __init__(self, out_dir: Path, stream: Stream, codec: str, digest: bool) -> None:
        self.s = stream
        cam = stream.camera
        self.link = None  # the camera's downlink, if any: it writes the video
        if cam.datalink is not None:
            self.link = Downlink(str(out_dir / stream.video), cam.datalink, cam.width_px,
                                 cam.height_px)
        else:
            self.video = open_video(str(out_dir / stream.video), codec, cam.rate_hz,
                                    cam.width_px, cam.height_px)
        self.gt_file = open(out_dir / stream.ground_truth, "w", newline="")  # noqa: SIM115
        self.gt = csv.writer(self.gt_file)
        self.gt.writerow(GT_COLUMNS + (DELIVERED_COLUMNS if self.link else ()))
        self.gt_file.flush()
        self.frames = 0
        self.hash = hashlib.sha256() if digest else None

    def write(self, frame_no: int, time_s: float, img: np.ndarray,
              rows: list[dict[str, Any]], target_ids: list[str],
              ids: np.ndarray | None = None) -> None:
        """One frame and its ground truth; ``ids`` (the frame's target-id image)
        is needed with a downlink, which measures the delivered frame with it."""
        if self.hash is not None:
            self.hash.update(img.tobytes())
        head = [frame_no, f"{time_s:.6f}", self.s.vehicle, self.s.camera.name]
        if self.link is None:
            self.video.write(img)
            self.gt.writerows([*head, tid, *[_fmt(r[c]) for c in _GT_VALUES]]
                              for tid, r in zip(target_ids, rows))
        else:
            self._deliver(frame_no, time_s, img, rows, target_ids, ids, head)
        self.gt_file.flush()
        self.frames += 1

    def shown(self, img: np.ndarray) -> np.ndarray:
        """What an operator sees of the frame just written (``img``): with a
        downlink, the last frame it delivered (held between deliveries)."""
        return img if self.link is None else self.link.latest()

    def _deliver(self, frame_no: int, time_s: float, img: np.ndarray,
                 rows: list[dict[str, Any]], target_ids: list[str], ids: np.ndarray | None,
                 head: list[Any]) -> None:
        """Through the downlink: every ``every``-th frame encoded, decoded and
        measured; the others' delivered columns empty."""
        link = self.s.camera.datalink
        assert self.link is not None and link is not None
        extra: list[list[str]] = [["", "", ""]] * len(rows)
        if frame_no % link.every == 0:
            if ids is None:
                raise ValueError("a downlink's frame needs its target-id image")
            self.link.send(img)
            at = f"{time_s + link.latency_ms / 1000:.6f}"
            seen = any(r["in_view"] and r["pixels_on_target"] for r in rows)  # else 0, None
            measures = delivered(rows, img, self.link.latest(), ids) if seen else \
                [(0, None)] * len(rows)
            extra = [[at, str(n), _fmt(c)] for n, c in measures]
        self.gt.writerows([*head, tid, *[_fmt(r[c]) for c in _GT_VALUES], *x]
                          for tid, r, x in zip(target_ids, rows, extra))

    def close(self) -> dict[str, Any]:
        link = self.link.close() if self.link is not None else {}
        if self.link is None:
            self.video.release()
        self.gt_file.close()
        return {"frames": self.frames, **link,
                **({"frames_sha256": self.hash.hexdigest()} if self.hash is not None else {})}


_GT_VALUES = GT_COLUMNS[5:]  # the columns of a ground-truth row after its target


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4f}"
    return str(v)


class Stills:
    """The stills a run takes into ``out_dir``/stills (``name`` when one is due,
    ``done`` once its frame is rendered); ``events`` gets a ``still`` event each."""

    def __init__(self, out_dir: Path, physics_hz: float, events: Any) -> None:
        self.out_dir, self.physics_hz, self.events = out_dir, physics_hz, events
        self.taken = 0
        self.refused = 0
        #: what each still was taken at (its file -> the record without ground truth)
        self.meta: dict[str, dict[str, Any]] = {}
        self.log: Any = None

    def name(self, s: Stream, frame_no: int, tick: int, pose6: tuple[float, ...],
             gimbal: tuple[float, float] | None, source: str) -> str | None:
        """The file of a still taken at this frame of ``s`` (None: the limit)."""
        if self.taken >= MAX_STILLS:
            self.refused += 1
            if self.refused == 1:
                log.warning("cameras: %d stills taken, the most a run takes; more are counted "
                            "(stills_refused in summary.json), not taken", MAX_STILLS)
            return None
        if self.log is None:
            (self.out_dir / "stills").mkdir(exist_ok=True)
            self.log = open(self.out_dir / "stills" / "stills.jsonl", "a")  # noqa: SIM115
        self.taken += 1
        name = f"stills/{s.vehicle}_{s.camera.name}_{self.taken:04d}.png"
        time_s = tick / self.physics_hz
        self.meta[name] = {
            "file": name, "vehicle": s.vehicle, "camera": s.camera.name, "frame": frame_no,
            "tick": tick, "time_s": time_s,
            "pose": dict(zip(("lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "pitch_deg",
                              "yaw_deg"), pose6)),
            "gimbal": None if gimbal is None else {"pitch_deg": gimbal[0], "yaw_deg": gimbal[1]}}
        self.events.emit("still", tick, vehicle=s.vehicle, camera=s.camera.name, file=name,
                         frame=frame_no, source=source)
        return name

    def done(self, still: tuple[str, list[dict[str, Any]] | None] | None) -> None:
        """A still's line in stills.jsonl, once its frame is rendered."""
        if still is None:
            return
        name, truth = still
        record = self.meta.pop(name)
        record["targets"] = truth
        self.log.write(json.dumps(record, default=_plain) + "\n")
        self.log.flush()

    def close(self) -> None:
        if self.log is not None:
            self.log.close()

    def summary(self) -> dict[str, Any] | None:
        """The ``stills`` entry of the summary, if any was due."""
        if self.taken or self.refused:
            return {"taken": self.taken, "refused": self.refused, "log": "stills/stills.jsonl"}
        return None


def summary(streams: list[Stream], closed: dict[int, dict[str, Any]], codec: str,
            operator: dict[str, Any] | None, stills: dict[str, Any] | None) -> dict[str, Any]:
    """The ``cameras`` section of ``summary.json``: each stream with what its
    writer reported when closed (``closed``, by stream index), the operator
    view's and the stills' entries if any."""
    out: dict[str, Any] = {"streams": [], "codec": codec}
    for s in streams:
        c = s.camera
        out["streams"].append({
            "vehicle": s.vehicle, "camera": c.name, "video": s.video,
            "ground_truth": s.ground_truth, "rate_hz": c.rate_hz, "width_px": c.width_px,
            "height_px": c.height_px, "hfov_deg": c.hfov_deg, "vfov_deg": c.vfov_deg,
            "mount": c.mount, "pitch_deg": c.pitch_deg,
            **closed.get(s.index, {"frames": None})})
    if operator is not None:
        out["operator"] = operator
    if stills is not None:
        out["stills"] = stills
    return out
