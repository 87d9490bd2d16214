#!/usr/bin/env bash
# Larger study: R = 1000 realisations of N = 400 for xi = 0 and xi = 0.001,
# one HDF5 file each (rows of per-realisation statistics; no forces kept).
#
#   bash mpi_runs/study_n400.sh                 # both values of xi, NP=2 ranks
#   NP=8 bash mpi_runs/study_n400.sh xi0.001    # one of them, more ranks
#
# Environment: NP (2), R (1000), BACKEND (fortran), OUT (results/mpi_runs),
# PY (.venv/bin/python).  Restartable: run it again to complete an
# interrupted file (--resume computes only the missing realisations).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
NP=${NP:-2}
R=${R:-1000}
BACKEND=${BACKEND:-fortran}
OUT=${OUT:-$ROOT/results/mpi_runs}
mkdir -p "$OUT"
cd "$ROOT"
# build (editable install) once here, not concurrently in every rank
"$PY" -c "import sliders._kernel"

cases=("$@")
[ ${#cases[@]} -gt 0 ] || cases=(xi0 xi0.001)
for c in "${cases[@]}"; do
  scene=mpi_runs/scenes/study_n400_$c.toml
  [ -f "$scene" ] || { echo "study_n400.sh: no scene $scene (use xi0 or xi0.001)" >&2; exit 2; }
  SECONDS=0
  mpirun -n "$NP" "$PY" -m sliders.ensemble --scene "$scene" --realisations "$R" \
    --out "$OUT/study_n400_$c.h5" --backend "$BACKEND" --resume --progress-interval 30
  echo "study_n400_$c: ${SECONDS} s -> $OUT/study_n400_$c.h5"
done
