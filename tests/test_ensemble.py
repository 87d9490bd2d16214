"""The MPI ensemble (``python -m sliders.ensemble``) and its HDF5 file.

Every run is a subprocess (``mpirun -n P python -m sliders.ensemble ...`` or
plain ``python -m sliders.ensemble ...``) in its own process group, killed
whole if it outlives its timeout, so that nothing can hang the suite.
"""

from __future__ import annotations

import atexit
import json
import math
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import sliders
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary
from sliders.runs.rows import compute_row
from sliders.runs.parallel import SerialComm
from sliders.io import h5tools, storage
from sliders.keyed_random import realisation_seed
from sliders.analysis.observables import default_grids, realisation_statistics, statistics_layout

# MPI ensembles under mpirun, kills and resumes (the few serial tests cost little beside them)
pytestmark = [pytest.mark.slow, pytest.mark.two_cores]

# The tests pick the backend explicitly (no skipping).  "fortran" is the
# production kernel; the lead makes sure it is built in the final set-up.
BACKEND = "fortran"  # the production kernel (numpy works too, about 50x slower here)
MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
PY = sys.executable
TIMEOUT = 180  # seconds for any single run; nothing should get close

# A tiny, fast scene: N = 10, the paper's parameters otherwise.
SCENE_OPTS = ["--n-sliders", "10", "--seed", "7"]
SCENE = sliders.Scene(n_sliders=10, seed=7)
R = 10
# per-row values that depend on the run (the checksums cover the wall time)
RESULTS_IGNORED = {"wall_time", "row_crc32"}
# differ per run (the attributes' checksum covers the creation date)
ATTRS_IGNORED = {"created", "attrs_crc32", "date_created", "date_modified", "history"}


# tests/hooks/sitecustomize.py: the test hooks (SLIDERS_ENSEMBLE_TEST_DELAY, ..._TEST_FAIL,
# ..._STOP_AFTER), installed in every rank of a command started with this environment
HOOKS = Path(__file__).parent / "hooks"


def _env(**extra):
    env = dict(os.environ)
    env.pop("SLIDERS_ENSEMBLE_STOP_AFTER", None)
    env.pop("SLIDERS_ENSEMBLE_TEST_DELAY", None)
    env.pop("SLIDERS_ENSEMBLE_TEST_FAIL", None)
    env["PYTHONUNBUFFERED"] = "1"
    env["PYTHONPATH"] = os.pathsep.join([str(HOOKS)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.update({k: str(v) for k, v in extra.items()})
    return env


def command(args, n=None, module="sliders.ensemble"):
    """The command line of ``python -m module``: plain python (n None) or mpirun -n n."""
    base = [PY, "-m", module]
    if n is not None:
        assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
        base = [MPIRUN, "-n", str(n)] + base
    return base + [str(a) for a in args]


def _children(pid: int) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                stat = (p / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(p.name))
    return out


def kill_tree(pid: int) -> None:
    """SIGKILL a process started here and all its descendants (mpirun puts its proxy
    and the ranks in process groups of their own, so killpg is not enough)."""
    todo, seen = [pid], []
    while todo:
        p = todo.pop()
        seen.append(p)
        todo += _children(p)
    for p in seen:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


_LIVE: "set[int]" = set()  # process trees started here and maybe still running


@atexit.register
def _kill_live() -> None:
    """The runs live in sessions of their own (so that a kill reaches the whole tree):
    a Ctrl-C or SIGTERM of the test run must take them down with it."""
    for pid in sorted(_LIVE):
        kill_tree(pid)
    _LIVE.clear()


@pytest.fixture(autouse=True, scope="module")
def _sigterm_ends_the_tests_like_ctrl_c():
    """While these tests run, SIGTERM ends pytest like Ctrl-C (so that the runs are killed);
    the handler is this module's only, not a side effect of collecting it."""
    if signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        yield
        return
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


class _Run:
    """A started run whose stderr is read by a thread (so that waits can time out)."""

    def __init__(self, args, n, env, module="sliders.ensemble"):
        self.cmd = command(args, n, module)
        self.proc = subprocess.Popen(self.cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env or _env(), start_new_session=True)
        _LIVE.add(self.proc.pid)
        self.lines: "queue.Queue[str | None]" = queue.Queue()
        self.err: list[str] = []
        self.out: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.lines), daemon=True).start()
        threading.Thread(target=self._drain, args=(self.proc.stdout, self.out), daemon=True).start()

    @staticmethod
    def _pump(stream, q):
        for line in stream:
            q.put(line)
        q.put(None)

    @staticmethod
    def _drain(stream, sink):
        for line in stream:
            sink.append(line)

    def wait_for(self, predicate, timeout=TIMEOUT) -> None:
        """Collect stderr lines until predicate(lines) holds; fail (and kill) otherwise."""
        deadline = time.monotonic() + timeout
        while not predicate(self.err):
            try:
                line = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                self.kill()
                pytest.fail(f"timed out waiting on {self.cmd}:\n{''.join(self.err)}")
            if line is None:
                pytest.fail(f"run ended early: {self.cmd}:\n{''.join(self.err)}")
            self.err.append(line)

    def finish(self, timeout=TIMEOUT) -> subprocess.CompletedProcess:
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"run did not finish within {timeout} s (hang?): {self.cmd}\n"
                        f"{''.join(self.err)}")
        except KeyboardInterrupt:
            self.kill()
            raise
        _LIVE.discard(self.proc.pid)
        while True:
            try:
                line = self.lines.get(timeout=10)
            except queue.Empty:  # a stray descendant still holds the pipe
                break
            if line is None:
                break
            self.err.append(line)
        return subprocess.CompletedProcess(self.cmd, self.proc.returncode, "".join(self.out),
                                           "".join(self.err))

    def kill(self) -> None:
        kill_tree(self.proc.pid)
        _LIVE.discard(self.proc.pid)


