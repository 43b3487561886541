"""scenario: YAML scenario files -> validated, typed, frozen ``Scenario``.

Owns the schema (``schema_version: 1``), formations and the resolution of
positions into the scenario's local WGS-84 frame. It never steps FDMs.
"""

from cosim.scenario.schema import (
    SCHEMA_VERSION,
    Origin,
    Rates,
    Scenario,
    ScheduleItem,
    SectionInfo,
    load_scenario,
    parse_scenario,
)

__all__ = ["SCHEMA_VERSION", "Origin", "Rates", "Scenario", "ScheduleItem", "SectionInfo",
           "load_scenario", "parse_scenario"]
