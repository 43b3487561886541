"""The search's pictures: the coverage map and coverage against time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cosim.search.coverage_map import NEVER


def plot_search(part: Any, out: Path) -> None:
    """``coverage_map.png`` and ``coverage.png`` of a finished search
    (``SearchParticipant``) into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s, cmap, plan = part.spec, part.cmap, part.plan
    period = part.cov_every / part.ctx.physics_hz
    seen = np.where(cmap.first == NEVER, np.nan, cmap.first * period / 60.0)
    seen[cmap.inside == 0] = np.nan
    missed = (cmap.first == NEVER) & (cmap.inside == 1)
    fig, ax = plt.subplots(figsize=(8.5, 7.5))
    e0, e1, n0, n1 = cmap.extent_ne()
    km = (e0 / 1e3, e1 / 1e3, n0 / 1e3, n1 / 1e3)
    im = ax.imshow(seen, origin="lower", extent=km, cmap="viridis", interpolation="nearest")
    if missed.any():
        from matplotlib.colors import ListedColormap

        ax.imshow(np.where(missed, 1.0, np.nan), origin="lower", extent=km,
                  cmap=ListedColormap(["#ff3030"]), vmin=0, vmax=1, interpolation="nearest")
    fig.colorbar(im, ax=ax, label="first seen (min); red: never", shrink=0.8)
    area = np.array(s.area_ne + s.area_ne[:1]) / 1e3
    ax.plot(area[:, 1], area[:, 0], "k-", lw=1.2)
    for z in s.no_fly_ne:
        zz = np.array(z + z[:1]) / 1e3
        ax.fill(zz[:, 1], zz[:, 0], facecolor="none", edgecolor="red", hatch="//", lw=1.0)
    for a in plan.aircraft[:400]:
        p = a.path(step_m=50.0)
        ax.plot(p[:, 0] / 1e3, p[:, 1] / 1e3, "w-", lw=0.3, alpha=0.5)
    ax.plot(s.base_ne[1] / 1e3, s.base_ne[0] / 1e3, "ks", ms=7, label="base")
    for j in range(len(part.fire_specs)):
        n, e = part.fire_ne[j] / 1e3
        ax.plot(e, n, "x" if part.decoy[j] else "*", color="orange" if part.decoy[j] else "red",
                ms=9 if part.decoy[j] else 14, mec="k",
                label="decoy" if part.decoy[j] and j == int(np.argmax(part.decoy)) else
                ("fire (target)" if not part.decoy[j] else None))
    for d in part.first.values():
        ax.plot(d["reported_east_m"] / 1e3, d["reported_north_m"] / 1e3, "o", mfc="none",
                mec="white", ms=11)
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    cov = cmap.fraction * 100
    tgt = next((d for d in part.first.values() if not d["decoy"]), None)
    ax.set_title(f"{len(part.rows)} aircraft, {s.airspeed_kt:g} kt at {s.alt_agl_m:.0f} m: "
                 f"{cov:.2f}% covered" + (f", fire found at {tgt['time_s']:.0f} s"
                                          if tgt else ""), fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(out / "coverage_map.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    t = np.array([c[0] for c in part.curve])
    f = np.array([c[1] for c in part.curve]) * 100
    ax.plot(t / 60.0, f, lw=1.5, label="covered")
    ax.axvline(part.planned_s / 60.0, color="gray", ls=":", label="plan done")
    ax.axvline(10.0, color="red", ls="--", lw=1, label="10 min")
    for d in sorted(part.first.values(), key=lambda d: d["time_s"]):
        ax.axvline(d["time_s"] / 60.0, color="orange" if d["decoy"] else "red", lw=0.8,
                   alpha=0.8)
    ax.set_xlabel("time (min)")
    ax.set_ylabel("area covered (%)")
    ax.set_ylim(0, 101)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "coverage.png", dpi=110)
    plt.close(fig)