def run(args, n=None, env=None, timeout=TIMEOUT, module="sliders.ensemble"):
    """Run to completion (or kill the whole process tree after ``timeout``)."""
    return _Run(args, n, env, module).finish(timeout)


def ensemble_args(out, r=R, backend=BACKEND, extra=()):
    return SCENE_OPTS + ["--realisations", r, "--out", out, "--backend", backend,
                         "--progress-interval", "0", *extra]


def rank_pids(mpirun_pid: int) -> list[int]:
    """PIDs of the rank processes below an mpirun (children of its hydra proxy), in rank order."""
    ranks = []
    for proxy in _children(mpirun_pid):
        for pid in _children(proxy):
            try:
                env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            rank = next((int(e.split(b"=", 1)[1]) for e in env if e.startswith(b"PMI_RANK=")), None)
            if rank is not None:
                ranks.append((rank, pid))
    return [pid for _, pid in sorted(ranks)]


def progress_lines(k):
    return lambda lines: sum("ETA" in ln for ln in lines) >= k


# ---------------------------------------------------------------------------
# comparisons
# ---------------------------------------------------------------------------
def read_all(path):
    """{dataset path: array} and root attributes of a file."""
    data = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: data.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
        attrs = {k: h5tools.plain_value(v) for k, v in f.attrs.items()}
    return data, attrs


def assert_same_file(a, b, rows=None):
    """Same datasets (bitwise, wall times aside) and attributes (creation date aside).

    ``rows``: compare only these realisation rows of /realisations (default all).
    """
    da, aa = read_all(a)
    db, ab = read_all(b)
    assert sorted(da) == sorted(db)
    for k in da:
        if k.rsplit("/", 1)[-1] in RESULTS_IGNORED:
            continue
        x, y = da[k], db[k]
        if rows is not None and k.startswith("realisations/"):
            x, y = x[rows], y[rows]
        assert x.dtype == y.dtype, k
        assert x.shape == y.shape, k
        assert x.tobytes() == y.tobytes(), f"{k} differs between {a} and {b}"
    assert {k: v for k, v in aa.items() if k not in ATTRS_IGNORED} == \
        {k: v for k, v in ab.items() if k not in ATTRS_IGNORED}


