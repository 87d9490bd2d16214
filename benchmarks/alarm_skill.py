"""The alarm's skill, measured as a lab measures it: held-out piles followed to their avalanche.

    .venv/bin/python benchmarks/alarm_skill.py --model src/sliders/data/default_forecaster.zip \\
        --out benchmarks/results [--write-model FILE.zip]

Held-out piles of the model's training prior (named in its provenance, as
``forecast_skill.py`` reads them; ``--max-piles`` of them at random), each followed
from 10° before its avalanche to 0.1° before it at ``--step`` (0.1°), and 0.25° before
it; at each step the forecast's P(avalanche within the next 1°), for each kind of
catalogue:

* ``angles and sizes``: the angles and sizes only (``learned_blind``);
* ``camera's units``: displacements in a unit drawn over four decades, positions as
  fractions of the pile's length, an exact record, forecast as ``predict`` does
  (``forecast_conditions.CameraForecast``: in the model's units when its lone slips fix
  the unit, else ``learned_camera``);
* ``model's units``: displacements and movers as simulated (``learned``);
* ``angles and sizes, size told``: each pile told its number of sliders (``learned_sized``);
* and the angles and sizes measured as a lab measures them: angle noise 0.15°, 10 %
  of the events missed, events of one slider unseen (each told to the forecaster).

Per kind and threshold (0.3-0.9), ``analysis.forecast.alarm_skill``: the share of piles
whose alarm rose before the avalanche, the warning (median, 10th percentile), the false
alarms (first rose more than 3° before); the default threshold chosen
(``choose_threshold``: most hits with at most 10 % false alarms) and, at it, the same per
kind of pile (N < 50, 50-199, ≥ 200; ξ < 0.1, ≥ 0.1); the median |error| and the 80 %
coverage 3°, 1° and 0.25° before.  Writes alarm_skill.json and alarm_skill.md to ``--out``
and the figure alarm_skill.png; ``--write-model FILE`` writes the model with each learned
forecaster's default threshold and its measured skill stored (``alarm_threshold_``,
``alarm_skill_``), which ``predict`` and ``--follow`` read.
"""

from __future__ import annotations

import argparse
import math
import os

import numpy as np

from forecast_conditions import CameraForecast, camera_cuts, held_out, told
from forecast_skill import blind, write_report
from sliders.analysis.forecast import Measurement
from sliders.analysis.forecast.alarm_skill import (THRESHOLDS, alarm_table, choose_threshold,
                                                   first_alarms)
from sliders.analysis.forecast.base import LOWER, MEDIAN, UPPER, probability_within
from sliders.analysis.forecast.evaluation import cuts_at_leads
from sliders.analysis.forecast.measurement import degrade_cuts
from sliders.analysis.forecast.model_file import save_forecasters

#: the alarm's horizon, degrees
WITHIN_DEG = 1.0
#: the leads (degrees) at which the error and coverage are read
CHECK_LEADS_DEG = (3.0, 1.0, 0.25)
#: kinds of pile: label -> mask of (n_sliders, xi)
PILES = {"N < 50": lambda n, xi: n < 50, "N 50-199": lambda n, xi: (n >= 50) & (n < 200),
         "N ≥ 200": lambda n, xi: n >= 200, "ξ < 0.1": lambda n, xi: xi < 0.1,
         "ξ ≥ 0.1": lambda n, xi: xi >= 0.1}
#: the lab's records of angles and sizes: label -> measurement
MEASURED = {"angle noise 0.15°": Measurement(angle_resolution=math.radians(0.15)),
            "10 % missed": Measurement(missed_fraction=0.1),
            "min size 2": Measurement(min_size=2.0)}
#: which learned forecaster each kind's default threshold is stored in
STORED_IN = {"angles and sizes": "learned_blind", "camera's units": "learned_camera",
             "model's units": "learned", "angles and sizes, size told": "learned_sized"}


