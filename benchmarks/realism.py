"""Realism benchmark (not a test): the spectral exponent of the camera frames of
every bundled scenario with a ``cameras:`` section.

Each scenario (a sweep's first point, as ``cosim run`` flies it, unless
``--set name=value`` picks another) is run for at most ``--max-s`` simulated
seconds, inline, its camera streams rendered as in any run; ``--frames``
frames per camera, evenly spread over the run, are taken as rendered (before
the video encoder) and measured by ``cosim.conspicuity.spectrum``: the
radially averaged power spectrum of their luminance, fitted as ``P ~ f**-a``
from 4 cycles per image to a quarter of Nyquist (the scene; above it the
rendering's interpolation takes over), and again up to Nyquist (the scene and
the rendering's fall-off together). Prints one row per camera (the exponent's
median and range over its frames, the fit's median R^2, the exponent to
Nyquist, whether the median is within the goal) and the natural scenes' range.
Exit 0 whatever the exponents: a measurement.

    python benchmarks/realism.py [--frames 8] [--max-s 20] [--set alt_agl_m=500]
        [--png DIR] [--json FILE] [SCENARIO ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import re
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from cosim.conspicuity.spectrum import GOAL, HI_NYQUIST, LO_CPI, luminance, spectral_exponent
from cosim.renderer.render_pool import RenderWorker
from cosim.scenario import load_scenario
from cosim.scenario.placeholders import protect_placeholders, sweep_values
from cosim.sync.runner import run_scenario

REPO = Path(__file__).resolve().parent.parent
_CAMERAS = re.compile(r"^cameras:", re.M)


def camera_scenarios() -> list[Path]:
    """The bundled scenarios with a ``cameras:`` section."""
    return sorted(p for p in (REPO / "scenarios").rglob("*.yaml")
                  if _CAMERAS.search(p.read_text()))


def frames_of(path: Path, frames: int, max_s: float, point: dict[str, Any]
              ) -> dict[str, list[np.ndarray]]:
    """Up to ``frames`` frames (RGB uint8) of each camera stream ('vehicle/camera')
    of a run of at most ``max_s`` seconds of the scenario at ``path``."""
    node = yaml.safe_load(protect_placeholders(path.read_text())[0]).get("sweep")
    first = {k: v[0] for k, v in sweep_values(node, lambda p, m: None).items()}
    given = {k: v for k, v in point.items() if k in first}
    scn = load_scenario(path, check_properties=False,
                        sweep_point={**first, **given} if given else None)
    cams = scn.sections["cameras"]
    scn.sections["cameras"] = dataclasses.replace(cams, render_workers=0, operator_view=False)
    scn = dataclasses.replace(scn, duration_s=min(scn.duration_s, max_s))
    per_stream = {c.name: max(1, int(scn.duration_s * c.rate_hz) // frames) for c in cams.views}
    got: dict[str, list[np.ndarray]] = {}
    original = RenderWorker.render

    def render(self: RenderWorker, stream: int, frame_no: int, *a: Any, **kw: Any) -> Any:
        out = original(self, stream, frame_no, *a, **kw)
        s = self.streams[stream]
        key = f"{s.vehicle}/{s.camera.name}"
        if frame_no % per_stream[s.camera.name] == 0 and len(got.get(key, ())) < frames:
            got.setdefault(key, []).append(self.frames[stream][..., 2::-1].copy())
        return out

    RenderWorker.render = render  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory() as d:
            run_scenario(scn, d, backend="inline")
    finally:
        RenderWorker.render = original  # type: ignore[method-assign]
    return got


def within(a: float) -> str:
    """Whether an exponent is within the goal: 'met', or how it misses it."""
    if GOAL[0] <= a <= GOAL[1]:
        return "met"
    return "too flat" if a < GOAL[0] else "too steep" if a > GOAL[1] else "no fit (flat image)"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="*", type=Path,
                    help="default: every bundled scenario with a cameras: section")
    ap.add_argument("--frames", type=int, default=8, help="frames measured per camera")
    ap.add_argument("--max-s", type=float, default=20.0, help="simulated seconds per run, at most")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a sweep point's value (a number), for the scenarios that sweep NAME")
    ap.add_argument("--png", type=Path, help="write the measured frames here as PNGs")
    ap.add_argument("--json", type=Path, help="write every frame's exponent here")
    args = ap.parse_args(argv)
    if args.frames < 1 or args.max_s <= 0:
        ap.error("--frames must be at least 1 and --max-s positive")
    point: dict[str, Any] = {}
    for kv in args.set:
        name, eq, value = kv.partition("=")
        if not eq:
            ap.error(f"--set {kv!r}: expected NAME=VALUE")
        point[name] = yaml.safe_load(value)  # 500, 2.5, truck, true
    logging.basicConfig(level=logging.WARNING)
    cv2.setNumThreads(1)
    rows, record = [], {}
    for path in args.scenarios or camera_scenarios():
        rel = path.resolve().relative_to(REPO) if path.resolve().is_relative_to(REPO) else path
        for stream, imgs in frames_of(path, args.frames, args.max_s, point).items():
            lums = [luminance(im) for im in imgs]
            fits = [spectral_exponent(y) for y in lums]
            full = [spectral_exponent(y, hi_nyquist=1.0).exponent for y in lums]
            a = [f.exponent for f in fits]
            record[f"{rel}:{stream}"] = {"exponent": a, "to_nyquist": full}
            rows.append((str(rel), stream, len(a), statistics.median(a), min(a), max(a),
                         statistics.median(f.r2 for f in fits), statistics.median(full),
                         min(full), max(full)))
            if args.png:
                args.png.mkdir(parents=True, exist_ok=True)
                for k, im in enumerate(imgs):
                    name = f"{path.stem}-{stream.replace('/', '-')}-{k}.png"
                    cv2.imwrite(str(args.png / name), im[..., ::-1])
    print(f"spectral exponent a of P(f) ~ f^-a, luminance (Rec. 709, linear sRGB), Hann "
          f"window, {LO_CPI:g} cycles/image to {HI_NYQUIST:g} x Nyquist (and, last, to Nyquist)")
    print(f"{'scenario':46} {'camera':16} {'frames':>6} {'median':>6} {'range':>11} "
          f"{'R^2':>5} | {'to Nyq.':>7} {'range':>11} | goal")
    for r in rows:
        print(f"{r[0]:46} {r[1]:16} {r[2]:6d} {r[3]:6.2f} {r[4]:5.2f}-{r[5]:<5.2f} {r[6]:5.2f} | "
              f"{r[7]:7.2f} {r[8]:5.2f}-{r[9]:<5.2f} | {within(r[3])}")
    print(f"{sum(within(r[3]) == 'met' for r in rows)} of {len(rows)} cameras within the goal")
    print(f"goal: {GOAL[0]:g} to {GOAL[1]:g} (natural scenes about 2: Field 1987; "
          f"van der Schaaf and van Hateren 1996, 1.88 +- 0.43)")
    if args.json:
        args.json.write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
