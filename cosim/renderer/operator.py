"""The operator view: up to nine camera thumbnails tiled beside a small map of
vehicle and target positions, one frame per period of the slowest camera
shown, written to ``cameras/operator.<ext>`` by the loop's process.

The map (``map_panel``) is north up, centred on what it shows, with its title,
a north arrow, a scale bar of a round length (``scale_bar``), a legend of its
symbols (``LEGEND``) and, for a few vehicles, their ids.

The frame at tick T shows each camera's frame at or before T, so it depends
only on the tick (not on when the render workers deliver).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.renderer.config import CamerasSpec
from cosim.renderer.targets import TargetSet
from cosim.renderer.video import open_video

if TYPE_CHECKING:
    from cosim.renderer.frame import WorldSpec
    from cosim.renderer.outputs import Stream
    from cosim.sync.participants import RunContext

_LAT, _LON = STATE_INDEX["lat_deg"], STATE_INDEX["lon_deg"]
#: the map's colours (BGR) and its legend: (symbol, colour, label)
AIRCRAFT_BGR, TARGET_BGR, TEXT_BGR, BACKGROUND = (0, 255, 255), (0, 0, 255), (230, 230, 230), 32
LEGEND = (("dot", AIRCRAFT_BGR, "vehicle"), ("cross", TARGET_BGR, "target"))
#: vehicles labelled with their ids on the map, at most
MAX_LABELLED = 6
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def scale_bar(px_per_m: float, width_px: int) -> tuple[float, int]:
    """A scale bar for a map of ``px_per_m``: a round length (1, 2 or 5 times a
    power of ten metres) drawn about a quarter of ``width_px`` long at most,
    and its length in pixels."""
    want_m = width_px / 4 / px_per_m
    base = 10.0 ** math.floor(math.log10(want_m))
    metres = max(m * base for m in (1, 2, 5) if m * base <= want_m)
    return metres, max(1, round(metres * px_per_m))


def _length(metres: float) -> str:
    return f"{metres / 1000:g} km" if metres >= 1000 else f"{metres:g} m"


def map_panel(width_px: int, height_px: int, vehicles_ne: np.ndarray, targets_ne: np.ndarray,
              ids: list[str] | None = None, target_ids: list[str] | None = None) -> np.ndarray:
    """The operator view's map (BGR): vehicles (``vehicles_ne``, (n, 2) north/east
    m) as dots and targets as crosses, each kind labelled with its ``ids`` /
    ``target_ids`` when there are at most ``MAX_LABELLED`` of it, north up, with
    a title, a north arrow, a scale bar and a legend."""
    w, h = width_px, height_px
    img = np.full((h, w, 3), BACKGROUND, np.uint8)
    pts = np.concatenate([np.reshape(vehicles_ne, (-1, 2)), np.reshape(targets_ne, (-1, 2))])
    cn, ce = (pts[:, 0].max() + pts[:, 0].min()) / 2, (pts[:, 1].max() + pts[:, 1].min()) / 2
    span = max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), 200.0) * 1.3
    scale = min(w, h) / span  # px per m
    fs = max(0.3, min(w, h) / 600)  # font scale
    lh = int(22 * fs) + 4  # a text line's height

    def px(nn: float, ee: float) -> tuple[int, int]:
        return int(w / 2 + (ee - ce) * scale), int(h / 2 - (nn - cn) * scale)

    mark = max(6, int(14 * fs))
    dot = max(3, mark // 2)

    def name(names: list[str] | None, k: int, n: int, at: tuple[int, int]) -> None:
        if names is not None and n <= MAX_LABELLED:
            cv2.putText(img, names[k], (at[0] + mark // 2 + 2, at[1] - mark // 3), _FONT,
                        fs * 0.9, TEXT_BGR, 1, cv2.LINE_AA)

    targets = np.reshape(targets_ne, (-1, 2))
    for k, (tn, te) in enumerate(targets):
        cv2.drawMarker(img, px(tn, te), TARGET_BGR, cv2.MARKER_TILTED_CROSS, mark, 2)
        name(target_ids, k, len(targets), px(tn, te))
    vehicles = np.reshape(vehicles_ne, (-1, 2))
    for k, (vn, ve) in enumerate(vehicles):
        cv2.circle(img, px(vn, ve), dot, AIRCRAFT_BGR, -1)
        name(ids, k, len(vehicles), px(vn, ve))
    # title, north arrow (top right), legend (bottom left), scale bar (bottom right)
    cv2.putText(img, "map, north up", (6, lh), _FONT, fs, TEXT_BGR, 1, cv2.LINE_AA)
    ax, ay = w - lh, 6
    cv2.arrowedLine(img, (ax, ay + 2 * lh), (ax, ay), TEXT_BGR, 1, cv2.LINE_AA, tipLength=0.35)
    cv2.putText(img, "N", (ax - lh, ay + lh), _FONT, fs, TEXT_BGR, 1, cv2.LINE_AA)
    box_w = int(110 * fs) + lh
    top = h - len(LEGEND) * lh - 6
    cv2.rectangle(img, (2, top - 4), (2 + box_w, h - 3), (60, 60, 60), -1)
    for i, (symbol, colour, label) in enumerate(LEGEND):
        cy = top + i * lh + lh // 2
        if symbol == "dot":
            cv2.circle(img, (6 + lh // 2, cy), dot, colour, -1)
        else:
            cv2.drawMarker(img, (6 + lh // 2, cy), colour, cv2.MARKER_TILTED_CROSS, mark, 2)
        cv2.putText(img, label, (8 + lh, cy + int(8 * fs)), _FONT, fs, TEXT_BGR, 1,
                    cv2.LINE_AA)
    metres, bar = scale_bar(scale, w)
    x1, y = w - 8, h - 8
    cv2.line(img, (x1 - bar, y), (x1, y), TEXT_BGR, 2)
    for x in (x1 - bar, x1):
        cv2.line(img, (x, y - 4), (x, y + 2), TEXT_BGR, 1)
    text = _length(metres)
    (tw, _), _ = cv2.getTextSize(text, _FONT, fs, 1)
    cv2.putText(img, text, (x1 - bar // 2 - tw // 2, y - 6), _FONT, fs, TEXT_BGR, 1,
                cv2.LINE_AA)
    return img


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
        self.ids = list(ctx.ids)
        self.target_ids = [t.id for t in world.targets]
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
        n, e, _ = self.frame.geodetic_to_ned(states[:, _LAT], states[:, _LON], 0.0)
        targets = np.column_stack([self.targets.north_m, self.targets.east_m])
        return map_panel(self.tw, self.th, np.column_stack([n, e]), targets, self.ids,
                         self.target_ids)

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
