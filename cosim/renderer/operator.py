"""The operator view: up to nine camera thumbnails tiled beside a small map of
vehicle and target positions, one frame per period of the slowest camera
shown, written to ``cameras/operator.<ext>`` by the loop's process.

The frame at tick T shows each camera's frame at or before T, so it depends
only on the tick (not on when the render workers deliver).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from cosim.renderer.config import CamerasSpec
from cosim.renderer.targets import TargetSet
from cosim.renderer.video import open_video
from cosim.vehicles.spec import STATE_INDEX

if TYPE_CHECKING:
    from cosim.renderer.frame import WorldSpec
    from cosim.renderer.participant import Stream
    from cosim.sync.participants import RunContext

_LAT, _LON = STATE_INDEX["lat_deg"], STATE_INDEX["lon_deg"]


class OperatorView:
    MAX_TILES = 9

    @staticmethod
    def tile_size(spec: CamerasSpec, n_streams: int) -> tuple[int, int]:
        n = min(n_streams, OperatorView.MAX_TILES) + 1  # + the map
        cols = math.ceil(math.sqrt(n))
        w = spec.operator_width_px // cols // 2 * 2
        return w, w * 3 // 4 // 2 * 2

    def __init__(self, spec: CamerasSpec, streams: list[Stream], world: WorldSpec,
                 ctx: RunContext, ext: str) -> None:
        self.shown = [s for s in streams if s.thumb_px is not None]
        self.tw, self.th = self.tile_size(spec, len(streams))
        n = len(self.shown) + 1
        self.cols = math.ceil(math.sqrt(n))
        self.rows = math.ceil(n / self.cols)
        # one composite per exchange at most: frames between exchanges are not shown
        self.every = max(max(s.camera.frame_every for s in self.shown), ctx.control_every)
        self.rate_hz = ctx.physics_hz / self.every
        self.path = f"cameras/operator.{ext}"
        self.size = (self.cols * self.tw, self.rows * self.th)
        self.video = open_video(str(ctx.out_dir / self.path), spec.codec, self.rate_hz,
                                *self.size)
        self.frame = ctx.frame
        self.targets = TargetSet(world.targets, ctx.frame, world.ground_alt_m)
        self.thumbs: dict[tuple[int, int], np.ndarray] = {}
        self.pending: list[tuple[int, np.ndarray]] = []  # (tick, map image)
        self.frames = 0

    def thumb(self, stream: int, frame_no: int, img: np.ndarray | None) -> None:
        if img is not None:
            self.thumbs[(stream, frame_no)] = img
            self._flush()

    def at_exchange(self, tick: int, states: np.ndarray) -> None:
        if tick % self.every == 0:
            self.pending.append((tick, self._map(states)))
            self._flush()

    def _map(self, states: np.ndarray) -> np.ndarray:
        img = np.full((self.th, self.tw, 3), 32, np.uint8)
        n, e, _ = self.frame.geodetic_to_ned(states[:, _LAT], states[:, _LON], 0.0)
        pn = np.concatenate([n, self.targets.north_m])
        pe = np.concatenate([e, self.targets.east_m])
        cn, ce = (pn.max() + pn.min()) / 2, (pe.max() + pe.min()) / 2
        span = max(pn.max() - pn.min(), pe.max() - pe.min(), 200.0) * 1.2
        scale = min(self.tw, self.th) / span

        def px(nn: float, ee: float) -> tuple[int, int]:
            return int(self.tw / 2 + (ee - ce) * scale), int(self.th / 2 - (nn - cn) * scale)

        for tn, te in zip(self.targets.north_m, self.targets.east_m):
            cv2.drawMarker(img, px(tn, te), (0, 0, 255), cv2.MARKER_TILTED_CROSS, 8, 2)
        for vn, ve in zip(n, e):
            cv2.circle(img, px(vn, ve), 4, (0, 255, 255), -1)
        cv2.putText(img, f"{span:.0f} m", (4, self.th - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (200, 200, 200), 1)
        return img

    def _flush(self) -> None:
        while self.pending:
            tick, map_img = self.pending[0]
            keys = [(s.index, tick // s.camera.frame_every) for s in self.shown]
            if any(k not in self.thumbs for k in keys):
                return
            canvas = np.zeros((self.size[1], self.size[0], 3), np.uint8)
            tiles = [self.thumbs[k] for k in keys] + [map_img]
            for i, t in enumerate(tiles):
                r, c = divmod(i, self.cols)
                canvas[r * self.th:(r + 1) * self.th, c * self.tw:(c + 1) * self.tw] = t
            self.video.write(canvas)
            self.frames += 1
            self.pending.pop(0)
            used = dict(keys)  # stream -> frame number shown
            for k in [k for k in self.thumbs if k[1] <= used.get(k[0], -1)]:
                del self.thumbs[k]

    def close(self) -> dict[str, Any]:
        self.video.release()
        return {"video": self.path, "frames": self.frames, "rate_hz": self.rate_hz,
                "width_px": self.size[0], "height_px": self.size[1]}
