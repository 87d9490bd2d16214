"""What a small pile's angles and sizes tell about its avalanche angle, its size told exactly.

The best of several learners, the information the events carry, and the coverage at each lead
read at the sample's resolution:

    .venv/bin/python benchmarks/small_pile_information.py \\
        --prior results/default_model/default_forecaster.zip.prior.h5 --out benchmarks/results

The rows are the model's, as ``camera_information.py`` reads them (``model_rows``: the
held-out rows its provenance names, the others that reached the avalanche train), kept to the
piles of fewer than ``SMALL`` sliders. Every cut is of angles and sizes only, exact, told its
pile's number of sliders exactly (``forecast_conditions.told``), as ``forecast_conditions.py``
measures ``learned_sized`` on the small piles; the held-out piles are cut at ``LEADS_DEG``
before their avalanche (one cut per pile and lead) and at random tilts (10 draws per pile, the
cut law of ``features.training_cuts``, drawn over all the held-out piles as there).

* **the best of several learners**: the shipped ``learned_sized`` (trained on every pile, over
  the training draw of degradations); and, trained on the small training piles' exact cuts
  told their size: ``Learned`` with ``learned_sized``'s registry options (and deeper trees),
  a random forest, extra trees and 50 nearest neighbours on its features
  (``camera_information.learners``); ``Learned`` refitted on the small piles over its own
  training draw of degradations. The median signed and absolute error 3° and 1° before the
  avalanche and over random cuts (where a point nearer the avalanche than the learner's median
  scores better at a fixed lead without being better: ``lead_bias.py``), the 80 % coverage
  0.25° before and over random cuts where the learner gives an interval; the best point
  learner trained on half the small piles, and on every pile.
* **the information**: the ROC AUC of a small boosted classifier telling a cut 3° before from
  one 10° before, and 0.25° from 2° before (``camera_information.approach_auc``: out of fold,
  5 folds of piles), for the small piles and, beside them, the piles of ``SMALL`` sliders or
  more; and the median signed error of the conditioned climatology (the training piles'
  avalanche angles above the tilt reached: of every pile, and of the small ones, the size
  told), which knows nothing but the tilt: a forecaster that cannot tell how near the
  avalanche is regresses towards it.
* **the coverage at each lead** of the learners with an interval: n, the Clopper-Pearson
  intervals at 95 % and at the Bonferroni level over the ``len(LEADS_DEG)`` leads
  (1 - 0.05/10), and the one-sided binomial p of "coverage ≥ 0.70" (rejected family-wise at 5 %
  when p < 0.005), with the highest coverage each lead's n rejects.

Every learner runs on one thread (``--rows``, ``--draws``, ``--test-rows`` and ``--quick`` cap
the cost). Writes small_pile_information.json and small_pile_information.md to ``--out``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from camera_information import (Refitted, approach_auc, learners, model_parser, one_thread_rows,
                                options_of)
from forecast_conditions import told
from forecast_skill import LEADS_DEG as CONDITIONS_LEADS_DEG
from forecast_skill import blind, write_report
from sliders.analysis.forecast.base import LOWER, MEDIAN, UPPER
from sliders.analysis.forecast.baselines import conditioned_quantiles
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.features import Cuts, training_cuts
from sliders.analysis.forecast.learned import Learned, with_design
from sliders.forecasting.common import TRAIN_MAX_ITER

#: the small piles: fewer sliders than this
SMALL = 50
#: the leads (deg) scored: forecast_conditions.py's nine and 10°, the classifier's far lead
LEADS_DEG = tuple(sorted({*CONDITIONS_LEADS_DEG, 10.0}))
#: the pairs of leads (near, far) the classifier tells apart
AUC_PAIRS_DEG = ((3.0, 10.0), (0.25, 2.0))
#: the targets: median signed error 3° before within this (deg); coverage at every lead at least
SIGNED_TARGET_DEG, COVERAGE_FLOOR = 1.0, 0.70
#: family-wise error rate of the coverage's reading, Bonferroni over the leads
FAMILY_ALPHA = 0.05
#: resamplings of the piles of the signed error's and the random cuts' resolution
BOOTSTRAP = 2000
SHIPPED = "learned_sized, shipped (every pile, training draw of degradations)"


def exact_told(cuts, seed: int):
    """``cuts`` as angles and sizes, exact, told their pile's number of sliders exactly, with the
    angles-and-sizes forecasters' features computed once."""
    return with_design(told(blind(cuts), "told exactly", seed), "angles_sizes")


