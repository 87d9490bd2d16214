"""A real SLURM on this machine runs the job scripts of mpi_runs/slurm/.

The session fixture ``slurm`` (tests/conftest.py, shared with the SLURM blocks
of mpi_runs/README.md) starts munged, slurmctld and slurmd for one node on
localhost (``scripts/slurm_local.sh start``), and stops them at the end by the
pids in their pid files.  The tests submit with ``sbatch``, poll ``squeue`` until the job
has left the queue, then read ``scontrol show job`` (no accounting, so no
``sacct``), and check the files against a plain serial run of the same
realisations.  They skip only when SLURM cannot be started, saying why.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from sliders.io.storage import read_realisations
from helpers import assert_same_file

pytestmark = [pytest.mark.slow, pytest.mark.two_cores]  # jobs on the session's SLURM cluster

ROOT = Path(__file__).resolve().parents[1]
JOBS = ROOT / "mpi_runs" / "slurm"
R = 6
SCENE = """[scene]
n_sliders = 30
xi = 0.0
seed = 5
mode = "explore"
record = "displacements"
"""


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A scene file and a serial run of its R realisations (the reference rows)."""
    d = tmp_path_factory.mktemp("slurm_work")
    os.chmod(d, 0o755)
    scene = d / "scene.toml"
    scene.write_text(SCENE)
    ref = d / "serial.h5"
    res = subprocess.run([sys.executable, "-m", "sliders.ensemble", "--scene", str(scene),
                          "--realisations", str(R), "--out", str(ref), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    return d, scene, ref


def test_mpi_ensemble_job(slurm, work):
    """sbatch ensemble_mpi.sbatch on 2 tasks: MPI inside the job, parallel HDF5, all rows."""
    d, scene, ref = work
    out = d / "mpi.h5"
    log = d / "mpi-%j.out"
    t0 = time.monotonic()
    job = slurm.submit(JOBS / "ensemble_mpi.sbatch", "-N", "1", "-n", "2", f"--output={log}",
                       SCENE=str(scene), R=str(R), OUT=str(out), PY=sys.executable)
    states = slurm.wait(job)
    text = Path(str(log).replace("%j", job)).read_text()
    assert states == [("COMPLETED", "0:0")], text
    sys.stderr.write(f"slurm: MPI job {job} done in {time.monotonic() - t0:.1f} s\n")
    assert "sliders: 2 ranks on 1 node(s)" in text
    assert "on 2 ranks, storage mpio" in text  # both ranks in one MPI world, writing in parallel
    rows = read_realisations(out)
    assert rows["done"].all() and rows["done"].size == R
    assert set(rows["status_name"]) <= {"avalanche", "event_duration_cap"}
    assert_same_file(ref, out)  # the rows of a serial run, bit for bit (wall times aside)
    with h5py.File(out) as f:  # described by rank 0 after the parallel file was closed
        assert list(f["realisations/statistics/force_counts"].dims[0].keys()) == ["realisation"]
        assert "-m sliders.ensemble --scene" in f.attrs["history"]


def test_job_array_chunks_merge_to_one_run(slurm, work):
    """sbatch --array=0-2 ensemble_array.sbatch, then merge.sbatch after it: the serial run's rows."""
    d, scene, ref = work
    out = d / "array.h5"
    env = {"SCENE": str(scene), "R": str(R), "OUT": str(out), "PY": sys.executable}
    t0 = time.monotonic()
    array = slurm.submit(JOBS / "ensemble_array.sbatch", "--array=0-2",
                         f"--output={d}/chunk-%A_%a.out", **env)
    merged = slurm.submit(JOBS / "merge.sbatch", f"--dependency=afterok:{array}",
                          f"--output={d}/merge-%j.out", **env)
    states = slurm.wait(array)
    assert states == [("COMPLETED", "0:0")] * 3, [p.read_text() for p in d.glob("chunk-*.out")]
    assert slurm.wait(merged) == [("COMPLETED", "0:0")], (d / f"merge-{merged}.out").read_text()
    sys.stderr.write(f"slurm: array of 3 chunks + merge done in {time.monotonic() - t0:.1f} s\n")
    chunk_files = sorted((d / "array.chunks").glob("chunk_*.h5"))
    assert [p.name for p in chunk_files] == [f"chunk_{i:05d}_of_00003.h5" for i in range(3)]
    assert [read_realisations(p)["done"].size for p in chunk_files] == [2, 2, 2]
    assert_same_file(ref, out)
    assert np.isfinite(read_realisations(out)["alpha_c"]).all()
