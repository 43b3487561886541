"""Renderer tests keep the ground tile cache in their own temporary folder."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def ground_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "ground_cache"
    monkeypatch.setenv("COSIM_GROUND_CACHE", str(folder))
    return folder