def signed_interval(err, seed: int, level: float = 0.95) -> list:
    """The ``level`` central range of the median of ``err`` (one per pile) over resampled piles."""
    pick = np.random.default_rng(seed).integers(0, err.size, (BOOTSTRAP, err.size))
    m = np.median(err[pick], axis=1)
    return [float(np.degrees(v)) for v in np.percentile(m, [50 * (1 - level),
                                                            50 * (1 + level)])]


def binomial(k: int, n: int, leads: int = len(LEADS_DEG)) -> dict:
    """A coverage of ``k`` in ``n`` independent cuts read against ``COVERAGE_FLOOR``: its 95 % and
    Bonferroni (``FAMILY_ALPHA`` over ``leads``) Clopper-Pearson intervals, the one-sided p of
    "coverage ≥ floor", whether the family rejects it, and the highest coverage ``n`` rejects."""
    from scipy.stats import binom, binomtest

    level = 1 - FAMILY_ALPHA / leads
    t = binomtest(k, n)
    p = float(binom.cdf(k, n, COVERAGE_FLOOR))
    below = np.flatnonzero(binom.cdf(np.arange(n + 1), n, COVERAGE_FLOOR) < FAMILY_ALPHA / leads)
    return {"coverage": k / n, "n": n,
            "ci95": list(t.proportion_ci(0.95)), "ci_bonferroni": list(t.proportion_ci(level)),
            "p_at_least_floor": p, "rejected_family_wise": bool(p < FAMILY_ALPHA / leads),
            "highest_rejected": float(below[-1] / n) if below.size else None}


def per_pile_interval(inside, row, seed: int, level: float) -> list:
    """The ``level`` central range of the share ``inside`` over resampled piles (random cuts: a
    pile's cuts are not independent)."""
    piles, of = np.unique(row, return_inverse=True)
    hits, cuts = np.bincount(of, inside.astype(float)), np.bincount(of)
    pick = np.random.default_rng(seed).integers(0, piles.size, (BOOTSTRAP, piles.size))
    share = hits[pick].sum(axis=1) / cuts[pick].sum(axis=1)
    return [float(v) for v in np.percentile(share, [50 * (1 - level), 50 * (1 + level)])]


def scores(f, at, lead, rnd, seed: int) -> dict:
    """``f`` on the cuts at each lead (``at``, ``lead`` in radians) and on the random cuts
    ``rnd``: per lead the median signed and absolute error (deg) and the coverage read by
    ``binomial`` (None: no interval), the signed error 3° before with its 95 % range over
    resampled piles, the random cuts' coverage, and the seconds the forecasts took."""
    t = time.time()
    q, _ = f.quantiles(at)
    has_interval = not np.isnan(q[:, [LOWER, UPPER]]).all()
    err = q[:, MEDIAN] - at.alpha_c
    inside = (q[:, LOWER] <= at.alpha_c) & (at.alpha_c <= q[:, UPPER])
    out = {"per_lead": {}}
    for d in LEADS_DEG:
        m = np.isclose(lead, math.radians(d))
        out["per_lead"][f"{d:g}"] = {
            "median_signed_deg": float(np.degrees(np.median(err[m]))),
            "median_abs_deg": float(np.degrees(np.median(np.abs(err[m])))),
            "coverage": binomial(int(inside[m].sum()), int(m.sum())) if has_interval else None,
            "n": int(m.sum())}
    m3 = np.isclose(lead, math.radians(3.0))
    out["signed_3_ci95"] = signed_interval(err[m3], seed)
    qr, _ = f.quantiles(rnd)
    e = qr[:, MEDIAN] - rnd.alpha_c
    out["random_cuts_error"] = {"median_signed_deg": float(np.degrees(np.median(e))),
                                "median_abs_deg": float(np.degrees(np.median(np.abs(e)))),
                                "n": int(len(rnd))}
    out["random_cuts"] = None
    if has_interval:
        ins = (qr[:, LOWER] <= rnd.alpha_c) & (rnd.alpha_c <= qr[:, UPPER])
        out["random_cuts"] = {"coverage": float(ins.mean()), "n": int(len(rnd)),
                              "piles": int(np.unique(rnd.row).size),
                              "ci95_piles": per_pile_interval(ins, rnd.row, seed, 0.95)}
    out["seconds_forecast"] = time.time() - t
    return out


