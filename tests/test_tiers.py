"""The test tiers (tests/conftest.py): each test lands in one, by the
fixtures it uses, the backend it runs on or its markers; two tier markers on
one test are a usage error."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

SUITE = '''
import pytest


def test_plain():
    pass


def test_in_a_browser(chromium):
    pass


@pytest.fixture(params=["inline", "ray"])
def backend(request):
    return request.param


def test_on_every_backend(backend):
    pass


@pytest.mark.slow
def test_long_on_request():
    pass


@pytest.mark.integration
def test_marked():
    pass
'''

#: a plugin that prints each collected test's tier and xdist group
DUMP = '''
def pytest_collection_finish(session):
    for item in session.items:
        tier = [m.name for m in item.iter_markers() if m.name in
                ("fast", "integration", "slow", "bench")]
        group = item.get_closest_marker("xdist_group").args[0]
        print("TIER", item.name, ",".join(tier), group.rsplit("/", 1)[-1])
'''


def _pytest(folder: Path, *args: str, **env: str) -> subprocess.CompletedProcess[str]:
    """``pytest`` of ``folder``'s tests with this conftest as a plugin, its
    temporary folder ``folder/base`` (its cosim cache folder there, not this
    session's)."""
    outer = {k: v for k, v in os.environ.items() if k != "COSIM_CACHE_DIR"}
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "tests.conftest",
                           "-p", "no:cacheprovider", "--rootdir", str(folder),
                           "-c", str(folder / "pytest.ini"), "--basetemp", str(folder / "base"),
                           *args, str(folder)],
                          cwd=REPO, capture_output=True, text=True, timeout=120,
                          env={**outer, **env, "PYTHONPATH": f"{folder}{os.pathsep}{REPO}"})


def _collect(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``pytest --collect-only`` of ``folder``'s tests, printing their tiers."""
    return _pytest(folder, "-p", "dump", "--collect-only", "-q", *args)


def test_every_test_lands_in_one_tier(tmp_path: Path) -> None:
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "dump.py").write_text(DUMP)
    (tmp_path / "test_suite.py").write_text(textwrap.dedent(SUITE))
    r = _collect(tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    tiers = {line.split()[1]: line.split()[2:] for line in r.stdout.splitlines()
             if line.startswith("TIER ")}
    assert tiers == {
        "test_plain": ["fast", "test_suite.py"],
        "test_in_a_browser": ["integration", "test_suite.py"],
        "test_on_every_backend[inline]": ["fast", "test_suite.py"],
        "test_on_every_backend[ray]": ["integration", "ray"],  # with the other Ray tests
        "test_long_on_request": ["slow", "test_suite.py"],
        "test_marked": ["integration", "test_suite.py"]}
    r = _collect(tmp_path, "-m", "fast or integration")
    assert "test_long_on_request" not in r.stdout and "test_marked" in r.stdout


def test_two_tiers_on_one_test_are_a_usage_error(tmp_path: Path) -> None:
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "dump.py").write_text("")
    (tmp_path / "test_suite.py").write_text(
        "import pytest\n\n\n@pytest.mark.integration\n@pytest.mark.slow\n"
        "def test_both():\n    pass\n")
    r = _collect(tmp_path)
    assert r.returncode == 4, r.stdout + r.stderr
    assert "test_suite.py::test_both is marked integration and slow: a test is in one tier" in (
        r.stdout + r.stderr)


#: a test file whose module fixture notes each time it is made
GROUPED = '''
import os

import pytest


@pytest.fixture(scope="module")
def made():
    with open(os.environ["SETUPS"], "a") as f:
        f.write(__name__ + "\\n")


@pytest.mark.parametrize("i", range(6))
def test_one_of_six(made, i):
    pass
'''


@pytest.mark.integration  # two pytest-xdist workers, each importing cosim
def test_a_files_tests_run_on_one_worker_and_make_its_module_fixture_once(
        tmp_path: Path) -> None:
    """``-n 2 --dist loadgroup`` sends each file's tests to one worker (on
    pytest 9 each test had gone on its own, round the workers, and a
    module fixture was made on each)."""
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    for name in ("test_one.py", "test_two.py"):
        (tmp_path / name).write_text(GROUPED)
    setups = tmp_path / "setups.txt"
    r = _pytest(tmp_path, "-n", "2", "--dist", "loadgroup", "-v", SETUPS=str(setups))
    assert r.returncode == 0, r.stdout + r.stderr
    assert sorted(setups.read_text().split()) == ["test_one", "test_two"], r.stdout
    workers: dict[str, set[str]] = {}
    for line in r.stdout.splitlines():
        if " PASSED " in line:  # "[gw0] [  8%] PASSED .../test_one.py::test_one_of_six[0]@..."
            name = Path(line.split()[-1].split("::")[0]).name
            workers.setdefault(name, set()).add(line.split()[0])
    assert {f: len(w) for f, w in workers.items()} == {"test_one.py": 1, "test_two.py": 1}, \
        r.stdout


#: a test calling the CLI in its process, then one looking at the logging it left
CLI_THEN_LOGGING = '''
import logging

from cosim.cli import main


def test_a_cli_call(tmp_path):
    assert main(["-v", "validate", str(tmp_path / "missing.yaml")]) == 2


def test_logging_is_as_before():
    root = logging.getLogger()
    assert root.level == logging.WARNING, logging.getLevelName(root.level)
    assert not [h for h in root.handlers if type(h) is logging.StreamHandler], root.handlers
    assert logging.getLogger("cosim.jsbsim").level == logging.NOTSET
'''


def test_a_cli_call_in_a_test_leaves_no_logging_to_the_next(tmp_path: Path) -> None:
    """``cosim.cli.main`` in a test's process sets the root logger to INFO
    with a handler on the test's captured stderr; the next test on that
    worker starts with logging as it was (it had inherited both: its log
    lines went to a closed file, and a test read records it had not asked
    for)."""
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_order.py").write_text(CLI_THEN_LOGGING)
    r = _pytest(tmp_path, "-p", "no:randomly", "-q")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "2 passed" in r.stdout, r.stdout


#: a test file noting its worker's cache folder and where its fused/ leads
CACHE = '''
import os
from pathlib import Path


def test_cache():
    root = Path(os.environ["COSIM_CACHE_DIR"])
    with open(os.environ["SETUPS"], "a") as f:
        f.write(f"{root} {(root / 'fused').resolve()}\\n")
'''


@pytest.mark.integration  # two pytest-xdist workers, each importing cosim
def test_the_workers_of_a_session_share_one_folder_of_fused_loops(tmp_path: Path) -> None:
    """Each worker has its own cache folder, in the session's temporary
    folder, but one ``fused/`` for all: a loop is compiled once a session."""
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    for name in ("test_one.py", "test_two.py"):
        (tmp_path / name).write_text(CACHE)
    setups = tmp_path / "setups.txt"
    r = _pytest(tmp_path, "-n", "2", "--dist", "loadgroup", SETUPS=str(setups))
    assert r.returncode == 0, r.stdout + r.stderr
    rows = [line.split() for line in setups.read_text().splitlines()]
    assert len(rows) == 2 and rows[0][0] != rows[1][0], rows  # a folder per worker
    assert {fused for _, fused in rows} == {str((tmp_path / "base" / "cosim-fused").resolve())}
