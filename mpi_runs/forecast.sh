#!/usr/bin/env bash
# The forecasting evaluation (docs/forecasting_results.md) from one script, on NP ranks:
#   1. the prior ensembles (python -m sliders.prior): R rows of the default prior, split by
#      realisation into training, validation and test (0.5 / 0.1 / 0.4: 2000 test rows at
#      R = 5000), and RR test-only rows of each other preparation (initial_forces = "zero",
#      and "history": the last stable state before an avalanche, tilted back to zero);
#   2. python -m sliders.forecast evaluate: fits every forecaster, prints the table, writes
#      forecast_table.md, forecast_metrics.json, forecaster.zip (for predict) and the figures.
#
#   bash mpi_runs/forecast.sh                        # NP=2, R=5000, RR=500, explore mode
#   R=2000 RR=300 OUT=/tmp/fc bash mpi_runs/forecast.sh
#
# Environment: NP (2), R (5000), RR (500), MODE (explore), SEED (0), OUT
# (results/forecast), FIGURES (where the figures go; default OUT), PY (.venv/bin/python),
# NICE (0; e.g. 19 to leave the cores to others).  Restartable: the prior files are
# completed (--resume), the evaluation is redone.  The priors are written into OUT/priors/.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
NP=${NP:-2}
R=${R:-5000}
RR=${RR:-500}
MODE=${MODE:-explore}
SEED=${SEED:-0}
OUT=${OUT:-$ROOT/results/forecast}
FIGURES=${FIGURES:-$OUT}
NICE=${NICE:-0}
mkdir -p "$OUT/priors"
cd "$ROOT"
"$PY" -c "import sliders._kernel"   # build once here, not in every rank

write_prior() {  # write_prior NAME ROWS SEED INITIAL_FORCES
  cat > "$OUT/priors/$1.toml" <<TOML
# written by mpi_runs/forecast.sh: the evaluation's default prior, preparation "$4"
[prior]
realisations = $2
design = "sobol"
seed = $3
ceiling_step = 0.01
ceiling_k = 8

[scene]
mode = "$MODE"
initial_forces = "$4"

[parameters]
mu_d = { uniform = [0.3, 0.8] }
mu_s_minus_mu_d = { loguniform = [0.02, 0.12] }
sigma_mu = { uniform = [0.005, 0.03] }
xi = { loguniform = [1e-4, 1e-2], zero = 0.5 }
n_sliders = { choice = [100, 200, 400] }
TOML
}

T0=$SECONDS
write_prior default "$R" "$SEED" uniform
write_prior zero "$RR" $((SEED + 1)) zero
write_prior history "$RR" $((SEED + 2)) history
for name in default zero history; do
  T=$SECONDS
  nice -n "$NICE" mpirun -n "$NP" "$PY" -m sliders.prior "$OUT/priors/$name.toml" \
    --out "$OUT/prior_$name.h5" --resume --progress-interval 60
  echo "forecast.sh: prior $name in $((SECONDS - T)) s -> $OUT/prior_$name.h5"
done

T=$SECONDS
nice -n "$NICE" "$PY" -m sliders.forecast evaluate --data "$OUT/prior_default.h5" \
  --robust "zero=$OUT/prior_zero.h5" --robust "history=$OUT/prior_history.h5" \
  --out "$OUT" --figures "$FIGURES" --seed "$SEED" "$@"
echo "forecast.sh: evaluation in $((SECONDS - T)) s; everything in $((SECONDS - T0)) s on $NP ranks ($MODE)"
