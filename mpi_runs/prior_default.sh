#!/usr/bin/env bash
# The default prior ensemble of the forecasting page (docs/forecasting.md): 4000 rows, each drawing its
# material (mu_d, mu_s - mu_d, sigma_mu, xi, N) from mpi_runs/priors/default.toml,
# with the catalogue of every event and the ceiling, into one HDF5 file.
#
#   bash mpi_runs/prior_default.sh                       # NP=2 ranks, explore mode
#   NP=8 PRIOR=mpi_runs/priors/default.toml bash mpi_runs/prior_default.sh
#
# Environment: NP (2), PRIOR (mpi_runs/priors/default.toml), OUT
# (results/mpi_runs/prior_default.h5), PY (.venv/bin/python).  Restartable: run it
# again to complete an interrupted file (--resume computes only the missing rows).
# On SLURM: srun/mpirun the same command in an allocation (mpi_runs/slurm/).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
NP=${NP:-2}
PRIOR=${PRIOR:-$ROOT/mpi_runs/priors/default.toml}
OUT=${OUT:-$ROOT/results/mpi_runs/prior_default.h5}
mkdir -p "$(dirname "$OUT")"
cd "$ROOT"
# build (editable install) once here, not concurrently in every rank
"$PY" -c "import sliders._kernel"
SECONDS=0
mpirun -n "$NP" "$PY" -m sliders.prior "$PRIOR" --out "$OUT" --resume --progress-interval 30
echo "prior_default: ${SECONDS} s -> $OUT"
