"""The learned forecasters' 80 % interval, central against shortest, on rows they never saw.

    nice -n 10 .venv/bin/python benchmarks/interval_per_lead.py \\
        --data /work/data/train1536/part_20{27,28,29,30}.h5 --out benchmarks/results

The rows of ``--data`` (prior files) are split at random (``--test-share``,
seeded); each learned forecaster of the model file (``registry.FORECASTERS``:
``learned_blind`` on angles and sizes only, ``learned`` on every column) is
fitted once on the rest with its defaults, then asked for both intervals
(``Learned(interval=...)`` acts at prediction only).  Measured on the held-out
rows: the coverage over random cuts, per bin of tilt reached and of events so
far, per lead (0.25° to 20°: a stress test, the forecaster does not know the
lead), the reliability of P(avalanche within 1°), the median interval width,
and 3° before the avalanche the median |error| over the conditioned
climatology's.  Writes interval_per_lead.json and interval_per_lead.md to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import os

import numpy as np

from forecast_skill import LEADS_DEG, blind, skill, write_report
from sliders.analysis.forecast.base import LOWER, UPPER
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.learned import INTERVALS
from sliders.analysis.forecast.registry import FORECASTERS
from sliders.analysis.forecast.reliability import coverage_report
from sliders.io.catalogue import CatalogueSet
from sliders.runs.forecast.catalogue import load_set

#: the learned forecasters measured, and how their test catalogues are stripped
MEASURED = {"learned_blind": blind, "learned": None}


def measure(forecaster, test, degrade, seed) -> dict:
    """Both intervals of one fitted forecaster on the held-out rows."""
    lead3, _ = cuts_at_leads(test, np.arange(len(test)), [math.radians(3.0)])
    lead3 = degrade(lead3) if degrade else lead3
    out = {}
    for interval in INTERVALS:
        forecaster.set_params(interval=interval)
        rep = coverage_report(forecaster, test, np.arange(len(test)), np.radians(LEADS_DEG),
                              degrade=degrade, seed=seed)
        q, _ = forecaster.quantiles(lead3)
        rep["width_3deg_deg"] = float(np.degrees(np.median(q[:, UPPER] - q[:, LOWER])))
        rep["skill_3deg"] = skill(forecaster, lead3, forecaster.climatology_.alpha_c_)
        out[interval] = rep
    return out


def markdown(rep: dict) -> str:
    """One table per forecaster: coverage per lead, in bins, width and skill, by interval."""
    lines = []
    for name, by_interval in rep["forecasters"].items():
        leads = list(next(iter(by_interval.values()))["per_lead"])
        lines += [f"### {name}", "", "| interval | all cuts | " + " | ".join(
            f"{k}°" for k in leads) + " | tilt bins | event bins | Brier 1° | width 3° (deg) |"
            " / cond. clim. 3° |", "|---" * (len(leads) + 7) + "|"]
        for interval, r in by_interval.items():
            bins = {k: [v["coverage"] for v in r[k].values()] for k in ("per_tilt_bin",
                                                                        "per_events_bin")}
            lines.append(f"| {interval} | {r['all_cuts']['coverage']:.2f} | " + " | ".join(
                f"{r['per_lead'][k]['coverage']:.2f}" for k in leads)
                + f" | {min(bins['per_tilt_bin']):.2f}-{max(bins['per_tilt_bin']):.2f}"
                f" | {min(bins['per_events_bin']):.2f}-{max(bins['per_events_bin']):.2f}"
                f" | {r['reliability']['brier']:.4f} | {r['width_3deg_deg']:.2f}"
                f" | {r['skill_3deg']['vs_conditioned']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", nargs="+", required=True, metavar="FILE.h5")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--test-share", type=float, default=0.2)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    data = CatalogueSet.joined([load_set(f) for f in args.data])
    ok = np.flatnonzero(np.isfinite(data.alpha_c))
    perm = np.random.default_rng(args.seed).permutation(ok)
    n_test = int(round(args.test_share * perm.size))
    test, train = data.subset(np.sort(perm[:n_test])), data.subset(np.sort(perm[n_test:]))
    rep = {"data": [os.path.abspath(f) for f in args.data], "rows_trained": len(train),
           "rows_tested": len(test), "forecasters": {}}
    for entry in FORECASTERS:
        if entry.method in MEASURED:
            f = entry.make(200, args.seed).fit(train)
            rep["forecasters"][entry.method] = measure(f, test, MEASURED[entry.method], args.seed)
    print(write_report(rep, args.out, "interval_per_lead", markdown))


if __name__ == "__main__":
    main()
