"""Ensemble throughput and parallel efficiency on 1 and 2 MPI ranks.

    .venv/bin/python benchmarks/ensemble_scaling.py            # N = 100 and 400, 1 and 2 ranks
    .venv/bin/python benchmarks/ensemble_scaling.py --sizes 100 --realisations 100:40

For each N, the same realisations (same base seed, hence the same seeds and
the same work) run under ``mpirun -n P python -m sliders.ensemble`` for each
P.  Reported per run:

* ``elapsed``: wall time of the ensemble phase as printed by rank 0 (from the
  first index handed out to the file closed; start-up of Python and MPI
  excluded, it is listed separately as ``process``);
* ``rate``: realisations per second = R / elapsed;
* ``efficiency``: rate(P) / (P rate(1));
* ``busy``: sum of the per-realisation compute times (file column
  ``wall_time``) / (P elapsed), the fraction of the ranks' time spent tilting
  (what the scheduling and the file writes leave);
* ``slowdown``: mean compute time of a realisation with P ranks / with 1 rank
  (the same realisations): the cost of P processes sharing the machine
  (caches, memory bandwidth, a VM's cores), which no scheduling removes.
  efficiency = busy(P) / busy(1) / slowdown, up to rounding;
* ``machine``: the same slowdown measured without MPI, P independent plain
  processes running the same K realisations at once against one alone, and
  ``eff/machine`` = efficiency x machine: the efficiency of the ensemble
  relative to what this machine allows P processes (1 = perfect scheduling).

Writes the table to stdout and to ``benchmarks/results/ensemble_scaling.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
DEFAULT_R = {100: 100, 400: 40}
FINAL = re.compile(r"in this run in ([0-9.]+) s")


def run_one(n_sliders: int, realisations: int, ranks: int, backend: str, seed: int,
            storage: str, workdir: Path) -> dict:
    import h5py

    out = workdir / f"n{n_sliders}_p{ranks}.h5"
    cmd = [shutil.which("mpirun") or "mpirun", "-n", str(ranks), sys.executable, "-m",
           "sliders.ensemble", "--n-sliders", str(n_sliders), "--seed", str(seed),
           "--realisations", str(realisations), "--out", str(out), "--backend", backend,
           "--storage", storage, "--overwrite", "--progress-interval", "1e9"]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=6 * 3600)
    process = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"benchmark run failed ({' '.join(cmd)}):\n{res.stderr}")
    m = FINAL.search(res.stderr)
    if not m:  # elapsed printed in minutes for long runs: fall back on the process time
        elapsed = process
    else:
        elapsed = float(m.group(1))
    with h5py.File(out, "r") as f:
        wall = f["realisations/wall_time"][()]
        n_events = f["realisations/n_events"][()]
        assert f["realisations/done"][()].all()
    out.unlink()
    return {
        "n_sliders": n_sliders, "ranks": ranks, "realisations": realisations,
        "elapsed_s": elapsed, "process_s": process, "rate_per_s": realisations / elapsed,
        "compute_s": float(wall.sum()), "busy": float(wall.sum()) / (ranks * elapsed),
        "mean_events": float(n_events.mean()),
        "realisation_s_min_mean_max": [float(wall.min()), float(wall.mean()), float(wall.max())],
    }


BASELINE = """
import sys, time
import sliders
from sliders.runs.ensemble import compute_row
from sliders.analysis.observables import default_grids
n, k, backend, seed = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
scene = sliders.Scene(n_sliders=n, seed=seed)
grids = default_grids(scene)
t = time.perf_counter()
for r in range(k):
    compute_row(scene, r, backend, grids)
