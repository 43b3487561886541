"""Run the mixed-world demo, export its KML and draw the tracks read back
from the KML file (the picture in the README's "Watching a run").

    python examples/export_preview.py [--out docs/images/export_kml.png]

The KML is parsed with the standard library's XML parser, so the picture
shows what Google Earth would read, not the states the run logged.
"""

from __future__ import annotations

import argparse
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from cosim.export import export_run  # noqa: E402
from cosim.scenario import load_scenario  # noqa: E402
from cosim.sync import run_scenario  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
KML, GX = "{http://www.opengis.net/kml/2.2}", "{http://www.google.com/kml/ext/2.2}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(REPO / "docs" / "images" / "export_kml.png"))
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        scn = load_scenario(REPO / "scenarios" / "hetero" / "quad_guides_car.yaml")
        res = run_scenario(scn, Path(d) / "run", backend="inline")
        assert res.stop_reason == "completed", res.error
        kml = export_run(Path(d) / "run", "kml", rate_hz=2.0)
        doc = ET.parse(kml).getroot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    for pm in doc.iter(f"{KML}Placemark"):
        name = pm.findtext(f"{KML}name")
        kind = pm.findtext(f"{KML}description")
        coords = [[float(x) for x in c.text.split()] for c in pm.iter(f"{GX}coord")]
        lon = [c[0] for c in coords]
        lat = [c[1] for c in coords]
        ax.plot(lon, lat, lw=1.5, label=f"{name}: {kind}")
        ax.plot(lon[-1], lat[-1], "o", ms=4, color=ax.lines[-1].get_color())
    for o in scn.sections.get("obstacles") or ():
        ring = [scn.origin.frame.place(n, e, scn.origin.ground_alt_m) for n, e in o.polygon]
        xs = [float(r[1]) for r in ring] + [float(ring[0][1])]
        ys = [float(r[0]) for r in ring] + [float(ring[0][0])]
        ax.fill(xs, ys, color="0.6", alpha=0.6)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_aspect(1 / 0.682)  # cos(47 deg): metres alike both ways
    ax.ticklabel_format(useOffset=False)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("track.kml, read back (gx:Track per vehicle)", fontsize=9)
    fig.tight_layout()
    fig.savefig(a.out)
    print(a.out)


if __name__ == "__main__":
    main()
