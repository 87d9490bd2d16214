"""``predict --follow`` as a process: SIGTERM and SIGINT end it within seconds whatever call
it is in (the open of a FIFO without a writer, a write to a full pipe, an idle poll, a wait on
standard input) with 143 and 130; its reads are bounded; a missing file, a row too long and a
picture that cannot be written are one line, exit 2; standard input is followed."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # each starts the command, which loads the model

F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)


def catalogue_text(n: int = 60, seed: int = 3) -> str:
    rng = np.random.default_rng(seed)
    alpha = np.round(31.0 - 31.0 * np.exp(-3.0 * np.sort(rng.random(n))), 4)
    size = np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)
    return "angle [deg],size\n" + "".join(f"{a},{s}\n" for a, s in zip(alpha, size))


def start(*args, **kw):
    kw.setdefault("stdout", subprocess.PIPE)
    return subprocess.Popen([sys.executable, "-m", "sliders.forecast", "predict", *args,
                             "--follow"], stderr=subprocess.PIPE, text=True, **kw)


def blocked_in(proc, calls, timeout=90.0) -> bool:
    """Wait until ``proc`` sleeps in the kernel in one of ``calls`` (its wchan)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        try:
            with open(f"/proc/{proc.pid}/wchan") as fh:
                where = fh.read()
            if any(c in where for c in calls):
                return True
        except OSError:
            return False
        time.sleep(0.1)
    return False


def stopped_by(proc, signum, timeout=10.0) -> tuple[int, str, float]:
    t = time.monotonic()
    proc.send_signal(signum)
    try:
        code = proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
    return code, proc.stderr.read(), time.monotonic() - t


@pytest.fixture
def needs_proc():
    if not os.path.exists("/proc/self/wchan"):
        pytest.skip("needs /proc/PID/wchan to see where a process sleeps")


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_fifo_without_writer_is_left_on_a_stop_signal(tmp_path, needs_proc, signum, status):
    fifo = tmp_path / "pile.csv"
    os.mkfifo(fifo)
    proc = start(str(fifo))
    assert blocked_in(proc, ("wait_for_partner", "fifo_open")), proc.stderr.read()
    code, err, took = stopped_by(proc, signum)
    assert code == status and took < 5, (code, err, took)
    assert f"stopped ({signal.Signals(signum).name})" in err and "Traceback" not in err


def test_a_full_output_pipe_does_not_hold_off_sigterm(tmp_path, needs_proc):
    """``--json | consumer`` whose consumer reads nothing: the write blocks, SIGTERM ends it."""
    path = tmp_path / "pile.csv"
    path.write_text(catalogue_text())
    read_end, write_end = os.pipe()
    fcntl.fcntl(read_end, F_SETPIPE_SZ, 4096)
    proc = start(str(path), "--json", "--tilt-rate", "1deg/s", stdout=write_end)
    os.close(write_end)
    try:
        assert blocked_in(proc, ("pipe_write",)), proc.stderr.read()
        code, err, took = stopped_by(proc, signal.SIGTERM)
    finally:
        os.close(read_end)
    assert code == 143 and took < 5, (code, err, took)
    assert "stopped (SIGTERM)" in err and "Traceback" not in err


def test_an_idle_follow_and_standard_input(tmp_path, needs_proc):
    """An idle poll stopped by Ctrl-C gives 130; standard input is followed (``-``), a wait
    on it stopped by SIGTERM gives 143, and its end ends the follow with 0."""
    path = tmp_path / "pile.csv"
    path.write_text(catalogue_text())
    proc = start(str(path))
    assert proc.stdout.readline().startswith("rows 60, tilt "), proc.stderr.read()
    code, err, took = stopped_by(proc, signal.SIGINT)
    assert code == 130 and took < 5 and "stopped (SIGINT)" in err, (code, err)

    proc = start("-", stdin=subprocess.PIPE)
    proc.stdin.write(catalogue_text(40))
    proc.stdin.flush()
    assert proc.stdout.readline().startswith("rows 40, tilt "), proc.stderr.read()
    assert blocked_in(proc, ("select", "poll", "hrtimer", "nanosleep"), timeout=10), \
        (proc.poll(), proc.stderr.read() if proc.poll() is not None else "")
    code, err, took = stopped_by(proc, signal.SIGTERM)
    assert code == 143 and took < 5, (code, err)

    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", "-", "--follow"],
                         input=catalogue_text(30), capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith("rows 30, tilt "), out.stderr
    assert "the input ended" in out.stderr


def test_unbounded_and_missing_sources_are_one_line(tmp_path):
    """``/dev/zero`` and a line growing past 4096 bytes (10 MB, no newline) are refused at once
    naming the file and the row, in bounded memory; a missing file before the model is read."""
    t = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict",
                          str(tmp_path / "no_such_pile.csv"), "--follow"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stdout == "" and time.monotonic() - t < 30
    assert out.stderr.count("\n") == 1 and "no_such_pile.csv: No such file" in out.stderr

    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", "/dev/zero",
                          "--follow"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert "/dev/zero: row 1: longer than 4096 bytes" in out.stderr

    path = tmp_path / "pile.csv"
    path.write_text(catalogue_text())
    proc = start(str(path))
    try:
        assert proc.stdout.readline().startswith("rows 60"), proc.stderr.read()
        with open(path, "ab") as fh:
            fh.write(b"7" * (10 * 2**20))
        code = proc.wait(timeout=30)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 2 and "pile.csv: row 62: longer than 4096 bytes" in err, err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_a_picture_that_cannot_be_written_is_one_line(tmp_path):
    """A --plot FIFO with no reader is refused at once; the --plot file replaced by a folder
    during the follow: one line naming it, exit 2, no temporary file named or left, though
    no update follows the one whose picture failed."""
    path = tmp_path / "pile.csv"
    path.write_text(catalogue_text(40))
    fifo = tmp_path / "live.fifo"
    os.mkfifo(fifo)
    out = subprocess.run([sys.executable, "-m", "sliders.forecast", "predict", str(path),
                          "--follow", "--plot", str(fifo)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "--plot" in out.stderr
    png = tmp_path / "live.png"
    proc = start(str(path), "--plot", str(png))
    try:
        assert proc.stdout.readline().startswith("rows 40"), proc.stderr.read()
        end = time.monotonic() + 60
        while not png.exists() and time.monotonic() < end:
            time.sleep(0.1)
        png.unlink()
        png.mkdir()
        with open(path, "a") as fh:  # a new state, a new picture; then the input is quiet
            fh.write("# tilt-now 31.2deg\n")
        code = proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 2 and err.count("\n") == 1 and str(png) in err, err
    assert ".tmp" not in err and not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]