print(time.perf_counter() - t)
"""


def machine_baseline(n_sliders: int, k: int, ranks: int, backend: str, seed: int) -> float:
    """Seconds for ``ranks`` independent plain processes (no MPI) to run the same k
    realisations each, at the same time: the machine's own cost of running P at once."""
    cmd = [sys.executable, "-c", BASELINE, str(n_sliders), str(k), backend, str(seed)]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(ranks)]
    times = [float(p.communicate(timeout=6 * 3600)[0]) for p in procs]
    return sum(times) / len(times)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 400])
    p.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    p.add_argument("--realisations", nargs="*", default=[], metavar="N:R",
                   help="realisations per size, e.g. 100:100 400:40 (defaults shown)")
    p.add_argument("--backend", choices=("fortran", "numpy"), default="fortran")
    p.add_argument("--storage", choices=("auto", "mpio", "gather"), default="auto")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--baseline", type=int, default=None, metavar="K",
                   help="also time K realisations in 1 and in P independent plain processes "
                        "at once (no MPI): the machine's slowdown when P run together "
                        "(default: R/4 per size; 0 to skip)")
    p.add_argument("--repeat", type=int, default=1,
                   help="run every configuration this many times and keep the fastest "
                        "(a shared machine: other load only ever slows a run down)")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "ensemble_scaling.json"))
    args = p.parse_args(argv)
    counts = dict(DEFAULT_R)
    for item in args.realisations:
        n, r = item.split(":")
        counts[int(n)] = int(r)

    load_before = _load()
    rows = []
    with tempfile.TemporaryDirectory(prefix="ens_bench_") as tmp:
        for n in args.sizes:
            r = counts.get(n, 20)
            for ranks in args.ranks:
                tries = [run_one(n, r, ranks, args.backend, args.seed, args.storage, Path(tmp))
                         for _ in range(max(1, args.repeat))]
                row = min(tries, key=lambda t: t["elapsed_s"])
                row["repeats_elapsed_s"] = [t["elapsed_s"] for t in tries]
                rows.append(row)
            k = args.baseline if args.baseline is not None else max(1, r // 4)
            if k > 0:
                alone = machine_baseline(n, k, 1, args.backend, args.seed)
                for ranks in args.ranks:
                    together = alone if ranks == 1 else machine_baseline(n, k, ranks, args.backend,
                                                                       args.seed)
                    for row in rows:
                        if row["n_sliders"] == n and row["ranks"] == ranks:
                            row["machine_slowdown"] = together / alone
                            row["machine_baseline_k"] = k
                print(f"  N={n}: {k} realisations alone {alone:.1f} s; P at once: "
                      + ", ".join(f"{row['ranks']}: x{row['machine_slowdown']:.2f}"
                                  for row in rows if row["n_sliders"] == n), flush=True)
                print(f"  N={n} ranks={ranks}: {row['elapsed_s']:.1f} s, "
                      f"{row['rate_per_s']:.3f} realisations/s", flush=True)
    base = {row["n_sliders"]: row for row in rows if row["ranks"] == 1}
    for row in rows:
        b = base.get(row["n_sliders"])
        row["efficiency"] = row["rate_per_s"] / (row["ranks"] * b["rate_per_s"]) if b else None
        row["slowdown"] = (row["realisation_s_min_mean_max"][1] / b["realisation_s_min_mean_max"][1]
                           if b else None)
        hw = row.get("machine_slowdown")
        row["efficiency_vs_machine"] = row["efficiency"] * hw if (hw and row["efficiency"]) else None

    lines = [f"{'N':>5} {'ranks':>5} {'R':>5} {'elapsed s':>10} {'real./s':>9} "
             f"{'efficiency':>10} {'busy':>6} {'slowdown':>8} {'machine':>8} {'eff/machine':>11} "
             f"{'s/real. (min/mean/max)':>24}"]
    for row in rows:
        eff = f"{100 * row['efficiency']:.1f}%" if row["efficiency"] else "-"
        slow = f"{row['slowdown']:.3f}" if row["slowdown"] else "-"
        hw = f"{row['machine_slowdown']:.3f}" if row.get("machine_slowdown") else "-"
        effm = (f"{100 * row['efficiency_vs_machine']:.1f}%" if row.get("efficiency_vs_machine")
                else "-")
        mn, me, mx = row["realisation_s_min_mean_max"]
        lines.append(f"{row['n_sliders']:>5} {row['ranks']:>5} {row['realisations']:>5} "
                     f"{row['elapsed_s']:>10.2f} {row['rate_per_s']:>9.3f} {eff:>10} "
                     f"{100 * row['busy']:>5.1f}% {slow:>8} {hw:>8} {effm:>11} "
                     f"{mn:>7.2f}/{me:.2f}/{mx:.2f}")
    table = "\n".join(lines)
    print(table)

    import sliders

    report = {
        "benchmark": "ensemble_scaling",
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {"cpus": os.cpu_count(), "processor": _cpu_model(), "python": platform.python_version()},
        "software_version": sliders.__version__, "backend": args.backend, "storage": args.storage,
        "base_seed": args.seed, "load_average_before": load_before, "load_average_after": _load(), "rows": rows, "table": lines,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"-> {out}")
    return 0


def _load() -> str:
    try:
        return Path("/proc/loadavg").read_text().split(" ", 3)[:3].__str__()
    except OSError:
        return "?"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


if __name__ == "__main__":
    sys.exit(main())
