"""The study file (``STUDY.yaml``) of a conspicuity trial with people.

Owns reading and checking the study: its clips (a ``cosim sweep`` folder
through its ``manifest.csv``, or an explicit list of video + ground truth),
the protocol, practice trials, breaks and the order of the trials in each
session. A clip's files, its per-frame ground truth for its target and its
video, are read by ``clips``. It does not serve, store or measure anything
(``server``, ``store``, ``measures``).

The file and everything it names are untrusted: the YAML goes through the
scenario loader's limits (``cosim.scenario.yaml_lines``), every problem is
reported as ``file:line: path: message`` (all at once, one ``ConfigError``),
the manifest and ground-truth files are bounded in size and read row by row
with their own ``file:line`` errors, and every video and ground-truth path
must resolve (symlinks followed) to a regular file inside the study's
folders: the study file's folder and the sweep folder. Every file is
checked to be a regular file on the descriptor opened, before it is read (a
FIFO or a device is refused, never waited on: ``open_regular``). Only those
resolved paths are ever served, by clip number, never a path from a request.
Each video is opened with PyAV: its size must match the manifest's and its codec
must play in browsers (H.264, VP8/9, AV1; cosim renders ``mp4v`` unless a
scenario says ``cameras: {codec: h264, ...}``).

Example::

    schema_version: 1
    name: exp2
    protocol: disappear        # or recognise, or track
    arrow_speed_deg_s: 2       # track: how fast the arrow leaves the target
    sweep: runs/exp2           # or {folder: runs/exp2, where: {target: truck}}
    # clips:                   # instead of sweep:
    #   - {video: clips/a.mp4, ground_truth: clips/a.gt.csv, target: truck,
    #      conditions: {speed_kt: 50, alt_agl_m: 100}}
    practice: 2                # practice trials first (clips drawn with the seed)
    # practice_clips: runs/training  # draw them from these instead of the clips: a list
    #                          # like `clips:` or a sweep folder like `sweep:`
    break_every: 12            # a break after every 12 trials (0: none)
    repeats: 1                 # every clip shown this many times
    order: latin_square        # or shuffle
    seed: 1
    # tlx: {after: block, weights: true}  # NASA-TLX; sagat: [...] freeze probes (live)
    #                          # (both read by ``instruments``)

Trial order (``Study.trial_order(session_number)``): ``latin_square`` takes
row ``session_number`` of a balanced (Williams) Latin square over the clips,
so each clip appears at each position and after each other clip equally often
over the sessions (for an odd number of clips over twice as many sessions);
``shuffle`` a permutation drawn by ``numpy.random.default_rng([seed,
session_number, repeat])``. Practice clips are drawn by
``default_rng([seed, session_number, PRACTICE_STREAM])`` from
``practice_clips`` if the study has them, else from the clips themselves.
``practice_clips`` take the same forms as ``clips:`` (a list) or ``sweep:``
(a folder, or ``{folder, where}``); their ids must differ from the clips'
(listed ones are ``practice0``, ``practice1``, ... unless given an ``id:``),
and they need ``practice:`` above 0. A trial's ``clip`` numbers
``Study.all_clips``: the clips, then the practice clips.

A study with ``protocol: live`` has ``scenarios:`` (read by ``live_study``:
a scenario file and the feeds to show, per condition) in place of clips,
and its trial order is drawn over them the same way (``Study.live``).

Each clip carries a fingerprint (``Clip.fingerprint``: the SHA-256 of its
ground-truth file and its video's size in bytes, taken when the study is
read); a session records each trial's clip id and fingerprint, so a study
file edited while sessions exist cannot silently show or measure another
clip (``server`` refuses such a session).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.limits import MAX_FILE_BYTES
from cosim.errors import ConfigError
from cosim.scenario.reader import Problems, Reader, describe
from cosim.scenario.yaml_lines import (
    YamlProblem,
    load_with_lines,
    read_text_bounded,
)
from cosim.trials.clips import GtFrame, csv_rows, inside, probe_video, read_bounded, read_clip_truth
from cosim.trials.instruments import (
    STUDY_KEYS,
    TlxSetting,
    check_fuel_questions,
    check_probe_times,
    parse_sagat,
    parse_tlx,
)
from cosim.trials.live_scoring import ScoringSettings, read_scoring
from cosim.trials.live_study import (
    LiveCondition,
    TimingLimits,
    read_live_conditions,
    read_timing_limits,
)
from cosim.trials.sagat import Probe

#: clips in one study (after ``repeats``: trials in one session)
MAX_CLIPS = 5000
MAX_TRIALS = 20_000
#: bytes of a manifest.csv read for a study
MAX_MANIFEST_BYTES = 16 * 1024 * 1024
MAX_PRACTICE = 100
MAX_REPEATS = 100
PROTOCOLS = ("disappear", "recognise", "track", "live")
#: a "track" trial's sub-trials: the arrow leaves the target this way (screen axes)
TRACK_DIRECTIONS = {"right": (1.0, 0.0), "left": (-1.0, 0.0), "up": (0.0, -1.0),
                    "down": (0.0, 1.0)}
#: video codecs (PyAV's names) that current browsers play
BROWSER_CODECS = ("h264", "vp8", "vp9", "av1", "libdav1d", "libvpx", "libvpx-vp9")
ORDERS = ("latin_square", "shuffle")
PRACTICE_STREAM = 1_000_003
#: the manifest columns that describe the clip, not the condition (cosim.sweep.runner)
MANIFEST_COLUMNS = ("run", "vehicle", "camera", "video", "ground_truth", "frames", "rate_hz",
                    "width_px", "height_px", "hfov_deg", "vfov_deg")
TOP_KEYS = ("schema_version", "name", "description", "protocol", "arrow_speed_deg_s", "sweep",
            "clips", "scenarios", "scoring", "timing_limits", "practice", "practice_clips",
            "break_every", "repeats", "order", "seed")
#: the keys of a live study only
LIVE_KEYS = ("scenarios", "scoring", "timing_limits")
CLIP_KEYS = ("id", "video", "ground_truth", "target", "rate_hz", "width_px", "height_px",
             "hfov_deg", "conditions", "run")


@dataclass(frozen=True)
class Clip:
    """One video and the ground truth of the target a trial is about.
    ``frames[k]`` is the ground truth of video frame ``k`` (presentation time
    ``k / rate_hz``)."""

    id: str
    video: Path
    ground_truth: Path
    target: str
    run: str
    rate_hz: float
    width_px: int
    height_px: int
    conditions: tuple[tuple[str, str], ...]
    frames: tuple[GtFrame, ...] = field(repr=False)
    #: the camera's horizontal field of view (the renderer's pinhole: square
    #: pixels, focal length ``width_px / 2 / tan(hfov / 2)``); None: not known
    hfov_deg: float | None = None
    #: the SHA-256 (hex) of the ground-truth file and the video's size, when read
    gt_sha256: str = ""
    video_bytes: int = 0

    @property
    def fingerprint(self) -> dict[str, Any]:
        """What a session records to know the clip again (see the module docstring)."""
        return {"ground_truth_sha256": self.gt_sha256, "video_bytes": self.video_bytes}

    @property
    def focal_px(self) -> float | None:
        """The camera's focal length in its pixels, if its field of view is known."""
        if self.hfov_deg is None:
            return None
        return self.width_px / 2.0 / math.tan(math.radians(self.hfov_deg) / 2.0)

    @property
    def condition_map(self) -> dict[str, str]:
        return dict(self.conditions)

    @property
    def still_frame(self) -> int:
        """The frame a ``track`` trial shows still: the target in view nearest
        the image centre (the first such, else frame 0)."""
        cx, cy = (self.width_px - 1) / 2, (self.height_px - 1) / 2
        best, best_d = 0, math.inf
        for k, g in enumerate(self.frames):
            if g.in_view and g.center_px is not None:
                d = math.hypot(g.center_px[0] - cx, g.center_px[1] - cy)
                if d < best_d:
                    best, best_d = k, d
        return best

    def frame_at(self, media_time_s: float) -> int:
        """The video frame index shown at ``media_time_s`` (the
        requestVideoFrameCallback ``mediaTime`` of the presented frame),
        clamped to the clip."""
        k = round(media_time_s * self.rate_hz)
        return min(max(k, 0), max(len(self.frames) - 1, 0))