def forecast_with_levels(f, cuts):
    """(quantiles, their levels) of forecaster ``f`` (or a ``CameraForecast``) on ``cuts``."""
    if isinstance(f, CameraForecast):
        q, _, lv = f.camera.quantiles(cuts, levels=True)
        from sliders.analysis.forecast.features import cuts_in_model_units

        converted, which = cuts_in_model_units(cuts)
        if which.any():
            q[which], _, lv[which] = f.complete.quantiles(converted, levels=True)
        return q, lv
    q, _, lv = f.quantiles(cuts, levels=True)
    return q, lv


def judge(f, cuts, lead, test) -> dict:
    """The alarm table of one kind, its default, per kind of pile at it, and the skill at the
    check leads."""
    q, lv = forecast_with_levels(f, cuts)
    p = probability_within(q, cuts.tilt_now, math.radians(WITHIN_DEG), lv)
    first, piles = first_alarms(p, lead, cuts.row)
    table = alarm_table(first)
    chosen = choose_threshold(table)
    n = np.asarray(test.parameters["n_sliders"], dtype=float)[piles]
    xi = np.asarray(test.parameters["xi"], dtype=float)[piles]
    per_pile = {}
    if chosen is not None:
        k = int(np.flatnonzero(np.isclose(THRESHOLDS, chosen["threshold"]))[0])
        for label, of in PILES.items():
            mask = of(n, xi)
            per_pile[label] = alarm_table(first[k:k + 1, mask], THRESHOLDS[k:k + 1])[0]
    skill = {}
    for d in CHECK_LEADS_DEG:
        m = np.isclose(lead, math.radians(d))
        truth = cuts.alpha_c[m]
        skill[f"{d:g}"] = {
            "median_abs_deg": float(np.degrees(np.median(np.abs(q[m, MEDIAN] - truth)))),
            "coverage": float(np.mean((q[m, LOWER] <= truth) & (truth <= q[m, UPPER]))),
            "n": int(m.sum())}
    return {"table": table, "default": chosen, "per_pile": per_pile, "skill": skill}


def markdown(rep: dict) -> str:
    """The tables of docs/forecasting_results.md."""
    lines = ["| catalogue | default threshold | rose before the avalanche | warning, median (deg) "
             "| warning, 10th pct (deg) | false alarms (> 3° early) | error 3° / 1° / 0.25° before "
             "(deg) | coverage 3° / 1° / 0.25° |", "|---|---|---|---|---|---|---|---|"]
    for kind, r in rep["kinds"].items():
        d, s = r["default"], r["skill"]
        err = " / ".join(f"{s[k]['median_abs_deg']:.2f}" for k in s)
        cov = " / ".join(f"{s[k]['coverage']:.2f}" for k in s)
        if d is None:
            lines.append(f"| {kind} | none ≤ 10 % false alarms | | | | | {err} | {cov} |")
            continue
        lines.append(f"| {kind} | {d['threshold']:.2f} | {d['hit_share']:.2f} | "
                     f"{d['warning_median_deg']:.2f} | {d['warning_p10_deg']:.2f} | "
                     f"{d['false_alarm_share']:.2f} | {err} | {cov} |")
    lines += ["", "| catalogue | threshold | " + " | ".join(
        f"{t:.2f}" for t in THRESHOLDS) + " |", "|---|---|" + "---|" * THRESHOLDS.size]
    for kind, r in rep["kinds"].items():
        lines.append(f"| {kind} | rose before | " + " | ".join(
            f"{row['hit_share']:.2f}" for row in r["table"]) + " |")
        lines.append(f"| {kind} | false alarms | " + " | ".join(
            f"{row['false_alarm_share']:.2f}" for row in r["table"]) + " |")
    lines += ["", "| catalogue | kind of pile | piles | rose before | warning, median (deg) | "
                  "false alarms |", "|---|---|---|---|---|---|"]
    for kind, r in rep["kinds"].items():
        for label, row in r["per_pile"].items():
            lines.append(f"| {kind} | {label} | {row['piles']} | {row['hit_share']:.2f} | "
                         f"{row['warning_median_deg']:.2f} | {row['false_alarm_share']:.2f} |")
    return "\n".join(lines) + "\n"


