"""export: a finished run's tracks for replay and map tools (``cosim export``),
one exporter a format (``EXPORTERS``, which gives the CLI its choices):

- ``acmi``: Tacview's ACMI 2.2 text format (what JSBSim and air-combat users
  replay in): a header with the reference time and position, then one frame
  ``#t`` per sample time with each vehicle's ``T=lon|lat|alt|roll|pitch|yaw``
  (longitude and latitude as offsets from the reference, as the format
  allows), its ``Type``, ``Name`` (the model) and ``CallSign`` (the vehicle id).
- ``kml``: one ``Placemark`` per vehicle holding a ``gx:Track`` (``when``,
  ``gx:coord`` longitude latitude altitude, ``gx:angles`` heading tilt roll;
  absolute altitudes) for Google Earth.
- ``czml``: Cesium's JSON: a ``document`` packet with the clock, then one
  packet per vehicle with sampled ``position`` (``cartographicDegrees``, WGS-84
  heights) and ``orientation`` (``unitQuaternion`` x, y, z, w turning the
  vehicle's body axes, x forward, y right, z down, into Earth-fixed ECEF
  axes), a label with the call sign and its path.

Times are seconds of simulation time after ``epoch`` (the simulation has no
calendar: 2000-01-01T00:00:00Z unless given). Samples are taken at ``rate_hz``
(default 10 Hz: the first logged row of each vehicle in each 1/rate_hz
interval), so a long run with many vehicles stays a file a viewer can open.
Files are written as they are built, a frame or a vehicle at a time, into a
temporary file renamed into place when whole. The run folder is untrusted
input (``cosim.logs.runfolder``): samples without a known position or
attitude (NaN) are left out; a value out of range is an error naming its row.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from cosim.errors import ConfigError


@dataclass(frozen=True)
class Exporter:
    """One format: its name (the file suffix), what it is for, and its writer
    (``"module:function"``, loaded when used, so the CLI lists formats
    without loading them)."""

    name: str
    description: str
    writer: str


#: every format, by name
EXPORTERS: dict[str, Exporter] = {e.name: e for e in (
    Exporter("acmi", "Tacview 2.2 text", "cosim.export.writers:write_acmi"),
    Exporter("kml", "one gx:Track per vehicle", "cosim.export.writers:write_kml"),
    Exporter("czml", "Cesium", "cosim.export.writers:write_czml"),
)}
DEFAULT_EPOCH = datetime(2000, 1, 1, tzinfo=timezone.utc)
DEFAULT_RATE_HZ = 10.0


def export_run(run: Path, fmt: str, out: Path | None = None, rate_hz: float = DEFAULT_RATE_HZ,
               epoch: datetime = DEFAULT_EPOCH) -> Path:
    """Write ``run``'s tracks as ``fmt`` to ``out`` (default RUN/track.<fmt>);
    the path written."""
    import importlib

    from cosim.export.tracks import iso, load_tracks
    from cosim.logs import replacing

    if fmt not in EXPORTERS:
        raise ConfigError(f"unknown export format {fmt!r}; expected one of: "
                          f"{', '.join(EXPORTERS)}")
    module, func = EXPORTERS[fmt].writer.split(":")
    write = getattr(importlib.import_module(module), func)
    tracks = load_tracks(run, rate_hz)
    last_s = max(float(t[-1]) for t in tracks.time_s.values())
    try:
        iso(epoch, last_s)
    except OverflowError:
        raise ConfigError(f"--epoch {epoch.isoformat()}: the run's last sample, {last_s:g} s "
                          f"later, would fall after the year 9999") from None
    path = out if out is not None else run / f"track.{fmt}"
    with replacing(path) as f:
        write(tracks, f, epoch)
    return path
