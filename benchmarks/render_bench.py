"""Camera rendering benchmark (not a test).

1. ms CPU per 640x480 frame on one core, including the ground-truth rows and
   mp4v encoding (a nadir camera at 100 m AGL, 51 m/s over the flyover
   targets, tile generation included as it happens in flight), frames/s per
   core, and where the time goes (encoding, of it the codec library's own
   call; OpenCV's warp of the ground; new ground tiles; the rest, ours):
   first with an empty ground tile cache (every tile generated: the cost of
   a first run over new ground), then again over the same ground with the
   tiles on disk (a repeated run or the next run of a sweep);
2. a real run (ground tile cache empty at start): N uav700s each with a 10 Hz
   640x480 nadir camera for D s through
   the lockstep loop (render pool), its real-time factor (the loop's, and end
   to end including the render pool's drain) and the CPU seconds all processes
   spent per simulated second (what a machine with that many idle cores needs
   for 1x; the shared machine's wall clock depends on others' load).

    python benchmarks/render_bench.py [--frames 200] [--repeat 1] [--vehicles 20]
        [--duration-s 10] [--backend process|inline] [--workers N] [--render-workers N]
        [--codec mp4v|h264|mjpg] [--sensor YAML] [--datalink YAML] [--haze-km V]
        [--trees flat|3d|none]

With ``--datalink`` the camera runs at 15 Hz and its frames go through that
downlink (encoded, decoded back where a target is in view, measured, in place
of the video writer): its part (encoding and decoding) is printed apart.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2

from cosim.core.cache import CACHE_ENV  # the whole cache folder (ground tiles: ground/)
from cosim.core.camera import CameraSpec, DatalinkSpec, SensorSpec
from cosim.core.geo import LocalFrame
from cosim.renderer.outputs import Stream
from cosim.renderer.render_pool import RenderWorker
from cosim.renderer.video import EXTENSIONS
from cosim.scenario import load_scenario, parse_scenario
from cosim.sync.runner import run_scenario
from cosim.world.atmosphere import AtmosphereSpec

REPO = Path(__file__).resolve().parent.parent


class _Timed:
    """Wraps an object's method and adds up the CPU time spent in it."""

    def __init__(self, fn: Any) -> None:
        self.fn, self.cpu_s, self.calls = fn, 0.0, 0

    def __call__(self, *a: Any, **kw: Any) -> Any:
        c = time.process_time()
        try:
            return self.fn(*a, **kw)
        finally:
            self.cpu_s += time.process_time() - c
            self.calls += 1


class _Video:
    def __init__(self, video: Any) -> None:
        self.video, self.write = video, _Timed(video.write)
        self.codec: _Encoder | None = None  # the codec library's own encode (PyAV's writers)
        if hasattr(video, "stream"):
            self.codec = video.stream = _Encoder(video.stream)

    def release(self) -> None:
        self.video.release()


class _Encoder:
    """A PyAV stream whose ``encode`` (FFmpeg's encoder) is timed."""

    def __init__(self, stream: Any) -> None:
        self.encode = _Timed(stream.encode)