class Climatology:
    """The conditioned climatology of ``alpha_c`` (sorted): quantiles of the avalanche angles
    above the tilt reached, no interval read from the catalogue."""

    def __init__(self, alpha_c):
        self.alpha_c = np.sort(np.asarray(alpha_c, dtype=float))

    def quantiles(self, cuts):
        return conditioned_quantiles(self.alpha_c, cuts.tilt_now)


def contenders(options: dict, deeper: bool) -> dict:
    """``camera_information.learners`` of ``options``, named as fitted on the small piles."""
    return {k.replace("refitted", f"refitted on the piles of N < {SMALL}"): v
            for k, v in learners(options, deeper).items()}


def line(name: str, s: dict) -> str:
    """A one-line summary of ``scores``."""
    p = s["per_lead"]
    cov = "" if p["0.25"]["coverage"] is None else \
        f", coverage 0.25° {p['0.25']['coverage']['coverage']:.3f}"
    return (f"{name}: signed 3° {p['3']['median_signed_deg']:+.2f} "
            f"({s['signed_3_ci95'][0]:+.2f} to {s['signed_3_ci95'][1]:+.2f}), |err| 3° "
            f"{p['3']['median_abs_deg']:.2f}, signed 1° {p['1']['median_signed_deg']:+.2f}, "
            f"|err| 1° {p['1']['median_abs_deg']:.2f}, random cuts signed "
            f"{s['random_cuts_error']['median_signed_deg']:+.2f} |err| "
            f"{s['random_cuts_error']['median_abs_deg']:.2f}{cov}")


