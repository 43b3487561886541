"""Run-folder fuzzing: one real short run (``camera_run``: a fixed-wing with
a nadir camera over a target), then mutated copies of its folder (files cut short, bytes
changed, symlinks to ``/dev/zero``, out of the folder and in loops, files
and columns missing, huge numbers, NaN, deep nesting, alias bombs, planted
journals, symlinks where the outputs go) through ``cosim export`` (every
format), ``visibility``, ``plot`` and ``recover``. Each must exit 0, or 2
with a message naming the folder; never a traceback (an exception escaping
``main``), a hang (a watchdog fails a case that takes too long) or a write
outside the run folder (the files the symlinks point at are checked byte for
byte after every command).

Seeded and bounded: ``MUTANTS`` mutants (``plot`` on every third: drawing
takes a second), about 10 s here; ``COSIM_FUZZ_SCALE=N`` multiplies them.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from cosim.cli import main
from tests.test_fuzz_scenarios import watchdog

MUTANTS = 60
COMMAND_LIMIT_S = 20
FILES = ("scenario.resolved.yaml", "summary.json", "events.jsonl",
         "states.parquet/part-000000.parquet", "cameras/uav_nadir.gt.csv")
OUTPUTS = ("track.acmi", "track.kml", "track.czml", "track.png", "visibility.csv",
           "summary.json.tmp", "track.kml.tmp", "visibility.csv.tmp", "track.png.tmp",
           "states.parquet/.part-000001.parquet.tmp")
NUMBERS = ["1e300", "-1e300", ".nan", ".inf", "1" + "0" * 400, "-1", "0", "1e12"]
JSON_NUMBERS = ["1e400", "-1e400", "NaN", "Infinity", "1" + "0" * 5000, "-1", "0", "1e12",
                "1" + "0" * 30, '"x"', "null", "[]", "{}", "true"]
BAD_VALUES = [float("nan"), float("inf"), -float("inf"), 1e12, -1.0, 1e300, 95.0, -200.0]


pytestmark = pytest.mark.integration  # fuzzing: hundreds of commands


# -- mutations: each changes the copy ``run``; ``outside`` is a folder beside it --------
def _plain(p: Path) -> Path:
    """``p`` if it is a regular file (not one an earlier mutation made a
    symlink, perhaps to a FIFO that would block the mutation's reading)."""
    if p.is_symlink() or not p.is_file():
        raise OSError(f"{p}: not a regular file any more")
    return p


def _truncate(rng: random.Random, run: Path, outside: Path) -> None:
    p = _plain(run / rng.choice(FILES))
    data = p.read_bytes()
    p.write_bytes(data[:rng.randrange(len(data) + 1)])


def _garble(rng: random.Random, run: Path, outside: Path) -> None:
    p = _plain(run / rng.choice(FILES))
    data = bytearray(p.read_bytes())
    for _ in range(rng.choice([1, 3, 20])):
        at = rng.randrange(len(data) + 1)
        junk = rng.choice([b"\x00", b"\xff\xfe", b"\n", b"[", b"{", b"*", b"-", b'"',
                           bytes(rng.randrange(256) for _ in range(8))])
        data[at:at + rng.choice([0, 1, 4])] = junk
    p.write_bytes(bytes(data))


def _link(rng: random.Random, run: Path, outside: Path) -> None:
    name = rng.choice([*FILES, "states.parquet", "cameras", "events.jsonl"])
    p = run / name
    kept = outside / f"copy-{p.name}"  # a tempting target: the real content, outside
    if p.is_symlink():
        raise OSError(f"{p}: a symlink already")
    if p.is_dir():
        shutil.copytree(p, kept)
        shutil.rmtree(p)
    else:
        shutil.copy(p, kept)
        p.unlink()
    target = rng.choice(["/dev/zero", str(kept), str(outside / "missing"), str(p),
                         os.path.relpath(kept, p.parent), str(outside / "fifo")])
    p.symlink_to(target)


def _remove(rng: random.Random, run: Path, outside: Path) -> None:
    p = run / rng.choice([*FILES, "states.parquet", "cameras"])
    shutil.rmtree(p) if p.is_dir() else p.unlink()


def _yaml(rng: random.Random, run: Path, outside: Path) -> None:
    p = _plain(run / "scenario.resolved.yaml")
    text = p.read_text()
    op = rng.randrange(7)
    if op == 0:
        text = ("a0: &a0 [x, x, x, x, x, x, x, x]\n" + "".join(
            f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 8)}]\n" for i in range(1, 9))) + text
    elif op == 1:
        depth = rng.choice([40, 5000])
        text += "deep: " + "[" * depth + "]" * depth + "\n"
    elif op == 2:
        found = list(re.finditer(r"(?<=: )-?\d+(\.\d+)?(?=\n)", text))
        m = rng.choice(found)
        text = text[:m.start()] + rng.choice(NUMBERS) + text[m.end():]
    elif op == 3:
        text = text.replace("vehicles:\n", f"vehicles: {rng.choice(['5', 'x', '{}'])}\nx:\n", 1)
    elif op == 4:
        text = text.replace("- id: uav", f"- id: {rng.choice(['x' * 300, '[1]', '~', 'uav'])}"
                                         "\n  model: uav700\n- id: uav", 1)
    elif op == 5:
        text += "obstacles: " + rng.choice(["5", "[1]", "[{polygon: [[1e300, 0], [0, 1], [1, "
                                                         "1]]}]", "[{polygon: [[1, 2]]}]"]) + "\n"
    else:
        text = text.replace("origin:\n", "origin: 7\nx:\n", 1)
    p.write_text(text)


