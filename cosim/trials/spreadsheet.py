"""CSV cells that are safe to open in a spreadsheet (CSV or formula injection).

A spreadsheet runs a cell beginning with ``=``, ``+``, ``-`` or ``@`` as a
formula, and one beginning with a tab or a carriage return may be taken as
one too (OWASP, "CSV Injection"). The trials' CSVs carry text that
participants or a study's author typed (participant ids, target names, clip
and run names), so every text cell that begins so gets a leading ``'``:
spreadsheets show the text and run nothing. A number stays a number: ``-1.5``
or ``+2e-3`` is left as it is.

Owns only the cells; the callers own their columns and files.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterable, Iterator
from typing import Any

#: what a spreadsheet may run as a formula when a cell begins with it
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")


def safe_cell(text: str) -> str:
    """``text`` with a leading ``'`` if a spreadsheet would run it as a
    formula; a decimal number (``-1.5``, ``+2e-3``) is returned as it is."""
    if text.startswith(FORMULA_START) and not _NUMBER.fullmatch(text):
        return "'" + text
    return text


def safe_values(rows: Iterable[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Each row (a mapping of column -> value) with its text values made
    ``safe_cell``; numbers, booleans and None pass unchanged."""
    for row in rows:
        yield {k: safe_cell(v) if isinstance(v, str) else v for k, v in row.items()}


class SafeWriter:
    """``csv.writer(f)`` (``f`` a text file opened with ``newline=""``) whose
    every text cell goes through ``safe_cell``."""

    def __init__(self, f: Any) -> None:
        self._w = csv.writer(f)

    def writerow(self, row: Iterable[Any]) -> None:
        self._w.writerow([safe_cell(c) if isinstance(c, str) else c for c in row])