def markdown(rep: dict) -> str:
    """The tables of docs/forecasting_results.md."""
    c = rep["caps"]
    lines = [f"piles of N < {SMALL}, angles and sizes exact, size told exactly: "
             f"{rep['rows_trained']} training piles ({c['training_cuts']} cuts, "
             f"{c['draws_per_row']} per pile), {rep['rows_tested']} held-out piles; "
             "errors in degrees (forecast − truth), in brackets the 95 % range over resampled "
             f"piles (the target, within ±{SIGNED_TARGET_DEG:g}° 3° before: met when the median "
             "lies within, missed beyond the resolution when the whole range lies outside); 80 % "
             "coverage (— : no interval)", "",
             "| learner | signed 3° before | abs 3° | signed 1° | abs 1° | signed, random cuts | "
             "abs, random cuts | coverage 0.25° | coverage, random cuts |",
             "|---|---|---|---|---|---|---|---|---|"]

    def cov(s):
        v = s["per_lead"]["0.25"]["coverage"]
        return "—" if v is None else f"{v['coverage']:.2f} ({v['n']})"

    def rnd(s):
        v = s["random_cuts"]
        return "—" if v is None else f"{v['coverage']:.2f} ({v['n']})"

    for name, s in rep["learners"].items():
        p, lo_hi, r = s["per_lead"], s["signed_3_ci95"], s["random_cuts_error"]
        lines.append(f"| {name} | {p['3']['median_signed_deg']:+.2f} ({lo_hi[0]:+.2f} to "
                     f"{lo_hi[1]:+.2f}) | {p['3']['median_abs_deg']:.2f} | "
                     f"{p['1']['median_signed_deg']:+.2f} | {p['1']['median_abs_deg']:.2f} | "
                     f"{r['median_signed_deg']:+.2f} | {r['median_abs_deg']:.2f} | "
                     f"{cov(s)} | {rnd(s)} |")
    if rep.get("curve"):
        lines += ["", f"{rep['best_point']}, trained on more piles", "",
                  "| training piles | training cuts | signed 3° before | abs 3° | signed 1° | "
                  "abs 1° | signed, random cuts | abs, random cuts |",
                  "|---|---|---|---|---|---|---|---|"]
        for label, s in rep["curve"].items():
            p, lo_hi, r = s["per_lead"], s["signed_3_ci95"], s["random_cuts_error"]
            lines.append(f"| {label} | {s['training_cuts']} | {p['3']['median_signed_deg']:+.2f} "
                         f"({lo_hi[0]:+.2f} to {lo_hi[1]:+.2f}) | {p['3']['median_abs_deg']:.2f} "
                         f"| {p['1']['median_signed_deg']:+.2f} | {p['1']['median_abs_deg']:.2f} | "
                         f"{r['median_signed_deg']:+.2f} | {r['median_abs_deg']:.2f} |")
    lines += ["", "the information: ROC AUC of a boosted classifier (out of fold, 5 folds of "
                  "piles, the cuts compared), and the median signed error 3° before of the "
                  "conditioned climatology and of the shipped learned_sized", "",
              "| piles | " + " | ".join(f"AUC {a:g}° vs {b:g}°" for a, b in AUC_PAIRS_DEG)
              + " | cond. climatology, every pile | cond. climatology, piles of its size class | "
                "learned_sized | n |", "|---|---|---|---|---|---|---|"]
    for label, v in rep["information"].items():
        lines.append(f"| {label} | " + " | ".join(f"{a['auc']:.3f} ({a['n']})"
                                                  for a in v["auc"].values())
                     + f" | {v['climatology_all_3']:+.2f} | {v['climatology_class_3']:+.2f} | "
                       f"{v['learned_sized_3']:+.2f} | {v['n_3']} |")
    leads = list(rep["learners"][SHIPPED]["per_lead"])
    head = "| " + " | ".join(f"{d}°" for d in leads) + " |"
    lines += ["", "median signed error (deg) at each lead", "", "| learner " + head,
              "|---|" + "---|" * len(leads)]
    for name, s in rep["learners"].items():
        lines.append(f"| {name} | " + " | ".join(f"{v['median_signed_deg']:+.2f}"
                                                for v in s["per_lead"].values()) + " |")
    lines += ["", f"80 % coverage at each lead (* : below {COVERAGE_FLOOR} at family-wise "
                  f"{FAMILY_ALPHA:g}, Bonferroni over {len(leads)} leads)", "",
              "| learner " + head, "|---|" + "---|" * len(leads)]
    for name in rep["coverage_learners"]:
        lines.append(f"| {name} | " + " | ".join(
            f"{v['coverage']['coverage']:.2f}{'*' if v['coverage']['rejected_family_wise'] else ''}"
            for v in rep["learners"][name]["per_lead"].values()) + " |")
    lvl = 100 * (1 - FAMILY_ALPHA / len(leads))
    r = rep["learners"][SHIPPED]["random_cuts"]
    lines += ["", f"{SHIPPED}: Clopper-Pearson intervals of the coverage (one cut per pile); p: "
                  f"one-sided binomial of coverage ≥ {COVERAGE_FLOOR}, rejected family-wise when "
                  f"p < {FAMILY_ALPHA / len(leads):g}; the highest coverage its n rejects so; "
                  f"random cuts {r['coverage']:.3f} ({r['n']} cuts of {r['piles']} piles, 95 % "
                  f"over resampled piles {r['ci95_piles'][0]:.3f}-{r['ci95_piles'][1]:.3f})", "",
              f"| lead | n | coverage | 95 % | {lvl:.1f} % | p | rejected | highest rejected |",
              "|---|---|---|---|---|---|---|---|"]
    for d, v in rep["learners"][SHIPPED]["per_lead"].items():
        b = v["coverage"]
        hr = "—" if b["highest_rejected"] is None else f"{b['highest_rejected']:.3f}"
        lines.append(f"| {d}° | {b['n']} | {b['coverage']:.3f} | {b['ci95'][0]:.3f}-"
                     f"{b['ci95'][1]:.3f} | {b['ci_bonferroni'][0]:.3f}-"
                     f"{b['ci_bonferroni'][1]:.3f} | {b['p_at_least_floor']:.3g} | "
                     f"{'yes' if b['rejected_family_wise'] else 'no'} | {hr} |")
    return "\n".join(lines) + "\n"