def _json(rng: random.Random, run: Path, outside: Path) -> None:
    if rng.random() < 0.5:
        p = _plain(run / "events.jsonl")
        n = rng.choice(JSON_NUMBERS)
        line = rng.choice([
            f'{{"event": "goal_reached", "tick": {n}, "vehicle": "uav"}}',
            f'{{"event": {n}, "tick": 1, "vehicle": "uav"}}',
            f'{{"event": "stall", "tick": 1, "vehicle": {n}}}',
            "[1, 2]", "[" * 3000 + "]" * 3000, "not json",
            '{"event": "x", "tick": 1, "pad": "' + "y" * 2_000_000 + '"}',
            '{"event": "stop", "tick": 99999999999999}'])
        with p.open("a") as f:
            f.write(line + rng.choice(["\n", ""]))
        return
    p = _plain(run / "summary.json")
    s = json.loads(p.read_text())
    stream = s["cameras"]["streams"][0]
    op = rng.randrange(6)
    if op == 0:
        s["physics_hz"] = "__N__"
    elif op == 1:
        stream["rate_hz"] = "__N__"
    elif op == 2:
        stream["ground_truth"] = rng.choice(["../../outside/secret.csv", "/dev/zero", 5, "",
                                             "cameras", "cameras/../../" + "x" * 300])
    elif op == 3:
        s["cameras"] = rng.choice(["x", 5, [1], {"streams": 7}, [None]])
    elif op == 4:
        s["complete"] = False
        s["nested"] = "__DEEP__"
    else:
        s = rng.choice([[], "x", 5])
    text = json.dumps(s).replace('"__N__"', rng.choice(JSON_NUMBERS))
    p.write_text(text.replace('"__DEEP__"', "[" * 5000 + "]" * 5000))


def _states(rng: random.Random, run: Path, outside: Path) -> None:
    p = _plain(run / "states.parquet" / "part-000000.parquet")
    t = pq.read_table(p)
    op = rng.randrange(5)
    if op == 0:
        t = t.drop([rng.choice(t.column_names)])
    elif op in (1, 2):
        name = rng.choice(["time_s", "lat_deg", "lon_deg", "alt_msl_m", "yaw_deg", "north_m",
                           "east_m", "tick", "vn_mps"])
        a = t[name].to_numpy().astype(float)
        a[rng.randrange(len(a))] = rng.choice(BAD_VALUES)
        t = t.set_column(t.schema.get_field_index(name), name, pa.array(a))
    elif op == 3:
        name = rng.choice(["lat_deg", "vehicle", "tick"])
        t = t.set_column(t.schema.get_field_index(name), name,
                         pa.array([None if i == 3 else "x" for i in range(t.num_rows)]))
    else:
        for k in range(1, rng.choice([2, 30])):  # many parts
            pq.write_table(t, p.parent / f"part-{k:06d}.parquet")
    pq.write_table(t, p)


def _journal(rng: random.Random, run: Path, outside: Path) -> None:
    """A killed run: ticks journalled (whole, cut short, garbage, linked away)."""
    states = run / "states.parquet"
    t = pq.read_table(_plain(states / "part-000000.parquet"))
    j = states / f"_journal-{rng.choice([0, 1]):06d}.arrows"
    if j.is_symlink():
        raise OSError(f"{j}: linked away already")
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, t.schema) as w:
        for b in t.to_batches(max_chunksize=5):
            w.write_batch(b)
    data = sink.getvalue().to_pybytes()
    op = rng.randrange(4)
    if op == 0:
        j.write_bytes(data)
    elif op == 1:
        j.write_bytes(data[:rng.randrange(len(data))])
    elif op == 2:
        j.write_bytes(bytes(rng.randrange(256) for _ in range(rng.choice([0, 8, 5000]))))
    else:
        j.symlink_to(rng.choice(["/dev/zero", str(outside / "fifo"), str(j)]))
    s = json.loads(_plain(run / "summary.json").read_text())
    s.update(complete=False, stop_reason="running")
    (run / "summary.json").write_text(json.dumps(s))


