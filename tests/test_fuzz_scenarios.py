"""Scenario fuzzing: mutated copies of every bundled scenario (types, numbers,
keys, lines, aliases, sizes, names, templates, bytes) go through ``cosim
validate`` and, where they are valid, a short ``cosim run``. Each must end
with exit 0, or exit 2 and messages that carry their file line; never a
traceback (an exception escaping ``main``), a hang (a watchdog fails a case
that takes too long) or a file written outside the run folder.

Seeded and bounded: the integration tier runs ``MUTANTS_PER_SCENARIO``
mutants of each scenario (about 260 validations and a dozen runs, ~20 s
here); ``COSIM_FUZZ_SCALE=N`` multiplies that, and the ``slow`` test runs
``SLOW_MUTANTS_PER_SCENARIO`` of each with another seed (``python -m pytest
-m slow -k fuzz``).
"""

from __future__ import annotations

import contextlib
import os
import random
import re
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = sorted((REPO / "scenarios").rglob("*.yaml"))
MUTANTS_PER_SCENARIO = 12
#: the slow test's mutants of each scenario, and its short runs in all
SLOW_MUTANTS_PER_SCENARIO = 500
SLOW_RUNS = 240
RUNS = 12  # short runs of mutants that validate, per fuzz pass
VALIDATE_LIMIT_S = 20  # a mutant slower than this to validate is a hang
RUN_LIMIT_S = 60
#: runs are kept small and off the network (a mutant may name a fixed port)
RUN_MAX_VEHICLES = 40

EXTREME_NUMBERS = ["0", "-1", "1e300", "-1e300", "1e-300", "-0.0", "1" + "0" * 400, ".nan",
                   ".inf", "-.inf", "9" * 30, "2147483648", "4294967296", "1e9", "0.5",
                   "123456789"]
WRONG_TYPES = ["high", "[]", "{}", "null", "true", "'12'", "[1, 2]", "{a: 1}", "~", "''",
               "'${x}'", "!!binary aGVsbG8=", "2001-12-14", "0x1F", "0o17", "1_000"]
PLACEHOLDERS = ["${10**10**10}", "${'a'*10**10}", "${9**9**7}", "${1/0}", "${nope}",
                "${__import__('os').system('true')}", "${(lambda: 1)()}", "${'%9999999d' % 1}",
                "${" + "(" * 300 + "1" + ")" * 300 + "}", "${2**62*4}", "${sqrt(-1)}",
                "${round(1.5, 10**9)}", "${1e308*10}", "${" + "1+" * 400 + "1}"]
NAMES = ["../../../escape", "/tmp/cosim-fuzz-abs/escape", "a/b", "..", ".", "x" * 300,
         "nul\x00byte", "tab\there", "semi;colon", "$(touch pwned)", "con", "*", "~"]
KEY = re.compile(r"\b([A-Za-z_][A-Za-z0-9_]*)(?=:\s)")  # \b: linear on long words
NUMBER = re.compile(r"(?<![\w.$])-?\d+(\.\d+)?([eE][-+]?\d+)?(?![\w.])")
SCALAR = re.compile(r"(?<=: )([^\s{}\[\],#][^,{}\[\]#\n]*)")


def _pick(rng: random.Random, pattern: re.Pattern[str], text: str) -> re.Match[str] | None:
    found = list(pattern.finditer(text))
    return rng.choice(found) if found else None


def _replace(text: str, m: re.Match[str] | None, new: str) -> str:
    return text if m is None else text[:m.start()] + new + text[m.end():]


def _number(rng: random.Random, text: str) -> str:
    return _replace(text, _pick(rng, NUMBER, text), rng.choice(EXTREME_NUMBERS))


def _type(rng: random.Random, text: str) -> str:
    return _replace(text, _pick(rng, SCALAR, text), rng.choice(WRONG_TYPES))


def _key(rng: random.Random, text: str) -> str:
    m = _pick(rng, KEY, text)
    if m is None:
        return text
    old = m.group(1)
    new = rng.choice([old[:-1] or "k", old + "s", old.upper(), "unknown_key", "<<", "? x"])
    return _replace(text, m, new)


