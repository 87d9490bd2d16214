"""Figures of the forecasting evaluation (``python -m sliders.forecast evaluate``, docs/forecasting.md).

* ``forecast_error``: median absolute error of alpha_c against the lead before the
  avalanche, one line per forecaster (bootstrap 90 % band), the lead itself
  (the "now" forecast) for scale;
* ``forecast_coverage``: measured coverage of the nominal 80 % intervals against the lead;
* ``forecast_convergence``: one test realisation's forecasts as the tilt grows, the truth marked;
* ``forecast_roc``: ROC of the alarm "the avalanche within delta", with its AUC.

They read the evaluation's results (the dict written to forecast_metrics.json),
never the data.
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.forecast.base import LOWER, MEDIAN, UPPER
from ..analysis.forecast.registry import by_name
from .style import COLUMN_WIDTH, STYLE, panel_label, save_figure
import matplotlib.pyplot as plt  # noqa: E402  (after style chose the backend)


def _style(name):
    """(colour, line style) of a forecaster: its registry entry's (``Entry.colour``, ``.line``)."""
    e = by_name().get(name)
    return ("0.5", "-") if e is None else (e.colour, e.line)


def _legend_below(fig, ax, ncol):
    """The legend of ``ax`` under the figure's panels."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, frameon=False)


def _column(rows, metric, k=0):
    """One metric (value k = 0, or its 5 % / 95 % bounds k = 1, 2) over the groups, NaN for none."""
    return np.array([np.nan if r[metric][k] is None else r[metric][k] for r in rows], dtype=float)


def _lead_scores(results, set_name="test"):
    return results["sets"][set_name]["lead"]["scores"]


def figure_error(results, out_dir, name="forecast_error"):
    """Median absolute error (and its 90 % band) against the lead, one line per forecaster, log-log."""

    leads = np.asarray(results["leads_deg"], dtype=float)
    deg = 180.0 / math.pi
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(2 * COLUMN_WIDTH, 0.78 * COLUMN_WIDTH * 2 / 1.4),
                                 sharex=True)
        for ax, metric, title in ((axes[0], "median_abs", "median |error|"),
                                  (axes[1], "p90_abs", "90th percentile |error|")):
            for nm, rows in _lead_scores(results).items():
                if nm == "now":
                    continue
                c, ls = _style(nm)
                v, lo, hi = (_column(rows, metric, k) * deg for k in range(3))
                ax.plot(leads, v, ls, color=c, marker="o", ms=2, lw=1.0, label=results["labels"][nm])
                ax.fill_between(leads, lo, hi, color=c, alpha=0.15, lw=0)
            ax.plot(leads, leads, color="k", lw=0.8, ls=":", label="the lead (\"now\")")
            ax.plot(leads, 0.25 * leads if metric == "median_abs" else 0.5 * leads, color="r", lw=0.6,
                    ls=(0, (1, 2)), label="target: 0.25 × lead" if metric == "median_abs"
                    else "target: 0.5 × lead")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(r"lead $\alpha_c - \alpha_{obs}$ (deg)")
            ax.set_ylabel(f"{title} of $\\alpha_c$ (deg)")
            ax.axvline(3.0, color="0.8", lw=0.6, zorder=0)
        panel_label(axes[0], "(a)")
        panel_label(axes[1], "(b)")
        _legend_below(fig, axes[0], 3)
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def figure_coverage(results, out_dir, name="forecast_coverage"):
    """Measured coverage of the 80 % intervals against the lead (test set, and robustness sets)."""

    leads = np.asarray(results["leads_deg"], dtype=float)
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH * 1.5, COLUMN_WIDTH * 1.15))
        ax.axhspan(0.77, 0.83, color="0.9", lw=0, label="target 77-83 %")
        ax.axhline(0.8, color="0.5", lw=0.6)
        for nm, rows in _lead_scores(results).items():
            if nm in ("now", "last_plus_lead"):
                continue
            c, ls = _style(nm)
            ax.plot(leads, _column(rows, "coverage"), ls, color=c, marker="o", ms=2,
                    label=results["labels"][nm])
        for set_name in results["sets"]:
            if set_name == "test":
                continue
            rows = results["sets"][set_name]["lead"]["scores"].get("learned")
            if rows:
                ax.plot(leads, _column(rows, "coverage"), ":", color=_style("learned")[0], marker="s", ms=2.5, mfc="none",
                        label=f"learned, {set_name} preparation")
        ax.set_xscale("log")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel(r"lead before the avalanche (deg)")
        ax.set_ylabel("coverage of the nominal 80 % interval")
        _legend_below(fig, ax, 2)
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def figure_convergence(example, out_dir, name="forecast_convergence"):
    """One realisation: the forecasts (median, 80 % band) as the tilt grows; the truth and the events."""

    t = np.degrees(example["tilts"])
    a_c = math.degrees(example["alpha_c"])
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH * 1.5, COLUMN_WIDTH * 1.15))
        for nm, q in example["forecasts"].items():  # the registry's example entries
            q = np.degrees(q)
            c, ls = _style(nm)
            ax.plot(t, q[:, MEDIAN], ls, color=c, label=example["labels"][nm])
            if by_name()[nm].band:
                ax.fill_between(t, q[:, LOWER], q[:, UPPER], color=c, alpha=0.15, lw=0)
        ax.axhline(a_c, color="k", lw=1.2, label=r"truth $\alpha_c$")
        ax.plot(t, t, color="k", lw=0.6, ls=":", label=r"$\alpha_{obs}$ (now)")
        ev = np.degrees(example["events"])
        ax.plot(ev, np.full(ev.size, ax.get_ylim()[0]), "|", color="0.4", ms=3, mew=0.3)
        ax.set_xlabel(r"tilt reached, $\alpha_{obs}$ (deg)")
        ax.set_ylabel(r"forecast of $\alpha_c$ (deg)")
        ax.set_xlim(t[0], t[-1] + 0.5)
        ax.set_ylim(max(0.0, ax.get_ylim()[0]), min(ax.get_ylim()[1], a_c + 15))
        _legend_below(fig, ax, 2)
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def figure_roc(results, out_dir, name="forecast_roc"):
    """ROC of the alarm "the avalanche within delta", one curve per forecaster, AUC in the legend."""

    a = results["alarm"]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH * 1.5, COLUMN_WIDTH * 1.4))
        for nm, v in a.items():
            if not isinstance(v, dict) or "fpr" not in v:
                continue
            c, ls = _style(nm)
            ax.plot(v["fpr"], v["tpr"], ls, color=c,
                    label=f"{results['labels'][nm]} (AUC {v['auc']:.2f})")
        ax.plot([0, 1], [0, 1], color="0.7", lw=0.6, ls=":")
        ax.set_xlabel("false alarm rate")
        ax.set_ylabel("hit rate")
        ax.set_title(f"alarm: avalanche within {a['delta_deg']:g}° (last {a['window_deg']:g}°)")
        _legend_below(fig, ax, 2)
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def draw_all(results: dict, example: dict, out_dir) -> list[str]:
    """Every forecasting figure into ``out_dir``; returns the paths written."""
    paths = []
    paths += figure_error(results, out_dir)
    paths += figure_coverage(results, out_dir)
    paths += figure_convergence(example, out_dir)
    paths += figure_roc(results, out_dir)
    return paths


# ---------------------------------------------------------------------------
# the shipped forecaster measured on held-out rows (benchmarks/forecast_skill.py)
# ---------------------------------------------------------------------------
def figure_lead_coverage(report, out_dir, name="forecast_lead_coverage"):
    """Coverage of the 80 % interval against the lead (stress test), and the reliability diagram."""

    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(2 * COLUMN_WIDTH, 1.05 * COLUMN_WIDTH),
                                 layout="constrained")
        ax = axes[0]
        ax.axhspan(0.77, 0.83, color="0.85", label="target over all cuts (0.77-0.83)")
        ax.axhline(0.70, color="0.4", ls=":", lw=1, label="floor at every lead (0.70)")
        for key, label, (colour, _) in (("coverage", "angles + sizes", _style("learned_blind")),
                                        ("coverage_all_inputs", "+ displacements, positions",
                                         _style("learned"))):
            per = report[key]["per_lead"]
            leads = np.array([float(k) for k in per])
            ax.plot(leads, [v["coverage"] for v in per.values()], "o-", color=colour, label=label)
        ax.set_xscale("log")
        ax.set_xlabel("lead before the avalanche (deg)")
        ax.set_ylabel("coverage of the 80 % interval")
        ax.set_ylim(0, 1)
        ax.legend(loc="lower right", fontsize="small")
        panel_label(ax, "a")
        ax = axes[1]
        ax.plot([0, 1], [0, 1], color="0.5", ls="--", lw=1, label="perfect")
        rel = report["coverage"]["reliability"]["bins"]
        p = np.array([b["p_mean"] for b in rel])
        n = np.array([b["n"] for b in rel], dtype=float)
        # the spread a calibrated forecast's bin of n cuts would show (binomial)
        observed = np.array([b["observed"] for b in rel])
        se = np.sqrt(p * (1 - p) / n)
        bars = np.vstack([np.minimum(se, observed), np.minimum(se, 1 - observed)])  # within [0, 1]
        ax.errorbar(p, observed, yerr=bars, fmt="o-", capsize=3, color=_style("learned_blind")[0],
                    label="angles + sizes (bars: ±1 s.e. if calibrated)")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("forecast P(avalanche within 1°)")
        ax.set_ylabel("observed frequency")
        ax.legend(loc="lower right", fontsize="small")
        panel_label(ax, "b")
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def figure_degradation(report, out_dir, name="forecast_degradation"):
    """Skill at 3° (error over the conditioned climatology's) and coverage, per measurement."""

    labels = list(report["degradation"])
    ratio = [report["degradation"][k]["vs_conditioned"] for k in labels]
    cover = [report["degradation"][k]["coverage"] for k in labels]
    y = np.arange(len(labels))[::-1]
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(2 * COLUMN_WIDTH, 1.1 * COLUMN_WIDTH),
                                 sharey=True, layout="constrained")
        axes[0].barh(y, ratio, color=_style("learned_blind")[0])
        axes[0].axvline(0.4, color="0.3", ls=":", lw=1, label="target 0.4")
        axes[0].axvline(1.0, color="0.6", ls="--", lw=1, label="conditioned climatology")
        axes[0].set_yticks(y, labels)
        axes[0].set_xlabel("median |error| / conditioned climatology's")
        axes[0].legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize="small",
                       frameon=False)
        axes[1].barh(y, cover, color=_style("learned")[0])
        axes[1].axvline(0.75, color="0.3", ls=":", lw=1, label="target 0.75")
        axes[1].axvline(0.8, color="0.6", ls="--", lw=1, label="nominal 0.8")
        axes[1].set_xlim(0, 1)
        axes[1].set_xlabel("coverage of the 80 % interval")
        axes[1].legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize="small",
                       frameon=False)
        panel_label(axes[0], "a")
        panel_label(axes[1], "b")
        paths = save_figure(fig, out_dir, name, palette_png=True)
        plt.close(fig)
    return paths


def draw_measured(report, out_dir) -> list:
    """Both figures of the measured forecaster; returns the paths written."""
    return figure_lead_coverage(report, out_dir) + figure_degradation(report, out_dir)
