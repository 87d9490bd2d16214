#!/usr/bin/env bash
# Submit an ensemble as a job array of K chunks, and its merge once every chunk succeeded.
#
#   K=16 R=10000 SCENE=mpi_runs/scenes/study_n400_xi0.toml bash mpi_runs/slurm/submit_array.sh [SBATCH OPTIONS]
#
# Run from the repository root.  Prints the two job ids (array, merge).  Extra
# arguments go to both sbatch calls (e.g. --partition=..., --account=...).
set -euo pipefail
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
K=${K:-8}
export SCENE=${SCENE:-mpi_runs/scenes/paper_n100.toml} R=${R:-1000}
export OUT=${OUT:-results/slurm/$(basename "$SCENE" .toml).h5}
(( K >= 1 && K <= R )) || { echo "submit_array.sh: need 1 <= K <= R (K=$K, R=$R)" >&2; exit 2; }
array=$(sbatch --parsable --array=0-$((K - 1)) "$@" "$HERE/ensemble_array.sbatch")
array=${array%%;*}
merge=$(sbatch --parsable --dependency=afterok:"$array" "$@" "$HERE/merge.sbatch")
echo "$array ${merge%%;*}"
