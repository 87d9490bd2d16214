#!/usr/bin/env bash
# One idempotent set-up of sliders; fast (seconds) once it has run before.
#
#   bash scripts/setup.sh                 set up only
#   bash scripts/setup.sh test [ARGS...]  set up, then the whole suite on both cores (docs build included)
#   bash scripts/setup.sh fast [ARGS...]  set up, then the fast loop: pytest -m "not slow" (1.5 min idle)
#   bash scripts/setup.sh run  [ARGS...]  set up, then the main job below
#
# Steps: Debian packages (+ SLURM for `test`) -> .venv -> Python deps -> mpi4py (PyPI's binary
# wheel, on MPICH's ABI) and h5py against parallel HDF5 (built once, kept in $SLIDERS_WHEEL_CACHE)
# -> editable install.  Tests run in SLIDERS_TEST_WORKERS processes (pytest-xdist; default: the
# number of cores), and tests that need both cores (mpirun -n 2, SLURM) run alone (tests/conftest.py).
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
         scikit-learn crepes        # the learned forecasters: scikit-learn, crepes (their
         sybil pytest-xdist         # conformal calibration);
         pytest-timeout)            # pytest-xdist: the suite on every core; pytest-timeout: a
                                    # hung test fails with its stack instead of stalling the suite
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

case "${1:-}" in ""|test|fast|run) ;; *) die "unknown command '$1' (use: test, fast, run, or nothing)" ;; esac

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
# uv installs the same packages from PyPI as pip would, four times faster (it downloads and
# unpacks in parallel and byte-compiles on every core: 15-18 s here, pip 59-72 s); its cache
# and pip's keep the downloads.  pip when uv cannot be had or fails.
installer=uv
pip_install() {  # pip_install PACKAGE...: by uv, or pip when uv cannot
  if [ "$installer" = uv ] && { [ -x "$VENV/bin/uv" ] || pip install -q uv; } \
       && "$VENV/bin/uv" pip install -q --python "$PY" --compile-bytecode "$@"; then
    return
  fi
  [ "$installer" = pip ] || echo "setup.sh: uv could not install the Python packages; pip installs them" >&2
  installer=pip
  pip install -q "$@"
}

# ---- c. MPI stack against Debian's MPICH, h5py's wheel built beside the other steps -
# mpi4py: PyPI's binary wheel, which runs against the machine's MPICH through MPICH's ABI: it
# loads libmpi.so.12.  Debian bookworm's libmpich12 names that library libmpich.so.12 only
# (trixie's names it both ways), so the ABI's name is added beside it once.  Where that cannot
# be done (no root), mpi4py is built from source against MPICH (-O1: the default flags take
# 15+ min).  h5py: PyPI has no wheel with parallel HDF5, so it is built once, against
# libhdf5-mpich, and kept in $WHEELS; concurrent set-ups wait for one build (flock).  The build
# (about 2 min of one core for Cython, then the C files on every core) runs in the background
# while SLURM, the Python packages and the package itself are installed.
LIBDIR=/usr/lib/$(gcc -print-multiarch 2>/dev/null || echo x86_64-linux-gnu)
mpi4py_ok() { "$PY" -c 'from mpi4py import MPI; MPI.Get_library_version()' 2>/dev/null; }
h5py_ok() { "$PY" -c 'import h5py; assert h5py.get_config().mpi' 2>/dev/null; }
cached() { pip install -q --no-index --no-deps --find-links "$WHEELS" "$1" 2>/dev/null; }
if mpi4py_ok; then
  step_done "mpi4py: already installed"
else
  if [ ! -e "$LIBDIR/libmpi.so.12" ] && [ -e "$LIBDIR/libmpich.so.12" ]; then
    SUDO=(); [ "$(id -u)" -eq 0 ] || SUDO=(sudo -n)
    "${SUDO[@]}" ln -s libmpich.so.12 "$LIBDIR/libmpi.so.12" 2>/dev/null \
      && { "${SUDO[@]}" ldconfig 2>/dev/null || true; }
  fi
  pip install -q --only-binary=mpi4py mpi4py
  if mpi4py_ok; then
    step_done "mpi4py: PyPI's binary wheel (MPICH ABI, $LIBDIR/libmpi.so.12)"
  else
    mkdir -p "$WHEELS"
    exec 9>"$WHEELS/.lock"; flock 9
    if cached mpi4py && mpi4py_ok; then
      step_done "mpi4py: built against MPICH, from the cache $WHEELS"
    else
      echo "setup.sh: no libmpi.so.12 (MPICH's ABI name): building mpi4py against MPICH (about 1.5 min)"
      CFLAGS="-O1 -g0" pip wheel -q --no-deps --no-binary=mpi4py -w "$WHEELS" mpi4py
      cached mpi4py && mpi4py_ok || die "mpi4py wheel built but does not load MPICH"
      step_done "mpi4py: built against MPICH into $WHEELS"
    fi
    exec 9>&-
  fi
