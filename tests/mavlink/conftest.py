"""Fixtures of the MAVLink tests (helpers in ``mavtest``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("pymavlink")

from mavtest import Rig  # noqa: E402


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    made: list[Rig] = []

    def make(n: int = 3, **kw: Any) -> Rig:
        r = Rig(tmp_path, n, **kw)
        made.append(r)
        return r

    yield make
    for r in made:
        r.close()
