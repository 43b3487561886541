"""SAGAT freeze probes: their questions, the true state at a freeze, and the
scoring of a participant's answers against it.

At a probe's time (``at_s`` seconds into a live trial) the participant's
feeds and map blank and the page asks the probe's questions. Kinds:

- ``last_target``: where was the last target seen? A click on the map,
  answered as ``{north_m, east_m}``; scored by its distance (m) from where
  that target is (the target whose latest sighting in any feed is the
  latest at the freeze), correct within ``tolerance_m``.
- ``count``: how many aircraft are in a sector (a polygon of
  ``[north_m, east_m]`` corners on the map)? A whole number; the error is
  the answer less the true count (aircraft inside by the even-odd rule),
  correct within ``tolerance`` (default 0).
- ``choice``: which aircraft is ``lowest`` or ``highest`` in ``of``
  (``fuel_kg``, ``alt_agl_m``, ``alt_msl_m``, ``airspeed_mps`` or
  ``distance_m`` from a point ``from: [north_m, east_m]``, horizontal)? A
  vehicle id; correct if it is (one of) the extreme ones, the error how far
  its value is from the extreme (in the quantity's unit, >= 0).

The true state is a ``FreezeState``: the vehicles as a run's state log
holds them (``from_state_log`` reads one from ``states.parquet`` at a time)
and the targets with when each was last seen in any feed (visible by the
reports' rules, ``live_scoring``): ``freeze_state_from_run`` makes one from
a live trial's run folder, or the live console hands one in. The fuel on
board is the state log's ``fuel_kg`` (JSBSim fixed-wings; a study whose
conditions have aircraft that record none is refused a fuel question when it
is read, ``instruments``); a fuel question is scored only from a state that
carries it (``VehicleAt.fuel_kg``, finite), and refused (``ScoringError``)
otherwise. Nothing
here knows about HTTP, the study file or the store.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from cosim.core.geo import MAX_DISTANCE_M
from cosim.errors import CosimError
from cosim.logs.runfolder import read_states
from cosim.trials.live_scoring import ScoringSettings, TargetFrame, read_run_truth, visible

KINDS = ("last_target", "count", "choice")
WHICH = ("lowest", "highest")
CHOICE_OF = ("fuel_kg", "alt_agl_m", "alt_msl_m", "airspeed_mps", "distance_m")
MAX_PROBES = 50
MAX_QUESTIONS = 20
MAX_SECTOR_VERTICES = 64
MAX_TEXT_CHARS = 300
#: the latest probe (s into a trial): a day
MAX_PROBE_S = 86_400.0
#: map coordinates (m from the scenario's origin)
MAX_COORD_M = MAX_DISTANCE_M
#: a count answer's largest value
MAX_COUNT = 100_000
VEHICLE_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
#: the state log's columns a freeze state reads
LOG_COLUMNS = ("time_s", "vehicle", "north_m", "east_m", "alt_msl_m", "alt_agl_m",
               "airspeed_mps")

#: the default question of each kind (a question's ``text`` replaces it)
DEFAULT_TEXT = {
    "last_target": "Where was the last target seen? Click the spot on the map.",
    "count": "How many aircraft are in the marked sector?",
}
_CHOICE_TEXT = {
    ("lowest", "fuel_kg"): "Which aircraft is lowest on fuel?",
    ("highest", "fuel_kg"): "Which aircraft has the most fuel?",
    ("lowest", "alt_agl_m"): "Which aircraft is lowest above the ground?",
    ("highest", "alt_agl_m"): "Which aircraft is highest above the ground?",
    ("lowest", "alt_msl_m"): "Which aircraft is lowest?",
    ("highest", "alt_msl_m"): "Which aircraft is highest?",
    ("lowest", "airspeed_mps"): "Which aircraft is slowest?",
    ("highest", "airspeed_mps"): "Which aircraft is fastest?",
    ("lowest", "distance_m"): "Which aircraft is nearest the marked point?",
    ("highest", "distance_m"): "Which aircraft is furthest from the marked point?",
}


class ScoringError(CosimError):
    """A question that cannot be scored against the state given."""


@dataclass(frozen=True)
class Question:
    id: str
    kind: str
    text: str = ""
    tolerance_m: float = 50.0
    tolerance: int = 0
    sector: tuple[tuple[float, float], ...] = ()
    which: str | None = None
    of: str | None = None
    point: tuple[float, float] | None = None

    @property
    def shown_text(self) -> str:
        if self.text:
            return self.text
        if self.kind == "choice":
            return _CHOICE_TEXT[(self.which or "lowest", self.of or "alt_msl_m")]
        return DEFAULT_TEXT[self.kind]

    def page_view(self) -> dict[str, Any]:
        """What the participant's page needs to ask it (never the answer)."""
        out: dict[str, Any] = {"id": self.id, "kind": self.kind, "text": self.shown_text}
        if self.sector:
            out["sector"] = [list(p) for p in self.sector]
        if self.point is not None:
            out["point"] = list(self.point)
        return out


