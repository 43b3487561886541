"""``cosim export``: a finished run's tracks for replay and map tools.

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

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import IO, Any
from xml.sax.saxutils import escape

import numpy as np

from cosim.errors import ConfigError
from cosim.logs import RunFolder, replacing
from cosim.logs.resolved import RESOLVED
from cosim.logs.runfolder import rows_by_vehicle

FORMATS = ("acmi", "kml", "czml")
DEFAULT_EPOCH = datetime(2000, 1, 1, tzinfo=timezone.utc)
DEFAULT_RATE_HZ = 10.0
MAX_RATE_HZ = 1000.0
_COLUMNS = ("time_s", "vehicle", "lat_deg", "lon_deg", "alt_msl_m", "roll_deg", "pitch_deg",
            "yaw_deg")


@dataclass(frozen=True)
class Vehicle:
    """What an export says of one vehicle: its id, model and replay type."""

    id: str
    model: str
    kind: str  # Tacview's object type (the class's ``display_type``)


@dataclass
class Tracks:
    """The sampled states of a run: per vehicle, arrays over its samples."""

    vehicles: list[Vehicle]
    time_s: dict[str, np.ndarray]
    lat: dict[str, np.ndarray]
    lon: dict[str, np.ndarray]
    alt: dict[str, np.ndarray]
    roll: dict[str, np.ndarray]
    pitch: dict[str, np.ndarray]
    yaw: dict[str, np.ndarray]
    origin: tuple[float, float]
    title: str


def load_tracks(run: Path, rate_hz: float = DEFAULT_RATE_HZ) -> Tracks:
    """A finished (or recovered) run's tracks sampled at ``rate_hz``; the
    folder is read as untrusted input (``cosim.logs.runfolder``)."""
    folder = RunFolder(run)
    if not folder.has("states.parquet"):
        raise ConfigError(f"{run}: not a cosim run folder (no states.parquet)")
    if not folder.has(RESOLVED):
        raise ConfigError(f"{run}: no {RESOLVED} (run `cosim recover {run}` first if the run "
                          f"was killed)")
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= MAX_RATE_HZ):
        raise ConfigError(f"--rate-hz must be > 0 and at most {MAX_RATE_HZ:g}, got {rate_hz:g}")
    resolved = folder.resolved()
    assert resolved is not None
    table = folder.states(_COLUMNS)
    cols = {c: table[c].to_numpy(zero_copy_only=False).astype(float) for c in _COLUMNS
            if c != "vehicle"}
    rows = rows_by_vehicle(table)
    slot = np.floor(cols["time_s"] * rate_hz + 1e-9)
    known = np.ones(table.num_rows, dtype=bool)  # NaN: not known, left out
    for c in _COLUMNS[2:]:
        known &= np.isfinite(cols[c])
    out: dict[str, dict[str, np.ndarray]] = {k: {} for k in _COLUMNS[2:]}
    times: dict[str, np.ndarray] = {}
    for v in resolved.vehicles:
        r = rows.get(v.id)
        if r is None:
            continue
        s = slot[r]
        keep = r[np.concatenate(([True], s[1:] != s[:-1]))]
        ok = keep[known[keep]]
        if not len(ok):
            continue
        times[v.id] = cols["time_s"][ok]
        for k in _COLUMNS[2:]:
            out[k][v.id] = cols[k][ok]
    if not times:
        raise ConfigError(f"{run}: the run logged no states to export")
    return Tracks([Vehicle(v.id, v.model, v.kind) for v in resolved.vehicles if v.id in times],
                  times, out["lat_deg"], out["lon_deg"], out["alt_msl_m"], out["roll_deg"],
                  out["pitch_deg"], out["yaw_deg"],
                  (resolved.origin_lat_deg, resolved.origin_lon_deg), resolved.name)


def _iso(epoch: datetime, t: float) -> str:
    """ISO 8601 UTC with milliseconds."""
    return (epoch + timedelta(seconds=t)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


# -- Tacview ACMI ---------------------------------------------------------------------
def _frames(tr: Tracks) -> Iterator[tuple[float, list[tuple[int, str, int]]]]:
    """(time, [(vehicle index, id, sample index)]) in time order."""
    events = sorted((float(t), k, v.id, j) for k, v in enumerate(tr.vehicles)
                    for j, t in enumerate(tr.time_s[v.id]))
    i = 0
    while i < len(events):
        t = events[i][0]
        group = []
        while i < len(events) and events[i][0] == t:
            group.append(events[i][1:])
            i += 1
        yield t, group


def write_acmi(tr: Tracks, f: IO[str], epoch: datetime) -> None:
    lat0, lon0 = tr.origin
    f.write("FileType=text/acmi/tacview\nFileVersion=2.2\n")
    f.write(f"0,ReferenceTime={epoch.strftime('%Y-%m-%dT%H:%M:%SZ')}\n")
    f.write(f"0,ReferenceLongitude={lon0:.7f}\n0,ReferenceLatitude={lat0:.7f}\n")
    f.write(f"0,DataSource=cosim\n0,Title={_acmi_text(tr.title)}\n")
    introduced: set[str] = set()
    for t, group in _frames(tr):
        f.write(f"#{t:.3f}\n")
        for k, vid, j in group:
            v = tr.vehicles[k]
            line = (f"{k + 1:x},T={tr.lon[vid][j] - lon0:.7f}|{tr.lat[vid][j] - lat0:.7f}|"
                    f"{tr.alt[vid][j]:.2f}|{tr.roll[vid][j]:.2f}|{tr.pitch[vid][j]:.2f}|"
                    f"{tr.yaw[vid][j] % 360.0:.2f}")
            if vid not in introduced:
                introduced.add(vid)
                line += (f",Type={v.kind},Name={_acmi_text(v.model)},"
                         f"CallSign={_acmi_text(v.id)}")
            f.write(line + "\n")


def _acmi_text(s: str) -> str:
    """A property value: commas escaped, one line."""
    return s.replace("\\", "\\\\").replace(",", "\\,").replace("\n", " ")


# -- KML ------------------------------------------------------------------------------
def write_kml(tr: Tracks, f: IO[str], epoch: datetime) -> None:
    f.write('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<kml xmlns="http://www.opengis.net/kml/2.2" '
            'xmlns:gx="http://www.google.com/kml/ext/2.2">\n<Document>\n'
            f"<name>{escape(tr.title)}</name>\n")
    for v in tr.vehicles:
        f.write(f"<Placemark>\n<name>{escape(v.id)}</name>\n"
                f"<description>{escape(v.kind)} ({escape(v.model)})</description>\n"
                "<gx:Track>\n<altitudeMode>absolute</altitudeMode>\n")
        times = tr.time_s[v.id]
        f.writelines(f"<when>{_iso(epoch, float(t))}</when>\n" for t in times)
        f.writelines(f"<gx:coord>{lo:.7f} {la:.7f} {al:.2f}</gx:coord>\n" for lo, la, al in
                     zip(tr.lon[v.id], tr.lat[v.id], tr.alt[v.id]))
        f.writelines(f"<gx:angles>{h % 360.0:.2f} {p:.2f} {r:.2f}</gx:angles>\n" for h, p, r in
                     zip(tr.yaw[v.id], tr.pitch[v.id], tr.roll[v.id]))
        f.write("</gx:Track>\n</Placemark>\n")
    f.write("</Document>\n</kml>\n")


# -- CZML -----------------------------------------------------------------------------
def body_to_ecef_quaternion(lat_deg: np.ndarray, lon_deg: np.ndarray, roll_deg: np.ndarray,
                            pitch_deg: np.ndarray, yaw_deg: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions (x, y, z, w) of the rotation taking body axes
    (x forward, y right, z down) to ECEF, from attitude relative to local NED."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    phi, th, psi = np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg)
    cp, sp, ct, st, cy, sy = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th), np.cos(psi), \
        np.sin(psi)
    # NED <- body (the 3-2-1 Euler rotation)
    n_b = np.empty((len(lat), 3, 3))
    n_b[:, 0] = np.stack([ct * cy, sp * st * cy - cp * sy, cp * st * cy + sp * sy], 1)
    n_b[:, 1] = np.stack([ct * sy, sp * st * sy + cp * cy, cp * st * sy - sp * cy], 1)
    n_b[:, 2] = np.stack([-st, sp * ct, cp * ct], 1)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    # ECEF <- NED: columns are north, east, down in ECEF
    e_n = np.empty((len(lat), 3, 3))
    e_n[:, :, 0] = np.stack([-sl * co, -sl * so, cl], 1)
    e_n[:, :, 1] = np.stack([-so, co, np.zeros_like(so)], 1)
    e_n[:, :, 2] = np.stack([-cl * co, -cl * so, -sl], 1)
    return _quaternions(e_n @ n_b)


def _quaternions(m: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices -> (n, 4) unit quaternions (x, y, z, w), w >= 0."""
    out = np.empty((len(m), 4))
    for i, r in enumerate(m):
        tr = r[0, 0] + r[1, 1] + r[2, 2]
        if tr > 0:
            s = 2.0 * math.sqrt(tr + 1.0)
            q = ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s,
                 0.25 * s)
        else:
            k = int(np.argmax(np.diag(r)))
            j, l_ = (k + 1) % 3, (k + 2) % 3
            s = 2.0 * math.sqrt(1.0 + r[k, k] - r[j, j] - r[l_, l_])
            v = [0.0, 0.0, 0.0]
            v[k] = 0.25 * s
            v[j] = (r[j, k] + r[k, j]) / s
            v[l_] = (r[l_, k] + r[k, l_]) / s
            q = (v[0], v[1], v[2], (r[l_, j] - r[j, l_]) / s)
        qa = np.array(q)
        qa /= np.linalg.norm(qa)
        out[i] = qa if qa[3] >= 0 else -qa
    return out


