"""Trust, third round: the run commands (ensemble, study, prior) against an adversary.

Classes (docs/reliability.md counts them): 1. a file is its identity (a hard
link is the same file, with or without HDF5's own locks); 2. one input, one
plan on every rank (rank 0 reads, every rank parses its bytes); 3. every early
exit reaches every rank (Ctrl-C while rank 0 still plans); 4. plans bounded
before they are drawn; 5. a full disk stops the run at the first write that
cannot be made; 6. prior parameters checked before any file exists.  Tiny
scenes; the MPI cases start ``mpirun -n 2`` themselves.
"""

from __future__ import annotations

import errno
import os
import resource
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from sliders.io.prior_file import read_prior_ensemble, read_prior_header
from sliders.runs import prior as prior_run
from sliders.runs import prior_spec
from helpers import (PY, RESULTS_IGNORED, STUDY_TEXT, _children, _env, _Run, assert_same_file,
                     assert_same_sets, kill_tree, one_error_line, rank_pids, read_all, run)

pytestmark = pytest.mark.slow  # attacks on the run commands under mpirun

PRIOR = """
[prior]
realisations = {R}
seed = 3
[scene]
mode = "explore"
{scene}
[parameters]
mu_d = {{ uniform = [{low}, {high}] }}
mu_s_minus_mu_d = {{ loguniform = [0.02, 0.12] }}
n_sliders = {{ choice = [{sizes}] }}
"""
STUDY = STUDY_TEXT.replace("mu_d = 0.5", "mu_d = {mu_d}")
SCENE = "n_sliders = 10\nseed = 7\nmode = \"explore\"\nmu_d = {mu_d}\n"
MODULES = {"ensemble": "sliders.ensemble", "study": "sliders.study", "prior": "sliders.prior"}


def prior_text(R=12, low=0.3, high=0.5, sizes="20, 30", scene=""):
    return PRIOR.format(R=R, low=low, high=high, sizes=sizes, scene=scene)


def input_text(command: str, variant: int = 0) -> str:
    """An input file of ``command``; variant 1 differs from variant 0 in the material."""
    if command == "prior":
        return prior_text(low=0.6, high=0.7) if variant else prior_text()
    text = STUDY if command == "study" else SCENE
    return text.format(mu_d=0.45 if variant else 0.5)


def command_args(command: str, source, out, extra=()) -> list:
    """The command line of ``command`` reading its input from ``source``."""
    if command == "ensemble":
        return ["--scene", source, "-R", 10, "--out", out, "--progress-interval", "0", *extra]
    return [source, "--out", out, "--progress-interval", "0", *extra]


def start(command, args, n=None, env=None) -> _Run:
    return _Run(args, n, env or _env(), module=MODULES[command])


def finish(command, args, n=None, env=None, timeout=120):
    return run(args, n, env or _env(), timeout, module=MODULES[command])


def assert_same_rows(command: str, a, b) -> None:
    """The same rows (a prior ensemble's catalogues in row order; any other file bit for bit)."""
    if command == "prior":
        assert_same_sets(read_prior_ensemble(a), read_prior_ensemble(b))
    elif command == "study":  # the datasets (the attributes name the input's path)
        (da, _), (db, _) = read_all(a), read_all(b)
        assert sorted(da) == sorted(db)
        for k in da:
            if k.rsplit("/", 1)[-1] not in RESULTS_IGNORED:
                assert da[k].tobytes() == db[k].tobytes(), k
    else:
        assert_same_file(a, b)


def process_tree(pid: int) -> list[int]:
    """``pid`` and all its descendants (mpirun, its proxy, the ranks)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(_children(p))
    return out


class FifoFeeder:
    """A named pipe whose first reader gets ``first`` and every later reader ``later``:
    an input file that changes between two ranks' reads."""

    def __init__(self, path: Path, first: str, later: str):
        self.path, self.texts = path, (first.encode(), later.encode())
        os.mkfifo(path)
        self.opens = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while not self.stop.is_set():
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_NONBLOCK)
            except OSError as exc:
                if exc.errno != errno.ENXIO:  # ENXIO: no reader yet
                    raise
                time.sleep(0.005)
                continue
            os.set_blocking(fd, True)
            try:
                os.write(fd, self.texts[min(self.opens, 1)])
            except BrokenPipeError:
                pass
            os.close(fd)
            self.opens += 1
            self._wait_for_no_reader()

    def _wait_for_no_reader(self):
        """Until the reader served has closed its end (so that the next text goes to a new one)."""
        while not self.stop.is_set():
            try:
                os.close(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError as exc:
                if exc.errno == errno.ENXIO:
                    return
                raise
            time.sleep(0.005)

    def close(self):
        self.stop.set()
        self.thread.join(5)


# ---------------------------------------------------------------------------
# 1. a file is its identity
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("command, ranks", [
    ("ensemble", None), pytest.param("ensemble", 2, marks=pytest.mark.two_cores),
    ("study", None), pytest.param("prior", 2, marks=pytest.mark.two_cores)])
def test_second_resume_through_a_hard_link_is_refused(tmp_path, command, ranks):
    source = tmp_path / "input.toml"
    source.write_text(input_text(command))
    out, link = tmp_path / "run.h5", tmp_path / "other_name.h5"
    no_hdf5_locks = {"HDF5_USE_FILE_LOCKING": "FALSE"}
    first = start(command, command_args(command, source, out), ranks,
                  _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.4, **no_hdf5_locks))
    try:
        first.wait_for(lambda lines: any("starting" in ln for ln in lines), timeout=90)
        os.link(out, link)
        frozen = process_tree(first.proc.pid)
        for pid in frozen:  # still writing, however slow this machine
            os.kill(pid, signal.SIGSTOP)
        try:
            second = finish(command, command_args(command, source, link, ["--resume"]),
                            env=_env(**no_hdf5_locks))
        finally:
            for pid in frozen:
                os.kill(pid, signal.SIGCONT)
        line = one_error_line(second)
        assert "is being written by" in line and "another name" in line, line
    finally:
        res = first.finish(120)
    assert res.returncode == 0, res.stderr
    # the first run's file is whole: a resume has nothing left to do
    again = finish(command, command_args(command, source, link, ["--resume"]))
    assert again.returncode == 0, again.stderr
    assert "starting 0 of" in again.stderr.replace("resuming", "starting") or \
        "nothing to do" in again.stderr, again.stderr


