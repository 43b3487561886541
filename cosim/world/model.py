"""The world (``World``): the ground, targets, obstacles, sun and
atmosphere every part reads, put together from what the scenario's sections add
(``World.assemble``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.ground import GroundSpec
from cosim.world.obstacles import Obstacle
from cosim.world.sun import DEFAULT as DEFAULT_SUN
from cosim.world.sun import SunSpec
from cosim.world.targets import TargetSpec

#: the kinds of things a section may add to the world
KINDS = ("ground", "targets", "obstacles", "sun", "atmosphere")
#: the kinds a world holds one of (the others are lists of things with ids)
SINGLE = ("ground", "sun", "atmosphere")


@dataclass(frozen=True)
class World:
    """The scenario's world, assembled from what its sections add."""

    ground: GroundSpec = field(default_factory=GroundSpec)
    targets: tuple[TargetSpec, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    sun: SunSpec = DEFAULT_SUN
    #: the haze (None: clear air)
    atmosphere: AtmosphereSpec | None = None

    @staticmethod
    def assemble(adds: Sequence[tuple[str, Mapping[str, Sequence[Any]]]]
                 ) -> tuple[World, list[tuple[str, str]]]:
        """The world from ``(section key, what it adds)`` in section order,
        and the problems found putting it together ``(section key, message)``:
        an unknown kind, a second ground or sun, an id two of them give."""
        single: dict[str, list[Any]] = {kind: [] for kind in SINGLE}
        targets: list[TargetSpec] = []
        obstacles: list[Obstacle] = []
        problems: list[tuple[str, str]] = []
        owner: dict[tuple[str, str], str] = {}
        for key, add in adds:
            for kind, items in add.items():
                if kind not in KINDS:
                    problems.append((key, f"adds {kind!r} to the world; it holds "
                                          f"{', '.join(KINDS)}"))
                    continue
                for item in items:
                    if kind in single:
                        single[kind].append(item)
                        continue
                    ident = (kind, item.id)
                    if ident in owner:
                        was = owner[ident]
                        problems.append((key, f"a {kind[:-1]} called {item.id!r} is "
                                              f"already in the world (from {was}:)"))
                        continue
                    owner[ident] = key
                    (targets if kind == "targets" else obstacles).append(item)
        for kind, items in single.items():
            if len(items) > 1:
                problems.append((adds[-1][0], f"the world has one {kind}; another section "
                                              "gives one too"))
        grounds, suns, airs = single["ground"], single["sun"], single["atmosphere"]
        world = World(ground=grounds[0] if grounds else GroundSpec(), targets=tuple(targets),
                      obstacles=tuple(obstacles), sun=suns[0] if suns else DEFAULT_SUN,
                      atmosphere=airs[0] if airs else None)
        return world, problems