def write_czml(tr: Tracks, f: IO[str], epoch: datetime) -> None:
    start = min(float(t[0]) for t in tr.time_s.values())
    end = max(float(t[-1]) for t in tr.time_s.values())
    interval = f"{_iso(epoch, start)}/{_iso(epoch, end)}"
    f.write("[\n")
    f.write(json.dumps({"id": "document", "name": tr.title, "version": "1.0",
                        "clock": {"interval": interval, "currentTime": _iso(epoch, start),
                                  "multiplier": 1, "range": "LOOP_STOP"}}))
    for v in tr.vehicles:
        t = tr.time_s[v.id]
        pos = np.stack([t, tr.lon[v.id], tr.lat[v.id], tr.alt[v.id]], 1)
        q = body_to_ecef_quaternion(tr.lat[v.id], tr.lon[v.id], tr.roll[v.id],
                                    tr.pitch[v.id], tr.yaw[v.id])
        quat = np.concatenate([t[:, None], q], 1)
        packet: dict[str, Any] = {
            "id": v.id, "name": v.id, "description": f"{v.kind} ({v.model})",
            "availability": f"{_iso(epoch, float(t[0]))}/{_iso(epoch, float(t[-1]))}",
            "label": {"text": v.id, "pixelOffset": {"cartesian2": [0, -20]}},
            "point": {"pixelSize": 8},
            "path": {"width": 2, "leadTime": 0, "trailTime": float(t[-1] - t[0]) + 1.0},
            "position": {"epoch": _iso(epoch, 0.0),
                         "cartographicDegrees": [round(float(x), 7) for x in pos.ravel()]},
            "orientation": {"epoch": _iso(epoch, 0.0),
                            "unitQuaternion": [round(float(x), 7) for x in quat.ravel()]}}
        f.write(",\n" + json.dumps(packet))
    f.write("\n]\n")


WRITERS = {"acmi": write_acmi, "kml": write_kml, "czml": write_czml}


def export_run(run: Path, fmt: str, out: Path | None = None, rate_hz: float = DEFAULT_RATE_HZ,
               epoch: datetime = DEFAULT_EPOCH) -> Path:
    """Write ``run``'s tracks as ``fmt`` to ``out`` (default RUN/track.<fmt>);
    the path written."""
    if fmt not in WRITERS:
        raise ConfigError(f"unknown export format {fmt!r}; expected one of: {', '.join(FORMATS)}")
    tracks = load_tracks(run, rate_hz)
    last_s = max(float(t[-1]) for t in tracks.time_s.values())
    try:
        _iso(epoch, last_s)
    except OverflowError:
        raise ConfigError(f"--epoch {epoch.isoformat()}: the run's last sample, {last_s:g} s "
                          f"later, would fall after the year 9999") from None
    path = out if out is not None else run / f"track.{fmt}"
    with replacing(path) as f:
        WRITERS[fmt](tracks, f, epoch)
    return path
