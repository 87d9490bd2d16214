"""Is a learner better, or only nearer the avalanche? Its error at fixed leads against its error
over random cuts, for the learners `camera_information.py` compares.

    .venv/bin/python benchmarks/lead_bias.py \\
        --prior results/default_model/default_forecaster.zip.prior.h5 --out benchmarks/results

Scoring a forecast a fixed angle before the avalanche (3°, 1° ...) rewards a point forecast
that sits nearer the avalanche than the forecaster's own median: every cut scored there is
one whose avalanche came soon.  A learner of the mean log remaining angle (a random forest,
or boosting of the squared error) sits lower than the median of the remaining angle the
shipped forecasters read from their quantile regressors.  This benchmark scores each learner
of `camera_information.learners` at leads from 0.25° to 20° and over random cuts of the same
held-out piles (the training cut law, `features.training_cuts`): the median |error| over the
conditioned climatology's (`forecast_skill.skill`'s ratio) and the median signed error.  A
learner better at every lead and over random cuts is better; one better near the avalanche,
worse far from it and biased low over random cuts has only moved its point.

Training piles and held-out piles are the model's (`train --hold-out 0.2`), ``--draws``
training cuts per pile (4) recorded as ``--record`` says (`camera_information.record`), each learner on one
thread.  Writes lead_bias_<forecaster>.json and .md to ``--out``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from camera_information import (LADDER, OnDesign, learners, model_parser, model_piles,
                                options_of, record)
from forecast_skill import write_report
from sliders.analysis.forecast.base import MEDIAN
from sliders.analysis.forecast.baselines import conditioned_quantiles
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.features import training_cuts
from sliders.forecasting.common import TRAIN_MAX_ITER

#: the leads (deg) scored
LEADS_DEG = (0.25, 1.0, 3.0, 8.0, 12.0, 20.0)
#: the boosting of the squared error of the log remaining angle (a mean, as the forest's)
BOOSTED_MEAN = {"max_iter": 300, "learning_rate": 0.05, "max_leaf_nodes": 31,
                "min_samples_leaf": 20, "random_state": 0}


def scored(point, cuts, train_ac, m=None) -> dict:
    """The median |error| of ``point`` (the forecasts of ``cuts``, those where ``m``) over the
    conditioned climatology's, and the median signed error (deg)."""
    m = np.ones(len(point), bool) if m is None else m
    truth, point = cuts.alpha_c[m], point[m]
    qc, _ = conditioned_quantiles(train_ac, cuts.tilt_now[m])
    err = np.abs(point - truth)
    return {"vs_conditioned": float(np.median(err) / np.median(np.abs(qc[:, MEDIAN] - truth))),
            "median_abs_deg": float(np.degrees(np.median(err))),
            "median_signed_deg": float(np.degrees(np.median(point - truth))),
            "n": int(len(err))}


def markdown(rep: dict) -> str:
    lines = [f"{rep['record']}, {rep['forecaster']}'s inputs: {rep['rows_trained']} training "
             f"piles, {rep['rows_tested']} held-out piles; median |error| / the conditioned "
             "climatology's, and (in brackets) the median signed error (deg)", "",
             "| learner | " + " | ".join(f"{d:g}° before" for d in LEADS_DEG)
             + " | random cuts | median abs err, random cuts (deg) |",
             "|---|" + "---|" * (len(LEADS_DEG) + 2)]
    for name, s in rep["learners"].items():
        cells = [f"{s[f'{d:g}']['vs_conditioned']:.2f} ({s[f'{d:g}']['median_signed_deg']:+.1f})"
                 for d in LEADS_DEG]
        r = s["random"]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {r['vs_conditioned']:.2f} "
                     f"({r['median_signed_deg']:+.2f}) | {r['median_abs_deg']:.2f} |")
    return "\n".join(lines) + "\n"


def main():
    p = model_parser(__doc__, 4)
    p.add_argument("--ladder", default="angles and sizes, exact", choices=list(LADDER),
                   help="the record and the forecaster of its inputs (camera_information.LADDER)")
    args = p.parse_args()
    from sklearn.ensemble import HistGradientBoostingRegressor

    t0 = time.time()
    models, train, test = model_piles(p, args)
    how, method = LADDER[args.ladder]
    train_ac = models[method].climatology_.alpha_c_
    options = {**options_of()[method], "max_iter": TRAIN_MAX_ITER}
    tr = record(training_cuts(train, args.draws, np.random.default_rng(args.seed)), how,
                args.seed + 1)
    at, which = cuts_at_leads(test, np.arange(len(test)), np.radians(LEADS_DEG))
    at, lead = record(at, how, args.seed + 2), np.radians(LEADS_DEG)[which]
    anywhere = record(training_cuts(test, 4, np.random.default_rng(args.seed + 9)), how,
                      args.seed + 3)
    competing = {f"{method}, shipped": None,
                 **{k: v for k, v in learners(options, deeper=False).items()
                    if "neighbours" not in k and "extra" not in k},
                 "boosting of the squared error (log remaining angle)": OnDesign(
                     lambda: HistGradientBoostingRegressor(**BOOSTED_MEAN), options)}
    rep = {"record": how, "forecaster": method, "rows_trained": int(len(train)),
           "rows_tested": int(len(test)), "training_cuts": int(len(tr)), "learners": {}}
    for name, f in competing.items():
        t = time.time()
        f = models[method] if f is None else f.fit(train, tr)
        point = f.quantiles(at)[0][:, MEDIAN]
        s = {f"{d:g}": scored(point, at, train_ac, np.isclose(lead, math.radians(d)))
             for d in LEADS_DEG}
        s["random"] = scored(f.quantiles(anywhere)[0][:, MEDIAN], anywhere, train_ac)
        s["seconds"] = time.time() - t
        rep["learners"][name] = s
        print(f"{name}: " + ", ".join(f"{k} {v['vs_conditioned']:.2f} "
                                      f"({v['median_signed_deg']:+.1f})"
                                      for k, v in s.items() if k != "seconds"), flush=True)
    rep["seconds"] = time.time() - t0
    stem = f"lead_bias_{method}"
    print(write_report(rep, args.out, stem, markdown))


if __name__ == "__main__":
    main()
