"""Errors of the MAVLink layer (all in the ``CosimError`` family)."""

from __future__ import annotations

from cosim.errors import CosimError


class MavlinkError(CosimError):
    """Base class of the MAVLink layer's errors."""


class LinkError(MavlinkError):
    """The MAVLink socket could not be opened or is closed."""


class EndpointClosed(MavlinkError):
    """The endpoint was used after ``close()``."""


class LockstepTimeout(MavlinkError):
    """The outside controller kept in lockstep did not answer in time."""
