#!/usr/bin/env bash
# The paper's statistics: 20 realisations of N = 100 (xi = 0) over MPI ranks,
# one HDF5 file, then the statistics figures drawn from it.
#
#   bash mpi_runs/paper_n100.sh            # NP=2 ranks, Fortran backend
#   NP=4 R=200 bash mpi_runs/paper_n100.sh # more ranks / realisations
#
# Environment: NP (ranks, 2), R (realisations, 20), BACKEND (fortran), OUT
# (results/mpi_runs), PY (.venv/bin/python), FIGURES (1: draw the figures).
# Restartable: an interrupted run is completed by running this again (--resume).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
NP=${NP:-2}
R=${R:-20}
BACKEND=${BACKEND:-fortran}
OUT=${OUT:-$ROOT/results/mpi_runs}
mkdir -p "$OUT"
cd "$ROOT"
# build (editable install) once here, not concurrently in every rank
"$PY" -c "import sliders._kernel"

SECONDS=0
mpirun -n "$NP" "$PY" -m sliders.ensemble --scene mpi_runs/scenes/paper_n100.toml \
  --realisations "$R" --out "$OUT/paper_n100.h5" --backend "$BACKEND" --resume "$@"
echo "paper_n100: ensemble in ${SECONDS} s -> $OUT/paper_n100.h5"

if [ "${FIGURES:-1}" = 1 ]; then
  SECONDS=0
  "$PY" -m sliders.figures --ensemble "$OUT/paper_n100.h5" --out "$OUT/figures" \
    --only force_pdf stopped_ratio bin_heights cumulated
  echo "paper_n100: figures in ${SECONDS} s -> $OUT/figures"
fi