def _line(rng: random.Random, text: str) -> str:
    lines = text.splitlines(keepends=True)
    if len(lines) < 2:
        return text
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    op = rng.randrange(4)
    if op == 0:
        del lines[i]
    elif op == 1:
        lines.insert(i, lines[i])
    elif op == 2:
        lines[i], lines[j] = lines[j], lines[i]
    else:
        lines[i] = "  " * rng.randrange(1, 6) + lines[i]
    return "".join(lines)


def _alias(rng: random.Random, text: str) -> str:
    bombs = [
        "x: &a [*a]\n",
        "x: &m {a: 1, b: {<<: *m}}\n",
        "a0: &a0 [x, x, x, x, x, x, x, x]\n" + "".join(
            f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 8)}]\n" for i in range(1, 9)),
        "".join(f"k{i}: &k{i} {i}\n" for i in range(120)),
        "d: *undefined\n",
        "e: &e {x: 1}\nf: {<<: [*e, *e, *e]}\n",
    ]
    return rng.choice(bombs) + text


def _size(rng: random.Random, text: str) -> str:
    choice = rng.randrange(6)
    if choice == 0:
        return re.sub(r"(?m)^name: .*$", "", text) + f"name: {rng.choice(NAMES)!r}\n"
    if choice == 1:
        return re.sub(r"\bid: ([\w.\-]+)", lambda m: "id: " + rng.choice(NAMES[:6]), text,
                      count=1)
    if choice == 2:
        return re.sub(r"\bcount: \d+", f"count: {rng.choice([10**9, 100_000, 10_001])}", text,
                      count=1)
    if choice == 3:
        depth = rng.choice([40, 500, 5000])
        return text + "deep: " + "[" * depth + "]" * depth + "\n"
    if choice == 4:
        return text + "".join(f"junk{i}: {i}\n" for i in range(rng.choice([60, 2000])))
    return text + f"description: {'y' * rng.choice([10_000, 3_000_000])}\n"


def _template(rng: random.Random, text: str) -> str:
    m = _pick(rng, NUMBER, text)
    text = _replace(text, m, rng.choice(PLACEHOLDERS))
    if rng.random() < 0.3 and "sweep:" not in text:
        text += "sweep: {x: [1, 2], y: " + rng.choice(["[]", "[1, 1]", "{a: 1}", "[.nan]"]) + "}\n"
    return text


def _bytes(rng: random.Random, text: str) -> bytes:
    data = text.encode()
    at = rng.randrange(len(data) + 1)
    op = rng.randrange(4)
    if op == 0:
        return data[:at]  # cut short
    if op == 1:
        return data[:at] + rng.choice([b"\xff\xfe", b"\x00", b"\xe9", b"\t", b"\r"]) + data[at:]
    if op == 2:
        return data[:at] + bytes(rng.randrange(256) for _ in range(20)) + data[at:]
    return b"\xef\xbb\xbf" + data  # a byte-order mark


MUTATIONS: list[Callable[[random.Random, str], str | bytes]] = [
    _number, _number, _type, _key, _line, _alias, _size, _template, _bytes]


def mutate(rng: random.Random, text: str) -> bytes:
    """One to three mutations of ``text`` (a change of size or bytes ends it)."""
    out: str | bytes = text
    for _ in range(rng.choice([1, 1, 2, 3])):
        if isinstance(out, bytes) or len(out) > 4 * len(text):
            break
        out = rng.choice(MUTATIONS)(rng, out)
    return out if isinstance(out, bytes) else out.encode()


class Hang(Exception):
    pass


