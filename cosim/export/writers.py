"""The exporters' formats (``cosim.export.EXPORTERS``): each writes a run's
``Tracks`` to an open text file, a frame or a vehicle at a time."""

from __future__ import annotations

import json
import math
from datetime import datetime
from typing import IO, Any
from xml.sax.saxutils import escape

import numpy as np

from cosim.export.tracks import Tracks, frames, iso


def write_acmi(tr: Tracks, f: IO[str], epoch: datetime) -> None:
    lat0, lon0 = tr.origin
    f.write("FileType=text/acmi/tacview\nFileVersion=2.2\n")
    f.write(f"0,ReferenceTime={epoch.strftime('%Y-%m-%dT%H:%M:%SZ')}\n")
    f.write(f"0,ReferenceLongitude={lon0:.7f}\n0,ReferenceLatitude={lat0:.7f}\n")
    f.write(f"0,DataSource=cosim\n0,Title={_acmi_text(tr.title)}\n")
    introduced: set[str] = set()
    for t, group in frames(tr):
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
        f.writelines(f"<when>{iso(epoch, float(t))}</when>\n" for t in times)
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
    interval = f"{iso(epoch, start)}/{iso(epoch, end)}"
    f.write("[\n")
    f.write(json.dumps({"id": "document", "name": tr.title, "version": "1.0",
                        "clock": {"interval": interval, "currentTime": iso(epoch, start),
                                  "multiplier": 1, "range": "LOOP_STOP"}}))
    for v in tr.vehicles:
        t = tr.time_s[v.id]
        pos = np.stack([t, tr.lon[v.id], tr.lat[v.id], tr.alt[v.id]], 1)
        q = body_to_ecef_quaternion(tr.lat[v.id], tr.lon[v.id], tr.roll[v.id],
                                    tr.pitch[v.id], tr.yaw[v.id])
        quat = np.concatenate([t[:, None], q], 1)
        packet: dict[str, Any] = {
            "id": v.id, "name": v.id, "description": f"{v.kind} ({v.model})",
            "availability": f"{iso(epoch, float(t[0]))}/{iso(epoch, float(t[-1]))}",
            "label": {"text": v.id, "pixelOffset": {"cartesian2": [0, -20]}},
            "point": {"pixelSize": 8},
            "path": {"width": 2, "leadTime": 0, "trailTime": float(t[-1] - t[0]) + 1.0},
            "position": {"epoch": iso(epoch, 0.0),
                         "cartographicDegrees": [round(float(x), 7) for x in pos.ravel()]},
            "orientation": {"epoch": iso(epoch, 0.0),
                            "unitQuaternion": [round(float(x), 7) for x in quat.ravel()]}}
        f.write(",\n" + json.dumps(packet))
    f.write("\n]\n")
