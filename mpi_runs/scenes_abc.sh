#!/usr/bin/env bash
# Scenes A (N=10, xi=0), B (N=400, xi=0) and C (N=400, xi=0.001): one full run
# each, written with `python -m sliders tilt` (Result files: every event's
# displacements, forces rebuilt on load).  B and C run side by side (2 cores).
#
#   bash mpi_runs/scenes_abc.sh
#
# Environment: BACKEND (fortran), OUT (results/mpi_runs), PY (.venv/bin/python).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
BACKEND=${BACKEND:-fortran}
OUT=${OUT:-$ROOT/results/mpi_runs}
mkdir -p "$OUT"
cd "$ROOT"
# build (editable install) once here, not concurrently in every rank
"$PY" -c "import sliders._kernel"

run() {  # run NAME: one tilt, timed
  local t0=$SECONDS
  "$PY" -m sliders tilt --scene "mpi_runs/scenes/$1.toml" --backend "$BACKEND" \
    --out "$OUT/$1.h5" --overwrite --quiet
  echo "$1: $((SECONDS - t0)) s -> $OUT/$1.h5"
}
SECONDS=0
run scene_A
run scene_B & pb=$!
run scene_C & pc=$!
status=0
wait $pb || status=$?
wait $pc || status=$?
echo "scenes A, B, C: ${SECONDS} s"
exit $status
