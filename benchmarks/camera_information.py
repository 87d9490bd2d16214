"""What a camera's displacements tell about the avalanche angle: the best of several learners on a
camera's records, and the information each input carries.

    .venv/bin/python benchmarks/camera_information.py \\
        --prior results/default_model/default_forecaster.zip.prior.h5 --out benchmarks/results

The training rows and the held-out rows are the model's (``train --hold-out 0.2``: the
held-out rows its provenance names, the others that reached the avalanche train). The
training cuts are drawn once by the learned forecasters' cut law (``features.training_cuts``,
as ``Learned.training_cuts`` draws them) and recorded as each input below reads them (the
training draw of degradations by ``measurement.degrade_cuts`` with ``camera=True``, as the
camera forecaster's training cuts are); the held-out piles are cut 3°, 1°, 2° and 0.25°
before their avalanche and recorded alike (``forecast_conditions.camera_cuts``).

* **the best of several learners** on a camera's record with a 10 % relative displacement
  error, and on the camera forecaster's training draw of degradations: the shipped
  ``learned_camera``; the same ``Learned`` refitted on this benchmark's cuts, with the
  registry's options and (on the first record) with deeper trees; a random forest, extra
  trees (both of the mean log remaining angle) and 50 nearest neighbours (standardised
  features, the neighbours' quantiles for the interval), all on ``Learned.design``'s
  feature matrix; the best on the first record is trained on the training draw with 2, 4
  and 10 cuts per pile (``CURVE_DRAWS``: does more data close the gap?);
* **the information in the features** (``LADDER``): that best learner trained and tested on
  angles and sizes only (exact, and with the training draw's degradations), on a camera's
  unit-free displacements (exact, 10 % error, the training draw) and on the displacements
  in the model's units (the unit known: the ceiling), each on the design of the learned
  forecaster of those inputs; and, for each input, how well a small boosted classifier
  tells a cut 0.25° before the avalanche from one 2° before (ROC AUC, out of fold in 5
  folds of piles).

Figures: the median |error| over the conditioned climatology's (``forecast_skill.skill``)
3° and 1° before the avalanche and the 80 % coverage where the learner gives an interval.
Every learner runs on one thread (``--rows``, ``--draws`` and ``--quick`` cap the cost).
Writes camera_information.json and camera_information.md to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from types import SimpleNamespace

import numpy as np

from forecast_conditions import camera, camera_cuts
from forecast_skill import blind, skill, write_report
from sliders.analysis.forecast.base import LEVELS, LOWER, MEDIAN, UPPER, edge
from sliders.analysis.forecast.baselines import conditioned_quantiles
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.features import training_cuts
from sliders.analysis.forecast.learned import Learned, with_design
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.analysis.forecast.registry import FORECASTERS
from sliders.forecasting.common import TRAIN_MAX_ITER
from sliders.io.catalogue import CatalogueSet
from sliders.runs.forecast.catalogue import load_set

#: the leads (deg) scored, and the two the classifier tells apart (near, far)
SCORED_LEADS_DEG = (3.0, 1.0)
AUC_LEADS_DEG = (0.25, 2.0)
TEST_LEADS_DEG = (*SCORED_LEADS_DEG, *AUC_LEADS_DEG)
#: the inputs of the ladder: label -> (how the cuts are recorded, the learned forecaster read)
LADDER = {
    "angles and sizes, exact": ("exact, angles and sizes", "learned_blind"),
    "angles and sizes, training draw's degradations": ("training draw, angles and sizes",
                                                       "learned_blind"),
    "+ unit-free displacements, exact": ("units only", "learned_camera"),
    "+ unit-free displacements, 10 % error": ("10 % displacement error", "learned_camera"),
    "+ unit-free displacements, training draw": ("training draw", "learned_camera"),
    "displacements in the model's units (unit known, exact)": ("exact", "learned"),
}
#: the camera's records on which the learners compete
COMPETED = ("10 % displacement error", "training draw")
#: resamplings of the piles that give each ratio's resolution (``ratio_interval``)
BOOTSTRAP = 400
#: training cuts per pile of the learning curve of the best learner on the training draw (the
#: camera forecaster's own: ``Learned.draws_per_row``)
CURVE_DRAWS = (2, 4, 10)
#: the deeper boosting tried beside the registry's options
DEEPER = {"max_iter": 300, "learning_rate": 0.05, "max_leaf_nodes": 31, "min_samples_leaf": 20}


def record(cuts, how: str, seed: int):
    """``cuts`` recorded as ``how`` says (the first of a ``LADDER`` value), their features computed
    once for the learned forecaster of its inputs: exact (in the model's units), a camera's
    (``forecast_conditions.camera_cuts``; ``camera`` for the training draw), or those kept to
    their angles and sizes."""
    inputs = {"exact": "all"}.get(how, "camera")
    if how.endswith("angles and sizes"):
        base = cuts if how.startswith("exact") else camera(cuts, seed)
        return with_design(blind(base), "angles_sizes")
    if how == "exact":
        return with_design(cuts, inputs)
    if how == "training draw":
        return with_design(camera(cuts, seed), inputs)
    return with_design(camera_cuts(cuts, how, seed), inputs)


def log_remaining(cuts) -> np.ndarray:
    """(n,) the learned forecasters' target: log of the avalanche angle above the tilt's edge."""
    return np.log(np.maximum(cuts.alpha_c - edge(cuts), 1e-9))


def finite(x) -> np.ndarray:
    """``x`` with infinities read as missing (NaN)."""
    x = np.array(x, dtype=float)
    x[~np.isfinite(x)] = np.nan
    return x


class OnDesign:
    """A scikit-learn learner of the log remaining angle on ``Learned(**options).design``'s
    features: its median at the point, and its 10 % and 90 % quantiles where it gives them
    (``interval``: the neighbours' quantiles of a k-nearest-neighbours learner)."""

    def __init__(self, make, options: dict, interval: bool = False):
        self.make, self.view, self.interval = make, Learned(**options), interval

    def fit(self, train, cuts):
        x = finite(self.view.design(cuts)[0])
        self.columns_ = np.isfinite(x).any(axis=0)
        self.y_ = log_remaining(cuts)
        self.model_ = self.make().fit(x[:, self.columns_], self.y_)
        return self

    def quantiles(self, cuts):
        x = finite(self.view.design(cuts)[0])[:, self.columns_]
        q = np.full((len(cuts), LEVELS.size), np.nan)
        if self.interval:
            steps = self.model_.steps
            z = x
            for _, s in steps[:-1]:
                z = s.transform(z)
            idx = steps[-1][1].kneighbors(z, return_distance=False)
            z = np.quantile(self.y_[idx], [LEVELS[LOWER], 0.5, LEVELS[UPPER]], axis=1).T
        else:
            z = np.full((len(cuts), 3), np.nan)
            z[:, 1] = self.model_.predict(x)
        e = edge(cuts)[:, None]
        q[:, [LOWER, MEDIAN, UPPER]] = e + np.exp(z)
        return q, np.zeros(len(cuts), bool)


class Refitted:
    """``Learned(**options)`` fitted on this benchmark's cuts (its own calibration and domain)."""

    def __init__(self, options: dict):
        self.f = Learned(**options)

    def fit(self, train, cuts):
        self.f.fit(train, cuts=cuts)
        return self

    def quantiles(self, cuts):
        return self.f.quantiles(cuts)


def learners(options: dict, deeper: bool = True) -> dict:
    """The learners that compete, unfitted: label -> object with ``fit(train, cuts)`` and
    ``quantiles(cuts)`` (``options``: the registry's for the camera's forecaster; ``deeper``:
    with the deeper boosting, ``DEEPER``)."""
    from sklearn.ensemble import ExtraTreesRegressor, RandomForestRegressor
    from sklearn.impute import SimpleImputer
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    forest = {"n_estimators": 100, "min_samples_leaf": 5, "max_features": 0.3, "n_jobs": 1,
              "random_state": 0}
    out = {"Learned, registry's options, refitted": Refitted(options)}
    if deeper:
        out["Learned, deeper trees (31 leaves, 300 iterations), refitted"] = Refitted(
            {**options, **DEEPER})
    out |= {
        "random forest (log remaining angle)": OnDesign(
            lambda: RandomForestRegressor(**forest), options),
        "extra trees (log remaining angle)": OnDesign(
            lambda: ExtraTreesRegressor(**forest), options),
        "50 nearest neighbours (standardised)": OnDesign(
            lambda: make_pipeline(SimpleImputer(strategy="median", add_indicator=True),
                                  StandardScaler(), KNeighborsRegressor(50)), options,
            interval=True)}
    return out


class Fixed:
    """Quantiles already computed, read by ``forecast_skill.skill``."""

    def __init__(self, q, fb):
        self.q, self.fb = q, fb

    def quantiles(self, cuts):
        return self.q, self.fb


def ratio_interval(point, truth, tilt, train_ac, seed: int, draws: int = BOOTSTRAP) -> list:
    """The 5-95 % range of ``skill``'s ratio (median |error| over the conditioned
    climatology's) over ``draws`` resamplings of the piles: the figure's resolution."""
    qc, _ = conditioned_quantiles(train_ac, tilt)
    err, err_c = np.abs(point - truth), np.abs(qc[:, MEDIAN] - truth)
    pick = np.random.default_rng(seed).integers(0, err.size, (draws, err.size))
    r = np.median(err[pick], axis=1) / np.median(err_c[pick], axis=1)
    return [float(v) for v in np.percentile(r, [5.0, 95.0])]


def scores(f, test, lead, train_ac, seed: int = 0) -> dict:
    """``skill`` of ``f`` at each of ``SCORED_LEADS_DEG`` (the coverage None where ``f`` gives no
    interval) with its ratio's resolution (``ratio_interval``), and the seconds its forecasts
    took."""
    t = time.time()
    q, fb = f.quantiles(test)
    out = {}
    for d in SCORED_LEADS_DEG:
        m = np.isclose(lead, math.radians(d))
        s = skill(Fixed(q[m], fb[m]), SimpleNamespace(alpha_c=test.alpha_c[m],
                                                      tilt_now=test.tilt_now[m]), train_ac)
        if np.isnan(q[m][:, [LOWER, UPPER]]).all():
            s["coverage"] = None
        s["vs_conditioned_5_95"] = ratio_interval(q[m, MEDIAN], test.alpha_c[m],
                                                  test.tilt_now[m], train_ac, seed)
        out[f"{d:g}"] = s
    out["seconds_forecast"] = time.time() - t
    return out


def approach_auc(view: Learned, test, lead, seed: int, leads=AUC_LEADS_DEG) -> dict:
    """ROC AUC of a small boosted classifier telling the cuts ``leads[0]`` (deg) before the
    avalanche from those ``leads[1]`` before, on ``view``'s features, its probabilities out of
    fold (5 folds of piles: a pile's two cuts lie in one fold)."""
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.metrics import roc_auc_score
    from sklearn.model_selection import GroupKFold, cross_val_predict

    near, far = (np.isclose(lead, math.radians(d)) for d in leads)
    m = near | far
    x = finite(view.design(test)[0])[m]
    x = x[:, np.isfinite(x).any(axis=0)]
    clf = HistGradientBoostingClassifier(max_iter=100, max_leaf_nodes=15, random_state=seed)
    p = cross_val_predict(clf, x, near[m], groups=test.row[m], cv=GroupKFold(5),
                          method="predict_proba")[:, 1]
    return {"auc": float(roc_auc_score(near[m], p)), "n": int(m.sum())}


def model_rows(prior: str, model: str):
    """The forecasters of ``model``, its training prior ``prior``, and the prior's rows that reached
    the avalanche: those the model trained on and those it held out (its provenance's); a
    ValueError when ``prior`` is not the model's."""
    models, prov = load_forecasters(model)
    data = CatalogueSet.joined([load_set(prior)])
    held, named = np.zeros(len(data), bool), np.asarray(prov["held_out_rows"], dtype=int)
    held[named[named < len(data)]] = True
    ok = np.isfinite(np.asarray(data.alpha_c, dtype=float))
    train_rows, test_rows = np.flatnonzero(ok & ~held), np.flatnonzero(ok & held)
    if len(train_rows) != prov["rows"] or (named >= len(data)).any():
        raise ValueError(f"--prior {prior}: {len(train_rows)} training rows, the model's "
                         f"{prov['rows']}: not its prior")
    return models, data, train_rows, test_rows


def options_of() -> dict:
    """The registry's options of each learned forecaster of the model file, by method."""
    return {e.method: dict(e.options) for e in FORECASTERS if e.method}


def markdown(rep: dict) -> str:
    """The tables of docs/forecasting_results.md."""
    c = rep["caps"]
    lines = [f"{rep['rows_trained']} training piles ({c['training_cuts']} cuts, "
             f"{c['draws_per_row']} per pile), {rep['rows_tested']} held-out piles; "
             "median abs err / the conditioned climatology's (5-95 % over resampled piles), "
             "80 % coverage (— : no interval)", "",
             "| learner | record | 3° before | 1° before | coverage 3° | coverage 1° | n |",
             "|---|---|---|---|---|---|---|"]

    def cov(s):
        return "—" if s["coverage"] is None else f"{s['coverage']:.2f}"

    def ratio(s):
        lo, hi = s["vs_conditioned_5_95"]
        return f"{s['vs_conditioned']:.2f} ({lo:.2f}-{hi:.2f})"

    for name, per in rep["learners"].items():
        for how, s in per.items():
            lines.append(f"| {name} | {how} | {ratio(s['3'])} | {ratio(s['1'])} | "
                         f"{cov(s['3'])} | {cov(s['1'])} | {s['3']['n']} |")
    if rep.get("curve"):
        lines += ["", f"{rep['ladder_learner']} on the {COMPETED[1]}, trained on more cuts", "",
                  "| cuts per training pile | training cuts | 3° before | 1° before |",
                  "|---|---|---|---|"]
        for draws, s in rep["curve"].items():
            lines.append(f"| {draws} | {s['training_cuts']} | {ratio(s['3'])} | "
                         f"{ratio(s['1'])} |")
    lines += ["", f"the ladder of inputs ({rep['ladder_learner']}); AUC: "
                  f"{AUC_LEADS_DEG[0]:g}° against {AUC_LEADS_DEG[1]:g}° before the avalanche", "",
              "| input | 3° before | 1° before | coverage 3° | coverage 1° | AUC | n |",
              "|---|---|---|---|---|---|---|"]
    for label, s in rep["ladder"].items():
        lines.append(f"| {label} | {ratio(s['3'])} | {ratio(s['1'])} | {cov(s['3'])} | "
                     f"{cov(s['1'])} | {s['auc']['auc']:.3f} ({s['auc']['n']}) | {s['3']['n']} |")
    return "\n".join(lines) + "\n"


def model_parser(doc: str, draws: int, piles: str = "") -> argparse.ArgumentParser:
    """The options of a benchmark on a model's training prior: the prior, the model, the output
    folder, the seed, and the caps of its cost (``piles``: which piles they count)."""
    p = argparse.ArgumentParser(description=doc.splitlines()[0])
    p.add_argument("--prior", default="results/default_model/default_forecaster.zip.prior.h5",
                   help="the model's training prior (its rows; the held-out ones the model's)")
    p.add_argument("--model", default="src/sliders/data/default_forecaster.zip")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--rows", type=int, default=0,
                   help=f"at most this many {piles}training piles (0: all)")
    p.add_argument("--draws", type=int, default=draws, help="training cuts drawn per training pile")
    p.add_argument("--test-rows", type=int, default=0,
                   help=f"at most this many {piles}held-out piles (0: all)")
    p.add_argument("--seed", type=int, default=0)
    return p


def one_thread_rows(p, args):
    """``model_rows`` of ``args.prior`` and ``args.model`` (a bad one ends the command through
    ``p``), every learner after limited to one thread."""
    if not os.path.isfile(args.prior):
        p.error(f"--prior {args.prior}: no such file")
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    try:
        return model_rows(args.prior, args.model)
    except ValueError as e:
        p.error(str(e))


def model_piles(p, args):
    """``(models, train, test)``: ``one_thread_rows``'s forecasters, and its training and held-out
    piles, at most ``args.rows`` and ``args.test_rows`` of them (drawn by ``args.seed``)."""
    models, data, train_rows, test_rows = one_thread_rows(p, args)
    rng = np.random.default_rng(args.seed)
    if args.rows and args.rows < len(train_rows):
        train_rows = np.sort(rng.choice(train_rows, args.rows, replace=False))
    if args.test_rows and args.test_rows < len(test_rows):
        test_rows = np.sort(rng.choice(test_rows, args.test_rows, replace=False))
    train, test = data.subset(train_rows), data.subset(test_rows)
    return models, train, test


def main():
    p = model_parser(__doc__, 4)
    p.add_argument("--quick", action="store_true",
                   help="800 training piles, 3 cuts each, 300 held-out piles, no deeper trees")
    args = p.parse_args()
    if args.quick:
        args.rows, args.draws, args.test_rows = args.rows or 800, 3, args.test_rows or 300
    t0 = time.time()
    models, train, test = model_piles(p, args)
    train_ac = models["learned_blind"].climatology_.alpha_c_
    options = options_of()
    for o in options.values():
        o["max_iter"] = TRAIN_MAX_ITER
    # the learned forecasters' cut law (as ``Learned.training_cuts`` draws them), the same tilts
    # recorded every way
    train_cuts = training_cuts(train, args.draws, np.random.default_rng(args.seed))
    test_cuts, which = cuts_at_leads(test, np.arange(len(test)), np.radians(TEST_LEADS_DEG))
    lead = np.radians(TEST_LEADS_DEG)[which]
    recorded = {}

    def recorded_as(how):
        if how not in recorded:
            t = time.time()
            recorded[how] = (record(train_cuts, how, args.seed + 1),
                             record(test_cuts, how, args.seed + 2))
            print(f"recorded {how}: {time.time() - t:.0f} s", flush=True)
        return recorded[how]

    rep = {"model": os.path.basename(args.model), "prior": os.path.basename(args.prior),
           "rows_trained": int(len(train)), "rows_tested": int(len(test)),
           "caps": {"rows": args.rows, "draws_per_row": args.draws, "test_rows": args.test_rows,
                    "training_cuts": int(len(train_cuts)), "max_iter": TRAIN_MAX_ITER,
                    "threads": 1},
           "learners": {}, "ladder": {}}
    shipped = "learned_camera, shipped (its own 32729 training cuts)"
    rep["learners"][shipped] = {}
    for how in COMPETED:
        _, te = recorded_as(how)
        rep["learners"][shipped][how] = scores(models["learned_camera"], te, lead, train_ac,
                                               args.seed)
        print(shipped, how, {d: round(rep["learners"][shipped][how][d]["vs_conditioned"], 3)
                             for d in ("3", "1")}, flush=True)
    for how in (COMPETED if not args.quick else COMPETED[:1]):
        tr, te = recorded_as(how)
        # the deeper boosting costs several times the others: on the first record only
        for name, f in learners(options["learned_camera"],
                                not args.quick and how == COMPETED[0]).items():
            t = time.time()
            f.fit(train, tr)
            s = scores(f, te, lead, train_ac, args.seed)
            s["seconds_fit"] = time.time() - t - s["seconds_forecast"]
            rep["learners"].setdefault(name, {})[how] = s
            print(f"{name}, {how}: {s['3']['vs_conditioned']:.3f} / {s['1']['vs_conditioned']:.3f}"
                  f" ({s['seconds_fit']:.0f} s)", flush=True)
    # the ladder's learner: the refitted learner of the best mean ratio on the 10 % record
    fitted = {k: v for k, v in rep["learners"].items() if k != shipped}
    best = min(fitted, key=lambda k: fitted[k][COMPETED[0]]["3"]["vs_conditioned"]
               + fitted[k][COMPETED[0]]["1"]["vs_conditioned"])
    rep["ladder_learner"] = best
    for label, (how, method) in LADDER.items():
        tr, te = recorded_as(how)
        f = learners(options[method])[best]
        t = time.time()
        f.fit(train, tr)
        s = scores(f, te, lead, train_ac, args.seed)
        s["seconds_fit"] = time.time() - t - s["seconds_forecast"]
        s["auc"] = approach_auc(Learned(**options[method]), te, lead, args.seed)
        rep["ladder"][label] = s
        print(f"{label}: {s['3']['vs_conditioned']:.3f} / {s['1']['vs_conditioned']:.3f}, "
              f"AUC {s['auc']['auc']:.3f}", flush=True)
    # the best learner on the training draw, trained on fewer and on more cuts per pile
    rep["curve"] = {}
    for draws in (() if args.quick else CURVE_DRAWS):
        if draws == args.draws and COMPETED[1] in rep["learners"][best]:
            s = rep["learners"][best][COMPETED[1]]
            n = len(train_cuts)
        else:
            t = time.time()
            more = record(training_cuts(train, draws, np.random.default_rng(args.seed)),
                          COMPETED[1], args.seed + 1)
            f = learners(options["learned_camera"])[best].fit(train, more)
            s = scores(f, recorded_as(COMPETED[1])[1], lead, train_ac, args.seed)
            s["seconds_fit"] = time.time() - t - s["seconds_forecast"]
            n = len(more)
        rep["curve"][f"{draws}"] = {**s, "training_cuts": int(n)}
        print(f"{best}, {COMPETED[1]}, {draws} cuts per pile ({n}): "
              f"{s['3']['vs_conditioned']:.3f} / {s['1']['vs_conditioned']:.3f}", flush=True)
    rep["seconds"] = time.time() - t0
    print(write_report(rep, args.out, "camera_information", markdown))


if __name__ == "__main__":
    main()