@dataclass(frozen=True)
class Probe:
    index: int
    at_s: float
    questions: tuple[Question, ...]


@dataclass(frozen=True)
class VehicleAt:
    """One aircraft at the freeze (the state log's columns; fuel if known)."""

    id: str
    north_m: float
    east_m: float
    alt_msl_m: float
    alt_agl_m: float
    airspeed_mps: float
    fuel_kg: float | None = None


@dataclass(frozen=True)
class TargetAt:
    """One target at the freeze: where it is and when it was last seen in any
    feed (None: not yet)."""

    id: str
    north_m: float
    east_m: float
    last_seen_s: float | None = None


@dataclass(frozen=True)
class FreezeState:
    """The true state at a freeze, ``time_s`` into the trial's run."""

    time_s: float
    vehicles: tuple[VehicleAt, ...]
    targets: tuple[TargetAt, ...] = ()

    def last_target(self) -> TargetAt | None:
        """The target seen last by the freeze (the first listed of a tie)."""
        seen = [t for t in self.targets
                if t.last_seen_s is not None and t.last_seen_s <= self.time_s]
        return max(seen, key=lambda t: t.last_seen_s or 0.0) if seen else None


@dataclass(frozen=True)
class Score:
    correct: bool
    #: metres (last_target), answer - truth (count), distance from the extreme (choice);
    #: None when there is nothing to measure (no target seen; an id not flying)
    error: float | None
    truth: Any


def from_state_log(table: pa.Table, time_s: float,
                   targets: tuple[TargetAt, ...] = ()) -> FreezeState:
    """The state at ``time_s`` from a run's state log (``read_states``):
    each vehicle's last row at or before it (a vehicle with none is left
    out), with ``fuel_kg`` where the log has such a column."""
    have = set(table.column_names)
    missing = [c for c in LOG_COLUMNS if c not in have]
    if missing:
        raise ScoringError(f"the state log lacks columns {', '.join(missing)}")
    t = table["time_s"].to_numpy()
    names = table["vehicle"].cast(pa.string()).to_pylist()
    cols = {c: table[c].to_numpy() for c in LOG_COLUMNS[2:]}
    fuel = table["fuel_kg"].to_numpy() if "fuel_kg" in have else None
    last: dict[str, int] = {}
    for i in np.flatnonzero(t <= time_s + 1e-9):
        last[names[i]] = int(i)  # rows in tick order: the last one wins
    vehicles = tuple(VehicleAt(
        id=v, **{c: float(cols[c][i]) for c in cols},
        fuel_kg=None if fuel is None else float(fuel[i])) for v, i in last.items())
    return FreezeState(time_s=float(time_s), vehicles=vehicles, targets=targets)


def last_sightings(truth: Iterable[TargetFrame], time_s: float,
                   settings: ScoringSettings | None = None) -> dict[str, float]:
    """Each target's latest time on screen at or before ``time_s`` in any
    feed, in a frame where it counts as visible (``live_scoring.visible``:
    the same thresholds as the reports' scoring)."""
    s = settings or ScoringSettings()
    out: dict[str, float] = {}
    for t in truth:
        if t.time_s <= time_s + 1e-9 and visible(t, s) and t.time_s > out.get(t.target, -1.0):
            out[t.target] = t.time_s
    return out


