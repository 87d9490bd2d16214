"""The suite's sharing of the cores (tests/conftest.py), checked on a suite of three tests.

A test that starts MPI ranks without saying so would share a core with another test's work
(and stay out of the group that holds both cores): under xdist it fails, naming the mark.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
INNER = '''
import subprocess
import pytest

def test_unmarked():
    subprocess.run(["mpirun", "-n", "1", "true"], check=True)

@pytest.mark.two_cores
def test_marked():
    subprocess.run(["mpirun", "-n", "1", "true"], check=True)

@pytest.mark.ranks_share_one_core
def test_serial_under_mpirun():
    subprocess.run(["mpirun", "-n", "1", "true"], check=True)
'''


@pytest.mark.slow  # a pytest session of its own, with an xdist worker
def test_a_test_that_starts_ranks_unmarked_fails_naming_the_mark(tmp_path):
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed (Debian mpich: scripts/setup.sh): no ranks to start")
    (tmp_path / "test_inner.py").write_text(INNER)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = str(TESTS)  # this suite's conftest, loaded as a plugin
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "1", "--dist", "loadgroup",
                          "-p", "conftest", "-p", "no:cacheprovider", "test_inner.py"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert "1 failed, 2 passed" in res.stdout, res.stdout[-3000:] + res.stderr[-2000:]
    assert "FAILED test_inner.py::test_unmarked" in res.stdout
    assert "mark it @pytest.mark.two_cores" in res.stdout
