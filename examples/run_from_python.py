"""Run a scenario from Python and read what it wrote.

    python examples/run_from_python.py

``cosim.run`` does what ``cosim run`` does and returns the result. Keep the
call under ``if __name__ == "__main__":``: cosim's worker processes start by
importing this script again (without the guard, ``cosim.run`` says so and
stops instead of starting workers from workers).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import cosim

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    out = Path(tempfile.mkdtemp()) / "quickstart"
    res = cosim.run(REPO / "scenarios" / "quickstart.yaml", out, duration_s=20.0,
                    backend="process", workers=2)
    print(res.stop_reason, f"{res.summary['real_time_factor']}x real time", res.out_dir)

    from cosim.logs import read_states  # the states as a pyarrow Table (pandas: .to_pandas())

    states = read_states(out)
    print(states.num_rows, "rows;", ", ".join(states.column_names[:8]), "...")


if __name__ == "__main__":
    main()
