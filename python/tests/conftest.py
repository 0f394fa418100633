"""Shared fixtures: the C++ command line the package is compared with, and a small simulated survey."""
import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def cli_path() -> Path:
    """The C++ `minemap` program of the same build (MINEMAP_CLI, else build/minemap). Missing is a
    failure, never a skip: the package is proven against it."""
    path = Path(os.environ.get("MINEMAP_CLI", REPO / "build" / "minemap"))
    if not (path.is_file() and os.access(path, os.X_OK)):
        pytest.fail(f"the minemap program is not at {path}: build it (scripts/test.sh) or set MINEMAP_CLI")
    return path


def run_cli(*args, check=True) -> subprocess.CompletedProcess:
    result = subprocess.run([str(cli_path()), *map(str, args)], capture_output=True, text=True)
    if check and result.returncode != 0:
        raise AssertionError(f"minemap {' '.join(map(str, args))} exited {result.returncode}:\n{result.stderr}")
    return result


@pytest.fixture(scope="session")
def small_survey(tmp_path_factory) -> Path:
    """6 simulated scans (uos, with truth/), written by the C++ program."""
    out = tmp_path_factory.mktemp("sim") / "survey"
    run_cli("simulate", "--out", out, "--scans", 6, "--seed", 3)
    return out


@pytest.fixture()
def fresh_copy(tmp_path, small_survey):
    def make(name="survey"):
        target = tmp_path / name
        shutil.copytree(small_survey, target)
        return target
    return make


def default_sigint():
    """preexec_fn for a child a test interrupts: SIGINT back to its default. A shell starts background
    jobs (`scripts/test.sh &`, nohup) with SIGINT ignored, children inherit that, and Python then
    installs no KeyboardInterrupt handler at all."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture()
def python_sigint():
    """Python's own SIGINT handler (KeyboardInterrupt) in this process for the test, whatever the
    shell that started pytest left (see default_sigint)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
