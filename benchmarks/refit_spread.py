"""How far a refit of the angles-and-sizes forecaster moves its own figures: ``learned_blind``
refitted with its shipped options and another random seed, scored as ``forecast_conditions.py``
scores the shipped one.

    .venv/bin/python benchmarks/refit_spread.py \\
        --prior results/default_model/default_forecaster.zip.prior.h5 --out benchmarks/results

A fitted forecaster is one draw: its random state seeds its training cuts (which tilt each
pile is cut at, how each cut is degraded), the out-of-fold split its conformal calibration
reads, and the novelty detector of its domain.  Its figures on the held-out piles therefore
move between fits as well as with the held-out cuts; the binomial error of a coverage
(``sqrt(p (1 - p) / n)``) is only the second.

For each seed of ``--seeds``: ``learned_blind`` made from its registry entry (its shipped
options, ``TRAIN_MAX_ITER`` boosting iterations, that seed) and fitted on the model's training
rows as ``train`` fits it (``fitting.fit_sharing_cuts``, calibrated out of fold), one thread.
Each refit and the model file's own ``learned_blind`` are scored on the same held-out cuts,
made by ``forecast_conditions``' and ``forecast_skill``'s functions with their seed (``--cut-seed``,
0 as theirs): random cuts (``training_cuts``, 10 a pile) and cuts at each lead from 0.25° to
20° (``cuts_at_leads``), angles and sizes only, the pile's size not told (``blind``, ``told``);
the noisy edge of the tilt (``edge_report``).  The figures:

* the 80 % coverage over random cuts per size class (``SIZE_CLASSES``) and over all piles;
* the lowest coverage over the leads per size class, and that of N < 50 1° before;
* the coverage of a noisy tilt cut near its avalanche (``edge_report``);
* the median absolute error 3° and 1° before the avalanche, over all piles.

Each figure with its spread over the refits (max - min) and its resolution on these cuts: a
coverage's binomial standard error, a median's half-distance between the order statistics
``n/2 ± sqrt(n)/2`` (about one standard error).  ``--quick`` fits and scores a quarter of the
training and held-out rows (a check of the run, not figures to cite).

Writes refit_spread.json and refit_spread.md to ``--out`` (refit_spread_quick.* with ``--quick``).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import time

import numpy as np

from forecast_conditions import SIZE_CLASSES, coverage_at, edge_report, held_out, told
from forecast_skill import LEADS_DEG, blind, write_report
from sliders.analysis.forecast.base import MEDIAN
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.features import training_cuts
from sliders.analysis.forecast.learned import with_design
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.forecasting.common import TRAIN_MAX_ITER
from sliders.io.catalogue import CatalogueSet
from sliders.runs.forecast.catalogue import load_set

METHOD = "learned_blind"
#: every how-many-th training and held-out row ``--quick`` keeps
QUICK_EVERY = 4


class Once:
    """A forecaster whose quantiles of one set of cuts are computed once (``coverage_at`` asks
    for them once per size class)."""

    def __init__(self, f):
        self.f, self._done = f, {}

    def quantiles(self, cuts):
        key = id(cuts)
        if key not in self._done:
            self._done[key] = (cuts, self.f.quantiles(cuts))
        return self._done[key][1]


def coverage_se(p: float, n: int) -> float:
    """The binomial standard error of a coverage ``p`` over ``n`` cuts."""
    return math.sqrt(p * (1.0 - p) / n) if n else math.nan


def median_se(values) -> float:
    """Half the distance between the order statistics ``n/2 ± sqrt(n)/2`` of ``values``
    (about one standard error of their median)."""
    v = np.sort(np.asarray(values, dtype=float))
    n = v.size
    lo = max(int(math.floor(n / 2 - math.sqrt(n) / 2)), 0)
    hi = min(int(math.ceil(n / 2 + math.sqrt(n) / 2)), n - 1)
    return float((v[hi] - v[lo]) / 2)


def held_out_cuts(test, seed: int) -> dict:
    """The held-out cuts of ``forecast_conditions.size_report`` (not told the size), their
    features computed once: random cuts, cuts at each lead, and their leads."""
    rnd = told(blind(training_cuts(test, 10, np.random.default_rng(seed))), "not told", seed)
    at, which = cuts_at_leads(test, np.arange(len(test)), np.radians(LEADS_DEG))
    at = told(blind(at), "not told", seed)
    return {"random": with_design(rnd, "angles_sizes"), "at": with_design(at, "angles_sizes"),
            "lead": np.radians(LEADS_DEG)[which], "n": np.asarray(test.parameters["n_sliders"])}


def figures(f, test, cuts: dict, seed: int) -> dict:
    """The figures of ``f`` on ``cuts`` (``held_out_cuts``) and the noisy edge of ``test``:
    each ``{"value", "n", "resolution"}`` (a lowest lead's also ``"lead_deg"``)."""
    g = Once(f)
    rnd, at, lead, n = cuts["random"], cuts["at"], cuts["lead"], cuts["n"]
    out = {}

    def cov(label, c):
        out[label] = {"value": c["coverage"], "n": c["n"],
                      "resolution": coverage_se(c["coverage"], c["n"])}

    for label, of in SIZE_CLASSES.items():
        cov(f"coverage, random cuts, {label}", coverage_at(g, rnd, mask=of(n[rnd.row])))
    cov("coverage, random cuts, all", coverage_at(g, rnd))
    for label, of in SIZE_CLASSES.items():
        per = coverage_at(g, at, lead, mask=of(n[at.row]))
        low = min(per, key=lambda k: per[k]["coverage"])
        cov(f"lowest coverage over leads, {label}", per[low])
        out[f"lowest coverage over leads, {label}"]["lead_deg"] = float(low)
        if label == "N < 50":
            cov(f"coverage 1° before, {label}", per["1"])
    e = edge_report(f, test, seed)
    out["coverage, noisy edge"] = {"value": e["coverage"], "n": e["n"],
                                   "resolution": coverage_se(e["coverage"], e["n"])}
    q = g.quantiles(at)[0]
    per = coverage_at(g, at, lead)
    for d in ("3", "1"):
        m = np.isclose(lead, math.radians(float(d)))
        out[f"median abs error {d}° before (deg)"] = {
            "value": per[d]["median_abs_deg"], "n": per[d]["n"],
            "resolution": median_se(np.degrees(np.abs(q[m, MEDIAN] - at.alpha_c[m])))}
    return out


def spread(rep: dict) -> dict:
    """Per figure: the refits' lowest and highest value, their spread, and the shipped file's."""
    fits = [v["figures"] for k, v in rep["fits"].items() if k != "shipped"]
    out = {}
    for name in fits[0]:
        vals = [f[name]["value"] for f in fits]
        out[name] = {"min": min(vals), "max": max(vals), "spread": max(vals) - min(vals),
                     "resolution": max(f[name]["resolution"] for f in fits),
                     "shipped": rep["fits"]["shipped"]["figures"][name]["value"]}
    return out


def markdown(rep: dict) -> str:
    names = list(rep["fits"])
    heads = ["shipped file" if k == "shipped" else f"refit, seed {k}" for k in names]
    lines = [f"`{METHOD}`, its shipped options, {rep['max_iter']} iterations, refitted on "
             f"{rep['rows_trained']} training piles; scored on {rep['rows_tested']} held-out "
             f"piles{' (--quick)' if rep['quick'] else ''}", "",
             "| figure | " + " | ".join(heads) + " | spread over refits (max - min) "
             "| resolution (±1 s.e., n) |", "|---|" + "---|" * (len(names) + 2)]
    for name, s in rep["spread"].items():
        cells = []
        for k in names:
            v = rep["fits"][k]["figures"][name]
            lead = f" ({v['lead_deg']:g}°)" if "lead_deg" in v else ""
            cells.append(f"{v['value']:.2f}{lead}")
        n = rep["fits"][names[0]]["figures"][name]["n"]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {s['spread']:.2f} "
                     f"({s['min']:.2f}-{s['max']:.2f}) | ±{s['resolution']:.2f} ({n}) |")
    return "\n".join(lines) + "\n"


