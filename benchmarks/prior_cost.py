"""Cost of a prior ensemble's rows, and the bias of explore on alpha_c (docs/performance.md).

    .venv/bin/python benchmarks/prior_cost.py mpi_runs/priors/default.toml --rows 60

For the first ``--rows`` rows of the prior (the design's first points, the
rows a run of the whole prior computes first in order of index), in
``explore`` and in ``statistics`` mode: the CPU seconds of each row with the
ceiling (``runs.prior.compute_prior_row``: the tilt cut at every grid angle)
and of the plain tilt of the same scene; and the paired difference of
alpha_c between the two modes (same scene, same seed).  CPU time is
``time.process_time`` (the machine may be shared).  Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from sliders.driver import run
from sliders.runs.prior import compute_prior_row
from sliders.runs.prior_spec import load_prior


def measure(prior, rows, mode):
    prior = load_prior_mode(prior, mode)
    grid = prior.ceiling_alpha()
    cpu_row, cpu_tilt, alpha_c, n = [], [], [], []
    for r in rows:
        t = time.process_time()
        row = compute_prior_row(prior, r, "fortran", grid)
        cpu_row.append(time.process_time() - t)
        t = time.process_time()
        run(prior.scene(r))
        cpu_tilt.append(time.process_time() - t)
        alpha_c.append(row["alpha_c"])
        n.append(int(prior.values()["n_sliders"][r]))
    return {"cpu_row": cpu_row, "cpu_tilt": cpu_tilt, "alpha_c": alpha_c, "n_sliders": n}


def load_prior_mode(path, mode):
    prior = load_prior(path)
    prior.base_scene = prior.base_scene.replace(mode=mode)
    return prior


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("prior")
    p.add_argument("--rows", type=int, default=60)
    args = p.parse_args()
    rows = range(args.rows)
    out = {m: measure(args.prior, rows, m) for m in ("explore", "statistics")}
    summary = {"rows": args.rows}
    for m, d in out.items():
        summary[m] = {"rows_per_cpu_s": args.rows / sum(d["cpu_row"]),
                      "tilt_only_rows_per_cpu_s": args.rows / sum(d["cpu_tilt"]),
                      "by_n": {int(k): float(np.mean(np.array(d["cpu_row"])[np.array(d["n_sliders"]) == k]))
                               for k in sorted(set(d["n_sliders"]))}}
    diff = np.array(out["explore"]["alpha_c"]) - np.array(out["statistics"]["alpha_c"])
    diff = diff[np.isfinite(diff)]
    summary["alpha_c_explore_minus_statistics"] = {
        "mean": float(diff.mean()), "sem": float(diff.std(ddof=1) / np.sqrt(diff.size)),
        "median": float(np.median(diff)), "max_abs": float(np.abs(diff).max()),
        "pairs": int(diff.size), "identical": int(np.sum(diff == 0))}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