@contextlib.contextmanager
def watchdog(seconds: int, what: str) -> Iterator[None]:
    """Fail (raise ``Hang``) if the block takes longer than ``seconds``."""
    def on_alarm(signum: int, frame: object) -> None:
        raise Hang(f"{what} took more than {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file() or p.is_symlink()}


#: problems that legitimately carry no line (the file as a whole)
_WHOLE_FILE = re.compile(r": (\d+ bytes; a scenario file may have at most|cannot read scenario)")


def check_validate(path: Path, capsys: pytest.CaptureFixture[str]) -> bool:
    """``cosim validate`` on one mutant: exit 0, or 2 with line-numbered problems."""
    with watchdog(VALIDATE_LIMIT_S, f"validate {path.name}"):
        rc = main(["validate", str(path)])
    out = capsys.readouterr()
    assert "Traceback" not in out.err, out.err
    assert rc in (0, 2), (rc, out.err)
    if rc == 0:
        return True
    lines = [x for x in out.err.splitlines() if x and not x.startswith("... and ")]
    assert lines, "exit 2 without a message"
    prefix = re.escape(str(path))
    for x in lines:
        if not x.startswith(str(path)):
            continue  # the continuation of a multi-line message
        assert re.match(prefix + r":\d+: ", x) or _WHOLE_FILE.search(x), x
    return False


def check_run(path: Path, cwd: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A short ``cosim run`` of a valid mutant, from ``cwd`` without ``--out``:
    exit 0 (or 2 for vehicles JSBSim cannot trim), and every file it writes
    is inside ``cwd/runs``."""
    root = cwd.parent
    before = _files(root)
    old = Path.cwd()
    os.chdir(cwd)
    try:
        with watchdog(RUN_LIMIT_S, f"run {path.name}"):
            rc = main(["run", str(path), "--duration-s", "0.5", "--backend", "inline",
                       "--no-progress"])
    finally:
        os.chdir(old)
    out = capsys.readouterr()
    assert "Traceback" not in out.err, out.err
    assert rc in (0, 2), (rc, out.err)
    made = _files(root) - before
    outside = [p for p in made if (cwd / "runs") not in p.parents]
    assert not outside, outside


def fuzz(tmp_path: Path, capsys: pytest.CaptureFixture[str], seed: int, scale: int,
         runs: int | None = None) -> dict:
    rng = random.Random(seed)
    base = tmp_path / "a" / "b" / "c" / "d"  # room for ../../../ to land inside tmp_path
    stats = {"mutants": 0, "valid": 0, "runs": 0}
    runs_left = RUNS * scale if runs is None else runs
    for scenario in SCENARIOS:
        text = scenario.read_text()
        # relative files (ground images) resolve as from the original's folder
        folder = base / "scn" / scenario.relative_to(REPO / "scenarios").parent
        folder.mkdir(parents=True, exist_ok=True)
        for k in range(MUTANTS_PER_SCENARIO * scale):
            data = mutate(rng, text)
            path = folder / f"{scenario.stem}-{k}.yaml"
            path.write_bytes(data)
            stats["mutants"] += 1
            if not check_validate(path, capsys):
                continue
            stats["valid"] += 1
            if runs_left <= 0 or b"mavlink" in data or b"udp" in data:
                continue
            try:
                n = len(load_scenario(path).vehicles)
            except ConfigError:
                continue
            if n > RUN_MAX_VEHICLES:
                continue
            cwd = base / f"cwd-{stats['runs']}"
            cwd.mkdir()
            check_run(path, cwd, capsys)
            stats["runs"] += 1
            runs_left -= 1
    assert not Path("/tmp/cosim-fuzz-abs").exists()
    assert not list(tmp_path.glob("*escape*")) and not list(base.parent.glob("*escape*"))
    return stats


@pytest.mark.integration
def test_mutated_scenarios_validate_and_run_cleanly(tmp_path: Path, capsys) -> None:
    scale = int(os.environ.get("COSIM_FUZZ_SCALE", "1"))
    stats = fuzz(tmp_path, capsys, seed=13, scale=scale)
    # the mutations must exercise both outcomes, or the test proves nothing
    assert stats["mutants"] == len(SCENARIOS) * MUTANTS_PER_SCENARIO * scale
    assert 0.05 * stats["mutants"] < stats["valid"] < 0.95 * stats["mutants"], stats
    assert stats["runs"] >= min(RUNS * scale, 5), stats


@pytest.mark.slow
def test_mutated_scenarios_long(tmp_path: Path, capsys) -> None:
    scale = -(-SLOW_MUTANTS_PER_SCENARIO // MUTANTS_PER_SCENARIO)
    stats = fuzz(tmp_path, capsys, seed=1313, scale=scale, runs=SLOW_RUNS)
    assert stats["runs"] >= RUNS, stats