def freeze_state_from_run(run_dir: str | Path, feeds: Sequence[str], time_s: float,
                          positions: Mapping[str, tuple[float, float]],
                          settings: ScoringSettings | None = None) -> FreezeState:
    """The true state ``time_s`` into a live trial, from its run folder: the
    aircraft as its ``states.parquet`` holds them (``from_state_log``); the
    targets at ``positions`` (``{id: (north_m, east_m)}``, the scenario's:
    e.g. the renderer's ``TargetSet``) with their last sightings in the
    ``feeds`` the participant watched (``VEHICLE/CAMERA``, their ground
    truth: ``last_sightings``)."""
    seen = last_sightings(read_run_truth(run_dir, list(feeds)), time_s, settings)
    targets = tuple(TargetAt(k, float(n), float(e), seen.get(k))
                    for k, (n, e) in positions.items())
    return from_state_log(read_states(run_dir), time_s, targets)


def inside_polygon(north_m: float, east_m: float, poly: tuple[tuple[float, float], ...]) -> bool:
    """Whether the point is inside the polygon (even-odd rule; ``[north,
    east]`` corners)."""
    inside = False
    n = len(poly)
    for k in range(n):
        (n0, e0), (n1, e1) = poly[k], poly[(k + 1) % n]
        if (n0 > north_m) != (n1 > north_m):
            e_cross = e0 + (north_m - n0) * (e1 - e0) / (n1 - n0)
            if east_m < e_cross:
                inside = not inside
    return inside


def quantity(q: Question, v: VehicleAt) -> float:
    """The value a choice question compares, of vehicle ``v``."""
    if q.of == "distance_m":
        pn, pe = q.point or (0.0, 0.0)
        return math.hypot(v.north_m - pn, v.east_m - pe)
    value = getattr(v, q.of or "")
    if value is None or not math.isfinite(value):
        raise ScoringError(f"question {q.id!r} asks {q.of}, which the state at the freeze does "
                           f"not hold for {v.id!r} (its class records no fuel)")
    return float(value)


def check_answer(q: Question, v: Any) -> Any:
    """A posted answer to ``q`` in its kind's form; ``ValueError`` says what
    is wrong."""
    if q.kind == "last_target":
        ok = isinstance(v, dict) and set(v) == {"north_m", "east_m"} and all(
            not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)
            and abs(x) <= MAX_COORD_M for x in v.values())
        if not ok:
            raise ValueError(f"{q.id}: expected {{north_m, east_m}}, finite, within "
                             f"+-{MAX_COORD_M:g} m, got {v!r}"[:300])
        return {"north_m": float(v["north_m"]), "east_m": float(v["east_m"])}
    if q.kind == "count":
        if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= MAX_COUNT:
            raise ValueError(f"{q.id}: expected a whole number 0..{MAX_COUNT}, got {v!r}"[:300])
        return v
    if not isinstance(v, str) or not VEHICLE_ID.match(v):
        raise ValueError(f"{q.id}: expected an aircraft's id, got {v!r}"[:300])
    return v


def score(q: Question, state: FreezeState, answer: Any) -> Score:
    """The answer (checked by ``check_answer``) against the state at the freeze."""
    if q.kind == "last_target":
        t = state.last_target()
        if t is None:
            return Score(False, None, None)
        d = math.hypot(answer["north_m"] - t.north_m, answer["east_m"] - t.east_m)
        return Score(d <= q.tolerance_m, d, {"target": t.id, "north_m": t.north_m,
                                             "east_m": t.east_m})
    if q.kind == "count":
        truth = sum(inside_polygon(v.north_m, v.east_m, q.sector) for v in state.vehicles)
        return Score(abs(answer - truth) <= q.tolerance, float(answer - truth), truth)
    values = {v.id: quantity(q, v) for v in state.vehicles}
    if not values:
        raise ScoringError(f"question {q.id!r}: no aircraft in the state at the freeze")
    best = min(values.values()) if q.which == "lowest" else max(values.values())
    extreme = sorted(k for k, x in values.items() if x == best)
    if answer not in values:
        return Score(False, None, extreme)
    return Score(answer in extreme, abs(values[answer] - best), extreme)
