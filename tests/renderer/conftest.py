"""Renderer tests keep the ground tile cache (and the rest of cosim's cache
folder) in their own temporary folder."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def ground_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("COSIM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("COSIM_GROUND_CACHE", raising=False)
    return tmp_path / "cache" / "ground"
