"""scenario: YAML scenario files -> validated, typed, frozen ``Scenario``.

Owns the scenario language (``yaml_lines``: YAML with every value's line;
``placeholders``: ``${...}``), the reader that collects every problem with
its line (``reader``), the model (``model``), the vehicles (``vehicles``,
``formation``), the schedule (``schedule``), raw property writes
(``writes``) and the loader that puts them and the sections together
(``schema``; sections are plug-ins, ``cosim.core.section``). It never steps
FDMs.
"""

from cosim.scenario.model import SCHEMA_VERSION, Origin, Rates, Scenario, ScheduleItem
from cosim.scenario.schema import SectionInfo, load_scenario, parse_scenario

__all__ = ["SCHEMA_VERSION", "Origin", "Rates", "Scenario", "ScheduleItem", "SectionInfo",
           "load_scenario", "parse_scenario"]
