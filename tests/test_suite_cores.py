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


@pytest.mark.parametrize("command, starts", [
    ("mpirun -n 2 python -m sliders.prior p.toml --out p.h5", True),
    ("OUT=fc bash mpi_runs/forecast.sh --quiet", True),
    ("python -m sliders.forecast train --prior p.toml --out m.zip --np 2", True),
    ("python -m sliders.forecast train --prior p.toml --out m.zip --np=4", True),
    ("python -m sliders.forecast train --prior p.toml --out m.zip --np 1", False),
    ("python -m sliders.prior p.toml --out p.h5", False),
])
def test_a_command_that_starts_ranks_is_known_by_its_words(command, starts):
    from conftest import starts_ranks

    assert starts_ranks(command) is starts
    assert starts_ranks(["bash", "-c", command]) is starts


def test_a_skipped_block_of_a_page_does_not_make_it_hold_both_cores():
    from conftest import run_blocks

    page = ('```bash\npython -m sliders.prior p.toml\n```\n\n'
            '<!-- skip: next "the full run, an hour" -->\n\n'
            '```bash\nmpirun -n 2 python -m sliders.prior big.toml\n```\n\n'
            '```console\n$ sbatch --wait job.sbatch\n```\n')
    assert run_blocks(page) == ["python -m sliders.prior p.toml\n", "$ sbatch --wait job.sbatch\n"]
