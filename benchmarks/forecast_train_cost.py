"""Cost of training the default forecaster, and what the 30-minute, 2-core budget buys.

    .venv/bin/python benchmarks/forecast_train_cost.py mpi_runs/priors/forecaster.toml --per-n 6
    .venv/bin/python benchmarks/forecast_train_cost.py mpi_runs/priors/forecaster.toml \
        --measured results/default_model/default_forecaster.zip.prior.h5

Simulates ``--per-n`` rows of each chain length N of the prior, drawn at
random among the rows of the prior's own design with that N (a row's cost is
heavy-tailed in the threshold gap and the disorder, so the first rows of an N
are not a fair sample), and weighs each N's mean CPU cost by its share of the
prior: the mean CPU seconds of a row, with its standard error.  Then fits
every forecaster of a model file (``fitting.fit_methods``) on those rows and
divides by the rows: the fit's CPU seconds per row.  CPU time is
``time.process_time`` (the machine may be shared; under load the wall clock
is longer, the CPU time is not).  ``--measured`` also reads the seconds each
row of a complete prior file took in its run (``realisations/wall_time``).
Projects the rows that fit in ``--budget-min`` minutes on ``--cores`` cores,
prints one JSON line and writes it to benchmarks/results/forecast_train_cost.json.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from sliders.analysis.forecast.fitting import fit_methods
from sliders.io.catalogue import Catalogue, CatalogueSet
from sliders.runs.prior import compute_prior_row
from sliders.runs.prior_spec import load_prior

HERE = os.path.dirname(os.path.abspath(__file__))


def simulate(prior, rows):
    """CPU seconds, catalogue and alpha_c of each row."""
    grid = prior.ceiling_alpha()
    out = []
    for r in rows:
        t = time.process_time()
        row = compute_prior_row(prior, int(r), "fortran", grid)
        ev = row["events"]
        cat = Catalogue(*(ev[c] for c in ("alpha", "size", "displacement", "first", "last")))
        out.append((time.process_time() - t, cat, row["alpha_c"]))
    return out


def measured(path) -> dict:
    """What each row of a complete prior file took in its own run (seconds a row, by N)."""
    import h5py

    with h5py.File(path, "r") as h:
        seconds = h["realisations/wall_time"][:]
        rows = h["realisations"]  # the parameters are its columns (format 2) or a group of them
        n = (rows["n_sliders"] if "n_sliders" in rows else rows["parameters/n_sliders"])[:]
        done = h["realisations/done"][:].astype(bool)
    return {"file": os.path.abspath(path), "rows": int(done.sum()),
            "seconds_per_row": float(seconds[done].mean()),
            "seconds_all_rows": float(seconds[done].sum()),
            "seconds_per_row_by_n": {int(k): float(seconds[done & (n == k)].mean())
                                     for k in np.unique(n[done])}}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("prior")
    p.add_argument("--per-n", type=int, default=6, help="rows simulated per chain length")
    p.add_argument("--seed", type=int, default=0, help="which rows of each chain length")
    p.add_argument("--measured", metavar="PRIOR.h5", help="a complete prior file of this prior")
    p.add_argument("--budget-min", type=float, default=30.0)
    p.add_argument("--cores", type=int, default=2)
    p.add_argument("--max-iter", type=int, default=150)
    args = p.parse_args()
    seen = None if args.measured is None else measured(args.measured)
    prior = load_prior(args.prior)
    n_all = prior.values()["n_sliders"].astype(int)
    lengths, share = np.unique(n_all, return_counts=True)
    share = share / share.sum()
    rng = np.random.default_rng(args.seed)
    rows = [int(r) for n in lengths
            for r in rng.permutation(np.flatnonzero(n_all == n))[:args.per_n]]
    sims = simulate(prior, rows)
    cpu = np.array([s[0] for s in sims])
    of_n = [cpu[[n_all[r] == n for r in rows]] for n in lengths]
    by_n = {int(n): float(c.mean()) for n, c in zip(lengths, of_n)}
    sim_per_row = float(sum(c.mean() * w for c, w in zip(of_n, share)))
    sim_error = float(np.sqrt(sum((w * c.std(ddof=1)) ** 2 / c.size for c, w in zip(of_n, share))))
    values = prior.values()
    cset = CatalogueSet.from_catalogues(
        [s[1] for s in sims], {k: np.asarray(values[k])[rows] for k in
                               ("mu_d", "mu_s_mean", "sigma_mu", "xi", "n_sliders")},
        [s[2] for s in sims], ["avalanche"] * len(rows))
    t = time.process_time()
    fit_methods(cset, args.max_iter, 0)
    fit_per_row = (time.process_time() - t) / len(rows)
    budget = args.budget_min * 60.0 * args.cores
    summary = {"prior": args.prior, "rows_measured": len(rows), "cpu_s_per_row_by_n": by_n,
               "sim_cpu_s_per_row": sim_per_row, "sim_cpu_s_per_row_error": sim_error,
               "sim_rows_per_cpu_s": 1.0 / sim_per_row,
               "fit_cpu_s_per_row": fit_per_row,
               "rows_per_cpu_s": 1.0 / (sim_per_row + fit_per_row),
               "budget_cpu_s": budget,
               "rows_in_budget": int(budget / (sim_per_row + fit_per_row)),
               "note": "fit cost per row measured on few rows; it grows slowly with the rows "
                       "(boosting is about linear, the outlier factor n log n on a capped sample)"}
    if seen is not None:
        summary["measured"] = seen
    line = json.dumps(summary)
    print(line)
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "forecast_train_cost.json"), "w") as fh:
        fh.write(line + "\n")


if __name__ == "__main__":
    main()