def _csv(rng: random.Random, run: Path, outside: Path) -> None:
    p = _plain(run / "cameras" / "uav_nadir.gt.csv")
    lines = p.read_text().splitlines(keepends=True)
    op = rng.randrange(5)
    if op == 0:
        lines[0] = lines[0].replace(rng.choice(["frame", "time_s", "in_view", "target"]), "x")
    elif op == 1:
        k = rng.randrange(1, len(lines))
        cells = lines[k].rstrip("\n").split(",")
        cells[rng.choice([0, 1, 5, 14, 17])] = rng.choice(
            ["x", "nan", "inf", "1e400", "-5", "2", "1" + "0" * 400, ""])
        lines[k] = ",".join(cells) + "\n"
    elif op == 2:
        lines.insert(rng.randrange(1, len(lines)), rng.choice(
            ["1,2,3\n", "a" * 200_000 + "\n", "\x00\n", '"open quote\n', "," * 21 + "\n"]))
    elif op == 3:
        lines = lines[:1] + lines[1:][::-1]  # times that fall as frames rise
    else:
        lines = [lines[0]] * rng.choice([1, 3])
    p.write_text("".join(lines))


def _outputs(rng: random.Random, run: Path, outside: Path) -> None:
    """Symlinks where the commands write, pointing out of the folder."""
    for name in rng.sample(OUTPUTS, rng.choice([1, 3, len(OUTPUTS)])):
        target = rng.choice([outside / "secret.csv", outside / f"new-{name.replace('/', '_')}"])
        if (run / name).parent.is_dir() and not (run / name).parent.is_symlink():
            (run / name).symlink_to(target)


MUTATIONS: list[Callable[[random.Random, Path, Path], None]] = [
    _truncate, _garble, _link, _remove, _yaml, _json, _json, _states, _states, _journal,
    _csv, _outputs]


def mutate(rng: random.Random, run: Path, outside: Path) -> list[str]:
    """One or two mutations of ``run`` (a second one that finds its file
    already unreadable by pyarrow or json is skipped); their names."""
    done = []
    for _ in range(rng.choice([1, 1, 2])):
        m = rng.choice(MUTATIONS)
        try:
            m(rng, run, outside)
        except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError):
            continue  # (pa.ArrowInvalid is a ValueError)
        done.append(m.__name__)
    return done


def _snapshot(root: Path) -> dict[str, str]:
    """Every file and link under ``root``: its content's hash (a link: its target)."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p)] = "-> " + os.readlink(p)
        elif p.is_file():
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
        elif not p.is_dir():
            out[str(p)] = "special"
    return out


def _check(args: list[str], run: Path, outside: Path, capsys: pytest.CaptureFixture[str]
           ) -> int:
    before = _snapshot(outside)
    with watchdog(COMMAND_LIMIT_S, " ".join(args[:1] + args[2:])):
        rc = main(args)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert rc in (0, 2), (args, rc, err)
    if rc == 2:
        assert str(run) in err, (args, err)  # the message names the file it is about
    assert _snapshot(outside) == before, f"{args}: wrote outside the run folder"
    return rc


def fuzz(tmp_path: Path, base: Path, capsys: pytest.CaptureFixture[str], seed: int,
         mutants: int) -> dict[int, int]:
    rng = random.Random(seed)
    outcomes = {0: 0, 2: 0}
    for k in range(mutants):
        case = tmp_path / f"case-{k}"
        run, outside = case / "run", case / "outside"
        shutil.copytree(base, run)
        outside.mkdir()
        (outside / "secret.csv").write_text("frame,time_s\n")
        os.mkfifo(outside / "fifo")
        with watchdog(COMMAND_LIMIT_S, f"mutating case {k}"):
            mutate(rng, run, outside)
        for fmt in ("acmi", "kml", "czml"):
            outcomes[_check(["export", str(run), "--format", fmt], run, outside, capsys)] += 1
        outcomes[_check(["visibility", str(run)], run, outside, capsys)] += 1
        if k % 3 == 0:
            outcomes[_check(["plot", str(run)], run, outside, capsys)] += 1
        outcomes[_check(["recover", str(run)], run, outside, capsys)] += 1
        shutil.rmtree(case)
    return outcomes


def test_mutated_run_folders_are_read_cleanly(tmp_path: Path, camera_run: Path,
                                              capsys) -> None:
    scale = int(os.environ.get("COSIM_FUZZ_SCALE", "1"))
    outcomes = fuzz(tmp_path, camera_run, capsys, seed=7, mutants=MUTANTS * scale)
    # the mutations must exercise both outcomes, or the test proves nothing
    assert outcomes[0] > 20 and outcomes[2] > 20, outcomes
