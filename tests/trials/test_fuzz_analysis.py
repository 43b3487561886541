"""Trial-analysis fuzzing: mutated copies of valid responses files (the
analysis tests' designs and a trial server's export) go through ``cosim
trials analyse``. Each must end with exit 0, or exit 2 and a message; never a
traceback (an exception escaping ``main``), a hang (a watchdog fails a case
that takes too long) or a file written outside the output folder.

Mutations: wrong types, extreme numbers, NaN and infinities, missing and
duplicated columns, huge cells, formula cells, many distinct held values,
many targets, rows dropped, doubled, swapped or indented, and bytes (cut
short, invalid UTF-8, NUL, a byte-order mark). Seeded and bounded:
``MUTANTS`` cases (about 15 s of CPU here); ``COSIM_FUZZ_SCALE=N`` multiplies
that (5 ran clean: 150 cases).
"""

from __future__ import annotations

import csv
import io
import os
import random
from collections.abc import Callable
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.trials.store import write_csv
from tests.test_fuzz_scenarios import _bytes, _files, _line, watchdog
from tests.trials.test_analysis import (
    COLUMNS,
    OPTIONAL_COLUMNS,
    _exp1_rows,
    _exp2_rows,
    _ground_rows,
    _write,
)
from tests.trials.test_store import _response

MUTANTS = 30
LIMIT_S = 30  # a case slower than this is a hang

WRONG_TYPES = ["abc", "1,5", "[]", "true", "0x10", "1e", "--1", "\u0661\u0662", "\u00bd", " ",
               "None", "1 2", "'3'", "\u00a0"]
EXTREME_NUMBERS = ["1e308", "-1e308", "1e-320", "0", "-0", "9" * 400, "nan", "NaN", "inf",
                   "-inf", "Infinity", "1_000", "-1", "4294967296", "1e9", "0.0000001"]
FORMULAS = ["=1+1", "@SUM(A1)", "+cmd|' /C calc'!A0", "-2+3", "\t=x", "=HYPERLINK(\"x\")"]


pytestmark = pytest.mark.integration  # fuzzing: many analyses


def _corpus(tmp: Path) -> list[str]:
    """Valid responses files: both experiments; altitudes seen from the
    camera (the optional columns); a trial server's export."""
    texts = []
    rows = _exp1_rows(seed=1, trials=2, targets=("truck", "firetruck")) + _exp2_rows(seed=1,
                                                                                     reps=2)
    texts.append(_write(tmp / "exp.csv", rows).read_text())
    texts.append(_write(tmp / "ground.csv", _ground_rows(seed=1, people=3, trials=1),
                        COLUMNS + OPTIONAL_COLUMNS).read_text())
    export = io.StringIO(newline="")
    write_csv([{**_response("s1", i, participant=f"p{i % 4}", condition_alt_agl_m=str(h),
                            camera_gap_deg=2.0 + i % 5, target_depth_m=h - 1.75,
                            reshown=False, practice=False)}
               for i, h in enumerate([30.0, 60.0, 100.0, 150.0, 200.0] * 4)], export)
    texts.append(export.getvalue())
    return texts


def _table(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text, newline="")))


def _text(rows: list[list[str]]) -> str:
    f = io.StringIO(newline="")
    csv.writer(f).writerows(rows)
    return f.getvalue()


def _cell(rng: random.Random, text: str, values: list[str]) -> str:
    rows = _table(text)
    if len(rows) < 2:
        return text
    row = rng.randrange(1, len(rows))
    if rows[row]:
        rows[row][rng.randrange(len(rows[row]))] = rng.choice(values)
    return _text(rows)


def _type(rng: random.Random, text: str) -> str:
    return _cell(rng, text, WRONG_TYPES)


def _number(rng: random.Random, text: str) -> str:
    return _cell(rng, text, EXTREME_NUMBERS)


def _formula(rng: random.Random, text: str) -> str:
    return _cell(rng, text, FORMULAS)


def _column(rng: random.Random, text: str) -> str:
    """A column dropped, doubled or renamed, or the header alone."""
    rows = _table(text)
    k = rng.randrange(len(rows[0]))
    op = rng.randrange(4)
    if op == 0:
        rows = [r[:k] + r[k + 1:] for r in rows]
    elif op == 1:
        rows = [r + [r[k]] if len(r) > k else r for r in rows]
    elif op == 2:
        rows[0][k] = rows[0][k].upper()
    else:
        rows = rows[:1]
    return _text(rows)


def _huge(rng: random.Random, text: str) -> bytes:
    """A huge cell (beyond the CSV reader's field limit, it ends the mutations)."""
    return _cell(rng, text, ["x" * rng.choice([5_000, 120_000, 300_000])]).encode()


def _held(rng: random.Random, text: str) -> str:
    """Many distinct held values: the rows again and again, each time at new
    altitudes or viewing distances (a measured value instead of a swept one)."""
    rows = _table(text)
    header = rows[0]
    col = header.index(rng.choice(["condition_alt_agl_m", "viewing_distance_mm"])) \
        if "condition_alt_agl_m" in header else 0
    out = [header]
    for _ in range(rng.choice([3, 20])):
        for r in rows[1:]:
            r = list(r)
            if len(r) > col:
                r[col] = f"{rng.uniform(300.0, 1200.0):.1f}"
            out.append(r)
    return _text(out)


def _targets(rng: random.Random, text: str) -> str:
    """A target per row (as many targets as rows: more fits than the limit)."""
    rows = _table(text)
    header = rows[0]
    if "condition_target" not in header:
        return text
    col = header.index("condition_target")
    out = [header]
    for k in range(rng.choice([2, 12])):
        for i, r in enumerate(rows[1:]):
            if len(r) > col:
                out.append(r[:col] + [f"t{k}-{i // 2}"] + r[col + 1:])
    return _text(out)


MUTATIONS: list[Callable[[random.Random, str], str | bytes]] = [
    _type, _number, _number, _formula, _column, _huge, _held, _targets, _line, _bytes]


def mutate(rng: random.Random, text: str) -> bytes:
    """One or two mutations of ``text`` (a change of bytes ends it)."""
    out: str | bytes = text
    for _ in range(rng.choice([1, 1, 2])):
        if isinstance(out, bytes):
            break
        out = rng.choice(MUTATIONS)(rng, out)
    return out if isinstance(out, bytes) else out.encode()


def test_mutated_responses_analyse_cleanly(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    scale = int(os.environ.get("COSIM_FUZZ_SCALE", "1"))
    rng = random.Random(17)
    corpus = _corpus(tmp_path)
    outcomes = {0: 0, 2: 0}
    for k in range(MUTANTS * scale):
        case = tmp_path / f"case{k}"
        case.mkdir()
        src = case / "responses.csv"
        src.write_bytes(mutate(rng, rng.choice(corpus)))
        before = _files(tmp_path)
        with watchdog(LIMIT_S, f"cosim trials analyse {src}"):
            rc = main(["-q", "trials", "analyse", str(src), "--out", str(case / "out")])
        out = capsys.readouterr()
        assert "Traceback" not in out.err, out.err
        assert rc in (0, 2), (k, rc, out.err)
        if rc == 2:
            assert out.err.strip(), f"case {k}: exit 2 without a message"
        outside = [p for p in _files(tmp_path) - before if (case / "out") not in p.parents]
        assert not outside, outside
        outcomes[rc] += 1
    # the mutations must reach both outcomes, or the test proves nothing
    assert outcomes[0] >= 0.15 * MUTANTS * scale and outcomes[2] >= 0.15 * MUTANTS * scale, \
        outcomes