@dataclass(frozen=True)
class Trial:
    index: int
    practice: bool
    clip: int  # index into Study.all_clips
    break_before: bool


@dataclass(frozen=True)
class Study:
    path: Path
    name: str
    protocol: str
    clips: tuple[Clip, ...]
    practice: int
    break_every: int
    repeats: int
    order: str
    seed: int
    roots: tuple[Path, ...]
    #: NASA-TLX after each block or the session (``instruments``); None: not asked
    tlx: TlxSetting | None = None
    #: SAGAT freeze probes of each live trial (``sagat``)
    sagat: tuple[Probe, ...] = ()
    #: ``track``: the arrow's speed away from the target (degrees of visual angle a second)
    arrow_speed_deg_s: float = 2.0
    #: the clips practice trials are drawn from (empty: from ``clips``)
    practice_clips: tuple[Clip, ...] = ()
    #: ``live``: the conditions (scenario and feeds) a trial runs, in place of clips
    live: tuple[LiveCondition, ...] = ()
    #: ``live``: how its reports are scored (``scoring:``)
    scoring: ScoringSettings = field(default_factory=ScoringSettings)
    #: ``live``: the timing beyond which a trial is flagged (``timing_limits:``)
    timing_limits: TimingLimits = field(default_factory=TimingLimits)

    @property
    def all_clips(self) -> tuple[Clip, ...]:
        """The clips, then the practice clips: what ``Trial.clip`` numbers."""
        return self.clips + self.practice_clips

    def trial_order(self, session_number: int) -> list[Trial]:
        """The trials of the ``session_number``-th session (0-based): practice
        first, then every clip ``repeats`` times (see the module docstring)."""
        n = len(self.clips) or len(self.live)
        trials: list[Trial] = []
        if self.practice:
            pool = len(self.practice_clips) or n
            first = n if self.practice_clips else 0  # the practice clips follow the clips
            rng = np.random.default_rng([self.seed, session_number, PRACTICE_STREAM])
            picks = rng.choice(pool, size=self.practice, replace=self.practice > pool)
            trials += [Trial(i, True, first + int(c), False) for i, c in enumerate(picks)]
        main: list[int] = []
        for rep in range(self.repeats):
            if self.order == "latin_square":
                main += williams_row(n, session_number + rep)
            else:
                perm = np.random.default_rng([self.seed, session_number, rep]).permutation(n)
                main += [int(c) for c in perm]
        for j, c in enumerate(main):
            brk = bool(self.break_every) and j > 0 and j % self.break_every == 0
            trials.append(Trial(len(trials), False, c, brk))
        return trials