def one_error_line(res):
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode != 0, res.stderr
    assert "Traceback" not in res.stderr, res.stderr
    assert len(lines) == 1, f"expected one line, got:\n{res.stderr}"
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


# ---------------------------------------------------------------------------
# fixtures: one serial reference run
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Plain python (no mpirun): serial run, gather writer."""
    out = tmp_path_factory.mktemp("ens") / "serial.h5"
    res = run(ensemble_args(out))
    assert res.returncode == 0, res.stderr
    assert "storage gather" in res.stderr
    return out


# ---------------------------------------------------------------------------
# content and independence of the rank count
# ---------------------------------------------------------------------------
def test_file_layout_and_attributes(reference):
    with h5py.File(reference, "r") as f:
        a = f.attrs
        assert a["format"] == storage.FORMAT
        assert json.loads(a["scene"]) == SCENE.to_dict()
        assert a["software_version"] == sliders.__version__
        assert a["base_seed"] == SCENE.seed and a["realisations"] == R
        assert a["backend"] == BACKEND
        assert "T" in a["created"] and a["created"].endswith("+00:00")
        rg = f["realisations"]
        assert rg["done"].dtype == np.uint8 and rg["done"].shape == (R,)
        assert np.all(rg["done"][()] == 1)
        assert list(rg["seed"][()]) == [realisation_seed(SCENE.seed, r) for r in range(R)]
        assert set(rg["status"][()]) <= set(sliders.status.NAMES)
        for name in ("alpha_c", "n_events", "slider_steps", "wall_time"):
            assert rg[name].shape == (R,)
        grids = default_grids(SCENE)
        for key, (shape, dtype) in statistics_layout(grids, SCENE.n_sliders).items():
            ds = rg["statistics"][key]
            assert ds.shape == (R,) + tuple(shape), key
            assert ds.dtype == np.dtype(dtype), key
        for k, v in grids.to_arrays().items():
            assert np.array_equal(f["grids"][k][()], v)
        # every dataset is contiguous (rows are raw bytes written in place)
        for key in rg["statistics"]:
            assert rg["statistics"][key].chunks is None


def test_rows_are_realisation_statistics(reference):
    """Row r holds observables.realisation_statistics of the scene with seed_r."""
    rows = read_realisations(reference)
    grids = default_grids(SCENE)
    for r in (0, R - 1):
        result = sliders.tilt(SCENE.replace(seed=realisation_seed(SCENE.seed, r)), backend=BACKEND)
        stats = realisation_statistics(result, grids)
        for k, v in stats.items():
            assert np.array_equal(rows["statistics"][k][r], v, equal_nan=True), k
        assert rows["status_name"][r] == result.status
        assert rows["n_events"][r] == result.n_events
        assert rows["alpha_c"][r] == result.alpha_c or math.isnan(result.alpha_c)


def test_load_summary(reference):
    summary, grids, scene, info = load_summary(reference)
    assert scene == SCENE
    assert info["n_done"] == R and info["n_realisations"] == R
    assert summary.n_realisations == R
    assert np.array_equal(grids.alpha, default_grids(SCENE).alpha)
    rows = read_realisations(reference)
    assert np.array_equal(summary.alpha_c_values, rows["alpha_c"], equal_nan=True)
    assert sum(info["statuses"].values()) == R


@pytest.mark.parametrize("n", [1, 2, 4])  # 4 ranks on 2 cores: MPICH oversubscribes
def test_rank_count_independence(reference, tmp_path, n):
    out = tmp_path / f"n{n}.h5"
    res = run(ensemble_args(out), n=n)
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)
    progress = [ln for ln in res.stderr.splitlines() if "ETA" in ln]
    assert len(progress) == R  # one line per realisation (interval 0), rank 0 only
    if n > 1:
        assert "storage mpio" in res.stderr


def test_gather_storage_same_content(reference, tmp_path):
    out = tmp_path / "gather.h5"
    res = run(ensemble_args(out, extra=["--storage", "gather"]), n=2)
    assert res.returncode == 0, res.stderr
    assert "storage gather" in res.stderr
    assert_same_file(reference, out)


def test_serial_mpio_same_content(reference, tmp_path):
    """One process, parallel-HDF5 writer forced: same file."""
    out = tmp_path / "serial_mpio.h5"
    res = run(ensemble_args(out, extra=["--storage", "mpio"]))
    assert res.returncode == 0, res.stderr
    assert "storage mpio" in res.stderr
    assert_same_file(reference, out)


def test_without_mpi4py(reference, tmp_path):
    """mpi4py not importable: serial run, gather writer, same file; mpio refused in one line."""
    block = tmp_path / "block"
    block.mkdir()
    (block / "mpi4py.py").write_text('raise ModuleNotFoundError("No module named mpi4py (blocked by the test)", name="mpi4py")\n')
    env = _env(PYTHONPATH=os.pathsep.join(filter(None, [str(block), os.environ.get("PYTHONPATH")])))
    out = tmp_path / "nompi.h5"
    res = run(ensemble_args(out), env=env)
    assert res.returncode == 0, res.stderr
    assert "on 1 rank, storage gather" in res.stderr
    assert_same_file(reference, out)
    res = run(ensemble_args(tmp_path / "x.h5", extra=["--storage", "mpio"]), env=env)
    assert "needs mpi4py" in one_error_line(res)


# ---------------------------------------------------------------------------
# interruption, kill -9, resume
# ---------------------------------------------------------------------------
def test_sigterm_then_resume(reference, tmp_path):
    """SIGTERM to every rank mid-run (as a batch system does): clean stop, then --resume."""
    out = tmp_path / "term.h5"
    job = _Run(ensemble_args(out), 2, _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.3))
    job.wait_for(progress_lines(1))
    for pid in rank_pids(job.proc.pid):
        os.kill(pid, signal.SIGTERM)
    res = job.finish()
    code, err = res.returncode, res.stderr
    assert code == 128 + signal.SIGTERM, err
    assert "interrupted (SIGTERM on rank" in err and "--resume" in err
    assert "Traceback" not in err
    rows = read_realisations(out)
    assert 1 <= rows["done"].sum() < R
    assert_same_file(reference, out, rows=np.flatnonzero(rows["done"]))

    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0, res.stderr
    assert f"resuming {R - rows['done'].sum()} of {R}" in res.stderr
    assert_same_file(reference, out)
    # a complete file: --resume has nothing to do
    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0 and "nothing to do" in res.stderr


def test_stop_hook_on_one_rank_stops_all(reference, tmp_path):
    """SLIDERS_ENSEMBLE_STOP_AFTER: rank 0 alone 'receives SIGTERM'; every rank stops."""
    out = tmp_path / "hook.h5"
    res = run(ensemble_args(out), n=2, env=_env(SLIDERS_ENSEMBLE_STOP_AFTER=3))
    assert res.returncode == 128 + signal.SIGTERM, res.stderr
    done = read_realisations(out)["done"]
    assert 3 <= done.sum() < R
    res = run(ensemble_args(out, extra=["--resume"]), n=4)
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)


@pytest.mark.parametrize("storage_kind,victim", [("mpio", 0), ("mpio", 1), ("gather", 0),
                                                 ("gather", 1)])
def test_kill9_leaves_readable_file(reference, tmp_path, storage_kind, victim):
    """kill -9 of one rank mid-run: the file opens, done rows are complete, --resume finishes."""
    out = tmp_path / f"kill_{storage_kind}_{victim}.h5"
    job = _Run(ensemble_args(out, extra=["--storage", storage_kind]), 2,
               _env(SLIDERS_ENSEMBLE_TEST_DELAY=0.3))
    job.wait_for(progress_lines(2))
    pids = rank_pids(job.proc.pid)
    assert len(pids) == 2
    os.kill(pids[victim], signal.SIGKILL)
    res = job.finish()
    assert res.returncode != 0, res.stderr
    rows = read_realisations(out)  # readable with h5py
    done = np.flatnonzero(rows["done"])
    assert 2 <= done.size < R
    assert_same_file(reference, out, rows=done)
    summary, *_ = load_summary(out)
    assert summary.n_realisations == done.size

    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)


def test_unexpected_exception_aborts_without_hang(tmp_path):
    out = tmp_path / "fail.h5"
    res = run(ensemble_args(out), n=2, env=_env(SLIDERS_ENSEMBLE_TEST_FAIL=4), timeout=120)
    assert res.returncode != 0
    assert "error: rank" in res.stderr and "row 4 fails" in res.stderr
    assert "Traceback" not in res.stderr
    done = read_realisations(out)["done"]
    assert not done[4]


# ---------------------------------------------------------------------------
# bad input: one line from rank 0, every rank non-zero, no hang
# ---------------------------------------------------------------------------
def _write(path, text):
    path.write_text(text)
    return path


BAD_CASES = {
    "unknown_key": (lambda d: ["--scene", _write(d / "s.toml", "n_sliders = 10\nbogus = 1\n"),
                               "-R", 2, "--out", d / "o.h5"], "unknown scene key"),
    "invalid_value": (lambda d: ["--scene", _write(d / "s.toml", "n_sliders = -3\n"),
                                 "-R", 2, "--out", d / "o.h5"], "n_sliders"),
    "bad_toml": (lambda d: ["--scene", _write(d / "s.toml", "n_sliders = = 3\n"),
                            "-R", 2, "--out", d / "o.h5"], "not valid TOML"),
    "missing_scene": (lambda d: ["--scene", d / "nope.toml", "-R", 2, "--out", d / "o.h5"],
                      "does not exist"),
    "zero_realisations": (lambda d: SCENE_OPTS + ["-R", 0, "--out", d / "o.h5"],
                          "--realisations=0"),
    "no_realisations": (lambda d: SCENE_OPTS + ["--out", d / "o.h5"], "--realisations R is required"),
    "unwritable_dir": (lambda d: SCENE_OPTS + ["-R", 2, "--out", d / "no" / "such" / "o.h5"],
                       "does not exist"),
    "out_is_dir": (lambda d: SCENE_OPTS + ["-R", 2, "--out", d], "directory"),
    "bad_option_value": (lambda d: SCENE_OPTS + ["-R", "many", "--out", d / "o.h5"], "invalid int"),
    "existing_output": (lambda d: SCENE_OPTS + ["-R", 2, "--out", _write(d / "o.h5", "x")],
                        "--overwrite"),
    "resume_missing_no_r": (lambda d: SCENE_OPTS + ["--resume", "--out", d / "o.h5"],
                            "does not exist; give --realisations"),
    "resume_not_an_ensemble": (lambda d: SCENE_OPTS + ["-R", 2, "--resume",
                                                       "--out", _write(d / "o.h5", "x")],
                               "not a readable HDF5 file"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_one_line(tmp_path, case):
    make, needle = BAD_CASES[case]
    args = make(tmp_path) + ["--backend", BACKEND]
    res = run(args, n=2, timeout=60)
    line = one_error_line(res)
    assert needle in line, line


def test_bad_input_serial(tmp_path):
    res = run(SCENE_OPTS + ["-R", 0, "--out", tmp_path / "o.h5", "--backend", BACKEND], timeout=60)
    assert "--realisations=0" in one_error_line(res)
    res = run(SCENE_OPTS + ["-R", 1, "--out", tmp_path / "o.h5", "--storage", "bogus"], timeout=60)
    assert "--storage" in one_error_line(res)


def test_resume_refuses_other_scene_or_size(reference, tmp_path):
    out = tmp_path / "copy.h5"
    shutil.copy(reference, out)
    before = out.read_bytes()
    other = [a if a != "7" else "8" for a in SCENE_OPTS]  # another base seed
    res = run(other + ["-R", R, "--out", out, "--backend", BACKEND, "--resume"], n=2, timeout=60)
    line = one_error_line(res)
    assert "different scene" in line and "seed=7 in the file, 8 given" in line
    res = run(ensemble_args(out, r=R + 1, extra=["--resume"]), n=2, timeout=60)
    assert f"{R} realisations" in one_error_line(res)
    other_backend = "fortran" if BACKEND == "numpy" else "numpy"
    res = run(ensemble_args(out, backend=other_backend, extra=["--resume"]), n=2, timeout=60)
    assert "--backend" in one_error_line(res)
    res = run(ensemble_args(out, extra=["--resume", "--overwrite"]), n=2, timeout=60)
    assert "exclude each other" in one_error_line(res)
    assert out.read_bytes() == before  # never touched


def test_overwrite(reference, tmp_path):
    out = tmp_path / "o.h5"
    out.write_text("old")
    res = run(ensemble_args(out, r=2, extra=["--overwrite", "--quiet"]), n=2)
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    rows = read_realisations(out)
    ref = read_realisations(reference)
    assert np.array_equal(rows["alpha_c"], ref["alpha_c"][:2], equal_nan=True)


def test_help_prints_once():
    res = run(["--help"], n=2, timeout=60)
    assert res.returncode == 0
    assert res.stdout.count("usage:") == 1


def test_resume_of_missing_file_starts_it(reference, tmp_path):
    out = tmp_path / "new.h5"
    res = run(ensemble_args(out, extra=["--resume"]), n=2)
    assert res.returncode == 0, res.stderr
    assert_same_file(reference, out)


def test_progress_is_not_spammy(tmp_path):
    """Default interval (5 s): a short run prints its start and its summary only, from rank 0."""
    out = tmp_path / "quiet.h5"
    args = SCENE_OPTS + ["-R", 4, "--out", out, "--backend", BACKEND]
    res = run(args, n=2)
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 2, res.stderr
    assert lines[0].startswith("ensemble: starting 4 of 4 realisations") and "on 2 ranks" in lines[0]
    assert lines[1].startswith("ensemble: 4/4 realisations done") and "ranks busy" in lines[1]


HANDLER_SCRIPT = """
import math, sys
import numpy as np
import pytest
import sliders
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary
from sliders.runs.rows import compute_row
from sliders.runs.parallel import SerialComm
from sliders.io import storage
from sliders.keyed_random import realisation_seed
from sliders.analysis.observables import default_grids, statistics_layout

