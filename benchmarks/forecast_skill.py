"""The shipped forecaster measured on rows it never saw: skill, coverage, domain flag, degradations.

    .venv/bin/python benchmarks/forecast_skill.py --model src/sliders/data/default_forecaster.zip \\
        --outside results/train/outside_*.h5 --out benchmarks/results

The model's provenance names its prior files and its held-out rows
(``python -m sliders.forecast train --hold-out``); those rows are the test set.
A prior file named by its name only (trained outside the repository) is looked
for beside the model file.
Measured, for the angles-and-sizes forecaster (``learned_blind``) and, where
the catalogue has them, the one with displacements and positions (``learned``):

* 3° before the avalanche: median |error| over the conditioned climatology's, 80 % coverage;
* coverage over random cuts, per bin of tilt reached and of events so far, per
  lead (0.25° to 20°), and the reliability of P(avalanche within 1°);
* coverage per kind of pile (``KINDS``: bins of the number of sliders, strong
  coupling), over random cuts and 3° and 1° before the avalanche;
* the accuracy stored in the model at training time (per bin of the forecast's lead);
* the domain flag: the share of cuts flagged on the held-out rows (false
  alarms) and on each set drawn outside the prior (true alarms);
* the degradation curve: angle noise, detection threshold, missed events,
  size unit unknown, each with the flags of ``predict`` set to the truth.

Writes forecast_skill.json and forecast_skill.md to ``--out`` and the
figures (``sliders.figures.forecast.draw_measured``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from dataclasses import replace

import numpy as np

from sliders.analysis.forecast import Cuts, Measurement
from sliders.analysis.forecast.base import LOWER, MEDIAN, UPPER
from sliders.analysis.forecast.baselines import conditioned_quantiles
from sliders.analysis.forecast.evaluation import coverage_by_kind, cuts_at_leads
from sliders.analysis.forecast.features import training_cuts
from sliders.analysis.forecast.measurement import degrade_cuts
from sliders.analysis.forecast.reliability import coverage_report
from sliders.io.catalogue import CatalogueSet
from sliders.analysis.forecast.model_file import load_forecasters
from sliders.runs.forecast.catalogue import load_set

LEADS_DEG = (0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
#: the leads (deg) of the coverage per kind of pile
KIND_LEADS_DEG = (3.0, 1.0)
#: kinds of pile whose coverage is reported apart: label -> mask of (n_sliders, xi)
KINDS = {
    "all": lambda n, xi: np.ones(n.shape, bool),
    "N < 50": lambda n, xi: n < 50,
    "N 50-199": lambda n, xi: (n >= 50) & (n < 200),
    "N ≥ 200": lambda n, xi: n >= 200,
    "ξ < 0.1": lambda n, xi: xi < 0.1,
    "ξ 0.1-1": lambda n, xi: xi >= 0.1,
}
#: the degradations of the curve: label -> (measurement, size scale)
DEGRADATIONS = {
    "exact": (Measurement(), 1.0),
    "angle noise 0.1°": (Measurement(angle_resolution=math.radians(0.1)), 1.0),
    "angle noise 0.3°": (Measurement(angle_resolution=math.radians(0.3)), 1.0),
    "angle noise 1°": (Measurement(angle_resolution=math.radians(1.0)), 1.0),
    "min size 2": (Measurement(min_size=2.0), 1.0),
    "min size 5": (Measurement(min_size=5.0), 1.0),
    "25 % missed": (Measurement(missed_fraction=0.25), 1.0),
    "50 % missed": (Measurement(missed_fraction=0.5), 1.0),
    "size unit unknown (x3)": (Measurement(size_unit="arbitrary", min_size=3.0), 3.0),
}


def blind(cuts):
    """The cuts as angles and sizes only (no displacement, no movers)."""
    cats = [c.angles_and_sizes() for c in cuts.catalogues]
    return replace(cuts, catalogues=cats, cache={})


def skill(forecaster, cuts, alpha_c_train) -> dict:
    """Median |error| / the conditioned climatology's, and the 80 % coverage, on ``cuts``."""
    q, fb = forecaster.quantiles(cuts)
    qc, _ = conditioned_quantiles(alpha_c_train, cuts.tilt_now)
    truth = cuts.alpha_c
    err, err_c = np.abs(q[:, MEDIAN] - truth), np.abs(qc[:, MEDIAN] - truth)
    return {"median_abs_deg": float(np.degrees(np.median(err))),
            "vs_conditioned": float(np.median(err) / np.median(err_c)),
            "coverage": float(np.mean((q[:, LOWER] <= truth) & (truth <= q[:, UPPER]))),
            "before_avalanche": float(np.mean(q[:, MEDIAN] < truth)),
            "out_of_domain": float(np.mean(fb)), "n": int(truth.size)}


