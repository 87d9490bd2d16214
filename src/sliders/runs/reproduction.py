"""``python -m sliders.reproduction``: compare this package with every statement of the paper.

Runs the experiments, judges every statement (``analysis.reproduction``:
the analyses, the claims and their thresholds) and writes REPRODUCTION.md.

Experiments (the paper's parameters l = 10, mu_d = 0.55, mu_s = 0.6,
sigma_mu = 0.01; realisation r has seed ``keyed_random.realisation_seed(base, r)``):

* **A**  ``--runs`` chains of N = 10, xi = 0 (first rearrangement, bursts, alpha_c);
* **B/C** ``--large-runs`` chains of N = 400 with xi = 0 and xi = 0.001, the
  same seeds (synchronisation, event sizes, alpha_c);
* **S**  ``--runs`` chains of N = 100, xi = 0, or an ensemble file
  (``--ensemble``): force statistics, P_i, stopped forces, A(alpha).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time

from .._version import __version__
from ..analysis import observables as ob
from ..analysis.reproduction import Evidence, Report, judge, report_markdown
from ..analysis.summary import load_ensemble_summary
from ..driver import tilt_realisations
from .cli import OneLineParser
from ..scene import Scene


def run_many(n_sliders: int, xi: float, runs: int, base_seed: int, backend: str, log=None,
             label: str = ""):
    """Tilt ``runs`` realisations of the paper's chain (seeds ``realisation_seed(base_seed, r)``); returns the Results."""
    out = []
    scene = Scene(n_sliders=n_sliders, xi=xi, seed=base_seed, record="displacements")
    runs_started = time.perf_counter()
    for r, res in tilt_realisations(scene, runs, backend=backend):
        out.append(res)
        if log:
            log(f"  {label} run {r + 1}/{runs}: N={n_sliders} xi={xi:g} {res.status} "
                f"alpha_c={res.alpha_c:.4f} events={res.n_events} "
                f"({time.perf_counter() - runs_started:.1f} s)")
            runs_started = time.perf_counter()
    return out


def write_report(rep: Report, path, meta: dict) -> str:
    """Write REPRODUCTION.md from the report to ``path`` (``report_markdown``); returns the text."""
    text = report_markdown(rep, meta)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return text


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m sliders.reproduction``."""
    p = OneLineParser(prog="python -m sliders.reproduction",
                                description="Compare the package with the paper's statements; "
                                            "writes REPRODUCTION.md.")
    p.add_argument("--runs", type=int, default=20,
                   help="realisations of N = 10 and of N = 100 (default 20, as the paper)")
    p.add_argument("--large-runs", type=int, default=6,
                   help="realisations of the N = 400 scenes with and without coupling (default 6)")
    p.add_argument("--n-large", type=int, default=400, help="N of scenes B and C (default 400)")
    p.add_argument("--n-stats", type=int, default=100, help="N of the statistics runs (default 100)")
    p.add_argument("--ensemble", metavar="FILE.h5",
                   help="take the statistics (P_i, stopped forces, A) from this ensemble file "
                        "instead of running --runs chains of N = --n-stats")
    p.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    p.add_argument("--backend", choices=("fortran", "numpy"), default="fortran",
                   help="tilt backend, one of {fortran, numpy} (default fortran)")
    p.add_argument("--out", default="REPRODUCTION.md", help="output Markdown file")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders.reproduction`` with ``argv``; returns the exit code."""
    args = build_parser().parse_args(argv)
    for name in ("runs", "large_runs", "n_large", "n_stats"):
        if getattr(args, name) < (1 if name == "large_runs" else 2):
            print(f"error: --{name.replace('_', '-')} is too small", file=sys.stderr)
            return 2
    t_all = time.perf_counter()
    rep = Report()

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    ev = Evidence(small=run_many(10, 0.0, args.runs, args.seed, args.backend, log, "A"))
    rep.timings["scene A ensemble (N=10)"] = time.perf_counter() - t0
    judge(rep, ev, "small")

    t0 = time.perf_counter()
    ev.uncoupled = run_many(args.n_large, 0.0, args.large_runs, args.seed, args.backend, log, "B")
    ev.coupled = run_many(args.n_large, 0.001, args.large_runs, args.seed, args.backend, log, "C")
    rep.timings[f"scenes B and C (N={args.n_large})"] = time.perf_counter() - t0
    judge(rep, ev, "large")

    t0 = time.perf_counter()
    stats_results = []
    if args.ensemble:
        summary, _, scene = load_ensemble_summary(args.ensemble)
        rep.notes.append(f"Statistics from the ensemble file {args.ensemble} "
                         f"({summary.n_realisations} finished realisations).")
        ev.ensemble_ac = summary.alpha_c_values
    else:
        stats_results = run_many(args.n_stats, 0.0, args.runs, args.seed, args.backend, log, "S")
        summary = ob.summary_from_results(stats_results)
    rep.timings[f"statistics ensemble (N={summary.n_sliders})"] = time.perf_counter() - t0
    ev.summary = summary
    judge(rep, ev, "statistics")
    ev.groups = {"N=10": ev.small, f"N={args.n_large}, xi=0": ev.uncoupled,
                 f"N={args.n_large}, xi=0.001": ev.coupled, f"N={args.n_stats}": stats_results}
    judge(rep, ev, "all")
    bad = [r for grp in (ev.small, ev.uncoupled, ev.coupled, stats_results) for r in grp if r.status != "avalanche"]
    if bad:
        rep.notes.append(f"{len(bad)} run(s) did not end in an avalanche: "
                         + ", ".join(f"seed {r.scene.seed}: {r.status} {r.message}" for r in bad))
    rep.notes.append("Paper typos met on the way (docs/model.md): the caption of the coupled large "
                     "system says N = 10 where the text says 400; the printed P_1 of Eq. (model) "
                     "lacks a term 1/(2 μ_s) (sliders.model.bin_heights uses the corrected form); "
                     "the caption of the single-slider figure writes μ_d = 0.6 for μ_s.")
    wall = time.perf_counter() - t_all
    rep.timings["total"] = wall
    meta = {"date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"), "version": __version__,
            "backend": args.backend, "python": platform.python_version(), "wall": wall,
            "command": "python -m sliders.reproduction " + " ".join(argv if argv is not None
                                                                    else sys.argv[1:])}
    text = write_report(rep, args.out, meta)
    print(text)
    log(f"wrote {os.path.abspath(args.out)} in {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