def training_and_test(args, p):
    """The model's forecasters, its training rows and its held-out rows that reached the
    avalanche (every ``QUICK_EVERY``-th of each with ``--quick``)."""
    if args.prior is None:
        models, prov, data, held = held_out(args.model)
    else:
        models, prov = load_forecasters(args.model)
        data = CatalogueSet.joined([load_set(args.prior)])
        held = np.asarray(prov["held_out_rows"], dtype=int)
        if held.size and held.max() >= len(data):
            p.error(f"--prior {args.prior}: {len(data)} rows, not the model's training prior")
        held = held[np.isfinite(data.alpha_c[held])]
    ok = np.isfinite(np.asarray(data.alpha_c, dtype=float))
    out = np.zeros(len(data), bool)
    out[np.asarray(prov["held_out_rows"], dtype=int)] = True
    rows = np.flatnonzero(ok & ~out)
    if rows.size != prov["rows"]:
        p.error(f"--prior {args.prior or prov['data_files']}: {rows.size} training rows, "
                f"the model's {prov['rows']}")
    if args.quick:
        rows, held = rows[::QUICK_EVERY], held[::QUICK_EVERY]
    return models, data.subset(rows), data.subset(held)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prior", default=None,
                   help="the model's training prior (default: as its provenance names it)")
    p.add_argument("--model", default="src/sliders/data/default_forecaster.zip")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2],
                   help="random states of the refits (default 0 1 2)")
    p.add_argument("--cut-seed", type=int, default=0,
                   help="seed of the held-out cuts (forecast_conditions' --seed, default 0)")
    p.add_argument("--quick", action="store_true",
                   help=f"a quarter of the rows (every {QUICK_EVERY}th training and held-out pile)")
    args = p.parse_args()
    if len(args.seeds) < 2 or len(set(args.seeds)) != len(args.seeds) or min(args.seeds) < 0:
        p.error(f"--seeds {' '.join(map(str, args.seeds))}: at least two distinct seeds ≥ 0")
    if args.prior is not None and not os.path.isfile(args.prior):
        p.error(f"--prior {args.prior}: no such file")
    if not os.path.isfile(args.model):
        p.error(f"--model {args.model}: no such file")
    from sklearn.ensemble import HistGradientBoostingRegressor  # noqa: F401 (its OpenMP, limited below)
    from threadpoolctl import threadpool_limits

    from sliders.analysis.forecast.fitting import fit_sharing_cuts
    from sliders.analysis.forecast.registry import FORECASTERS

    threadpool_limits(1)
    t0 = time.time()
    models, train, test = training_and_test(args, p)
    entry = next(e for e in FORECASTERS if e.method == METHOD)
    cuts = held_out_cuts(test, args.cut_seed)
    print(f"{len(train)} training piles, {len(test)} held-out piles: {len(cuts['random'])} "
          f"random cuts, {len(cuts['at'])} at leads ({time.time() - t0:.0f} s)", flush=True)
    rep = {"forecaster": METHOD, "options": entry.options, "max_iter": TRAIN_MAX_ITER,
           "model": os.path.basename(args.model), "quick": args.quick,
           "rows_trained": int(len(train)), "rows_tested": int(len(test)),
           "cut_seed": args.cut_seed, "fits": {}}
    for seed in ["shipped", *args.seeds]:
        t = time.time()
        if seed == "shipped":
            f = models[METHOD]
        else:
            f = entry.make(TRAIN_MAX_ITER, seed)
            if f.calibration != "out_of_fold":
                p.error(f"{METHOD}: calibrated {f.calibration}, this benchmark refits the "
                        "forecasters calibrated out of fold")
            fit_sharing_cuts(f, train, None, {}, seed)
        t_fit = time.time() - t
        rep["fits"][str(seed)] = {"figures": figures(f, test, cuts, args.cut_seed),
                                  "seconds_fit": t_fit, "seconds_score": time.time() - t - t_fit}
        print(f"{seed}: fitted in {t_fit:.0f} s, scored in {time.time() - t - t_fit:.0f} s; "
              + ", ".join(f"{k} {v['value']:.3f}"
                          for k, v in rep["fits"][str(seed)]["figures"].items()), flush=True)
    rep["spread"] = spread(rep)
    rep["seconds"] = time.time() - t0
    stem = "refit_spread_quick" if args.quick else "refit_spread"
    print(write_report(rep, args.out, stem, markdown))
    print(f"{rep['seconds']:.0f} s in all")


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    try:
        main()
    except KeyboardInterrupt:
        sys.exit(130)
