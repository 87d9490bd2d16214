#!/usr/bin/env bash
# The three parameter studies of docs/studies.md (python -m sliders.study), one HDF5 file each:
#   dmu (N = 100, R = 200), xi (N = 400, R = 40), N (25..800, R = 40).
#
#   bash mpi_runs/study_sweeps.sh            # all three, NP=2 ranks
#   NP=8 bash mpi_runs/study_sweeps.sh xi    # one of them
#
# Environment: NP (2), OUT (results/studies), PY (.venv/bin/python).  Restartable: run it
# again to complete an interrupted file (--resume computes only the missing rows).
# Then: python -m sliders.figures --study results/studies/study_dmu.h5 --out docs/figures
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
NP=${NP:-2}
OUT=${OUT:-$ROOT/results/studies}
mkdir -p "$OUT"
cd "$ROOT"
"$PY" -c "import sliders._kernel"   # build once here, not concurrently in every rank
cases=("$@")
[ ${#cases[@]} -gt 0 ] || cases=(n xi dmu)
for c in "${cases[@]}"; do
  study=mpi_runs/scenes/study_$c.toml
  [ -f "$study" ] || { echo "study_sweeps.sh: no study $study (use dmu, xi or n)" >&2; exit 2; }
  SECONDS=0
  mpirun -n "$NP" "$PY" -m sliders.study "$study" --out "$OUT/study_$c.h5" --resume \
    --progress-interval 60
  echo "study_sweeps.sh: $c took $SECONDS s wall on $NP ranks"
done
