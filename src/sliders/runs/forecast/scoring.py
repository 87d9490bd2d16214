"""``evaluate``'s scores: every forecaster on the test part (at leads and tilts), on the
robustness sets (at leads) and as an alarm, and the markdown tables of them."""

from __future__ import annotations

import math
import time

import numpy as np

from ...analysis.forecast import evaluation as ev
from ...analysis.forecast.base import LOWER, MEDIAN, UPPER
from ...analysis.forecast.registry import names_where
from ...forecasting.common import (ALARM_DELTA_DEG, ALARM_STEP_DEG, ALARM_WINDOW_DEG, TARGET_LEAD_DEG,
                     provenance)


def _fmt(triple, scale=1.0, nd=3):
    v, lo, hi = triple
    if not np.isfinite(v):
        return "—"
    return f"{v * scale:.{nd}f} [{lo * scale:.{nd}f}, {hi * scale:.{nd}f}]"


def format_table(scores: dict, labels: dict, group_names: list, group: int) -> str:
    """One markdown table: every forecaster's metrics on one group of cuts (one lead or tilt)."""
    head = ("| forecaster | median abs err (deg) | p90 abs err (deg) | safe | 80 % coverage | "
            "CRPS (deg) | skill vs clim. | / cond. clim. | / remaining | p90 / remaining | fallback |")
    lines = [f"**{group_names[group]}** (n = {next(iter(scores.values()))[group]['n']})", "",
             head, "|" + "---|" * 11]
    deg = 180.0 / math.pi
    for name, rows in scores.items():
        m = rows[group]
        lines.append(
            f"| {labels[name]} | {_fmt(m['median_abs'], deg, 2)} | {_fmt(m['p90_abs'], deg, 2)} | "
            f"{_fmt(m['safe'], 1, 2)} | {_fmt(m['coverage'], 1, 2)} | {_fmt(m['crps'], deg, 2)} | "
            f"{_fmt(m['skill'], 1, 2)} | {_fmt(m['vs_conditioned'], 1, 2)} | "
            f"{_fmt(m['vs_remaining'], 1, 2)} | {_fmt(m['p90_vs_remaining'], 1, 2)} | "
            f"{m['fallback']:.2f} |")
    return "\n".join(lines)


def format_compact(scores: dict, labels: dict, columns: list, metric: str, scale: float,
                   title: str, nd: int = 2) -> str:
    """One metric of every forecaster (rows) over the groups (columns: leads or tilts)."""
    lines = [f"**{title}**", "", "| forecaster | " + " | ".join(columns) + " |",
             "|---|" + "---|" * len(columns)]
    for name, rows in scores.items():
        vals = [m[metric][0] if isinstance(m[metric], tuple) else m[metric] for m in rows]
        lines.append(f"| {labels[name]} | " + " | ".join(
            "—" if not np.isfinite(v) else f"{v * scale:.{nd}f}" for v in vals) + " |")
    return "\n".join(lines)


def score_forecasters(args, argv, data, robust, split, forecasters, log) -> tuple[dict, str]:
    """The metrics of every forecaster on the test part (at leads and tilts) and on the robustness
    sets (at leads), and the alarm's; returns the results (forecast_metrics.json) and the table."""
    log(f"forecast: {len(data)} realisations ({len(split.train)} train, {len(split.validation)} "
        f"validation, {len(split.test)} test) + robustness {[(k, len(v)) for k, v in robust.items()]}")
    labels = {f.name: f.label for f in forecasters}
    sets = {"test": (data, split.test)} | {k: (v, np.arange(len(v))) for k, v in robust.items()}
    results = {"provenance": provenance(argv), "split": {k: v.size for k, v in vars(split).items()},
               "leads_deg": list(args.leads_deg), "tilts": list(args.tilts),
               "labels": labels, "sets": {}}
    tables = []
    for set_name, (cset, rows) in sets.items():
        tables += score_set(args, set_name, cset, rows, forecasters, labels, results, log)
    alarm_lines = score_alarm(args, data, split, forecasters, labels, results, log)
    pr = next((f for f in forecasters if f.name == "paper_rule"), None)
    if pr is not None and pr.c_quantiles_ is not None:
        results["paper_rule"] = {"c_median": pr.c_quantiles_[MEDIAN], "c_10": pr.c_quantiles_[LOWER],
                                 "c_90": pr.c_quantiles_[UPPER], "detected_share": pr.detected_share_}
    text = "\n\n".join(tables + [f"**alarm: the avalanche within {ALARM_DELTA_DEG:g}°** "
                                 f"(last {ALARM_WINDOW_DEG:g}° every {ALARM_STEP_DEG:g}°, "
                                 f"{results['alarm']['rows']} test realisations)", "\n".join(alarm_lines)])
    if "paper_rule" in results:
        c = results["paper_rule"]
        text += (f"\n\npaper's rule: alpha_c / alpha_t = {c['c_median']:.2f} "
                 f"(80 %: {c['c_10']:.2f}-{c['c_90']:.2f}), transition found in "
                 f"{100 * c['detected_share']:.0f} % of training runs")
    return results, text


