"""A truthful exit status under MPI: Ctrl-C of ``mpirun -n 2 python -m sliders.prior`` (SIGINT
to the whole foreground process group: the launcher, its proxy and every rank, as a terminal
sends it) ends the job with 130, SIGTERM with 143, after one line (MPICH's ``mpiexec`` returned
0 when the proxy took the Ctrl-C too)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from test_prior import SMALL

pytestmark = pytest.mark.slow  # commands interrupted under mpirun

MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
PRIOR = SMALL.format(R=4000, design="sobol")  # rows of 20-40 sliders: minutes in all


def _reading(fifo) -> int:
    """Wait until rank 0 opens the prior file (a fifo) to read it; the write end, kept open
    and silent: rank 0 waits in the read, the other rank in the next collective step."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:  # no reader yet
            time.sleep(0.1)
    pytest.fail("rank 0 never opened the prior file")


@pytest.mark.parametrize("phase", ["plans", "runs"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_prior_under_mpirun_exits_with_128_plus_the_signal(tmp_path, sig, phase):
    """Stopped while rank 0 reads its input (planning), or while the rows run."""
    assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
    prior = tmp_path / "p.toml"
    if phase == "plans":
        os.mkfifo(prior)
    else:
        prior.write_text(PRIOR)
    err_path = tmp_path / "err.txt"
    writer = None
    with open(err_path, "w") as err:
        job = subprocess.Popen([MPIRUN, "-n", "2", sys.executable, "-m", "sliders.prior",
                                str(prior), "--out", str(tmp_path / "out.h5")],
                               stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        try:
            if phase == "plans":
                writer = _reading(prior)
                time.sleep(1.0)
            else:
                deadline = time.monotonic() + 120
                while "starting" not in err_path.read_text() and time.monotonic() < deadline:
                    time.sleep(0.2)
                assert "starting" in err_path.read_text(), err_path.read_text()
                time.sleep(1.0)
            os.killpg(job.pid, sig)  # the terminal's Ctrl-C reaches the whole group
            code = job.wait(timeout=60)
        finally:
            if writer is not None:
                os.close(writer)
            if job.poll() is None:
                os.killpg(job.pid, signal.SIGKILL)
                job.wait()
    text = err_path.read_text()
    assert code == 128 + sig, (code, text)
    assert f"interrupted ({signal.Signals(sig).name}" in text
    assert "Traceback" not in text and "MPI_Abort" not in text