def williams_row(n: int, row: int) -> list[int]:
    """Row ``row`` of a balanced Latin square of order ``n`` (Williams design;
    for odd ``n`` rows ``n..2n-1`` are the reverses of rows ``0..n-1``)."""
    if n < 1:
        return []
    base, lo, hi = [0], 1, n - 1
    while len(base) < n:
        base.append(lo)
        lo += 1
        if len(base) < n:
            base.append(hi)
            hi -= 1
    period = n if n % 2 == 0 else 2 * n
    r = row % period
    seq = [(b + r) % n for b in base]
    return seq[::-1] if r >= n else seq


def load_study(path: str | Path) -> Study:
    """Read and check a study file; ``ConfigError`` lists every problem found."""
    p = Path(path)
    text = read_text_bounded(p, MAX_FILE_BYTES, "the study file", "a study file")
    return parse_study(text, p)


def parse_study(text: str, path: Path) -> Study:
    fname = str(path)
    try:
        data, lines, dups = load_with_lines(text)
    except YamlProblem as e:
        raise ConfigError([f"{fname}:{ln}: {m}" for ln, m in e.problems]) from None
    ctx = Problems(fname, lines)
    for ln, m in dups:
        ctx.problems.append((ln, m))
    top = Reader(ctx, data, (), TOP_KEYS + STUDY_KEYS)
    version = top.integer("schema_version", 1)
    if version is not None and version != 1:
        ctx.err(("schema_version",), f"unsupported schema_version {version}; this cosim reads 1")
    name = top.string("name", path.stem)
    protocol = top.string("protocol", choices=PROTOCOLS)
    arrow = top.num("arrow_speed_deg_s", 2.0, lo=0.05, hi=60.0)
    practice = top.integer("practice", 0, lo=0, hi=MAX_PRACTICE)
    break_every = top.integer("break_every", 0, lo=0, hi=MAX_TRIALS)
    repeats = top.integer("repeats", 1, lo=1, hi=MAX_REPEATS)
    order = top.string("order", "shuffle", choices=ORDERS)
    seed = top.integer("seed", 0, lo=0, hi=2**32 - 1)
    tlx = parse_tlx(ctx, top.d.get("tlx"))
    sagat = parse_sagat(ctx, top.d["sagat"]) if "sagat" in top.d else ()
    if sagat and protocol != "live":
        ctx.err(("sagat",), f"freeze probes are asked during live trials (`protocol: live`), "
                            f"not during {protocol} clips")
    if isinstance(top.d.get("description", ""), (dict, list)):
        ctx.err(("description",), "expected text")
    base = path.resolve().parent
    roots: list[Path] = [base]
    clips: list[Clip] = []
    live: list[LiveCondition] = []
    scoring = ScoringSettings()
    limits = TimingLimits()
    if protocol == "live":
        for key in ("sweep", "clips", "practice_clips"):
            if key in top.d:
                ctx.err((key,), "a live study runs scenarios (`scenarios:`), not clips")
        if practice:
            ctx.err(("practice",), "a live study has no practice trials yet: set it to 0")
        live = read_live_conditions(ctx, top.d.get("scenarios"), base, tuple(roots),
                                    condition_values)
        check_probe_times(ctx, sagat, {c.id: c.duration_s for c in live})
        check_fuel_questions(ctx, sagat, {c.id: c.no_fuel for c in live})
        scoring = read_scoring(ctx, top.d.get("scoring", {}))
        limits = read_timing_limits(ctx, top.d.get("timing_limits", {}))
    elif any(k in top.d for k in LIVE_KEYS):
        key = next(k for k in LIVE_KEYS if k in top.d)
        ctx.err((key,), f"`{key}:` is for `protocol: live`; clips are given with `sweep:` or "
                        f"`clips:`")
    which = None if protocol == "live" else top.one_of("sweep", "clips")
    if which is None and protocol != "live" and not ctx.problems:
        ctx.err((), "missing the clips: give `sweep:` (a cosim sweep folder) or `clips:` "
                    "(a list of video + ground_truth)")
    elif which is not None:
        clips = _clips_of(ctx, which, top.d[which], base, roots)
    if len(clips) * (repeats or 1) > MAX_TRIALS:
        ctx.err(("clips",), f"{len(clips)} clips x {repeats} repeats is more than "
                            f"{MAX_TRIALS} trials")
    _check_ids(ctx, which or "clips", [c.id for c in clips])
    practice_clips: list[Clip] = []
    if "practice_clips" in top.d:
        practice_clips = _clips_of(ctx, "practice_clips", top.d["practice_clips"], base, roots)
        if practice == 0:
            ctx.err(("practice_clips",), "practice clips given, but `practice:` is 0: say how "
                                         "many practice trials to draw from them")
        _check_ids(ctx, "practice_clips", [c.id for c in practice_clips])
        main_ids = {c.id for c in clips}
        both = sorted({c.id for c in practice_clips if c.id in main_ids})
        if both:
            ctx.err(("practice_clips",), f"clip ids also among the main clips: "
                                         f"{', '.join(both[:10])}; a practice clip needs an id "
                                         f"of its own (`id:`, or another sweep folder)")
    if ctx.problems or ctx.more:
        raise ctx.error()
    return Study(tlx=tlx, sagat=sagat,
                 path=path, name=name, protocol=protocol, clips=tuple(clips), practice=practice,
                 break_every=break_every, repeats=repeats, order=order, seed=seed,
                 roots=tuple(roots), arrow_speed_deg_s=float(arrow or 2.0),
                 practice_clips=tuple(practice_clips), live=tuple(live), scoring=scoring,
                 timing_limits=limits)


