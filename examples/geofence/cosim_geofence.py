"""A scenario section in a package of its own: ``geofence:``, an alarm for
vehicles that leave an area. cosim finds it through the ``cosim.sections``
entry point (see pyproject.toml) without any change to cosim::

    geofence:
      area: [[-2000, -2000], [-2000, 2000], [2000, 2000], [2000, -2000]]  # north_m, east_m
      vehicles: all              # which vehicles it watches (ids, patterns)

It shows each part of the section contract (``cosim.core.section.Section``):
a parser reporting problems with their lines, a participant in the tick loop
(reading the state array at every exchange, emitting ``geofence_breach`` and
``geofence_return`` events), an output (``geofence.csv`` in the run folder
and a ``geofence`` part of ``summary.json``) and a CLI command
(``cosim geofence-report RUN_DIR``).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.args import EXIT_OK
from cosim.core.section import CliCommand, P, Section, SectionContext
from cosim.core.state import STATE_INDEX
from cosim.errors import ConfigError
from cosim.world.obstacles import inside

MAX_CORNERS = 64
CSV_NAME = "geofence.csv"
COLUMNS = ("tick", "time_s", "vehicle", "event", "north_m", "east_m")


def parse_geofence(info: SectionContext, node: Any, path: P) -> dict[str, Any] | None:
    """``area`` (3 to ``MAX_CORNERS`` [north_m, east_m] corners) and
    ``vehicles``; every problem reported through ``info`` with its line."""
    r = info.reader(node, path, ("area", "vehicles"))
    area = r.d.get("area")
    if not isinstance(area, list) or not 3 <= len(area) <= MAX_CORNERS:
        info.err(path + ("area",), f"expected 3 to {MAX_CORNERS} [north_m, east_m] corners")
        area = None
    else:
        for i, c in enumerate(area):
            if not (isinstance(c, list) and len(c) == 2 and all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                    and abs(x) <= 1e6 for x in c)):
                info.err(path + ("area", i), f"expected [north_m, east_m], got {c!r}"[:200])
                area = None
                break
    rows = info.select(r.d.get("vehicles", "all"), path + ("vehicles",))
    if area is None or not rows:
        return None
    return {"area": tuple((float(n), float(e)) for n, e in area), "rows": tuple(rows)}


class GeofenceAlarm:
    """The participant: at every exchange, which watched vehicles are outside."""

    name = "geofence"

    def __init__(self, scenario: Any) -> None:
        spec = scenario.sections["geofence"]
        self.area = np.array(spec["area"], dtype=float)
        self.rows = np.array(spec["rows"], dtype=int)
        self.outside = np.zeros(len(self.rows), dtype=bool)
        self.records: list[tuple[Any, ...]] = []
        self.ctx: Any = None

    def start(self, ctx: Any) -> None:
        self.ctx = ctx

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        s = states[self.rows]
        n, e, _ = self.ctx.frame.geodetic_to_ned(s[:, STATE_INDEX["lat_deg"]],
                                                s[:, STATE_INDEX["lon_deg"]],
                                                s[:, STATE_INDEX["alt_msl_m"]])
        out = ~inside(self.area, np.column_stack([n, e]))
        for k in np.flatnonzero(out != self.outside).tolist():
            kind = "geofence_breach" if out[k] else "geofence_return"
            vid = self.ctx.ids[int(self.rows[k])]
            self.ctx.events.emit(kind, tick, vehicle=vid, north_m=float(n[k]),
                                 east_m=float(e[k]))
            self.records.append((tick, tick / self.ctx.physics_hz, vid, kind, float(n[k]),
                                 float(e[k])))
        self.outside = out

    def finish(self, tick: int, reason: str) -> dict[str, Any]:
        with open(self.ctx.out_dir / CSV_NAME, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(COLUMNS)
            w.writerows(self.records)
        return {"breaches": sum(r[3] == "geofence_breach" for r in self.records),
                "outside_at_end": [self.ctx.ids[int(r)] for r in self.rows[self.outside]]}

    def after_run(self, out_dir: Path) -> None:
        pass


def _report_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN_DIR", help="a run folder of a scenario with geofence:")


def _report(a: argparse.Namespace) -> int:
    path = Path(a.run) / CSV_NAME
    if not path.is_file():
        raise ConfigError(f"{a.run}: no {CSV_NAME} (was the run's scenario given geofence:?)")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    breaches: dict[str, int] = {}
    for r in rows:
        if r["event"] == "geofence_breach":
            breaches[r["vehicle"]] = breaches.get(r["vehicle"], 0) + 1
    for vid, k in sorted(breaches.items()):
        print(f"{vid}: left the area {k} time{'s' * (k != 1)}")
    print(f"{sum(breaches.values())} breach(es) by {len(breaches)} vehicle(s)")
    return EXIT_OK


class GeofenceSection(Section):
    key = "geofence"
    description = "an alarm for vehicles that leave an area (an example out-of-tree section)"
    outputs = (CSV_NAME,)
    commands = (CliCommand("geofence-report", "which vehicles left a run's geofence area",
                           _report_args, _report),)

    def parse(self, info: SectionContext, node: Any, path: P) -> dict[str, Any] | None:
        return parse_geofence(info, node, path)

    def participant(self, scenario: Any) -> GeofenceAlarm:
        return GeofenceAlarm(scenario)


GEOFENCE = GeofenceSection()