def per_frame(frames: int, cache_dir: str, codec: str = "mp4v",
              sensor: SensorSpec | None = None, datalink: DatalinkSpec | None = None,
              haze_km: float | None = None, trees: str = "flat") -> dict[str, float]:
    """One camera's frames; cosim's cache folder (its ground tiles in
    ``ground/``) in ``cache_dir``; ``sensor``: the camera's sensor and lens,
    ``datalink`` its downlink, ``haze_km`` the atmosphere's visibility (each's
    cost timed apart; the haze's: the ground's, the faces' is in the rest);
    ``trees``: the procedural ground's (``ground: {trees: ...}``)."""
    os.environ[CACHE_ENV] = cache_dir
    cv2.setNumThreads(1)
    scn = load_scenario(REPO / "scenarios/cameras/flyover.yaml", check_properties=False)
    from cosim.renderer.frame import WorldSpec

    air = AtmosphereSpec(haze_km) if haze_km else None
    ws = WorldSpec(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m, scn.seed,
                   120.0, dataclasses.replace(scn.world.ground, trees=trees), scn.world.targets,
                   atmosphere=air)
    cam: CameraSpec = dataclasses.replace(scn.sections["cameras"].views[0], sensor=sensor,
                                          datalink=datalink)
    frame = LocalFrame(scn.origin.lat_deg, scn.origin.lon_deg, scn.origin.ground_alt_m)
    poses = []
    for i in range(frames):
        t = i / 10.0
        la, lo = frame.place(-150 + 51.4 * t, 0.0, scn.origin.ground_alt_m + 100)
        poses.append((float(la), float(lo), scn.origin.ground_alt_m + 100, 0.0, 0.0, 0.0))
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "cameras").mkdir()
        s = Stream(0, "uav1", 0, cam, f"cameras/b.{EXTENSIONS[codec]}", "cameras/b.gt.csv", None)
        w = RenderWorker(ws, [s], Path(d), codec, False)
        link = w.writers[0].link
        link_fns: tuple[_Timed, ...] = ()
        if link is not None:  # the downlink writes the video (encode; decode when looked at)
            send_fn, latest_fn = _Timed(link.send), _Timed(link.latest)
            link.send = send_fn  # type: ignore[method-assign]
            link.latest = latest_fn  # type: ignore[method-assign]
            link_fns = (send_fn, latest_fn)
        else:
            video = _Video(w.writers[0].video)
            w.writers[0].video = video
        ground = w.world.ground
        sensor_fn = _Timed(w.sensors[0].apply) if w.sensors else None
        if sensor_fn is not None:
            w.sensors[0].apply = sensor_fn  # type: ignore[method-assign]
        haze = w.world.haze
        haze_fn = _Timed(haze.ground) if haze is not None else None
        if haze is not None:
            haze.ground = haze_fn  # type: ignore[method-assign,assignment]
        tiles = _Timed(ground._make_tile)
        ground._make_tile = tiles  # type: ignore[method-assign]
        warp_fn = cv2.warpPerspective
        warp = cv2.warpPerspective = _Timed(warp_fn)  # the ground's warp (frame.py)
        try:
            cpu0, wall0 = time.process_time(), time.perf_counter()
            for i, pose in enumerate(poses):
                w.render(0, i, i * 12, pose, motion=(51.4, 0.0, 0.0, 0.0, 0.0, 0.0))
            cpu = time.process_time() - cpu0
            wall = time.perf_counter() - wall0
        finally:
            cv2.warpPerspective = warp_fn
        w.close()
    codec_s = video.codec.encode.cpu_s if link is None and video.codec else float("nan")
    encode_s = video.write.cpu_s if link is None else 0.0
    return {"cpu_ms": cpu / frames * 1000, "wall_ms": wall / frames * 1000,
            "encode_ms": encode_s / frames * 1000,
            "datalink_ms": sum(f.cpu_s for f in link_fns) / frames * 1000,
            "codec_ms": codec_s / frames * 1000, "warp_ms": warp.cpu_s / frames * 1000,
            "tiles_ms": tiles.cpu_s / frames * 1000, "tiles": tiles.calls,
            "sensor_ms": sensor_fn.cpu_s / frames * 1000 if sensor_fn else 0.0,
            "haze_ms": haze_fn.cpu_s / frames * 1000 if haze_fn else 0.0,
            "tile_ms": tiles.cpu_s / max(tiles.calls, 1) * 1000,
            "tiles_generated": ground.tiles_made, "tiles_from_disk": ground.tiles_loaded}


def _camera(key: str, text: str, rate_hz: float = 10.0) -> CameraSpec:
    """The flyover's camera at ``rate_hz`` with ``key: text`` (a mapping), read
    as a scenario's camera would read it."""
    scn = (REPO / "scenarios/cameras/flyover.yaml").read_text()
    scn = scn.replace("  views:\n    - {", f"  views:\n    - {{{key}: {text}, ", 1)
    scn = scn.replace("\n       rate_hz: 10}", f"\n       rate_hz: {rate_hz:g}}}", 1)
    cam: CameraSpec = parse_scenario(scn, f"--{key}", check_properties=False
                                     ).sections["cameras"].views[0]
    return cam


def _sensor(text: str) -> SensorSpec:
    """A ``sensor:`` mapping read as a scenario's camera would read it."""
    sensor = _camera("sensor", text).sensor
    assert sensor is not None
    return sensor


