"""The ``sweep:`` section as a sweep runs it: every combination of the
swept values (``SweepSpec.points``), those ``only: EXPRESSION`` allows (e.g.
``only: "tier == 'batched' or fleet <= 32"``), and each run's folder name.
The ``${...}`` placeholders and the values' rules are the scenario
language's (``cosim.scenario.placeholders``).
"""

from __future__ import annotations

import hashlib
import itertools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.scenario.placeholders import (
    ONLY,
    TOKEN,
    ExprError,
    P,
    Report,
    Scalar,
    evaluate,
    format_value,
    protect_placeholders,
    sweep_values,
    swept_names,
)

#: runs in one sweep (every combination of the swept values)
MAX_SWEEP_RUNS = 10_000
#: characters in a run's folder name (file systems allow 255 bytes)
MAX_FOLDER_CHARS = 120




@dataclass(frozen=True)
class SweepSpec:
    path: str
    values: dict[str, tuple[Scalar, ...]]
    swept: tuple[str, ...]  # the names given as lists (columns of visibility.csv)
    #: an expression over the names: only the combinations where it is true run
    only: str | None = None

    def points(self) -> list[dict[str, Scalar]]:
        """Every combination (those ``only`` allows), the first name varying
        slowest (file order)."""
        names = list(self.values)
        combos = [dict(zip(names, combo))
                  for combo in itertools.product(*(self.values[n] for n in names))]
        if self.only is None:
            return combos
        return [c for c in combos if evaluate(self.only, c)]

    def folder(self, point: Mapping[str, Scalar]) -> str:
        """The run's folder name: ``speed_kt=50,alt_agl_m=30,target=truck``
        (swept names only; characters unsafe in file names become ``_``). A name
        longer than ``MAX_FOLDER_CHARS`` is cut and ends in a hash of the whole,
        so it stays one valid, unique file name."""
        parts = [f"{n}={format_value(point[n])}" for n in self.swept] or ["run"]
        name = re.sub(r"[^A-Za-z0-9_.=,+\-]", "_", ",".join(parts))
        if len(name) > MAX_FOLDER_CHARS:
            digest = hashlib.sha256(name.encode()).hexdigest()[:16]
            name = f"{name[:MAX_FOLDER_CHARS - 17]}-{digest}"
        return name


def read_sweep(path: str | Path, parsed: tuple[Any, dict[P, int]] | None = None
               ) -> SweepSpec:
    """The ``sweep:`` section of a scenario file; ``ConfigError`` with lines.
    ``parsed``: the file's (data, lines) when the caller has parsed it already
    (placeholders protected)."""
    from cosim.scenario.yaml_lines import (
        YamlProblem,
        format_path,
        load_with_lines,
        read_scenario_text,
    )

    p = Path(path)
    if parsed is None:
        text = read_scenario_text(p)
        try:
            data, lines, _ = load_with_lines(protect_placeholders(text)[0])
        except YamlProblem as e:
            raise ConfigError([f"{p}:{ln}: {m}" for ln, m in e.problems]) from None
    else:
        data, lines = parsed
    problems: list[tuple[int, str]] = []

    def err(q: P, msg: str) -> None:
        while q and q not in lines:
            q = q[:-1]
        problems.append((lines.get(q, 1), f"{format_path(q)}: {msg}"))

    raw = data.get("sweep") if isinstance(data, dict) else None
    values = sweep_values(raw, err)
    if any(isinstance(v, str) and TOKEN.search(v) for vals in values.values() for v in vals):
        err(("sweep",), "placeholders are not allowed in the sweep: section")
    runs = math.prod(len(v) for v in values.values())
    if runs > MAX_SWEEP_RUNS:
        err(("sweep",), f"{runs} combinations; a sweep may have at most {MAX_SWEEP_RUNS} runs")
    only = raw.get(ONLY) if isinstance(raw, dict) else None
    if only is not None and not problems:
        only = _check_only(only, values, err)
    if problems:
        raise ConfigError([f"{p}:{ln}: {m}" for ln, m in sorted(problems, key=lambda x: x[0])])
    return SweepSpec(path=str(p), values=values, swept=tuple(swept_names(raw)), only=only)


def _check_only(only: Any, values: Mapping[str, tuple[Scalar, ...]], err: Report
                ) -> str | None:
    """``only:``, an expression over the sweep's names (e.g. ``tier == 'batched'
    or fleet <= 32``): it must evaluate to true or false for every
    combination and leave at least one."""
    if not isinstance(only, str) or not only.strip():
        err(("sweep", ONLY), f"expected an expression over the sweep names, e.g. "
                             f"\"fleet <= 32 or tier == 'batched'\", got {only!r}")
        return None
    names = list(values)
    kept = 0
    for combo in itertools.product(*(values[n] for n in names)):
        env = dict(zip(names, combo))
        try:
            v = evaluate(only, env)
        except ExprError as e:
            err(("sweep", ONLY), f"cannot evaluate {only!r}: {e}")
            return None
        if not isinstance(v, bool):
            err(("sweep", ONLY), f"{only!r} must be true or false, got {format_value(v)} at "
                                 + ", ".join(f"{k}={format_value(x)}" for k, x in env.items()))
            return None
        kept += v
    if not kept:
        err(("sweep", ONLY), f"{only!r} leaves no combination to run")
        return None
    return only
