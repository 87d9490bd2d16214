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
from pathlib import Path

import pytest

from helpers import SMALL_PRIOR

pytestmark = pytest.mark.slow  # commands interrupted under mpirun

MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
PRIOR = SMALL_PRIOR.format(R=4000, design="sobol")  # rows of 20-40 sliders: minutes in all


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
@pytest.mark.two_cores  # it starts mpirun -n 2
def test_a_stopped_prior_under_mpirun_exits_with_128_plus_the_signal(tmp_path, sig, phase):
    """Stopped while rank 0 reads its input (planning), or while the rows run."""
    assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
    prior = tmp_path / "p.toml"
    if phase == "plans":
        os.mkfifo(prior)
    else:
        prior.write_text(PRIOR)

    def ready(job, err_path):
        if phase == "plans":
            return _reading(prior)
        deadline = time.monotonic() + 120
        while "starting" not in err_path.read_text() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert "starting" in err_path.read_text(), err_path.read_text()
        return None

    code, text = _stopped(tmp_path, ["sliders.prior", str(prior), "--out", str(tmp_path / "out.h5")],
                          ready, sig)
    assert code == 128 + sig, (code, text)
    assert f"interrupted ({signal.Signals(sig).name}" in text
    assert "Traceback" not in text and "MPI_Abort" not in text


def _stopped(tmp_path, module_args: list[str], ready, sig) -> tuple[int, str]:
    """``mpirun -n 2 python -m MODULE ARGS``, sent ``sig`` as a terminal does (to the whole
    group) one second after ``ready(job, err_path)`` returned (a fifo's write end to keep
    open, or None): its exit status and stderr."""
    err_path = tmp_path / "err.txt"
    writer = None
    with open(err_path, "w") as err:
        job = subprocess.Popen([MPIRUN, "-n", "2", sys.executable, "-m", *module_args],
                               stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        try:
            writer = ready(job, err_path)
            _handling_signals(job.pid)
            time.sleep(1.0)
            os.killpg(job.pid, sig)  # the terminal's Ctrl-C reaches the whole group
            code = job.wait(timeout=60)
        finally:
            if writer is not None:
                os.close(writer)
            if job.poll() is None:
                os.killpg(job.pid, signal.SIGKILL)
                job.wait()
    return code, err_path.read_text()


def _descendants(pid: int):
    """``pid`` and the processes under it that are still running (``/proc``'s children lists)."""
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            children = Path(f"/proc/{p}/task/{p}/children").read_text().split()
        except OSError:
            continue
        yield p
        todo += [int(c) for c in children]


def _ranks(launcher: int) -> list[int]:
    """The Python processes (the ranks) among the launcher's descendants (each rank in its
    own session, as MPICH's proxy starts it)."""
    ranks = []
    for pid in _descendants(launcher):
        try:
            argv0 = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
        except OSError:
            continue
        if argv0 == os.fsencode(sys.executable):
            ranks.append(pid)
    return ranks


def _handling_signals(launcher: int) -> None:
    """Wait until both ranks handle SIGTERM (catch or ignore it): past their imports, inside
    the command.  A signal that reaches a rank still importing kills it by the default
    action, and the launcher's status then depends on which process it reaps first."""
    mask = 1 << (signal.SIGTERM - 1)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        caught = []
        for pid in _ranks(launcher):
            try:
                status = Path(f"/proc/{pid}/status").read_text()
            except OSError:
                continue
            handled = 0  # the signals caught or ignored: not left to the default action
            for line in status.splitlines():
                if line.startswith(("SigCgt:", "SigIgn:")):
                    handled |= int(line.split()[1], 16)
            caught.append(bool(handled & mask))
        if len(caught) == 2 and all(caught):
            return
        time.sleep(0.05)
    pytest.fail("the ranks never installed their signal handlers")


def _cpu_seconds(pid: int) -> float:
    """CPU time used by ``pid`` and its descendants that are still running."""
    total = 0.0
    for p in _descendants(pid):
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def _computing(pid: int, seconds: float = 3.0) -> None:
    """Wait until the job has used ``seconds`` of CPU: past its imports (half a second each)."""
    deadline = time.monotonic() + 120
    while _cpu_seconds(pid) < seconds and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _cpu_seconds(pid) >= seconds, "the job never started computing"


@pytest.mark.ranks_share_one_core  # rank 1 sleeps until rank 0's status
@pytest.mark.parametrize("phase", ["reads", "computes"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stopped_forecast_command_under_mpirun_exits_with_128_plus_the_signal(tmp_path, sig,
                                                                               phase):
    """A serial command under ``mpirun -n 2``: stopped while rank 0 reads its catalogue (a
    fifo, ``predict``) or while it computes (``evaluate`` on development data)."""
    assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
    if phase == "reads":
        catalogue = tmp_path / "pile.csv"
        os.mkfifo(catalogue)
        args = ["predict", str(catalogue)]
    else:
        args = ["evaluate", "--dev", "400", "--out", str(tmp_path / "out")]

    def ready(job, err_path):
        if phase == "reads":
            return _reading(catalogue)
        _computing(job.pid)
        return None

    code, text = _stopped(tmp_path, ["sliders.forecast", *args], ready, sig)
    assert code == 128 + sig, (code, text)
    assert f"interrupted ({signal.Signals(sig).name})" in text
    assert "Traceback" not in text and "MPI_Abort" not in text
    assert text.count("interrupted") == 1, text  # one line, from rank 0


@pytest.mark.ranks_share_one_core  # rank 1 sleeps until rank 0's status
@pytest.mark.parametrize("args, code", [(["predict", "--help"], 0), (["--help"], 0),
                                         (["predict", "--no-such-option"], 2),
                                         (["predict", "missing.csv"], 2)])
def test_a_forecast_command_under_mpirun_ends_on_every_rank(tmp_path, args, code):
    """Help, a bad option, a missing file: rank 0 ends the command, and the waiting rank
    ends with it (no hang), with rank 0's status and one copy of its output."""
    assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
    res = subprocess.run([MPIRUN, "-n", "2", sys.executable, "-m", "sliders.forecast", *args],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert res.returncode == code, res.stderr
    assert res.stdout.count("usage:") == (1 if "--help" in args else 0)
    assert len(res.stderr.splitlines()) == (0 if code == 0 else 1), res.stderr
