"""The image detector on board: every frame the search aircraft's cameras
render is searched for fires (``image_detect.detect_fires``), as an
aircraft would search its own raw frames before any video encoding.

Each frame's blobs are matched against where the fires are in that frame
(``sensing.fire_truth`` from the state rows of the frame's tick, the
renderer's pose and boxes): a blob on the fire or on a decoy hits it, any
other blob is a false alarm on the ground. A fire counts as found by a
camera once hit in ``dwell`` frames in a row. Decoys are fires to the
detector (it sees only colours), so a decoy found is its false alarm.
Only cameras whose frames fall on exchanges take part (the rows of other
ticks are not kept), and not gimbals (their angles are the cameras').
"""

from __future__ import annotations

import logging
import math
from collections import defaultdict
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.renderer.frame import probe_offsets
from cosim.search import sensing
from cosim.search.image_detect import detect_fires, match_blobs
from cosim.search.spec import dwell_frames

log = logging.getLogger(__name__)

#: a blob this far (px) outside a fire's box still hits it
MAX_DIST_PX = 3.0


class ImageSearch:
    def __init__(self, part: Any, views: list[Any]) -> None:
        self.part = part  # the SearchParticipant (its fires, rows, frame)
        self.views = {c.name: c for c in views}
        self.every = 0  # the ticks any view takes a frame at: multiples of this
        for c in views:
            self.every = math.gcd(self.every, c.frame_every)
        #: a view's frames still being rendered reach back this far (ticks)
        cams = part.scn.sections["cameras"]
        self.keep = (cams.max_in_flight + 2) * max(c.frame_every for c in views)
        #: frames in a row a fire must be hit in, per view (its rate's share of dwell_s)
        self.dwell = {c.name: dwell_frames(part.spec.detection.dwell_s, c.rate_hz)
                      for c in views}
        self.rows: dict[int, np.ndarray] = {}  # tick -> the search rows' states
        self.row_of: dict[str, int] = {}  # vehicle id -> position in the search rows
        self.run: dict[tuple[str, str, str], int] = defaultdict(int)
        self.first: dict[str, dict[str, Any]] = {}
        self.frames = self.blobs = self.false_alarm_frames = self.no_pose = 0
        self.last = -1  # the last exchange's tick remembered
        #: frames that came before their tick's rows: (vehicle, camera, time_s, bgr)
        self.early: list[tuple[str, str, float, np.ndarray]] = []

    def start(self, ids: list[str]) -> None:
        self.row_of = {ids[int(r)]: i for i, r in enumerate(self.part.rows)}

    def remember(self, tick: int, st: np.ndarray) -> None:
        """The search rows at exchange ``tick``; then the frames that came
        before their tick's rows did (rendered in this process, at the
        cameras' turn of this exchange)."""
        self.last = tick
        if tick % self.every == 0:
            self.rows[tick] = st.copy()
            for old in [t for t in self.rows if t < tick - self.keep]:
                del self.rows[old]
        early, self.early = self.early, []
        for args in early:
            self.tap(*args)

    def tap(self, vehicle: str, camera: str, time_s: float, bgr: np.ndarray) -> None:
        cam = self.views.get(camera)
        i = self.row_of.get(vehicle)
        if cam is None or i is None:
            return
        p = self.part
        tick = round(time_s * p.ctx.physics_hz)
        st = self.rows.get(tick)
        if st is None:
            if tick > self.last:  # its rows come at this exchange's turn: kept till then
                self.early.append((vehicle, camera, time_s, bgr.copy()))
            else:
                self.no_pose += 1
            return
        self.frames += 1
        row = st[i].copy()
        lift = p.lift_m.get(vehicle, 0.0)
        row[STATE_INDEX["alt_msl_m"]] += lift
        pose = sensing.pose_of(cam, row, STATE_INDEX, p.ground)
        origins = p.targets.origins_in(pose.local, pose.local_ecef_m)
        now = [f.at(time_s) for f in p.fire_specs]
        offsets = probe_offsets(now)
        scale = bgr.shape[1] / cam.width_px  # taps may get smaller frames
        truth = []
        for j, f in enumerate(now):
            seen = sensing.fire_truth(cam, pose, origins[j] + offsets[j, :8])
            if seen.bbox is None:
                continue
            x0, y0, x1, y1 = (v * scale for v in seen.bbox)
            truth.append({"target": f.id, "in_view": seen.in_view, "bbox_x0_px": x0,
                          "bbox_y0_px": y0, "bbox_x1_px": x1, "bbox_y1_px": y1,
                          "center_x_px": None, "center_y_px": None})
        blobs = detect_fires(bgr)
        self.blobs += len(blobs)
        m = match_blobs(blobs, truth, MAX_DIST_PX)
        if m.false_alarms:
            self.false_alarm_frames += 1
        hit = set(m.detected)
        for j, f in enumerate(now):
            key = (vehicle, camera, f.id)
            self.run[key] = self.run[key] + 1 if f.id in hit else 0
            if self.run[key] >= self.dwell[camera] and f.id not in self.first:
                self.first[f.id] = {"fire": f.id, "decoy": bool(p.decoy[j]),
                                    "time_s": round(time_s, 3), "vehicle": vehicle,
                                    "camera": camera}
                p.ctx.events.emit("fire_seen_in_image", tick, vehicle=vehicle, camera=camera,
                                  fire=f.id, decoy=bool(p.decoy[j]))

    def summary(self) -> dict[str, Any]:
        target = next((d for d in self.first.values() if not d["decoy"]), None)
        return {"cameras": sorted(self.views), "frames": self.frames, "blobs": self.blobs,
                "target": {"detected": target is not None,
                           "time_to_detect_s": target["time_s"] if target else None},
                "decoys_detected": sum(1 for d in self.first.values() if d["decoy"]),
                "frames_with_false_alarms": self.false_alarm_frames,
                "frames_without_pose": self.no_pose + len(self.early),
                "first_detections": sorted(self.first.values(), key=lambda d: d["time_s"])}