def degradation_curve(forecaster, test, alpha_c_train, seed) -> dict:
    """``skill`` at 3° for every degradation, the flags told the truth."""
    cuts, _ = cuts_at_leads(test, np.arange(len(test)), [math.radians(3.0)])
    cuts = blind(cuts)
    out = {}
    for label, (m, scale) in DEGRADATIONS.items():
        d = degrade_cuts(cuts, np.random.default_rng(seed), m, scale)
        out[label] = skill(forecaster, d, alpha_c_train)
    return out


def domain_rates(forecaster, test, outside: dict, seed) -> dict:
    """Share of random cuts flagged out of the domain: held-out rows, and each outside set."""
    out = {}
    for label, cset in {"held-out (in prior)": test, **outside}.items():
        cuts = blind(training_cuts(cset, 5, np.random.default_rng(seed)))
        inside, _ = forecaster.domain(cuts)
        late, _ = cuts_at_leads(cset, np.arange(len(cset)), [math.radians(3.0)])
        late = blind(late)
        inside_late, _ = forecaster.domain(late)
        told = replace(late, measurement=[Measurement(n_sliders=int(n)) for n in
                                          np.asarray(cset.parameters["n_sliders"])[late.row]])
        inside_told, _ = forecaster.domain(told)
        out[label] = {"flagged_random_cuts": float(np.mean(~inside)), "n_cuts": int(len(cuts)),
                      "flagged_3deg": float(np.mean(~inside_late)), "n_3deg": int(len(late)),
                      "flagged_3deg_told_n": float(np.mean(~inside_told)),
                      "skill_3deg": skill(forecaster, late, forecaster.climatology_.alpha_c_)}
    return out


def small_pile_example(forecaster, lead_deg: float = 0.5) -> dict:
    """The paper's 10-slider chain (``Scene(n_sliders=10, seed=1)``) forecast from its angles and
    sizes ``lead_deg`` before its avalanche, with what the model says of its accuracy there."""
    import sliders
    from sliders.analysis.forecast.evaluation import typical_accuracy
    from sliders.io.catalogue import Catalogue

    result = sliders.tilt(sliders.Scene(n_sliders=10, seed=1))
    full = Catalogue.from_result(result)
    cat = full.cut(result.alpha_c - math.radians(lead_deg))
    cat = cat.angles_and_sizes()
    f = forecaster.predict(cat)
    return {"alpha_c_deg": math.degrees(result.alpha_c), "lead_deg": lead_deg,
            "point_deg": math.degrees(f.point), "interval_deg": [math.degrees(a) for a in f.interval],
            "in_domain": not f.fallback, "events_seen": len(cat),
            "typical": typical_accuracy(forecaster, f)}


def kinds_of(cset) -> dict:
    """``KINDS`` as masks over the rows of ``cset``."""
    n = np.asarray(cset.parameters["n_sliders"], dtype=float)
    xi = np.asarray(cset.parameters["xi"], dtype=float)
    return {label: f(n, xi) for label, f in KINDS.items()}