def draw(rep: dict, out: str) -> str:
    """Rose-before and false-alarm shares against the threshold, one colour per kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sliders.figures.style import save_figure

    fig, (a, b) = plt.subplots(1, 2, figsize=(9.0, 3.6), sharex=True)
    for kind, r in rep["kinds"].items():
        t = [row["threshold"] for row in r["table"]]
        line, = a.plot(t, [row["hit_share"] for row in r["table"]], marker="o", ms=3, label=kind)
        b.plot(t, [row["false_alarm_share"] for row in r["table"]], marker="o", ms=3,
               color=line.get_color())
        if r["default"] is not None:
            d = r["default"]
            a.plot(d["threshold"], d["hit_share"], "*", ms=12, color=line.get_color())
            b.plot(d["threshold"], d["false_alarm_share"], "*", ms=12, color=line.get_color())
    b.axhline(0.10, color="0.5", ls=":", lw=1)
    b.text(0.9, 0.115, "10 % false alarms", color="0.4", fontsize=8, ha="right")
    a.set_ylabel("piles whose alarm rose before the avalanche")
    b.set_ylabel("false alarms (first rose > 3° early)")
    for ax in (a, b):
        ax.set_xlabel("alarm threshold, P(avalanche within the next 1°)")
        ax.set_ylim(-0.02, 1.02)
    b.legend(*a.get_legend_handles_labels(), fontsize=7, loc="upper right")  # off the data
    fig.suptitle(f"The alarm on {rep['piles']} held-out piles followed from 10° before their "
                 "avalanche (★: default)", fontsize=9)
    fig.tight_layout()
    paths = save_figure(fig, out, "alarm_skill", formats=("png",), palette_png=True)
    plt.close(fig)
    return " ".join(map(str, paths)) if isinstance(paths, (list, tuple)) else str(paths)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="src/sliders/data/default_forecaster.zip")
    p.add_argument("--out", default="benchmarks/results")
    p.add_argument("--figures", default="docs/figures")
    p.add_argument("--step", type=float, default=0.1, help="degrees between the steps")
    p.add_argument("--max-piles", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--write-model", default=None, metavar="FILE")
    args = p.parse_args()
    models, prov, data, held = held_out(args.model)
    rng = np.random.default_rng(args.seed)
    held = np.sort(rng.choice(held, min(args.max_piles, held.size), replace=False))
    test = data.subset(held)
    leads = np.radians(np.r_[np.arange(10.0, 0.05, -args.step), 0.25])
    cuts, g = cuts_at_leads(test, np.arange(len(test)), leads)
    lead = leads[g]
    angles_sizes = blind(cuts)
    kinds = {"angles and sizes": (models["learned_blind"], angles_sizes),
             "camera's units": (CameraForecast(models), camera_cuts(cuts, "units only", args.seed)),
             "model's units": (models["learned"], cuts)}
    if "learned_sized" in models:
        kinds["angles and sizes, size told"] = (models["learned_sized"],
                                                told(angles_sizes, "told exactly", args.seed))
    for label, m in MEASURED.items():
        kinds[f"angles and sizes, {label}"] = (
            models["learned_blind"], degrade_cuts(angles_sizes, np.random.default_rng(args.seed), m))
    rep = {"model": os.path.basename(args.model), "piles": int(len(test)),
           "step_deg": args.step, "within_deg": WITHIN_DEG, "kinds": {}}
    for kind, (f, c) in kinds.items():
        rep["kinds"][kind] = judge(f, c, lead, test)
        print(kind, rep["kinds"][kind]["default"], flush=True)
    print(write_report(rep, args.out, "alarm_skill", markdown))
    print(draw(rep, args.figures))
    if args.write_model:
        for kind, method in STORED_IN.items():
            d = rep["kinds"].get(kind, {}).get("default")
            if d is not None:
                models[method].alarm_threshold_ = d["threshold"]
                models[method].alarm_skill_ = {
                    "hit_share": d["hit_share"], "false_alarm_share": d["false_alarm_share"],
                    "warning_median_deg": d["warning_median_deg"],
                    "warning_p10_deg": d["warning_p10_deg"], "within_deg": WITHIN_DEG,
                    "piles": d["piles"]}
        save_forecasters(args.write_model, models, prov)
        print(f"wrote {args.write_model}")


if __name__ == "__main__":
    main()