def main():
    p = model_parser(__doc__, 10, f"small (N < {SMALL}) ")
    p.add_argument("--quick", action="store_true",
                   help="600 small training piles, 4 cuts each, 250 small held-out piles, no "
                        "deeper trees, no learning curve")
    args = p.parse_args()
    if args.quick:
        args.rows, args.draws, args.test_rows = args.rows or 600, 4, args.test_rows or 250
    if min(args.rows, args.test_rows) < 0 or args.draws < 1:
        p.error("--rows and --test-rows must be at least 0, --draws at least 1")
    t0 = time.time()
    models, data, train_rows, test_rows = one_thread_rows(p, args)
    n = np.asarray(data.parameters["n_sliders"])
    rng = np.random.default_rng(args.seed)
    train_all = data.subset(train_rows)
    train_small, test_small = train_rows[n[train_rows] < SMALL], test_rows[n[test_rows] < SMALL]
    if args.rows and args.rows < len(train_small):
        train_small = np.sort(rng.choice(train_small, args.rows, replace=False))
    if args.test_rows and args.test_rows < len(test_small):
        test_small = np.sort(rng.choice(test_small, args.test_rows, replace=False))
    train, test = data.subset(train_small), data.subset(test_small)
    options = options_of()["learned_sized"]
    options["max_iter"] = TRAIN_MAX_ITER

    # the held-out small piles at each lead, and at random tilts drawn over every held-out pile
    # (as forecast_conditions.size_report draws them), kept to the small ones
    at, which = cuts_at_leads(test, np.arange(len(test)), np.radians(LEADS_DEG))
    lead = np.radians(LEADS_DEG)[which]
    at = exact_told(at, args.seed)
    every = training_cuts(data.subset(test_rows), 10, np.random.default_rng(args.seed))
    keep = np.isin(test_rows[every.row], test_small)
    rnd = Cuts.from_set(test, np.searchsorted(test_small, test_rows[every.row[keep]]),
                        every.tilt_now[keep])
    rnd = exact_told(rnd, args.seed)
    t = time.time()
    tr = exact_told(training_cuts(train, args.draws, np.random.default_rng(args.seed)), args.seed)
    print(f"{len(train)} small training piles ({len(tr)} cuts), {len(test)} held-out "
          f"({len(at)} cuts at leads, {len(rnd)} random): {time.time() - t0:.0f} s", flush=True)

    rep = {"model": os.path.basename(args.model), "prior": os.path.basename(args.prior),
           "rows_trained": int(len(train)), "rows_tested": int(len(test)),
           "caps": {"rows": args.rows, "draws_per_row": args.draws, "test_rows": args.test_rows,
                    "training_cuts": int(len(tr)), "max_iter": TRAIN_MAX_ITER, "threads": 1},
           "leads_deg": list(LEADS_DEG), "learners": {}}

    def run(name, f, fit=None):
        t = time.time()
        if fit is not None:
            fit(f)
        s = scores(f, at, lead, rnd, args.seed)
        s["seconds_fit"] = time.time() - t - s["seconds_forecast"]
        rep["learners"][name] = s
        print(line(name, s), f"({s['seconds_fit']:.0f} s)", flush=True)
        return s

    run(SHIPPED, models["learned_sized"])
    run("conditioned climatology, every pile", Climatology(train_all.alpha_c))
    run(f"conditioned climatology, piles of N < {SMALL}", Climatology(
        data.alpha_c[train_rows[n[train_rows] < SMALL]]))
    for name, f in contenders(options, not args.quick).items():
        run(name, f, lambda f: f.fit(train, tr))
    own_cuts = Learned(**options).training_cuts(train, np.random.default_rng(args.seed))
    run(f"Learned, registry's options, refitted on the piles of N < {SMALL} over its "
        "training draw of degradations", Refitted(options), lambda f: f.fit(train, own_cuts))
    rep["coverage_learners"] = [k for k, v in rep["learners"].items()
                                if v["random_cuts"] is not None and not k.startswith("conditioned")]

    # the best learner on the exact cuts (lowest median |error| 3° before), trained on half the
    # small piles and on every pile
    best = min(contenders(options, not args.quick),
               key=lambda k: rep["learners"][k]["per_lead"]["3"]["median_abs_deg"])
    rep["best_point"], rep["curve"] = best, {}
    for label, rows in ({} if args.quick else {
            f"half the piles of N < {SMALL}": data.subset(np.sort(
                rng.choice(train_small, len(train_small) // 2, replace=False))),
            f"the piles of N < {SMALL}": train,
            f"every pile (N from {n[train_rows].min()} to {n[train_rows].max()})": train_all}
            ).items():
        if rows is train:
            s, k = rep["learners"][best], len(tr)
        else:
            cuts = exact_told(training_cuts(rows, args.draws, np.random.default_rng(args.seed)),
                              args.seed)
            f = contenders(options, True)[best].fit(rows, cuts)
            s, k = scores(f, at, lead, rnd, args.seed), len(cuts)
        rep["curve"][f"{label} ({len(rows)})"] = {**s, "training_cuts": int(k)}
        print(line(f"{best}, {label}", s), flush=True)

    # the information: can the events tell how near the avalanche is?
    view = Learned(**options)
    big_rows = test_rows[n[test_rows] >= SMALL]
    if args.test_rows and args.test_rows < len(big_rows):
        big_rows = np.sort(rng.choice(big_rows, args.test_rows, replace=False))
    big = data.subset(big_rows)
    big_at, big_which = cuts_at_leads(big, np.arange(len(big)),
                                      np.radians(sorted({d for p in AUC_PAIRS_DEG for d in p})))
    big_lead = np.radians(sorted({d for p in AUC_PAIRS_DEG for d in p}))[big_which]
    big_at = exact_told(big_at, args.seed)
    q, _ = models["learned_sized"].quantiles(big_at)
    big3 = np.isclose(big_lead, math.radians(3.0))
    clim_all, clim_big = Climatology(train_all.alpha_c), Climatology(
        data.alpha_c[train_rows[n[train_rows] >= SMALL]])

    def signed3(f, cuts, m):
        return float(np.degrees(np.median(f.quantiles(cuts)[0][m, MEDIAN] - cuts.alpha_c[m])))

    m3 = np.isclose(lead, math.radians(3.0))
    rep["information"] = {
        f"N < {SMALL}": {
            "auc": {f"{a:g}-{b:g}": approach_auc(view, at, lead, args.seed, (a, b))
                    for a, b in AUC_PAIRS_DEG},
            "climatology_all_3": rep["learners"]["conditioned climatology, every pile"][
                "per_lead"]["3"]["median_signed_deg"],
            "climatology_class_3": rep["learners"][
                f"conditioned climatology, piles of N < {SMALL}"]["per_lead"]["3"][
                "median_signed_deg"],
            "learned_sized_3": rep["learners"][SHIPPED]["per_lead"]["3"]["median_signed_deg"],
            "n_3": int(m3.sum())},
        f"N ≥ {SMALL}": {
            "auc": {f"{a:g}-{b:g}": approach_auc(view, big_at, big_lead, args.seed, (a, b))
                    for a, b in AUC_PAIRS_DEG},
            "climatology_all_3": signed3(clim_all, big_at, big3),
            "climatology_class_3": signed3(clim_big, big_at, big3),
            "learned_sized_3": float(np.degrees(np.median(q[big3, MEDIAN]
                                                          - big_at.alpha_c[big3]))),
            "n_3": int(big3.sum())}}
    for label, v in rep["information"].items():
        print(label, {k: round(a["auc"], 3) for k, a in v["auc"].items()},
              f"climatology 3° {v['climatology_all_3']:+.2f} / {v['climatology_class_3']:+.2f}, "
              f"learned_sized {v['learned_sized_3']:+.2f}", flush=True)
    rep["seconds"] = time.time() - t0
    print(write_report(rep, args.out, "small_pile_information", markdown))


if __name__ == "__main__":
    main()