kind, path, backend = sys.argv[1], sys.argv[2], sys.argv[3]
if kind == "mpio":
    from mpi4py import MPI
    comm = MPI.COMM_WORLD  # one process: singleton MPI
else:
    comm = SerialComm()
scene = sliders.Scene(n_sliders=10, seed=7)
grids = default_grids(scene)
seeds = [realisation_seed(scene.seed, r) for r in range(3)]
attrs = storage.file_attributes(scene.to_dict(), scene.seed, 3, backend)
layout = storage.make_layout(3, seeds, grids.to_arrays(), statistics_layout(grids, 10), attrs)
row = compute_row(scene, 1, backend, grids)
f = storage.HANDLERS[kind].create(path, layout, comm, overwrite=False)
f.write_row(1, row)
f.mark_done(1)
f.flush()
f.close()
with pytest.raises(storage.StorageError, match="exists"):
    storage.HANDLERS[kind].create(path, layout, comm, overwrite=False)
rows = read_realisations(path)
assert rows["done"].tolist() == [False, True, False]
assert rows["status"][0] == storage.NOT_RUN and math.isnan(rows["alpha_c"][0])
assert rows["alpha_c"][1] == row["alpha_c"]
f = storage.HANDLERS[kind].open_for_resume(path, layout, comm)
f.write_row(0, compute_row(scene, 0, backend, grids))
f.mark_done(0)
with pytest.raises(storage.StorageError, match="shape"):
    f.write_row(2, {**row, "alpha_c": np.zeros(2)})
f.close()
assert read_realisations(path)["done"].tolist() == [True, True, False]
print("handler ok")
"""


@pytest.mark.parametrize("kind", ["gather", "mpio"])
def test_file_handler_interface(tmp_path, kind):
    """storage.EnsembleFile in one process: create, write_row, mark_done, flush, close, resume
    (in a subprocess: the test process itself stays without MPI)."""
    script = tmp_path / "handler.py"
    script.write_text(HANDLER_SCRIPT)
    res = subprocess.run([PY, str(script), kind, str(tmp_path / f"{kind}.h5"), BACKEND],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "handler ok" in res.stdout, res.stderr