def _cpu_s() -> float:
    me, kids = (resource.getrusage(resource.RUSAGE_SELF),
                resource.getrusage(resource.RUSAGE_CHILDREN))
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def swarm(n: int, duration_s: float, backend: str, workers: int | None,
          render_workers: int | None) -> dict[str, object]:
    text = (REPO / "scenarios/cameras/flyover.yaml").read_text()
    text = text.replace("  - id: uav1\n", f"  - id: uav\n    count: {n}\n"
                        "    formation: {type: line, spacing_m: 200}\n")
    text = text.replace("vehicles: uav1", "vehicles: all").replace("operator_view: true",
                                                                   "operator_view: false")
    if render_workers is not None:
        text = text.replace("cameras:\n", f"cameras:\n  render_workers: {render_workers}\n")
    scn = parse_scenario(text, str(REPO / "scenarios/cameras/bench.yaml")).with_duration(
        duration_s)
    with tempfile.TemporaryDirectory() as d:
        os.environ[CACHE_ENV] = str(Path(d) / "cache")  # empty: every tile generated
        cpu0, wall0 = _cpu_s(), time.perf_counter()
        r = run_scenario(scn, d, backend=backend, workers=workers)
        wall = time.perf_counter() - wall0
        cpu = _cpu_s() - cpu0  # render and physics workers are joined (reaped) by now
        sm = r.summary
        sim_s = sm["sim_time_s"]
        e2e = round(sim_s / (wall - sm["startup_s"]), 3) if sim_s else None
        return {"real_time_factor": sm["real_time_factor"], "end_to_end_real_time_factor": e2e,
                "cpu_s_per_sim_s": round(cpu / sim_s, 3) if sim_s else None,
                "wall_time_s": sm["wall_time_s"], "stop": r.stop_reason,
                "frames": sum(s["frames"] for s in sm["cameras"]["streams"]),
                "render_workers": render_workers, "backend": backend, "workers": sm["workers"]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--vehicles", type=int, default=20)
    ap.add_argument("--duration-s", type=float, default=10.0)
    ap.add_argument("--backend", default="process", choices=("process", "inline"))
    ap.add_argument("--workers", type=int, default=None, help="physics workers")
    ap.add_argument("--render-workers", type=int, default=None)
    ap.add_argument("--codec", default="mp4v", choices=tuple(EXTENSIONS),
                    help="for the per-frame cost")
    ap.add_argument("--repeat", type=int, default=1,
                    help="per-frame cost: this many runs (each new ground, then cached); "
                         "prints the median and range")
    ap.add_argument("--sensor", default=None, metavar="YAML",
                    help="per-frame cost with this camera sensor (the cameras: section's "
                         "sensor: mapping, e.g. '{vignetting: cos4, snr_db: 30}'); its part "
                         "is printed apart")
    ap.add_argument("--datalink", default=None, metavar="YAML",
                    help="per-frame cost through this downlink, the camera at 15 Hz (the "
                         "cameras: section's datalink: mapping, e.g. '{bitrate_kbps: 1000}'); "
                         "its part is printed apart")
    ap.add_argument("--haze-km", type=float, default=None, metavar="V",
                    help="per-frame cost also through haze of this visibility (km; the "
                         "atmosphere: section), each pass run without it, then with it; the "
                         "ground's haze is printed apart")
    ap.add_argument("--trees", default="flat", choices=("flat", "3d", "none"),
                    help="the procedural ground's trees (ground: {trees: ...}) for the "
                         "per-frame cost")
    a = ap.parse_args()
    sensor = _sensor(a.sensor) if a.sensor else None
    datalink = _camera("datalink", a.datalink, 15.0).datalink if a.datalink else None
    if a.frames:
        runs: dict[str, list[dict[str, float]]] = {"tiles generated": [], "tiles from disk": []}
        for _ in range(a.repeat):  # each repeat: a new empty tile cache, then the same again
            with tempfile.TemporaryDirectory() as cache:
                for (label, got), km in ((lk, km) for lk in runs.items()
                                         for km in (None, a.haze_km)[:1 + bool(a.haze_km)]):
                    f = per_frame(a.frames, cache, a.codec, sensor, datalink, km, a.trees)
                    if km is None:
                        got.append(f)
                    rest = f["cpu_ms"] - f["encode_ms"] - f["warp_ms"] - f["tiles_ms"] \
                        - f["haze_ms"]
                    what = f"a {datalink.bitrate_kbps:g} kbit/s datalink" if datalink \
                        else a.codec
                    if km:
                        what += f", haze of {km:g} km (the ground's {f['haze_ms']:.2f} ms)"
                    print(f"640x480 nadir frame incl. ground truth + {what}, {label}: "
                          f"{f['cpu_ms']:.2f} ms CPU ({f['wall_ms']:.2f} ms wall), "
                          f"{1000 / f['cpu_ms']:.0f} frames/s per core; of which {a.codec} "
                          f"encoding {f['encode_ms']:.2f} ms (the codec itself "
                          f"{f['codec_ms']:.2f} ms), the ground's warp {f['warp_ms']:.2f} ms, "
                          f"new ground tiles {f['tiles_ms']:.2f} ms ({f['tiles']:.0f} tiles, "
                          f"{f['tile_ms']:.2f} ms each: {f['tiles_generated']} generated, "
                          f"{f['tiles_from_disk']} read), the sensor {f['sensor_ms']:.2f} ms, "
                          f"the datalink {f['datalink_ms']:.2f} ms, "
                          f"the rest {rest - f['sensor_ms'] - f['datalink_ms']:.2f} ms",
                          flush=True)
        if a.repeat > 1:
            for label, got in runs.items():
                ms = sorted(f["cpu_ms"] for f in got)
                parts = {k: statistics.median(f[k] for f in got)
                         for k in ("encode_ms", "codec_ms", "warp_ms", "tiles_ms")}
                print(f"{label}: median {statistics.median(ms):.2f} ms CPU a frame "
                      f"(min {ms[0]:.2f}, max {ms[-1]:.2f}, {len(ms)} runs); medians of the "
                      f"parts: encoding {parts['encode_ms']:.2f} (codec "
                      f"{parts['codec_ms']:.2f}), warp {parts['warp_ms']:.2f}, new tiles "
                      f"{parts['tiles_ms']:.2f} ms")
    if a.vehicles:
        res = swarm(a.vehicles, a.duration_s, a.backend, a.workers, a.render_workers)
        print(f"{a.vehicles} uav700 x 10 Hz 640x480 cameras, {a.duration_s:g} s: "
              + json.dumps(res))


if __name__ == "__main__":
    main()
