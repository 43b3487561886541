"""The ``search:`` section as the scenario, the runner, a sweep and the CLI
see it (``cosim.core.section``): parsed by ``spec`` (it reads the cameras, for
the image detector), its fires added to the world as targets, run by the
search participant (a MAVLink client flying the plan as missions), its
tables of a sweep (``sweep``)."""

from __future__ import annotations

from typing import Any

from cosim.core.section import P, Section, SectionContext
from cosim.search.command import COMMAND


def _search_table(result: Any, spec: Any) -> Any:
    from cosim.search.sweep import write_table

    return write_table(result, spec)


class SearchSection(Section):
    key = "search"
    description = "a wide-area search flown as MAVLink missions, its fires detected and scored"
    reads = ("cameras",)
    talks_mavlink = True
    outputs = ("search/",)
    sweep_tables = (_search_table,)

    commands = (COMMAND,)

    def parse(self, info: SectionContext, node: Any, path: P) -> Any:
        from cosim.search.spec import parse_search

        return parse_search(info, node, path)

    def world(self, parsed: Any) -> dict[str, tuple[Any, ...]]:
        from cosim.search.spec import fire_targets

        return {"targets": fire_targets(parsed)}

    def participant(self, scenario: Any) -> Any:
        from cosim.search.participant import SearchParticipant

        return SearchParticipant(scenario)


SEARCH = SearchSection()
