"""Procedural ground tiles are a pure function of (seed, level, tile): the per-cell
tables kept across tiles (noise.TABLES) and the order tiles are made in do not
change a pixel."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from cosim.core.geo import LocalFrame
from cosim.renderer import noise, pyramid, tile_cache
from cosim.renderer.ground import GroundTexture
from cosim.world.ground import GroundSpec

KEYS = [(0, 3, -2), (0, -4000, 3000), (1, -1, 0), (2, 0, -1), (2, 0, 0), (2, -1, -1),
        (2, 7, 5), (3, -2, 1), (4, 0, 0), (6, -1, 2), (8, 0, -1), (9, 1, 1)]


def _tiles(keys: list[tuple[int, int, int]], seed: int = 7) -> dict[tuple[int, int, int], bytes]:
    tex = GroundTexture(GroundSpec(), LocalFrame(37.0, -122.0, 10.0), seed)
    return {k: tex.tile(*k).tobytes() for k in keys}


def _forget(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(noise, "TABLES", noise.Tables(noise.TABLES.max_bytes))
    noise.WEIGHTS.clear()


@pytest.mark.integration
def test_tiles_do_not_depend_on_the_kept_tables_or_the_order(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COSIM_GROUND_CACHE", "off")
    _forget(monkeypatch)
    made = _tiles(KEYS)
    assert _tiles(KEYS[::-1]) == made  # tables kept by the first texture, other order
    _forget(monkeypatch)
    assert {k: _tiles([k])[k] for k in KEYS} == made  # each alone, from the start
    # no table kept at all: each made for exactly its tile's cells (tree cells: for
    # the candidate samples where a tile spans more cells than it has samples)
    def own_only(self: noise.Tables, key: tuple[object, ...], i0: int, i1: int, j0: int,
                 j1: int, size: int, make: Any, own: bool = True) -> Any:
        return (i0, i1 + 1, j0, j1 + 1, make(i0, i1 + 1, j0, j1 + 1)) if own else None

    monkeypatch.setattr(noise.Tables, "cover", own_only)
    _forget(monkeypatch)
    assert _tiles(KEYS) == made


def test_kept_tables_are_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COSIM_GROUND_CACHE", "off")
    monkeypatch.setattr(noise, "TABLES", noise.Tables(200_000))
    made = _tiles([(2, i, -i) for i in range(-20, 20, 3)])
    assert 0 < noise.TABLES.nbytes <= 200_000
    assert noise.TABLES.nbytes == sum(a.nbytes for t in noise.TABLES._held.values()
                                        for a in t)
    assert all(np.frombuffer(t, np.uint8).reshape(256, 256, 4)[..., 3].min() == 255
               for t in made.values())


def test_each_slot_keeps_its_own_patch_within_the_bound(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """Two streams looking at different ground keep their patches apart (no
    reassembly when they take turns), a patch is the tiles it covers, and no more
    than PATCH_MB of patches is kept."""
    monkeypatch.setenv(tile_cache.CACHE_ENV, "off")
    tex = GroundTexture(GroundSpec(), LocalFrame(37.0, -122.0, 10.0), 7)
    T = tex.tile_px
    made = []
    tile = tex.tile

    def counted(*k: int) -> np.ndarray:
        made.append(k)
        return tile(*k)

    monkeypatch.setattr(tex, "tile", counted)
    a = tex.patch(2, 10, 300, 20, 200, slot="a")
    b = tex.patch(2, 5000, 5200, 7000, 7300, slot="b")
    assert np.array_equal(a[:T - 10], tile(2, 0, 0)[10:, 20:200])
    assert np.array_equal(b[:100, :50], tile(2, 5000 // T, 7000 // T)[5000 % T:5000 % T + 100,
                                                                        7000 % T:7000 % T + 50])
    n = len(made)
    for _ in range(3):  # taking turns, same tiles: nothing is assembled again
        assert np.array_equal(tex.patch(2, 10, 300, 20, 200, slot="a"), a)
        assert np.array_equal(tex.patch(2, 5000, 5200, 7000, 7300, slot="b"), b)
    assert len(made) == n
    monkeypatch.setattr(pyramid, "PATCH_MB", 1)  # one 2 x 2 tile patch is 1 MB
    for s in range(5):
        tex.patch(2, 0, 300, 0, 300, slot=s)
    assert len(tex._patches) == 1
    # the oldest slot moving onto more tiles, over the bound: its new patch is kept
    monkeypatch.setattr(pyramid, "PATCH_MB", 2)
    tex.patch(2, 0, 300, 0, 300, slot="x")
    tex.patch(2, 0, 300, 0, 300, slot="y")
    assert list(tex._patches) == [("x", 2), ("y", 2)]
    moved = tex.patch(2, 600, 1100, 0, 300, slot="x")  # 3 x 2 tiles: 1.5 MB
    assert list(tex._patches) == [("x", 2)]
    assert np.array_equal(moved[:100, :100], tile(2, 600 // T, 0)[600 % T:600 % T + 100, :100])
