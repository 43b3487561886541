"""YAML loading that remembers where every value came from.

``load_with_lines`` returns plain Python data (as ``yaml.safe_load`` would)
plus a map from each value's path (a tuple of keys and indices) to its
1-based line, so validation can report ``file:line: path: message``.
Duplicate mapping keys are reported (``safe_load`` silently keeps the last).
Unquoted numbers in exponent form without a sign (``1e3``, ``2.5e-3`` is
fine already) are read as numbers, as YAML 1.2 and every user expect;
PyYAML's YAML 1.1 rules would make them strings.

The text is untrusted: ``read_scenario_text`` reads at most
``MAX_FILE_BYTES`` from a regular file, and ``load_with_lines`` refuses,
with the line of each, nesting deeper than ``MAX_DEPTH`` (checked on the
event stream before any recursive composing), more than ``MAX_ALIASES``
aliases, a recursive alias, more than ``MAX_NODES`` values once aliases are
expanded, and whole numbers beyond ``MAX_INT`` (see ``limits``).
"""

from __future__ import annotations

import contextlib
import os
import re
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import yaml

from cosim.core.limits import MAX_ALIASES, MAX_DEPTH, MAX_FILE_BYTES, MAX_INT, MAX_NODES
from cosim.errors import ConfigError

_EXP_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")

Path_ = tuple[Any, ...]


#: libyaml's parser when PyYAML was built with it (about 30x faster), else PyYAML's own
_Loader: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YamlProblem(Exception):
    """The text cannot be loaded: a syntax error, or a limit exceeded.
    ``line``/``message``: the first problem; ``problems``: all of them."""

    def __init__(self, line: int, message: str,
                 problems: list[tuple[int, str]] | None = None) -> None:
        super().__init__(line, message, problems)
        self.line = line
        self.message = message
        self.problems = problems or [(line, message)]


def read_scenario_text(path: str | Path) -> str:
    """The text of a scenario file: a regular file of at most
    ``MAX_FILE_BYTES`` bytes of UTF-8; ``ConfigError`` saying what is wrong
    otherwise (a device such as ``/dev/zero`` is never read)."""
    return read_text_bounded(path, MAX_FILE_BYTES, "scenario", "a scenario file")


