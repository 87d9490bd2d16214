#!/usr/bin/env bash
# One idempotent set-up of sliders; fast (seconds) once it has run before.
#
#   bash scripts/setup.sh                 set up only
#   bash scripts/setup.sh test [ARGS...]  set up, then python -m pytest -q ARGS (docs build included)
#   bash scripts/setup.sh run  [ARGS...]  set up, then the main job below
#
# Steps: Debian packages (+ SLURM for `test`) -> .venv -> Python deps -> mpi4py/h5py against MPICH
# (wheels built once, kept in $SLIDERS_WHEEL_CACHE) -> editable install.
set -euo pipefail

# ---- the main job of `setup.sh run` (the lead changes this) -----------------
# An MPI ensemble of the paper's N = 100 scene (200 realisations on 2 ranks,
# parallel HDF5) and the statistics figures drawn from it, in results/main/.
# Restartable: running it again completes what is missing (--resume).
main_job() {
  R=${R:-200} NP=${NP:-2} OUT=${OUT:-results/main} bash mpi_runs/paper_n100.sh "$@"
}
# -----------------------------------------------------------------------------

APT_PACKAGES=(gfortran mpich libmpich-dev libhdf5-mpich-dev pkg-config)
# sphinx, numpydoc, myst-nb (+ ipykernel to execute the tutorial): tests/test_docs.py builds the
# documentation with warnings as errors; sybil: tests/test_docs_commands.py runs every page's commands
PY_DEPS=(meson-python meson ninja numpy scipy pytest matplotlib xarray h5netcdf sphinx numpydoc myst-nb ipykernel
         scikit-learn skops crepes  # the learned forecasters: scikit-learn, skops (their model
         sybil)                     # files, read as data), crepes (their conformal calibration)
H5PY_BUILD_DEPS=(cython pkgconfig "setuptools>=77")

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv
WHEELS=${SLIDERS_WHEEL_CACHE:-$HOME/.cache/sliders/wheels}
export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_PROGRESS_BAR=off
cd "$ROOT"

trap 'echo "setup.sh: FAILED (line $LINENO): $BASH_COMMAND" >&2' ERR
die() { echo "setup.sh: ERROR: $*" >&2; exit 1; }
T_START=$SECONDS T_STEP=$SECONDS SUMMARY=""
step_done() {  # step_done "what happened"
  SUMMARY+=$(printf '  %-58s %4ss' "$1" $((SECONDS - T_STEP)))$'\n'
  T_STEP=$SECONDS
}

case "${1:-}" in ""|test|run) ;; *) die "unknown command '$1' (use: test, run, or nothing)" ;; esac

# ---- a. Debian packages (apt only when one is missing) ----------------------
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${db:Status-Abbrev}' "$p" 2>/dev/null | grep -q '^ii' || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup.sh: installing Debian packages: ${missing[*]}"
  SUDO=(); [ "$(id -u)" -eq 0 ] || SUDO=(sudo)
  "${SUDO[@]}" apt-get update -qq
  "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${APT_PACKAGES[@]}"
  step_done "apt: installed ${missing[*]}"
else
  step_done "apt: all present"
fi

# SLURM (munge, slurmctld, slurmd, sbatch) for tests/test_slurm.py, which starts a
# real one-node cluster of its own; only the test command needs it.
if [ "${1:-}" = test ]; then
  bash scripts/slurm_local.sh install
  step_done "apt: SLURM for the tests (scripts/slurm_local.sh install)"
fi

# ---- b. virtual environment -------------------------------------------------
command -v python3 >/dev/null || die "python3 not on PATH"
want=$(python3 -c 'import sys; print("%d.%d" % sys.version_info[:2])')
have=$("$VENV/bin/python" -c 'import sys, pip; print("%d.%d" % sys.version_info[:2])' 2>/dev/null || true)
if [ "$have" != "$want" ]; then
  echo "setup.sh: creating $VENV with Python $want"
  rm -rf "$VENV"
  python3 -m venv "$VENV"
  step_done "venv: created (Python $want)"
else
  step_done "venv: reused (Python $want)"
fi
export PATH="$VENV/bin:$PATH" VIRTUAL_ENV=$VENV
PY=$VENV/bin/python
# (the grep hides this machine's pip-config noise about absent local index dirs)
pip() { "$PY" -m pip "$@" 2> >(grep -v "^WARNING: Location 'file:" >&2); }

# ---- c. Python deps (pip's own cache keeps the downloads) ---------------------
pip install -q "${PY_DEPS[@]}"
step_done "pip: ${PY_DEPS[*]}"

# ---- d. MPI stack against Debian's MPICH (-O1: the default flags take 15+ min), wheels cached
mpi_ok() { "$PY" -c 'from mpi4py import MPI; import h5py; assert h5py.get_config().mpi' 2>/dev/null; }
cached() { pip install -q --no-index --no-deps --find-links "$WHEELS" "$1" 2>/dev/null; }
if mpi_ok; then
  step_done "mpi4py + h5py(mpi): already installed"
else
  mkdir -p "$WHEELS"
  if ! cached mpi4py; then
    echo "setup.sh: building mpi4py wheel against MPICH (about 1.5 min) into $WHEELS"
    CFLAGS="-O1 -g0" pip wheel -q --no-deps --no-binary=mpi4py -w "$WHEELS" mpi4py
    cached mpi4py || die "mpi4py wheel built but does not install"
  fi
  if ! cached h5py; then
    echo "setup.sh: building h5py wheel with parallel HDF5 (about 1 min) into $WHEELS"
    pip install -q "${H5PY_BUILD_DEPS[@]}"
    HDF5_MPI=ON HDF5_PKGCONFIG_NAME=hdf5-mpich CC=mpicc CFLAGS="-O1 -g0" \
      pip wheel -q --no-deps --no-binary=h5py --no-build-isolation -w "$WHEELS" h5py
    cached h5py || die "h5py wheel built but does not install"
  fi
  "$PY" -c 'from mpi4py import MPI' || die "mpi4py does not load MPICH"
  "$PY" -c 'import h5py; assert h5py.get_config().mpi' || die "h5py lacks MPI support"
  step_done "mpi4py + h5py(mpi): installed from $WHEELS"
fi

# ---- e. the package itself, editable ------------------------------------------
# Editable: meson-python rebuilds the Fortran extension (ninja, in build/) on
# import when a source changed.  setup.sh imports it once, so the build is up
# to date before jobs start several ranks under mpirun (concurrent rebuilds by
# several ranks would race in the same build directory).
stamp=$VENV/.sliders-install-stamp
key=$(sha256sum < pyproject.toml | cut -c1-16)
kernel_ok() {
  "$PY" -c 'import sys, sliders._kernel as k; sys.exit(not k.__file__.startswith(sys.argv[1]))' \
    "$ROOT/build/" 2>/dev/null
}
if [ "$(cat "$stamp" 2>/dev/null)" = "$key" ] && kernel_ok; then
  step_done "sliders: editable install up to date"
else
  pip install -q --no-build-isolation --no-deps -e .
  echo "$key" > "$stamp"
  step_done "sliders: editable install (meson build)"
fi
"$PY" -c 'import sliders._kernel' || die "cannot import sliders._kernel"

echo "setup.sh: ready in $((SECONDS - T_START)) s ($VENV)"
printf '%s' "$SUMMARY"

# ---- what to do after set-up ----------------------------------------------------
case "${1:-}" in
  "") ;;
  test) shift; exec "$PY" -m pytest -q "$@" ;;
  run) shift; main_job "$@" ;;
esac