fi
h5py_build=""  # the background build's log, when one runs
if h5py_ok; then
  step_done "h5py(mpi): already installed"
else
  mkdir -p "$WHEELS"
  pip_install numpy  # h5py imports it
  exec 9>"$WHEELS/.lock"; flock 9   # a second set-up waits here for the first one's build
  if cached h5py && h5py_ok; then
    step_done "h5py(mpi): from the cache $WHEELS"
    exec 9>&-
  else
    pip_install "${H5PY_BUILD_DEPS[@]}"
    step_done "$installer: numpy ${H5PY_BUILD_DEPS[*]} (to build h5py)"
    h5py_build=$(mktemp "${TMPDIR:-/tmp}/sliders-h5py-build.XXXXXX")
    echo "setup.sh: building h5py with parallel HDF5 (about 2 min, once, beside the next steps) into $WHEELS"
    cfg=$h5py_build.cfg; printf '[build_ext]\nparallel = %s\n' "$(getconf _NPROCESSORS_ONLN)" > "$cfg"
    (  # holds the lock (fd 9) until the wheel is in the cache
      started=$SECONDS
      DIST_EXTRA_CONFIG=$cfg HDF5_MPI=ON HDF5_PKGCONFIG_NAME=hdf5-mpich CC=mpicc CFLAGS="-O1 -g0" \
        "$PY" -m pip wheel -q --no-deps --no-binary=h5py --no-build-isolation -w "$WHEELS" h5py
      echo "built in $((SECONDS - started)) s"
    ) > "$h5py_build" 2>&1 &
    h5py_pid=$!
    exec 9>&-
  fi
fi

# SLURM (munge, slurmctld, slurmd, sbatch) for tests/test_slurm.py, which starts a
# real one-node cluster of its own; only the test command needs it.
if [ "${1:-}" = test ]; then
  bash scripts/slurm_local.sh install
  step_done "apt: SLURM for the tests (scripts/slurm_local.sh install)"
fi

# ---- d. Python deps -----------------------------------------------------------
deps_stamp=$VENV/.sliders-deps-stamp
deps_key=$(printf '%s\n' "${PY_DEPS[@]}" | sha256sum | cut -c1-16)
if [ "$(cat "$deps_stamp" 2>/dev/null)" = "$deps_key" ]; then
  step_done "Python packages: the same ${#PY_DEPS[@]} as last time, present"
else
  pip_install "${PY_DEPS[@]}"
  echo "$deps_key" > "$deps_stamp"
  step_done "$installer: ${PY_DEPS[*]}"
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

if [ -n "$h5py_build" ]; then
  wait "$h5py_pid" || { tail -30 "$h5py_build" >&2; die "the h5py build failed (its log: $h5py_build)"; }
  cached h5py || die "h5py wheel built but does not install"
  h5py_ok || die "h5py lacks MPI support"
  step_done "h5py(mpi): built in $(tail -1 "$h5py_build" | cut -d' ' -f3) s beside the steps above, into $WHEELS"
  rm -f "$h5py_build" "$h5py_build.cfg"
fi

echo "setup.sh: ready in $((SECONDS - T_START)) s ($VENV)"
printf '%s' "$SUMMARY"

# ---- what to do after set-up ----------------------------------------------------
case "${1:-}" in
  "") ;;
  test) shift; exec "$PY" -m pytest -q -n "${SLIDERS_TEST_WORKERS:-$(getconf _NPROCESSORS_ONLN)}" --dist loadgroup "$@" ;;
  fast) shift; exec "$PY" -m pytest -q -n "${SLIDERS_TEST_WORKERS:-$(getconf _NPROCESSORS_ONLN)}" --dist loadgroup -m "not slow" "$@" ;;
  run) shift; main_job "$@" ;;
esac