# ---------------------------------------------------------------------------
# 2. one input, one plan on every rank
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("command", sorted(MODULES))
@pytest.mark.two_cores  # it starts mpirun -n 2
def test_every_rank_runs_the_input_rank_0_read(tmp_path, command):
    """The input changes after its first read (a pipe here; a file edited at job start or two
    copies on NFS elsewhere): every rank still computes rank 0's plan."""
    regular = tmp_path / "input.toml"
    regular.write_text(input_text(command))
    reference = tmp_path / "serial.h5"
    res = finish(command, command_args(command, regular, reference, ["--quiet"]))
    assert res.returncode == 0, res.stderr
    feeder = FifoFeeder(tmp_path / "changing.toml", input_text(command), input_text(command, 1))
    try:
        out = tmp_path / "two.h5"
        res = finish(command, command_args(command, feeder.path, out, ["--quiet"]), 2)
    finally:
        feeder.close()
    assert res.returncode == 0, res.stderr
    assert feeder.opens == 1  # read once, by rank 0
    assert_same_rows(command, reference, out)


# ---------------------------------------------------------------------------
# 3. every early exit reaches every rank
# ---------------------------------------------------------------------------
def _blocked_in_open(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/wchan").read_text().strip() == "wait_for_partner"
    except OSError:
        return False


@pytest.mark.parametrize("command", sorted(MODULES))
@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=pytest.mark.two_cores)])
def test_ctrl_c_while_rank_0_plans_ends_every_rank(tmp_path, command, ranks):
    """Rank 0 is still planning (its input, a pipe, has no writer yet) and gets SIGINT alone:
    every rank exits at once with 128 + 2 and one line, no traceback, no file."""
    fifo = tmp_path / "input.toml"
    os.mkfifo(fifo)
    out = tmp_path / "run.h5"
    job = start(command, command_args(command, fifo, out), ranks)
    try:
        deadline = time.monotonic() + 60
        rank0 = None
        while time.monotonic() < deadline:
            pids = [job.proc.pid] if ranks is None else rank_pids(job.proc.pid)
            if pids and len(pids) == (ranks or 1) and _blocked_in_open(pids[0]):
                rank0 = pids[0]
                break
            time.sleep(0.05)
        assert rank0 is not None, "rank 0 never reached its input"
        time.sleep(0.3)  # the other rank is in the first collective step by now
        os.kill(rank0, signal.SIGINT)
        res = job.finish(30)
    finally:
        kill_tree(job.proc.pid)
    line = one_error_line(res)
    assert "interrupted (SIGINT) while planning" in line, line
    assert res.returncode == 128 + signal.SIGINT, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["input.toml"]


# ---------------------------------------------------------------------------
# 4. plans bounded before they are drawn
# ---------------------------------------------------------------------------
def _as_limited_memory():
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_a_prior_of_1e8_rows_is_refused_before_anything_is_drawn(tmp_path):
    """With a disk that would hold it (the disk check stubbed) and 3 GB of address space, a
    prior of 10^8 rows is refused in one line, at once, instead of drawing gigabytes."""
    path = tmp_path / "huge.toml"
    path.write_text(prior_text(R=100_000_000))
    code = ("import sys\nfrom sliders.io import storage\n"
            "storage.check_room = lambda *a, **k: None  # a disk that holds anything\n"
            "from sliders.runs import prior\nsys.exit(prior.main(sys.argv[1:]))")
    t0 = time.monotonic()
    res = subprocess.run([PY, "-c", code, str(path), "--out", str(tmp_path / "x.h5")],
                         capture_output=True, text=True, timeout=120, env=_env(),
                         preexec_fn=_as_limited_memory)
    assert res.returncode == 2, res.stderr
    line = one_error_line(res)
    assert "realisations = 100000000" in line and "split" in line, line
    assert time.monotonic() - t0 < 60
    assert sorted(os.listdir(tmp_path)) == ["huge.toml"]


