"""Installing anywhere: a wheel from a clean copy of the repository, and MPI as an option.

``test_wheel_from_clean_checkout`` builds a wheel from ``git archive HEAD``
(the committed tree, as a new user gets it), checks that every module of
src/sliders and the compiled kernel are in it, installs it into a bare venv
with its PyPI dependencies (by uv where set-up installed it, else pip), and runs
a tilt, a serial ensemble (no mpi4py) and a forecast there.  About 40 s, most of it the
wheel's build; the installers' caches keep the downloads.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # builds a wheel from a clean copy and installs it into a new environment

ROOT = Path(__file__).resolve().parents[1]
# the installer scripts/setup.sh puts beside the test's Python (pip when it is absent)
UV = Path(sys.executable).with_name("uv")
BROKEN_MPI = "libmpi.so.12: cannot open shared object file: No such file or directory"


def run(cmd, timeout=600, **kw):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout,
                          **kw)


def _pip_env():
    # no user/site config leaking in; pip's own config (indexes, cache) stays
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    # no byte-compiling of every installed module (SciPy, scikit-learn, Matplotlib): 15 s of
    # the install; the few modules the commands import compile when first imported
    env["PIP_NO_COMPILE"] = "1"
    return env


@pytest.fixture(scope="module")
def clean_checkout(tmp_path_factory):
    if run(["git", "-C", ROOT, "rev-parse", "HEAD"]).returncode != 0:
        pytest.skip("not a git checkout: no committed tree to archive")
    src = tmp_path_factory.mktemp("clean") / "sliders"
    src.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "HEAD"], capture_output=True,
                             check=True).stdout
    res = subprocess.run(["tar", "-x", "-C", str(src)], input=archive, capture_output=True)
    assert res.returncode == 0, res.stderr
    return src


def test_wheel_from_clean_checkout(clean_checkout, tmp_path):
    dist = tmp_path / "dist"
    res = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dist, clean_checkout],
              env=_pip_env())
    assert res.returncode == 0, res.stdout + res.stderr
    (wheel,) = dist.glob("sliders-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = sorted(p.name for p in (clean_checkout / "src" / "sliders").glob("*.py"))
    assert modules and [m for m in modules if f"sliders/{m}" not in names] == []
    assert any(n.startswith("sliders/_kernel") and n.endswith(".so") for n in names), sorted(names)

    venv = tmp_path / "bare"
    py = venv / "bin" / "python"
    python3 = shutil.which("python3") or sys.executable
    if UV.exists():  # the same resolution of the wheel's dependencies as pip's, in 1 s, not 45
        assert run([UV, "venv", "-q", "--python", python3, venv]).returncode == 0
        res = run([UV, "pip", "install", "-q", "--python", py, wheel], env=_pip_env())
    else:
        assert run([python3, "-m", "venv", venv]).returncode == 0
        res = run([py, "-m", "pip", "install", "-q", wheel], env=_pip_env())
    assert res.returncode == 0, res.stdout + res.stderr
    work = tmp_path / "work"  # not the repository: the installed package must be the one imported
    work.mkdir()
    res = run([py, "-c", "import importlib.util as u, sliders; print(sliders.__file__); "
                         "print(u.find_spec('mpi4py') is None)"], cwd=work, env=_pip_env())
    assert res.returncode == 0, res.stderr
    where, no_mpi4py = res.stdout.split()
    assert where.startswith(str(venv)) and no_mpi4py == "True"  # MPI is an extra, not a dependency
    res = run([py, "-m", "sliders", "tilt", "--n-sliders", "10", "--seed", "2", "--out", "t.h5"],
              cwd=work, env=_pip_env())
    assert res.returncode == 0 and "avalanche" in res.stdout and (work / "t.h5").exists(), res.stderr
    res = run([py, "-m", "sliders.ensemble", "--n-sliders", "10", "--realisations", "3", "--out",
               "e.h5", "--quiet"], cwd=work, env=_pip_env())
    assert res.returncode == 0, res.stderr
    assert "warning" not in res.stderr  # mpi4py absent: serial, nothing to warn about
    res = run([py, "-c", "from sliders.io.storage import read_realisations; r = read_realisations('e.h5'); "
                         "print(int(r['done'].sum()))"], cwd=work, env=_pip_env())
    assert res.stdout.strip() == "3", res.stderr
    # the shipped forecaster is in the wheel, and forecasts with the declared dependencies only
    assert {"sliders/data/default_forecaster.zip",
            "sliders/data/default_forecaster.zip.sha256"} <= names
    (work / "pile.csv").write_text("angle [deg],size\n" + "".join(
        f"{20 + 8 * (1 - 0.9 ** k):.4f},{1 + k % 3}\n" for k in range(40)))
    res = run([py, "-m", "sliders.forecast", "predict", "pile.csv", "--json"], cwd=work,
              env=_pip_env())
    assert res.returncode == 0 and '"alpha_c"' in res.stdout, res.stderr


# ---------------------------------------------------------------------------
# an mpi4py that is installed but cannot load its MPI library
# ---------------------------------------------------------------------------
@pytest.fixture
def broken_mpi4py(tmp_path):
    """PYTHONPATH with an mpi4py whose MPI module fails as the PyPI wheel does without libmpi."""
    pkg = tmp_path / "broken" / "mpi4py"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "MPI.py").write_text(f"raise ImportError({BROKEN_MPI!r})\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(tmp_path / "broken"), os.environ.get("PYTHONPATH")])))
    return env


def ensemble_cmd(out):
    return [sys.executable, "-m", "sliders.ensemble", "--n-sliders", "10", "--realisations", "2",
            "--out", out, "--quiet"]


def test_broken_mpi4py_plain_process_warns_once_then_runs_serially(broken_mpi4py, tmp_path):
    res = run(ensemble_cmd(tmp_path / "e.h5"), env=broken_mpi4py, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if "mpi4py" in ln]
    assert len(lines) == 1 and "warning" in lines[0] and "running serially" in lines[0], res.stderr
    assert "libmpi.so.12" in lines[0]


@pytest.mark.ranks_share_one_core  # both ranks stop at their first import: they need no core
@pytest.mark.parametrize("what", ["broken", "absent"])
def test_under_mpirun_without_working_mpi4py_every_rank_exits(broken_mpi4py, tmp_path, what):
    """mpirun -n 2 with no usable MPI in Python: one line saying what to install, exit != 0, no hang."""
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed: cannot launch ranks")
    env = broken_mpi4py
    if what == "absent":
        (tmp_path / "broken" / "mpi4py" / "MPI.py").unlink()
        (tmp_path / "broken" / "mpi4py.py").write_text(
            "raise ModuleNotFoundError(\"No module named 'mpi4py'\", name='mpi4py')\n")
        shutil.rmtree(tmp_path / "broken" / "mpi4py")
    res = run(["mpirun", "-n", "2", *ensemble_cmd(tmp_path / "e.h5")], env=env, timeout=60)
    assert res.returncode != 0
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, res.stderr  # rank 0 speaks; rank 1 exits quietly
    assert "MPI launcher" in lines[0] and "install" in lines[0]
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "e.h5").exists()  # no rank ran the ensemble alone


@pytest.mark.parametrize("env, launched, rank", [
    ({}, False, 0),
    ({"PMI_RANK": "1", "PMI_SIZE": "2"}, True, 1),  # MPICH Hydra, srun --mpi=pmi2
    ({"HYDRA_CONTROL_FD": "5"}, True, 0),
    ({"OMPI_COMM_WORLD_SIZE": "4", "OMPI_COMM_WORLD_RANK": "3"}, True, 3),
    ({"PMIX_RANK": "2"}, True, 2),
    ({"SLURM_STEP_NUM_TASKS": "4", "SLURM_PROCID": "1"}, True, 1),  # srun, no MPI plugin
    ({"SLURM_STEP_NUM_TASKS": "1", "SLURM_PROCID": "0"}, False, 0),  # a serial job step
])
def test_launcher_detection(env, launched, rank):
    from sliders.runs.parallel import launcher_rank, under_mpi_launcher

    assert under_mpi_launcher(env) is launched and launcher_rank(env) == rank
