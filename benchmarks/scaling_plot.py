"""Draw the scaling plot (real-time factor and efficiency against the number
of aircraft, one line per tier) from ``cosim bench --json`` files.

    python benchmarks/scaling_plot.py benchmarks/results/scale-*.json --out docs/images/scaling.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cosim.bench.plot import plot_scaling


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", type=Path, help="cosim bench --json files")
    ap.add_argument("--out", type=Path, required=True, help="the PNG to write")
    a = ap.parse_args(argv)
    series = {}
    for f in a.files:
        doc = json.loads(f.read_text())
        label = (f"{doc['model']} ({doc.get('class', 'jsbsim')}), {doc['control_hz']:g} Hz "
                 f"exchange, {doc['workers']} workers")
        series[label] = doc["results"]
    plot_scaling(series, a.out, "cosim bench: the pool against its limits, "
                                "120 Hz physics")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