def kind_table(per_kind: dict) -> list:
    """Markdown rows: coverage (cuts) and median |error| per kind of pile."""
    keys = ["random_cuts"] + [f"{d:g}deg" for d in KIND_LEADS_DEG]
    heads = ["random cuts"] + [f"{d:g}° before" for d in KIND_LEADS_DEG]
    lines = ["| kind of pile | " + " | ".join(f"coverage, {h}" for h in heads) + " | "
             + " | ".join(f"median abs err (deg), {h}" for h in heads[1:]) + " |",
             "|---|" + "---|" * (2 * len(keys) - 1)]
    for label, v in per_kind.items():
        lines.append(f"| {label} | " + " | ".join(f"{v[k]['coverage']:.2f} ({v[k]['n']})" for k in keys)
                     + " | " + " | ".join(f"{v[k]['median_abs_deg']:.2f}" for k in keys[1:]) + " |")
    return lines


def accuracy_lines(stored: dict) -> list:
    """Markdown rows: the accuracy a model stores per bin of its forecast's lead."""
    lines = ["| forecast lead (deg) | " + " | ".join(stored) + " |", "|---|" + "---|" * len(stored)]
    first = next(iter(stored.values()))
    edges = first["lead_edges_deg"]
    for k, lo in enumerate(edges):
        hi = f"{edges[k + 1]:g}" if k + 1 < len(edges) else ""
        cells = [f"{t['median_abs_deg'][k]:.2f}°, {t['coverage'][k]:.2f} ({int(t['n'][k])})"
                 for t in stored.values()]
        lines.append(f"| {lo:g}-{hi} | " + " | ".join(cells) + " |")
    return lines


def markdown(rep: dict) -> str:
    """The tables of docs/forecasting_results.md."""
    lines = ["| 3° before the avalanche | median abs err (deg) | / cond. clim. | 80 % coverage |"
             " point before avalanche | n |", "|---|---|---|---|---|---|"]
    for name, s in rep["skill_3deg"].items():
        lines.append(f"| {name} | {s['median_abs_deg']:.2f} | {s['vs_conditioned']:.2f} | "
                     f"{s['coverage']:.2f} | {s['before_avalanche']:.2f} | {s['n']} |")
    lines += ["", "| lead (deg) | " + " | ".join(rep["coverage"]["per_lead"]) + " |",
              "|---|" + "---|" * len(rep["coverage"]["per_lead"]),
              "| coverage | " + " | ".join(f"{v['coverage']:.2f}" for v in
                                           rep["coverage"]["per_lead"].values()) + " |"]
    lines += ["", "| bin | coverage | n |", "|---|---|---|",
              f"| all random cuts | {rep['coverage']['all_cuts']['coverage']:.2f} | "
              f"{rep['coverage']['all_cuts']['n']} |"]
    for kind in ("per_tilt_bin", "per_events_bin"):
        for b, v in rep["coverage"][kind].items():
            what = "tilt (rad)" if kind == "per_tilt_bin" else "events so far"
            lines.append(f"| {what} {b} | {v['coverage']:.2f} | {v['n']} |")
    for name, per_kind in rep.get("per_kind", {}).items():
        lines += ["", f"{name}:", ""] + kind_table(per_kind)
    if rep.get("expected_accuracy"):
        lines += ["", "stored in the model (median abs err, coverage (cuts)):", ""]
        lines += accuracy_lines(rep["expected_accuracy"])
    ex = rep.get("small_pile_example")
    if ex:
        lo, hi = ex["interval_deg"]
        lines += ["", f"Scene(n_sliders=10, seed=1), avalanche at {ex['alpha_c_deg']:.2f}°, "
                  f"{ex['lead_deg']:g}° before it ({ex['events_seen']} events): forecast "
                  f"{ex['point_deg']:.2f}° [{lo:.2f}-{hi:.2f}°], "
                  f"{'in' if ex['in_domain'] else 'out of'} the domain"]
    lines += ["", "| set | flagged (random cuts) | flagged (3° before) | 3° before, N told |"
              " 3° before: / cond. clim. | coverage |", "|---|---|---|---|---|---|"]
    for label, v in rep["domain"].items():
        lines.append(f"| {label} | {v['flagged_random_cuts']:.2f} ({v['n_cuts']}) | "
                     f"{v['flagged_3deg']:.2f} ({v['n_3deg']}) | {v['flagged_3deg_told_n']:.2f} | "
                     f"{v['skill_3deg']['vs_conditioned']:.2f} | {v['skill_3deg']['coverage']:.2f} |")
    lines += ["", "| measured as | / cond. clim. | coverage | flagged out of domain |",
              "|---|---|---|---|"]
    for label, v in rep["degradation"].items():
        lines.append(f"| {label} | {v['vs_conditioned']:.2f} | {v['coverage']:.2f} | "
                     f"{v['out_of_domain']:.2f} |")
    return "\n".join(lines) + "\n"


