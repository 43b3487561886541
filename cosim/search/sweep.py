"""A sweep of searches: one row per run in ``search.csv`` and the fleet-size
curve ``search_curve.png`` (time to detect the fire against the number of
aircraft, with the 10-minute line), written by ``cosim sweep`` when its
runs have a ``search:`` section.

The curve groups runs by every swept name except the fleet size and the
seed (e.g. the vehicle class, so the JSBSim and the batched tiers are two
lines, compared where they overlap) and, over seeds, draws the mean time
to detection with its range; runs that never found the fire are drawn at
their end time with an open marker.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path
from typing import Any

from cosim.logs import replacing

log = logging.getLogger(__name__)

COLUMNS = ("aircraft", "time_to_detect_s", "coverage_final", "time_to_99_s",
           "plan_completion_s", "decoys_detected", "alt_agl_m", "sim_time_s",
           "real_time_factor", "wall_time_s", "run")
#: names not drawn as separate lines: the fleet size and the repetitions
_ACROSS = ("seed",)
DEADLINE_S = 600.0


def write_table(result: Any, spec: Any) -> Path | None:
    """``search.csv`` and ``search_curve.png`` in the sweep folder (None: no
    run searched)."""
    from cosim.errors import ConfigError
    from cosim.logs import RunFolder

    out = Path(result.out_dir)
    rows = []
    for o in result.runs:
        if o.status != "completed":
            continue
        try:  # read as untrusted input: bounded, inside the run's folder
            s = RunFolder(out / o.name).summary() or {}
        except ConfigError as e:
            log.warning("search.csv: run %s left out: %s", o.name, e)
            continue
        sec = s.get("search")
        if not sec:
            continue
        target = sec.get("target") or {}
        rows.append({**{n: o.point[n] for n in spec.swept},
                     "aircraft": sec["aircraft"],
                     "time_to_detect_s": target.get("time_to_detect_s"),
                     "coverage_final": sec["coverage"]["final"],
                     "time_to_99_s": sec["coverage"]["time_to_fraction_s"].get("0.99"),
                     "plan_completion_s": sec["plan_completion_s"],
                     "decoys_detected": sec["decoys_detected"], "alt_agl_m": sec["alt_agl_m"],
                     "sim_time_s": s["sim_time_s"], "real_time_factor": s["real_time_factor"],
                     "wall_time_s": s["wall_time_s"], "run": o.name})
    if not rows:
        return None
    names = [n for n in spec.swept if n not in COLUMNS]
    path = out / "search.csv"
    with replacing(path) as f:
        w = csv.DictWriter(f, names + list(COLUMNS))
        w.writeheader()
        w.writerows([{k: ("" if v is None else v) for k, v in r.items()} for r in rows])
    try:
        plot_curve(rows, [n for n in names if n not in _ACROSS], out / "search_curve.png")
    except Exception as e:  # a plot never loses the table
        log.warning("could not draw search_curve.png: %s", e)
    return path


def _groups(rows: list[dict[str, Any]], names: list[str]) -> dict[str, list[dict[str, Any]]]:
    """Rows by the values of ``names`` that differ between runs of the same
    fleet size (the fleet size itself, and names that only follow it, drawn
    along one line)."""
    varying = []
    for n in names:
        by_fleet: dict[Any, set[Any]] = {}
        for r in rows:
            by_fleet.setdefault(r["aircraft"], set()).add(r[n])
        if any(len(v) > 1 for v in by_fleet.values()):
            varying.append(n)
    out: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        key = ", ".join(f"{n}={r[n]}" for n in varying) or "runs"
        out.setdefault(key, []).append(r)
    return out


def plot_curve(rows: list[dict[str, Any]], names: list[str], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from cosim.logs.figures import plain_log_axis

    fig, ax = plt.subplots(figsize=(8, 5))
    handles: list[Any] = []
    most = 0  # runs behind one point
    for k, (label, rs) in enumerate(sorted(_groups(rows, names).items())):
        fleets = sorted({r["aircraft"] for r in rs})
        mean, lo, hi, plan, miss = [], [], [], [], []
        for n in fleets:
            mine = [r for r in rs if r["aircraft"] == n]
            most = max(most, len(mine))
            t = [r["time_to_detect_s"] for r in mine if r["time_to_detect_s"] is not None]
            mean.append(np.mean(t) / 60 if t else np.nan)
            lo.append(min(t) / 60 if t else np.nan)
            hi.append(max(t) / 60 if t else np.nan)
            plan.append(np.mean([r["plan_completion_s"] for r in mine]) / 60)
            miss.append(max(r["sim_time_s"] for r in mine) / 60 if len(t) < len(mine)
                        else np.nan)
        x = np.array(fleets, dtype=float) * (1.0 + 0.015 * k)  # side by side where they overlap
        color = f"C{k}"
        m, lo_a, hi_a = np.array(mean), np.array(lo), np.array(hi)
        handles.append(ax.errorbar(x, m, yerr=[m - lo_a, hi_a - m], fmt="o-", color=color,
                                   capsize=3, label=f"{label}: fire found (mean, range over "
                                                    f"the runs)"))
        handles += ax.plot(x, plan, ":", marker="_", ms=8, color=color, lw=1.2,
                           label=f"{label}: plan done (area covered)")
        if not np.all(np.isnan(miss)):
            handles += ax.plot(x, miss, "o", mfc="none", color=color,
                               label=f"{label}: fire not found by the run's end")
    handles.append(ax.axhline(DEADLINE_S / 60, color="red", ls="--", lw=1,
                              label=f"deadline ({DEADLINE_S / 60:g} min)"))
    ax.set_xscale("log")
    plain_log_axis(ax.xaxis, [r["aircraft"] for r in rows])
    ax.set_xlabel("aircraft in the fleet (log scale)")
    ax.set_ylabel("time from the start (min)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3, which="major")
    ax.set_title(f"Time to find the fire against the fleet size ({len(rows)} runs, up to "
                 f"{most} a point)", fontsize=10)
    ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.9)
    fig.tight_layout()
    with replacing(png, "wb") as f:
        fig.savefig(f, dpi=110, format="png")
    plt.close(fig)
