"""Plan the search of a 32 x 32 km area (1024 km2) by a fixed-wing fleet and
draw it: the smallest fleet flying 200 kt with 45 degrees of bank whose
nadir cameras (60 degrees across, from 300 m) cover the area within 10
minutes of leaving a base at its centre; each aircraft's strip, lanes,
turns and transit.

    python examples/coverage_plan.py --out coverage_plan.png
    python examples/coverage_plan.py --no-fly 20000,4000,26000,4000,26000,9000,20000,9000
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from cosim.core.units import KT_TO_MPS
from cosim.coverage import (  # noqa: E402
    area_polygon,
    completion_s,
    min_fleet,
    no_fly_polygon,
    swath_m,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="coverage_plan.png")
    ap.add_argument("--alt-agl-m", type=float, default=300.0)
    ap.add_argument("--deadline-s", type=float, default=600.0)
    ap.add_argument("--no-fly", action="append", default=[], metavar="N,E,N,E,...",
                    help="a no-fly zone's corners, north and east metres (repeatable)")
    a = ap.parse_args()
    zones = []
    for spec in a.no_fly:
        xs = [float(t) for t in spec.split(",")]
        if len(xs) < 6 or len(xs) % 2:
            ap.error(f"--no-fly {spec}: expected at least three north,east pairs")
        zones.append(no_fly_polygon(list(zip(xs[::2], xs[1::2]))))
    area = area_polygon([(0, 0), (0, 32_000), (32_000, 32_000), (32_000, 0)])
    v = 200 * KT_TO_MPS
    plan = min_fleet(area, v, 45.0, swath_m(a.alt_agl_m, 60.0), a.deadline_s,
                     base_ne=(16_000.0, 16_000.0), no_fly=zones)
    n = len(plan.aircraft)
    print(f"{n} aircraft; the last done after {completion_s(plan, v):.0f} s; lanes "
          f"{plan.lane_spacing_m:.0f} m apart, turns of {plan.turn_radius_m:.0f} m radius")
    fig, ax = plt.subplots(figsize=(8, 8))
    xs, ys = area.exterior.xy
    ax.fill([x / 1e3 for x in xs], [y / 1e3 for y in ys], color="0.93")
    for z in zones:
        xs, ys = z.exterior.xy
        ax.fill([x / 1e3 for x in xs], [y / 1e3 for y in ys], color="tab:red", alpha=0.4)
    cmap = plt.get_cmap("tab20")
    for k, craft in enumerate(plan.aircraft):
        path = craft.path(step_m=50.0)
        ax.plot(path[:, 0] / 1e3, path[:, 1] / 1e3, lw=0.6, color=cmap(k % 20))
    ax.plot([16], [16], "k^", ms=10, label="base")
    ax.set(xlabel="east (km)", ylabel="north (km)", aspect="equal",
           title=f"{n} aircraft, 200 kt, 45 deg bank, {a.alt_agl_m:.0f} m: "
                 f"{completion_s(plan, v):.0f} s")
    ax.legend(loc="upper right")
    fig.savefig(a.out, dpi=110, bbox_inches="tight")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
