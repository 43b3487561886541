"""The Python entry point: ``cosim.run`` runs a scenario like ``cosim run``
(the example script works), refuses to mix with an earlier run, and a
script that forgets the ``if __name__ == "__main__":`` guard gets a clear
error, quickly, instead of workers starting runs of their own."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import cosim
from cosim.errors import ConfigError

REPO = Path(__file__).resolve().parent.parent
QUICK = REPO / "scenarios" / "quickstart.yaml"


def test_run_returns_the_result_and_refuses_to_overwrite(tmp_path: Path) -> None:
    res = cosim.run(QUICK, tmp_path / "r", duration_s=2.0, backend="inline")
    assert res.stop_reason == "completed" and res.summary["sim_time_s"] == pytest.approx(2.0)
    with pytest.raises(ConfigError, match="already holds a run"):
        cosim.run(QUICK, tmp_path / "r", duration_s=2.0, backend="inline")
    again = cosim.run(QUICK, tmp_path / "r", duration_s=1.0, backend="inline", overwrite=True)
    assert again.summary["sim_time_s"] == pytest.approx(1.0)


@pytest.mark.integration
def test_the_example_script_runs() -> None:
    r = subprocess.run([sys.executable, str(REPO / "examples" / "run_from_python.py")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("completed") and "rows;" in r.stdout


def test_a_missing_main_guard_is_a_clear_error_not_a_hang(tmp_path: Path) -> None:
    script = tmp_path / "noguard.py"
    script.write_text(textwrap.dedent(f"""\
        import cosim
        res = cosim.run({str(QUICK)!r}, {str(tmp_path / 'out')!r}, duration_s=2, workers=2)
        print("RESULT", res.stop_reason)
        """))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                       timeout=120, cwd=tmp_path)
    assert "GuardMissing" in r.stderr
    assert 'if __name__ == "__main__":' in r.stderr
    assert "RESULT worker_failure" in r.stdout  # the run ends at once, naming the worker