def test_a_plan_larger_than_the_memory_is_refused(tmp_path, capsys, monkeypatch):
    """Within the row limit, a plan that would not fit in the memory of this node (here: 1 GB
    available) is refused before a row is drawn, naming the count and the memory."""
    monkeypatch.setattr(prior_spec, "available_memory", lambda: 1 << 30)
    path = tmp_path / "big.toml"
    path.write_text(prior_text(R=5_000_000))
    assert prior_run.main([str(path), "--out", str(tmp_path / "x.h5")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "realisations = 5000000" in lines[0] and "GB" in lines[0], lines
    assert sorted(os.listdir(tmp_path)) == ["big.toml"]


# ---------------------------------------------------------------------------
# 5. a full disk
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=pytest.mark.two_cores)])
def test_a_full_disk_stops_a_prior_run_at_the_first_write_in_one_line(tmp_path, ranks):
    """A 600 kB file system (tmpfs in a user and mount namespace) cannot hold the run: one
    line, exit 1, no crash (HDF5 is never left with a failed write), the rows marked done
    whole.  A write is made only with room for it and a margin (``writes.write_row``)."""
    (tmp_path / "p.toml").write_text(prior_text(R=40, sizes="60, 80"))
    launcher = "" if ranks is None else f"{subprocess.list2cmdline(['mpirun', '-n', str(ranks)])} "
    script = (f"mount -t tmpfs -o size=600k tmpfs {tmp_path}/mnt && "
              f"{launcher}{PY} -m sliders.prior {tmp_path}/p.toml --out {tmp_path}/mnt/p.h5 "
              f"--quiet; code=$?; cp {tmp_path}/mnt/p.h5 {tmp_path}/copy.h5; exit $code")
    (tmp_path / "mnt").mkdir()
    res = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script],
                         capture_output=True, text=True, timeout=180, env=_env())
    assert res.returncode == 1, res.stderr[-3000:]
    lines = [ln for ln in res.stderr.splitlines()
             if ln.strip() and not ln.startswith("Abort(")]  # MPICH's own line after MPI_Abort
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-3000:]
    assert lines[0].startswith("error: rank 0: cannot write") and \
        "No space left on device" in lines[0], lines[0]
    head = read_prior_header(tmp_path / "copy.h5")
    assert head["done"].sum() < 40 and not head["damaged"]


# ---------------------------------------------------------------------------
# 6. prior parameters checked before any file exists
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("head, parameters, words", [
    ("", "n_sliders = 20.0", "[parameters] n_sliders = 20.0: n_sliders is an integer"),
    ("", "n_sliders = { uniform = [20, 40] }", "n_sliders takes integers"),
    ("", "xi = { choice = [true, false] }", "[parameters] xi: True is not a number"),
    ("ceiling_k = 100000\n", "n_sliders = 30", "ceiling_k = 100000 is more than the largest "
                                               "chain (n_sliders up to 30)"),
    ("", "mu_d = nan", "[parameters] mu_d: nan is not a finite number"),
    ("", "mu_d = { choice = [0.3, inf] }", "[parameters] mu_d: inf is not a finite number"),
])
def test_bad_prior_parameters_are_refused_before_any_file(tmp_path, capsys, head, parameters,
                                                          words):
    path = tmp_path / "bad.toml"
    path.write_text(f"[prior]\nrealisations = 4\n{head}[scene]\nmode = 'explore'\n"
                    f"mu_s_mean = 0.9\n[parameters]\n{parameters}\n")
    assert prior_run.main([str(path), "--out", str(tmp_path / "x.h5")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: prior file") and words in lines[0], \
        lines
    assert sorted(os.listdir(tmp_path)) == ["bad.toml"]


def test_plans_cost_memory_per_row_not_per_scene():
    """A prior's plan keeps a few numbers a row (no scene objects): planning 8 000 rows takes
    fewer bytes per row more than planning 2 000 does than ``PLAN_BYTES_PER_ROW`` promises
    (the difference leaves out what any plan costs once)."""
    import tracemalloc

    def plan_peak(rows: int) -> int:
        prior = prior_spec.parse_prior({"prior": {"realisations": rows, "design": "random"},
                                       "scene": {"mode": "explore"},
                                       "parameters": {"mu_d": {"uniform": [0.3, 0.5]},
                                                      "n_sliders": {"choice": [20, 30]}}})
        tracemalloc.start()
        try:
            prior.check_rows()
            seeds = prior.seeds()
            order = np.argsort(-prior.values()["n_sliders"], kind="stable")
            assert seeds.size == order.size == rows
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    plan_peak(20)  # what the first plan loads once (modules, caches)
    small, large = plan_peak(2_000), plan_peak(8_000)
    assert (large - small) / 6_000 < prior_spec.PLAN_BYTES_PER_ROW, (small, large)