def _clips_of(ctx: Problems, key: str, spec: Any, base: Path, roots: list[Path]) -> list[Clip]:
    """The clips of top-level ``key``: a list (like ``clips:``) or a sweep
    folder (like ``sweep:``); ``key`` names them in the messages."""
    listed = isinstance(spec, list) if key == "practice_clips" else key == "clips"
    if listed:
        prefix = "clip" if key == "clips" else "practice"
        return _listed_clips(ctx, spec, base, tuple(roots), key, prefix)
    return _sweep_clips(ctx, spec, base, roots, key)


def _check_ids(ctx: Problems, key: str, ids: list[str]) -> None:
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        ctx.err((key,), f"clip ids given twice: {', '.join(dup[:10])}")


def _file(ctx: Problems, at: tuple[Any, ...], value: Any, base: Path, roots: tuple[Path, ...],
          what: str) -> Path | None:
    if not isinstance(value, str) or not value or "\x00" in value:
        ctx.err(at, f"expected the path of the {what}, got {describe(value)}")
        return None
    p, instead = inside(base / value, roots)
    if p is None:
        ctx.err(at, f"{value[:200]!r}: the {what} must be an existing file inside the study's "
                    f"folders ({', '.join(str(r) for r in roots)}){instead}")
    return p


def _clip_from(ctx: Problems, at: tuple[Any, ...], cid: str, video: Path, gt: Path,
               target: str | None, run: str, rate: float | None, width: int | None,
               height: int | None, conditions: dict[str, str],
               hfov: float | None = None) -> Clip | None:
    try:
        target, frames, gt_sha256 = read_clip_truth(gt, target)
        r2, w2, h2, codec, n2, video_bytes = probe_video(video)
        if codec not in BROWSER_CODECS:
            raise ConfigError(f"{video}: codec {codec} does not play in browsers; render the "
                              f"clips with `cameras: {{codec: h264, views: [...]}}`")
        if (width or w2, height or h2) != (w2, h2):
            raise ConfigError(f"{video}: the video is {w2} x {h2} px, not {width} x {height}")
        # a key press's frame is found from the rate: a wrong one measures the wrong frame
        if rate is not None and abs(rate - r2) > 1e-3 * r2:
            raise ConfigError(f"{video}: the video runs at {r2:g} frames/s, not {rate:g}")
        if n2 and frames and abs(n2 - len(frames)) > 1:
            raise ConfigError(f"{video}: {n2} frames, but {gt} has {len(frames)} for "
                              f"target {target!r}")
        rate, width, height = rate or r2, w2, h2
    except ConfigError as e:
        for msg in e.problems:
            ctx.err(at, msg)
        return None
    if not frames:
        ctx.err(at, f"{gt}: no rows for target {target!r}")
        return None
    return Clip(id=cid, video=video, ground_truth=gt, target=target, run=run,
                rate_hz=float(rate), width_px=int(width), height_px=int(height),
                conditions=tuple(conditions.items()), frames=frames, hfov_deg=hfov,
                gt_sha256=gt_sha256, video_bytes=video_bytes)


