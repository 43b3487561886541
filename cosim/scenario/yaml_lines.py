"""YAML loading that remembers where every value came from.

``load_with_lines`` returns plain Python data (as ``yaml.safe_load`` would)
plus a map from each value's path (a tuple of keys and indices) to its
1-based line, so validation can report ``file:line: path: message``.
Duplicate mapping keys are reported (``safe_load`` silently keeps the last).
Unquoted numbers in exponent form without a sign (``1e3``, ``2.5e-3`` is
fine already) are read as numbers, as YAML 1.2 and every user expect;
PyYAML's YAML 1.1 rules would make them strings.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

_EXP_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")

Path_ = tuple[Any, ...]


class YamlProblem(Exception):
    def __init__(self, line: int, message: str) -> None:
        super().__init__(line, message)
        self.line = line
        self.message = message


def format_path(path: Path_) -> str:
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def load_with_lines(text: str) -> tuple[Any, dict[Path_, int], list[tuple[int, str]]]:
    """Parse ``text``; return (data, lines, duplicate-key problems).

    Raises ``YamlProblem`` on a syntax error.
    """
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 1 if mark is not None else 1
        raise YamlProblem(line, f"YAML syntax error: {e.problem or e}") from None
    except yaml.YAMLError as e:
        raise YamlProblem(1, f"YAML error: {e}") from None
    lines: dict[Path_, int] = {}
    dups: list[tuple[int, str]] = []
    if node is None:
        return None, lines, dups
    constructor = yaml.SafeLoader("")

    def construct(n: yaml.Node) -> Any:
        try:
            return constructor.construct_object(n, deep=True)
        except yaml.MarkedYAMLError as e:
            mark = e.problem_mark or n.start_mark
            raise YamlProblem(mark.line + 1, f"YAML error: {e.problem or e}") from None

    def build(n: yaml.Node, path: Path_) -> Any:
        lines[path] = n.start_mark.line + 1
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
        if isinstance(n, yaml.SequenceNode):
            return [build(v, path + (i,)) for i, v in enumerate(n.value)]
        value = construct(n)
        if (isinstance(value, str) and isinstance(n, yaml.ScalarNode) and n.style is None
                and _EXP_FLOAT.match(value)):
            return float(value)
        return value

    return build(node, ()), lines, dups
