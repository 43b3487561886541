"""The world's scenario sections: ``ground:``, ``targets:``, ``obstacles:``,
``sun:`` and ``atmosphere:``. Each parses its key (with ``ground``,
``targets``, ``obstacles``, ``sun`` and ``atmosphere``) and adds what it
parsed to the world. The parsers are imported when a scenario is read, not
when the section table is, so that ``cosim --help`` does not load numpy."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cosim.core.section import P, Section, SectionContext

if TYPE_CHECKING:
    from cosim.world.atmosphere import AtmosphereSpec
    from cosim.world.ground import GroundSpec
    from cosim.world.obstacles import Obstacle
    from cosim.world.sun import SunSpec
    from cosim.world.targets import TargetSpec


class GroundSection(Section):
    key = "ground"
    description = "the ground's texture: procedural, or a picture or GeoTIFF placed in the frame"

    def parse(self, info: SectionContext, node: Any, path: P) -> GroundSpec:
        from cosim.world.ground import parse_ground

        return parse_ground(info, node, path)

    def world(self, parsed: GroundSpec) -> dict[str, tuple[GroundSpec, ...]]:
        return {"ground": (parsed,)}


class TargetsSection(Section):
    key = "targets"
    description = "targets on the ground (trucks, cars, people, fires), drawn by the cameras"

    def parse(self, info: SectionContext, node: Any, path: P) -> tuple[TargetSpec, ...]:
        from cosim.world.targets import parse_targets

        return parse_targets(info, node, path)

    def world(self, parsed: tuple[TargetSpec, ...]) -> dict[str, tuple[TargetSpec, ...]]:
        return {"targets": parsed}


class ObstaclesSection(Section):
    key = "obstacles"
    description = "polygons on the ground that vehicles keep out of"

    def parse(self, info: SectionContext, node: Any, path: P) -> tuple[Obstacle, ...]:
        from cosim.world.obstacles import parse_obstacles

        return parse_obstacles(info, node, path)

    def world(self, parsed: tuple[Obstacle, ...]) -> dict[str, tuple[Obstacle, ...]]:
        return {"obstacles": parsed}


class SunSection(Section):
    key = "sun"
    description = "where the sun stands: from a date and time at the origin, or given"

    def parse(self, info: SectionContext, node: Any, path: P) -> SunSpec:
        from cosim.world.sun import parse_sun

        return parse_sun(info, node, path)

    def world(self, parsed: SunSpec) -> dict[str, tuple[SunSpec, ...]]:
        return {"sun": (parsed,)}


class AtmosphereSection(Section):
    key = "atmosphere"
    description = "haze: the cameras see through air of a given visibility"

    def parse(self, info: SectionContext, node: Any, path: P) -> AtmosphereSpec | None:
        from cosim.world.atmosphere import parse_atmosphere

        return parse_atmosphere(info, node, path)

    def world(self, parsed: AtmosphereSpec) -> dict[str, tuple[AtmosphereSpec, ...]]:
        return {"atmosphere": (parsed,)}


GROUND = GroundSection()
TARGETS = TargetsSection()
OBSTACLES = ObstaclesSection()
SUN = SunSection()
ATMOSPHERE = AtmosphereSection()
