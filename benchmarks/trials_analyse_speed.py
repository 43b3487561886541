"""How fast `cosim trials analyse` reads and analyses responses, in rows per
second, on two shapes of data made here (no participant needed):

- ``designed``: a study as it is meant to be run: "disappear" trials over 10
  viewing distances (the gap on the screen) and over 7 altitudes (the gap on
  the ground), two targets, "recognise" trials over 5 altitudes and 3
  speeds; every participant does every level;
- ``continuous``: the same rows, but the altitude a trial was flown at takes
  a new value every few rows (drawn from 30-500 m to 0.1 m), as it does when
  a measured altitude is exported in place of the swept one: the held
  condition of the screen fits, the variable of the ground fits and a factor
  of recognition are all continuous.

The analysis runs with its defaults (1000 bootstrap resamples, both figures);
the figures' pixel sizes and the number of fits are printed with the time.

    python benchmarks/trials_analyse_speed.py --rows 100000 --participants 758
    python benchmarks/trials_analyse_speed.py --rows 190000 --shape continuous
"""

from __future__ import annotations

import argparse
import struct
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.trials.analysis import analyse
from cosim.trials.responses import COLUMNS, OPTIONAL_COLUMNS

DISTANCES_MM = np.arange(300.0, 1201.0, 100.0)
ALTITUDES_M = np.array([30.0, 60.0, 100.0, 150.0, 200.0, 300.0, 500.0])
CG_MM = {"truck": 40.0, "fire_truck": 60.0}
GROUND_CG_M = {"truck": 12.0, "fire_truck": 18.0}
F_SCREEN_MM = 428.0  # the camera's focal length drawn on the screen


def _text(v: np.ndarray) -> np.ndarray:
    """A column's cells: numbers to 6 significant digits, NaN as an empty cell."""
    if v.dtype.kind != "f":
        return v.astype(str)
    return np.where(np.isnan(v), "", np.char.mod("%.6g", v))


def responses_csv(path: Path, rows: int, participants: int, shape: str, seed: int = 0) -> int:
    """Write ``rows`` responses of ``participants`` people to ``path``: half
    "disappear" over viewing distances, a third over altitudes, the rest
    "recognise". Returns the rows written."""
    rng = np.random.default_rng(seed)
    n_screen, n_ground = rows // 2, rows // 3
    n_rec = rows - n_screen - n_ground
    who = rng.integers(participants, size=rows)
    target = rng.choice(list(CG_MM), size=rows)
    person = rng.normal(0.0, 1.5, participants)
    # screen: the on-screen gap rises up to d0 = 600 mm, then stays at CG
    d = rng.choice(DISTANCES_MM, size=n_screen)
    cg = np.array([CG_MM[t] for t in target[:n_screen]])
    a_s = np.degrees(np.arctan(np.minimum(d * cg / 600.0, cg) / d)) + rng.normal(0, 0.2, n_screen)
    alt = np.concatenate([np.full(n_screen, np.nan), rng.choice(ALTITUDES_M, size=n_ground),
                          rng.choice(np.array([30.0, 100.0, 200.0, 300.0, 500.0]), size=n_rec)])
    if shape == "continuous":  # a new altitude every few rows
        every = rng.integers(1, 4, size=rows).cumsum()
        alt = np.round(rng.uniform(30.0, 500.0, every[-1] + 1)[every], 1)
    # ground: tan(beta) * h rises up to h0 = 100 m, then stays at CG, seen at 600 mm
    h = alt[n_screen:n_screen + n_ground]
    gcg = np.array([GROUND_CG_M[t] for t in target[n_screen:n_screen + n_ground]])
    g = np.maximum(np.minimum(h * gcg / 100.0, gcg) + person[who[n_screen:n_screen + n_ground]]
                   + rng.normal(0, 1.0, n_ground), 0.1)
    beta = np.degrees(np.arctan(g / h))
    mm = g / h * F_SCREEN_MM
    a_g = np.degrees(np.arctan(mm / 600.0))
    p = 1.0 / (1.0 + np.exp(-(2.5 - 1.2 * alt[n_screen + n_ground:] / 100.0)))
    vd = np.concatenate([d, np.full(n_ground + n_rec, 600.0)])
    ecc = np.concatenate([a_s, a_g, rng.uniform(0, 15, n_rec)])
    onscreen = np.concatenate([np.tan(np.radians(a_s)) * d, mm, np.full(n_rec, np.nan)])
    protocol = np.array(["disappear"] * (n_screen + n_ground) + ["recognise"] * n_rec)
    cols: dict[str, np.ndarray] = {
        "participant": np.char.add("p", who.astype(str)),
        "protocol": protocol, "condition_target": target,
        "condition_alt_agl_m": alt, "viewing_distance_mm": vd,
        "eccentricity_deg": ecc, "onscreen_distance_mm": onscreen,
        "camera_gap_deg": np.concatenate([np.full(n_screen, np.nan), beta,
                                          np.full(n_rec, np.nan)]),
        "recognised": np.concatenate([np.full(n_screen + n_ground, ""),
                                      (rng.random(n_rec) < p).astype(int).astype(str)]),
        "condition_speed_kt": np.concatenate([np.full(n_screen + n_ground, np.nan),
                                              rng.choice([50.0, 100.0, 200.0], n_rec)]),
    }
    fixed = {"session": "bench", "practice": "0", "clip": "", "run": "", "frame": "30",
             "video_time_s": "1", "key": "space", "target_in_view": "1",
             "target_angular_size_deg": "0.5", "screen_width_mm": "520",
             "screen_height_mm": "320", "screen_width_px": "1920", "screen_height_px": "1080",
             "target_depth_m": "", "reshown": "0"}
    cols["trial_index"] = np.arange(rows)
    cols["reaction_time_ms"] = rng.integers(300, 1500, size=rows)
    header = list(COLUMNS + OPTIONAL_COLUMNS)
    cells = [np.full(rows, fixed[c]) if c in fixed else _text(cols[c]) for c in header]
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        f.writelines(",".join(row) + "\n" for row in zip(*cells))
    return rows


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels from a PNG's header."""
    with open(path, "rb") as f:
        head = f.read(24)
    return struct.unpack(">II", head[16:24])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--participants", type=int, default=758)
    ap.add_argument("--shape", choices=("designed", "continuous"), default="designed")
    a = ap.parse_args()
    if a.rows < 10 or a.participants < 1:
        ap.error("--rows must be at least 10 and --participants at least 1")
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "responses.csv"
        n = responses_csv(src, a.rows, a.participants, a.shape)
        t0, c0 = time.perf_counter(), time.process_time()
        summary = analyse(src, Path(tmp) / "out")
        wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
        sizes = {name: png_size(Path(tmp) / "out" / name)
                 for name in ("critical_gap.png", "recognition.png")}
    fits = summary["critical_gap"]
    made = sum(f["status"] != "insufficient_data" for f in fits.values())
    print(f"{a.shape}: {n} rows of {a.participants} participants analysed in {wall_s:.1f} s "
          f"({cpu_s:.1f} s of CPU): {n / wall_s:,.0f} rows/s ({n / cpu_s:,.0f} a CPU second)")
    print(f"{len(fits)} critical-gap fits ({made} with enough data); figures: "
          + ", ".join(f"{k} {w} x {h} px" for k, (w, h) in sizes.items()))


if __name__ == "__main__":
    main()