def _listed_clips(ctx: Problems, items: Any, base: Path, roots: tuple[Path, ...],
                  key: str = "clips", id_prefix: str = "clip") -> list[Clip]:
    if not isinstance(items, list) or not items:
        ctx.err((key,), f"expected a non-empty list of clips, got {describe(items)}")
        return []
    if len(items) > MAX_CLIPS:
        ctx.err((key,), f"{len(items)} clips; a study may have at most {MAX_CLIPS}")
        return []
    out = []
    for i, item in enumerate(items):
        at = (key, i)
        r = Reader(ctx, item, at, CLIP_KEYS)
        before = len(ctx.problems)
        video = _file(ctx, at + ("video",), r.d.get("video"), base, roots, "video")
        gt = _file(ctx, at + ("ground_truth",), r.d.get("ground_truth"), base, roots,
                   "ground truth")
        target = r.string("target", None)
        rate = r.num("rate_hz", None, lo=0, hi=1000, lo_open=True)
        width = r.integer("width_px", None, lo=1, hi=100_000)
        height = r.integer("height_px", None, lo=1, hi=100_000)
        hfov = r.num("hfov_deg", None, lo=0, hi=179, lo_open=True)
        cid = r.string("id", f"{id_prefix}{i}")
        run = r.string("run", "")
        conds = condition_values(ctx, at, r.d.get("conditions", {}))
        if len(ctx.problems) != before or video is None or gt is None:
            continue
        c = _clip_from(ctx, at, cid, video, gt, target, run, rate, width, height, conds,
                       hfov)
        if c is not None:
            out.append(c)
    return out


