"""How the trials analysis writes its files: CSV tables whose cells are
formatted alike and safe to open in a spreadsheet (``write_csv``, through
``cosim.trials.spreadsheet``), and values made fit for JSON (``json_clean``).

It computes nothing and reads nothing.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.spreadsheet import SafeWriter


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):  # as in the responses export
        return "1" if v else "0"
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def write_csv(path: Path, fields: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    """``rows`` (dicts) as a CSV of the columns ``fields``."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = SafeWriter(f)  # a target or participant named "=..." is not run as a formula
        w.writerow(fields)
        for row in rows:
            w.writerow([_fmt(row.get(k)) for k in fields])


def json_clean(v: Any) -> Any:
    """NaN/inf -> None, numpy scalars -> Python, tuples -> lists."""
    if isinstance(v, dict):
        return {str(k): json_clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_clean(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