def write_report(rep: dict, out: str, stem: str, tables) -> str:
    """``rep`` as ``stem``.json and ``tables(rep)`` as ``stem``.md in ``out``; returns the tables."""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, f"{stem}.json"), "w") as fh:
        json.dump(rep, fh, indent=1)
    text = tables(rep)
    with open(os.path.join(out, f"{stem}.md"), "w") as fh:
        fh.write(text)
    return text


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True)
    p.add_argument("--outside", nargs="*", default=[], metavar="LABEL=FILE.h5")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    models, prov = load_forecasters(args.model)
    beside = os.path.dirname(os.path.abspath(args.model))
    data = CatalogueSet.joined([load_set(f if os.path.exists(f)
                                         else os.path.join(beside, os.path.basename(f)))
                                for f in prov["data_files"]])
    held = np.asarray(prov["held_out_rows"], dtype=int)
    held = held[np.isfinite(data.alpha_c[held])]
    test = data.subset(held)
    train_ac = models["learned_blind"].climatology_.alpha_c_
    outside = {}
    for spec in args.outside:
        label, _, path = spec.partition("=")
        outside[label] = load_set(path)
    lead3, _ = cuts_at_leads(test, np.arange(len(test)), [math.radians(3.0)])
    kinds = kinds_of(test)
    leads = np.radians(KIND_LEADS_DEG)
    rep = {"model": os.path.relpath(args.model) if not os.path.relpath(args.model).startswith("..")
           else os.path.basename(args.model), "rows_trained": prov["rows"],
           "rows_tested": int(len(test)),
           "skill_3deg": {"learned, angles + sizes": skill(models["learned_blind"], blind(lead3), train_ac),
                          "learned, + displacements, positions": skill(models["learned"], lead3, train_ac),
                          "model-based": skill(models["model_based"], lead3, train_ac)},
           "coverage": coverage_report(models["learned_blind"], test, np.arange(len(test)),
                                       np.radians(LEADS_DEG), degrade=blind, seed=args.seed),
           "coverage_all_inputs": coverage_report(models["learned"], test, np.arange(len(test)),
                                                  np.radians(LEADS_DEG), seed=args.seed),
           "per_kind": {
               "learned, angles + sizes": coverage_by_kind(models["learned_blind"], test, kinds,
                                                           leads, seed=args.seed, degrade=blind),
               "learned, + displacements, positions": coverage_by_kind(models["learned"], test, kinds,
                                                                       leads, seed=args.seed)},
           "expected_accuracy": {name: models[m].expected_accuracy_ for name, m in
                                 (("learned, angles + sizes", "learned_blind"),
                                  ("learned, + displacements, positions", "learned"))
                                 if getattr(models[m], "expected_accuracy_", None)},
           "small_pile_example": small_pile_example(models["learned_blind"]),
           "domain": domain_rates(models["learned_blind"], test, outside, args.seed),
           "degradation": degradation_curve(models["learned_blind"], test, train_ac, args.seed)}
    print(write_report(rep, args.out, "forecast_skill", markdown))
    from sliders.figures.forecast import draw_measured

    print(" ".join(draw_measured(rep, args.out)))


if __name__ == "__main__":
    main()
