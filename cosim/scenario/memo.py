"""Work shared by the loads of one scenario file at many sweep combinations
(``Memo``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.scenario.reader import P, Problems
from cosim.scenario.yaml_lines import YamlProblem, load_with_lines, read_scenario_text


class Memo:
    """Work shared by the loads of one scenario file at many sweep
    combinations (``cosim validate`` and ``cosim sweep`` load every one): the
    file is read and parsed once, and a part whose input, once the
    placeholders are substituted, equals that of an earlier combination is not
    checked again: its result is reused and its problems reported again,
    exactly as a fresh check would report them. At most ``MAX_PARTS`` results
    of each part are kept (the most recent)."""

    MAX_PARTS = 64

    def __init__(self) -> None:
        self._texts: dict[str, str] = {}
        self._parsed: dict[str, tuple[Any, dict[P, int], list[tuple[int, str]],
                                      dict[str, str]]] = {}
        self._parts: dict[str, dict[Any, tuple[Any, list[tuple[int, str]], int]]] = {}
        #: (model, aircraft folder) -> an FDM whose properties are looked up
        self.fdms: dict[tuple[str, str], Any] = {}
        self.hits = 0  # parts reused (for tests and progress)

    def read(self, path: Path) -> str:
        key = str(path)
        if key not in self._texts:
            self._texts = {key: read_scenario_text(path)}  # one file at a time
        return self._texts[key]

    def parsed(self, text: str, fname: str
               ) -> tuple[Any, dict[P, int], list[tuple[int, str]], dict[str, str]]:
        """(data, lines, duplicate-key problems, placeholders) of ``text``.
        The data is shared: callers must not change it (``substitute`` copies)."""
        if text not in self._parsed:
            from cosim.scenario.placeholders import protect_placeholders

            protected, placeholders = protect_placeholders(text)
            try:
                data, lines, dups = load_with_lines(protected)
            except YamlProblem as e:
                raise ConfigError([f"{fname}:{ln}: {m}" for ln, m in e.problems]) from None
            self._parsed = {text: (data, lines, dups, placeholders)}
        return self._parsed[text]

    def part(self, name: str, key: Any, ctx: Problems, check: Callable[[Problems], Any]) -> Any:
        """``check(sub)`` (a part's check, reporting into ``sub``), or its
        result for the same ``key`` kept from an earlier call; its problems
        are reported into ``ctx`` either way."""
        kept = self._parts.setdefault(name, {})
        if key in kept:
            self.hits += 1
            result, problems, more = kept.pop(key)
        else:
            sub = Problems(ctx.fname, ctx.lines, ctx.vehicles)
            result = check(sub)
            problems, more = sub.problems, sub.more
            if len(kept) >= self.MAX_PARTS:
                del kept[next(iter(kept))]
        kept[key] = (result, problems, more)  # most recent last
        for problem in problems:
            ctx.add(problem)
        ctx.more += more
        return result