@contextlib.contextmanager
def open_bounded(path: str | Path, limit: int, what: str, one: str) -> Iterator[BinaryIO]:
    """A regular file of at most ``limit`` bytes, open for reading (binary;
    ``what`` it is and ``one`` of them in the messages, as for
    ``read_text_bounded``); ``ConfigError`` saying what is wrong otherwise (a
    device such as ``/dev/zero`` or a FIFO is never read, nor waited for)."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise ConfigError(f"{p}: cannot read {what}: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
            raise ConfigError(f"{p}: cannot read {what}: {kind}")
        if st.st_size > limit:
            raise ConfigError(f"{p}: {st.st_size} bytes; {one} may have at most "
                              f"{limit} ({limit / 1024 / 1024:g} MiB)")
        with os.fdopen(fd, "rb", closefd=False) as f:
            yield f
    except OSError as e:
        raise ConfigError(f"{p}: cannot read {what}: {e.strerror or e}") from None
    finally:
        os.close(fd)


def read_bounded(f: BinaryIO, limit: int) -> bytes:
    """The rest of a file ``open_bounded`` opened: at most ``limit + 1``
    bytes (more than ``limit``: it grew since it was opened), read without
    setting aside ``limit`` bytes first."""
    data = f.read(min(os.fstat(f.fileno()).st_size, limit) + 1)
    while len(data) <= limit and (more := f.read(min(65536, limit + 1 - len(data)))):
        data += more
    return data


def read_text_bounded(path: str | Path, limit: int, what: str, one: str) -> str:
    """The UTF-8 text of a regular file of at most ``limit`` bytes (``what``
    it is, e.g. "scenario", and ``one`` of them, e.g. "a scenario file",
    in the messages); ``ConfigError`` saying what is wrong otherwise."""
    p = Path(path)
    with open_bounded(p, limit, what, one) as f:
        data = read_bounded(f, limit)
    if len(data) > limit:  # grew while we looked
        raise ConfigError(f"{p}: {one} may have at most {limit} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise ConfigError(f"{p}:{line}: cannot read {what}: not UTF-8 text (byte "
                          f"{data[e.start]:#04x} at offset {e.start})") from None


def _check_structure(text: str, max_nodes: int = MAX_NODES) -> None:
    """Nesting depth, alias count and the number of values once aliases are
    expanded, from the event stream: iterative (no recursion however deep the
    text nests) and before anything is expanded (an alias "bomb" is counted,
    not built)."""
    depth = aliases = total = 0
    open_: list[tuple[str | None, int]] = []  # (anchor, total before) per open collection
    size: dict[str, int] = {}  # anchor -> values it expands to
    problem: tuple[int, str] | None = None
    try:
        for ev in yaml.parse(text, Loader=_Loader):
            line = ev.start_mark.line + 1
            if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                open_.append((ev.anchor, total))
                total += 1
                depth += 1
                if depth > MAX_DEPTH:
                    problem = (line, f"nested more than {MAX_DEPTH} levels deep")
            elif isinstance(ev, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                anchor, before = open_.pop()
                depth -= 1
                if anchor is not None:
                    size[anchor] = total - before
            elif isinstance(ev, yaml.ScalarEvent):
                total += 1
                if ev.anchor is not None:
                    size[ev.anchor] = 1
            elif isinstance(ev, yaml.AliasEvent):
                aliases += 1
                total += size.get(ev.anchor, 1)  # not yet closed: recursive, found later
                if aliases > MAX_ALIASES:
                    problem = (line, f"more than {MAX_ALIASES} aliases (*name)")
            if problem is None and total > max_nodes:
                problem = (line, f"more than {max_nodes} values once aliases are expanded")
            if problem is not None:
                raise YamlProblem(*problem)
    except yaml.YAMLError:
        return  # compose reports the syntax error with its line


def _too_big(n: yaml.Node) -> str:
    digits = sum(c.isdigit() for c in str(n.value))
    return f"a {digits}-digit number is too large (whole numbers are limited to +-{MAX_INT})"


def format_path(path: Path_) -> str:
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def load_with_lines(text: str, max_nodes: int = MAX_NODES
                    ) -> tuple[Any, dict[Path_, int], list[tuple[int, str]]]:
    """Parse ``text``; return (data, lines, duplicate-key problems).

    Raises ``YamlProblem`` on a syntax error or a limit exceeded; ``max_nodes``
    bounds the values once aliases are expanded (a run's resolved scenario,
    which lists every vehicle, may hold more than a scenario file).
    """
    _check_structure(text, max_nodes)
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 1 if mark is not None else 1
        raise YamlProblem(line, f"YAML syntax error: {e.problem or e}") from None
    except yaml.YAMLError as e:
        raise YamlProblem(1, f"YAML error: {e}") from None
    except RecursionError:  # _check_structure bounds the depth; this is a last resort
        raise YamlProblem(1, f"nested more than {MAX_DEPTH} levels deep") from None
    lines: dict[Path_, int] = {}
    dups: list[tuple[int, str]] = []
    if node is None:
        return None, lines, dups
    constructor = yaml.SafeLoader("")
    nodes = 0
    on_path: set[int] = set()  # the nodes being built: one seen again is a recursive alias
    big: list[tuple[int, str]] = []

    def construct(n: yaml.Node) -> Any:
        try:
            return constructor.construct_object(n, deep=True)
        except yaml.MarkedYAMLError as e:
            mark = e.problem_mark or n.start_mark
            raise YamlProblem(mark.line + 1, f"YAML error: {e.problem or e}") from None
        except ValueError:  # a number of thousands of digits: int() refuses to read it
            raise YamlProblem(n.start_mark.line + 1, _too_big(n)) from None

    def build(n: yaml.Node, path: Path_) -> Any:
        nonlocal nodes
        nodes += 1
        if nodes > max_nodes:
            raise YamlProblem(n.start_mark.line + 1, f"more than {max_nodes} values once "
                                                     f"aliases are expanded")
        line = n.start_mark.line + 1
        lines[path] = line
        if isinstance(n, (yaml.MappingNode, yaml.SequenceNode)):
            if id(n) in on_path:
                raise YamlProblem(line, "an alias refers to a value that contains it "
                                        "(a recursive alias)")
            on_path.add(id(n))
            try:
                return build_collection(n, path)
            finally:
                on_path.discard(id(n))
        value = construct(n)
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
            big.append((line, f"{format_path(path)}: {_too_big(n)}"))
            return None
        if (isinstance(value, str) and isinstance(n, yaml.ScalarNode) and not n.style
                and _EXP_FLOAT.match(value)):
            return float(value)
        return value

    def build_collection(n: yaml.Node, path: Path_) -> Any:
        if isinstance(n, yaml.MappingNode):
            own = sum(1 for k, _ in n.value if k.tag != "tag:yaml.org,2002:merge")
            try:
                constructor.flatten_mapping(n)  # YAML merge keys: `<<: *anchor`
            except yaml.MarkedYAMLError as e:
                mark = e.problem_mark or n.start_mark
                raise YamlProblem(mark.line + 1, f"YAML error: {e.problem or e}") from None
            out: dict[Any, Any] = {}
            merged = len(n.value) - own  # merged pairs come first; own keys override them
            own_seen: set[Any] = set()
            for j, (k_node, v_node) in enumerate(n.value):
                key = construct(k_node)
                if isinstance(key, (list, dict)):
                    key = str(key)
                if j >= merged:
                    if key in own_seen:
                        dups.append((k_node.start_mark.line + 1,
                                     f"{format_path(path + (key,))}: duplicate key {key!r}"))
                    own_seen.add(key)
                out[key] = build(v_node, path + (key,))
                lines[path + (key,)] = k_node.start_mark.line + 1
            return out
        return [build(v, path + (i,)) for i, v in enumerate(n.value)]

    try:
        data = build(node, ())
    except RecursionError:  # e.g. merge keys (<<: *a) that include themselves
        raise YamlProblem(1, "an alias refers to a value that contains it (a recursive "
                             "alias)") from None
    if big:
        raise YamlProblem(*big[0], big)
    return data, lines, dups
