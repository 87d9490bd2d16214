"""The MPI ensemble (``python -m sliders.ensemble``) and its HDF5 file.

Every run is a subprocess (``mpirun -n P python -m sliders.ensemble ...`` or
plain ``python -m sliders.ensemble ...``) in its own process group, killed
whole if it outlives its timeout, so that nothing can hang the suite.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess

import h5py
import numpy as np
import pytest

import sliders
from sliders.io.storage import read_realisations
from sliders.analysis.summary import load_summary
from sliders.runs.rows import compute_row
from sliders.runs.parallel import SerialComm
from sliders.io import storage
from sliders.keyed_random import realisation_seed
from sliders.analysis.observables import default_grids, realisation_statistics, statistics_layout
from helpers import (BACKEND, PY, R, SCENE_OPTS, _env, _Run, assert_same_file, ensemble_args,
                     one_error_line, progress_lines, rank_pids, run)

# MPI ensembles under mpirun, kills and resumes (the few serial tests cost little beside them)
pytestmark = [pytest.mark.slow, pytest.mark.two_cores]

SCENE = sliders.Scene(n_sliders=10, seed=7)  # the scene of SCENE_OPTS


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
