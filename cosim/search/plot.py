"""The search's pictures: the coverage map and coverage against time, each
with a title, its units and a legend for every kind of mark."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cosim.search.coverage_map import NEVER

#: the deadline drawn on the search's time axes (min)
DEADLINE_MIN = 10.0


def _title(part: Any) -> str:
    s = part.spec
    tgt = next((d for d in part.first.values() if not d["decoy"]), None)
    found = f"fire found at {tgt['time_s']:.0f} s" if tgt else "fire not found"
    covered = np.floor(part.cmap.fraction * 1e5) / 1e3  # 99.999, never a rounded-up 100
    return (f"{len(part.rows)} aircraft at {s.airspeed_kt:g} kt, {s.alt_agl_m:.0f} m above "
            f"ground: {covered:g}% covered, {found}")


def coverage_map_figure(part: Any) -> Any:
    """The coverage map of a finished search (``SearchParticipant``): when each
    cell was first seen, the area, no-fly zones, planned tracks, base, fires,
    decoys and where their first reports put them."""
    import matplotlib.pyplot as plt
    from matplotlib import patheffects
    from matplotlib.colors import ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    s, cmap, plan = part.spec, part.cmap, part.plan
    period = part.cov_every / part.ctx.physics_hz
    seen = np.where(cmap.first == NEVER, np.nan, cmap.first * period / 60.0)
    seen[cmap.inside == 0] = np.nan
    missed = (cmap.first == NEVER) & (cmap.inside == 1)
    fig, ax = plt.subplots(figsize=(8.5, 7.5))
    e0, e1, n0, n1 = cmap.extent_ne()
    km = (e0 / 1e3, e1 / 1e3, n0 / 1e3, n1 / 1e3)
    im = ax.imshow(seen, origin="lower", extent=km, cmap="viridis", interpolation="nearest")
    handles: list[Any] = []
    if missed.any():
        ax.imshow(np.where(missed, 1.0, np.nan), origin="lower", extent=km,
                  cmap=ListedColormap(["#ff3030"]), vmin=0, vmax=1, interpolation="nearest")
        share = 100.0 * missed.sum() / max(1, int((cmap.inside == 1).sum()))
        handles.append(Patch(color="#ff3030", label=f"never seen ({share:.2g}% of the area)"))
    fig.colorbar(im, ax=ax, label="first seen (minutes after the start)", shrink=0.8)
    area = np.array(s.area_ne + s.area_ne[:1]) / 1e3
    ax.plot(area[:, 1], area[:, 0], "k-", lw=1.2)
    handles.append(Line2D([], [], color="k", lw=1.2, label="search area"))
    for z in s.no_fly_ne:
        zz = np.array(z + z[:1]) / 1e3
        ax.fill(zz[:, 1], zz[:, 0], facecolor="none", edgecolor="red", hatch="//", lw=1.0)
    if s.no_fly_ne:
        handles.append(Patch(facecolor="none", edgecolor="red", hatch="//", label="no-fly zone"))
    for a in plan.aircraft[:400]:
        p = a.path(step_m=50.0)
        ax.plot(p[:, 0] / 1e3, p[:, 1] / 1e3, "w-", lw=0.3, alpha=0.5)
    outlined = [patheffects.withStroke(linewidth=3, foreground="0.35")]  # white on the key
    handles.append(Line2D([], [], color="w", lw=1.0, label="planned tracks",
                          path_effects=outlined))
    ax.plot(s.base_ne[1] / 1e3, s.base_ne[0] / 1e3, "ks", ms=7)
    handles.append(Line2D([], [], ls="", marker="s", color="k", ms=7, label="base"))
    for j in range(len(part.fire_specs)):
        n, e = part.fire_ne[j] / 1e3
        decoy = bool(part.decoy[j])
        ax.plot(e, n, "x" if decoy else "*", color="orange" if decoy else "red",
                ms=9 if decoy else 14, mec="k")
    if (~part.decoy).any():
        handles.append(Line2D([], [], ls="", marker="*", color="red", mec="k", ms=12,
                              label="fire (the target)"))
    if part.decoy.any():
        handles.append(Line2D([], [], ls="", marker="x", color="orange", mec="k", ms=9,
                              label="decoy fire"))
    for d in part.first.values():
        ax.plot(d["reported_east_m"] / 1e3, d["reported_north_m"] / 1e3, "o", mfc="none",
                mec="white", ms=11)
    if part.first:
        handles.append(Line2D([], [], ls="", marker="o", mfc="none", mec="w", ms=10,
                              label="first report's position", path_effects=outlined))
    ax.set_xlabel("east of the origin (km)")
    ax.set_ylabel("north of the origin (km)")
    ax.set_title(_title(part), fontsize=10)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3,
              fontsize=8, frameon=False)  # below the map: nothing of it hidden
    ax.set_aspect("equal")
    fig.tight_layout()
    return fig


def coverage_figure(part: Any) -> Any:
    """Coverage against time of a finished search, with when the plan was done,
    the deadline, and when the fire and each decoy were first found."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    t = np.array([c[0] for c in part.curve], dtype=float)
    f = np.array([c[1] for c in part.curve], dtype=float) * 100
    ax.plot(t / 60.0, f, lw=1.8, color="C0", label="area covered")
    plan_min = part.planned_s / 60.0
    ax.axvline(plan_min, color="gray", ls=":", lw=1.2, label=f"plan done ({plan_min:.1f} min)")
    ax.axvline(DEADLINE_MIN, color="k", ls="--", lw=1,
               label=f"deadline ({DEADLINE_MIN:g} min)")
    found = sorted(part.first.values(), key=lambda d: d["time_s"])
    decoys = [d for d in found if d["decoy"]]
    for k, d in enumerate(decoys):
        ax.axvline(d["time_s"] / 60.0, color="orange", ls="-.", lw=1.1,
                   label=f"decoy found ({len(decoys)})" if k == 0 else None)
    for d in found:
        if not d["decoy"]:
            m = d["time_s"] / 60.0
            ax.axvline(m, color="red", lw=2.0, label=f"fire found ({m:.1f} min)")
    ax.set_xlabel("time since the start (min)")
    ax.set_ylabel("area covered (% of the search area)")
    ax.set_ylim(0, 101)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    ax.set_title(_title(part), fontsize=9)
    ax.legend(fontsize=8, loc="lower right", framealpha=0.9)
    fig.tight_layout()
    return fig


def plot_search(part: Any, out: Path) -> None:
    """``coverage_map.png`` and ``coverage.png`` of a finished search
    (``SearchParticipant``) into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name, make in (("coverage_map.png", coverage_map_figure),
                       ("coverage.png", coverage_figure)):
        fig = make(part)
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
