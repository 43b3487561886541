"""A pytest plugin for a driver inside namespace ``a`` of ``tests.ray_netns``
(run with ``--noconftest -p tests.fdm_pool.netns_driver``): the suite's
fixtures, with ``ray_cluster`` the cluster ``RAY_ADDRESS`` names, joined
rather than started (the ray backend joins it on its first pool)."""

from __future__ import annotations

import os

import pytest

from tests.conftest import _ground_cache, specs  # noqa: F401 - the suite's fixtures


@pytest.fixture(scope="session")
def ray_cluster() -> str:
    """The address of the cluster across the namespaces (``RAY_ADDRESS``)."""
    address = os.environ.get("RAY_ADDRESS")
    if not address:
        raise RuntimeError("RAY_ADDRESS must name the cluster across the namespaces")
    return address