def condition_values(ctx: Problems, at: tuple[Any, ...], cd: Any) -> dict[str, str]:
    """A clip's or live condition's ``conditions:`` mapping as name: text
    (problems go to ``ctx``)."""
    conds: dict[str, str] = {}
    if not isinstance(cd, dict):
        ctx.err(at + ("conditions",), f"expected a mapping, got {describe(cd)}")
        return conds
    for k, v in list(cd.items())[:100]:
        if isinstance(v, (dict, list)) or v is None or not isinstance(k, str):
            ctx.err(at + ("conditions", k), f"expected a name: value, got {describe(v)}")
        else:
            conds[k] = _fmt_value(v)
    return conds


def _fmt_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def _sweep_clips(ctx: Problems, spec: Any, base: Path, roots: list[Path],
                 key: str = "sweep") -> list[Clip]:
    at: tuple[Any, ...] = (key,)
    where: Mapping[str, Any] = {}
    if isinstance(spec, dict):
        r = Reader(ctx, spec, at, ("folder", "where"))
        folder = r.string("folder")
        w = spec.get("where", {})
        if not isinstance(w, dict):
            ctx.err(at + ("where",), f"expected a mapping of manifest column: value, got "
                                     f"{describe(w)}")
        else:
            where = w
        at = at + ("folder",)
    else:
        folder = spec
    if not isinstance(folder, str) or not folder:
        ctx.err(at, f"expected the path of a cosim sweep folder, got {describe(folder)}")
        return []
    try:
        sweep = (base / folder).resolve(strict=True)
    except (OSError, RuntimeError) as e:
        ctx.err(at, f"{folder[:200]!r}: cannot open the sweep folder: {e}")
        return []
    manifest = sweep / "manifest.csv"
    if not sweep.is_dir() or not manifest.exists():  # (a FIFO is refused as it is read)
        ctx.err(at, f"{folder[:200]!r}: not a sweep folder (no manifest.csv; run `cosim sweep "
                    f"... --out {folder[:200]}` first)")
        return []
    if sweep not in roots:
        roots.append(sweep)
    try:
        rows = csv_rows(read_bounded(manifest, MAX_MANIFEST_BYTES, "manifest"), manifest,
                        "sweep manifest", MANIFEST_COLUMNS)
    except ConfigError as e:
        for m in e.problems:
            ctx.err(at, m)
        return []
    if len(rows) > MAX_CLIPS:
        ctx.err(at, f"{manifest}: {len(rows)} clips; a study may have at most {MAX_CLIPS}")
        return []
    for k in where:
        if not rows or k not in rows[0][1]:
            ctx.err((key, "where", k), f"no column {k!r} in {manifest}")
    out = []
    for line, row in rows:
        if any(row.get(k) != _fmt_value(v) for k, v in where.items()):
            continue
        where_at = f"{manifest}:{line}"
        sroots = (sweep,)
        video, v_instead = inside(sweep / row["video"], sroots) if row["video"] else (None, "")
        gt, g_instead = (inside(sweep / row["ground_truth"], sroots) if row["ground_truth"]
                        else (None, ""))
        if video is None or gt is None:
            bad, instead = ("video", v_instead) if video is None else ("ground_truth", g_instead)
            ctx.err(at, f"{where_at}: {bad} {row[bad][:200]!r} must be an existing file inside "
                        f"the sweep folder{instead}")
            continue
        try:
            rate = float(row["rate_hz"])
            width, height = int(row["width_px"]), int(row["height_px"])
            if not (0 < rate <= 1000 and 0 < width <= 100_000 and 0 < height <= 100_000):
                raise ValueError
        except ValueError:
            ctx.err(at, f"{where_at}: rate_hz, width_px, height_px: expected a rate in "
                        f"(0, 1000] and sizes >= 1")
            continue
        conds = {k: v for k, v in row.items() if k not in MANIFEST_COLUMNS}
        cid = f"{row['run']}/{row['vehicle']}_{row['camera']}"
        target = row.get("target") or None
        try:  # the field of view: empty or unreadable means "not known" (no camera gap)
            hfov: float | None = float(row["hfov_deg"])
            if not 0 < hfov < 180:  # type: ignore[operator]
                hfov = None
        except ValueError:
            hfov = None
        c = _clip_from(ctx, at, cid, video, gt, target, row["run"], rate, width, height, conds,
                       hfov)
        if c is not None:
            out.append(c)
    if rows and not out and not ctx.problems:
        ctx.err(at, f"{manifest}: no clip matches `where:`")
    return out