def score_set(args, set_name, cset, rows, forecasters, labels, results, log) -> list[str]:
    """One set's scores at the leads (and, for the test part, the tilts) into ``results``;
    returns its tables."""
    leads = np.radians(np.asarray(args.leads_deg, dtype=float))
    tables = []
    for kind, (cuts, group, names) in {
            "lead": (*ev.cuts_at_leads(cset, rows, leads),
                     [f"{set_name}: {d:g}° before the avalanche" for d in args.leads_deg]),
            "tilt": (*ev.cuts_at_tilts(cset, rows, np.asarray(args.tilts, dtype=float)),
                     [f"{set_name}: at tilt {a:g} rad" for a in args.tilts])}.items():
        if set_name != "test" and kind == "tilt":
            continue
        preds = {}
        for f in forecasters:
            if any(getattr(cuts, n) is None for n in f.needs):
                continue
            t = time.time()
            preds[f.name] = f.quantiles(cuts, levels=True)
            log(f"forecast: {set_name}/{kind}: {f.name} on {len(cuts)} cuts in {time.time() - t:.1f} s")
        sc = ev.score(preds, cuts, group, len(names), n_boot=args.boot, seed=args.seed)
        results["sets"].setdefault(set_name, {})[kind] = {"groups": names, "scores": sc}
        tables += set_tables(args, set_name, kind, sc, labels, names)
    return tables


def set_tables(args, set_name, kind, sc, labels, names) -> list[str]:
    """The compact tables of one set and kind of cut, and the full ones asked for."""
    cols = ([f"{d:g}°" for d in args.leads_deg] if kind == "lead"
            else [f"{a:g} rad" for a in args.tilts])
    where = "before the avalanche" if kind == "lead" else "at the tilt"
    deg = 180.0 / math.pi
    tables = [format_compact(sc, labels, cols, "median_abs", deg,
                             f"{set_name}: median |error| (deg) {where}"),
              format_compact(sc, labels, cols, "coverage", 1.0,
                             f"{set_name}: coverage of the 80 % interval {where}")]
    if kind == "lead":
        tables.append(format_compact(sc, labels, cols, "vs_conditioned", 1.0,
                                     f"{set_name}: median |error| / that of the conditioned "
                                     f"climatology {where}"))
        tables.append(format_compact(sc, labels, cols, "skill", 1.0,
                                     f"{set_name}: CRPS skill against climatology {where}"))
    for g in range(len(names)):
        if args.all_tables or (kind == "lead" and args.leads_deg[g] == TARGET_LEAD_DEG):
            tables.append(format_table(sc, labels, names, g))
    return tables


def score_alarm(args, data, split, forecasters, labels, results, log) -> list[str]:
    """The alarm "the avalanche within ALARM_DELTA_DEG" on the test part into ``results``;
    returns its table's lines."""
    delta = math.radians(ALARM_DELTA_DEG)
    cuts, lead = ev.alarm_cuts(data, split.test[:args.alarm_rows], math.radians(ALARM_WINDOW_DEG),
                               math.radians(ALARM_STEP_DEG))
    alarm = {}
    thresholds = np.linspace(0.0, 1.0, 101)
    for f in forecasters:
        if f.name not in names_where("alarm") or any(getattr(cuts, n) is None for n in f.needs):
            continue
        t = time.time()
        q, _, levels = f.quantiles(cuts, levels=True)
        p = ev.alarm_probabilities(q, cuts, delta, levels)
        roc = ev.alarm_roc(p, lead, delta)
        seq = ev.alarm_sequences(p, lead, cuts.row, thresholds)
        rec = ev.recommended_threshold(seq)
        k = int(np.argmin(np.abs(thresholds - rec)))
        alarm[f.name] = {"auc": roc["auc"], "fpr": roc["fpr"], "tpr": roc["tpr"], "threshold": rec,
                         "safe": seq["safe"][k], "median_warning_deg": math.degrees(seq["median_warning"][k])
                         if np.isfinite(seq["median_warning"][k]) else None}
        log(f"forecast: alarm {f.name} on {len(cuts)} cuts in {time.time() - t:.1f} s")
    results["alarm"] = {"delta_deg": ALARM_DELTA_DEG, "window_deg": ALARM_WINDOW_DEG,
                        "step_deg": ALARM_STEP_DEG, "rows": int(np.unique(cuts.row).size), **alarm}
    lines = ["| forecaster | AUC | threshold | alarms before the avalanche | median warning (deg) |",
             "|---|---|---|---|---|"]
    for name, a in alarm.items():
        w = a["median_warning_deg"]
        lines.append(f"| {labels[name]} | {a['auc']:.3f} | {a['threshold']:.2f} | {a['safe']:.2f} | "
                     f"{'—' if w is None else f'{w:.2f}'} |")
    return lines


