"""Figures of a study file against its axis (``python -m sliders.figures --study FILE.h5``).

One figure per quantity, at print size (``figure_style``): α_c with its bounds, the
event-size distribution, the transition angle against the model's two values, the burst
periods against their predictions, the synchronisation share, and the paired differences
of α_c to the first point (common random numbers) beside their unpaired error.  The x axis
is the study's first dimension; further dimensions give one line per value.
"""

from __future__ import annotations

import itertools
import os

import numpy as np

from .style import COLUMN_WIDTH, ORDER_CMAP, PNG_DPI, STYLE, save_figure
import matplotlib.pyplot as plt  # noqa: E402  (after style chose the backend)
from matplotlib.ticker import NullFormatter, NullLocator  # noqa: E402
from ..analysis.study_analysis import load_study_file, paired_difference, point_summary
from ..io import formats

LABELS = {"n_sliders": "N", "xi": r"$\xi$", "mu_d": r"$\mu_d$", "mu_s_mean": r"$\bar\mu_s$",
          "sigma_mu": r"$\sigma_\mu$"}
# every study axis is a dimensionless scene parameter (N a count, the others ratios of
# forces or stiffnesses)
UNITS = {"n_sliders": "sliders"}
LEGEND_PAIR_CHARS = 26  # labels up to this long fit two to a line at the column's width


def _axis_label(study) -> str:
    d = study.dims[0]
    if d == ["mu_d"] and "mu_s_mean" not in study.axes:
        return r"$\Delta\mu = \bar\mu_s - \mu_d$ [1]"
    return ", ".join(LABELS.get(n, n) for n in d) + f" [{UNITS.get(d[0], '1')}]"


def _x(study, table, p) -> float:
    """Abscissa of point p: its first-dimension value (Δμ for a mu_d axis)."""
    if study.dims[0] == ["mu_d"] and "mu_s_mean" not in study.axes:
        return table[p]["delta_mu"]
    return float(table[p][study.dims[0][0]])


def _series(study):
    """(label, [points in x order]) for each combination of the other dimensions."""
    shape = study.shape
    points = np.arange(int(np.prod(shape))).reshape(shape)
    out = []
    for idx in itertools.product(*(range(n) for n in shape[1:])):
        label = ", ".join(f"{LABELS.get(d[0], d[0])} = {study.axes[d[0]][i]:g}"
                          for d, i in zip(study.dims[1:], idx))
        out.append((label, list(points[(slice(None),) + idx])))
    return out


def _xscale(ax, study, xs) -> None:
    name = study.dims[0][0]
    positive = [x for x in xs if x > 0]
    if name == "n_sliders":
        ax.set_xscale("log")
        ax.set_xlim(min(xs) / 1.3, max(xs) * 1.3)
    elif name == "xi" and positive and max(positive) / min(positive) > 50:
        ax.set_xscale("symlog", linthresh=min(positive), linscale=0.5)
        ax.set_xlim(-0.4 * min(positive) if min(xs) <= 0 else min(positive) / 1.5,
                    max(xs) * 1.5)  # autoscaling pads in linear units: half the plot empty
    else:
        return

    ax.xaxis.set_minor_locator(NullLocator())  # one labelled tick per point, nothing between
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xticks(list(xs), [f"{x:g}" for x in xs])


class StudyPlot:
    """What every study figure reads: the study, its rows, the per-point table, the x axis."""

    def __init__(self, path):
        self.study, self.rows = load_study_file(path)
        self.table = [point_summary(self.study, p, r) for p, r in enumerate(self.rows)]
        self.xlabel = _axis_label(self.study)
        self.series = _series(self.study)

    def x(self, pts) -> np.ndarray:
        """Abscissae of the points ``pts``."""
        return np.array([_x(self.study, self.table, p) for p in pts])

    def col(self, pts, key) -> np.ndarray:
        """Column ``key`` of the per-point table at the points ``pts``."""
        return np.array([self.table[p][key] for p in pts], dtype=float)

    def finish(self, fig, ax, xs):
        """The study's axis below, its scale, and the legend if any line has a label."""
        _xscale(ax, self.study, xs)
        ax.set_xlabel(self.xlabel)
        handles, labels = ax.get_legend_handles_labels()
        if handles:  # below the axes, the data stay clear; long labels one per line
            fig.legend(handles, labels, loc="outside lower center", frameon=False, fontsize=7,
                       ncol=2 if max(len(t) for t in labels) <= LEGEND_PAIR_CHARS else 1,
                       columnspacing=1.0)
        return fig


def _fig_ax(h=2.8):

    return plt.subplots(figsize=(COLUMN_WIDTH, h))


def fig_alpha_c(sp: StudyPlot):
    """α_c (mean ± s.e.m., band of ±1 sd) against the axis, with atan μ_d and atan μ̄_s."""
    fig, ax = _fig_ax()
    for i, (label, pts) in enumerate(sp.series):
        x = sp.x(pts)
        m, s, e = (sp.col(pts, k) for k in ("alpha_c_mean", "alpha_c_std", "alpha_c_sem"))
        ax.fill_between(x, m - s, m + s, alpha=0.2, color=f"C{i}", lw=0)
        ax.errorbar(x, m, e, marker="o", color=f"C{i}",
                    label=(label + ": " if label else "") + r"$\alpha_c$ (mean, ±1 sd)")
        ax.plot(x, sp.col(pts, "bound_low"), "--", color=f"C{i}", lw=0.7,
                label=r"atan $\mu_d$" if i == 0 else None)
        ax.plot(x, sp.col(pts, "bound_high"), "k:", lw=0.9,
                label=r"atan $\bar\mu_s$" if i == 0 else None)
    ax.set_ylabel(r"avalanche angle $\alpha_c$ [rad]")
    return sp.finish(fig, ax, x)


def fig_event_sizes(sp: StudyPlot):
    """The distribution of event sizes, one line per point."""

    fig, ax = _fig_ax(3.2)
    cmap = plt.get_cmap(ORDER_CMAP)
    for p, row in enumerate(sp.table):
        pdf = row["event_size_pdf"]
        if pdf is None:
            continue
        s = np.arange(1, pdf.size + 1)
        keep = pdf > 0
        lab = ", ".join(f"{LABELS.get(k, k)}={v:g}" for k, v in sp.study.points[p].items())
        ax.loglog(s[keep], pdf[keep], marker=".", lw=0.6, ms=2,
                  color=cmap(p / max(len(sp.table) - 1, 1)), label=lab)
    ax.set_xlabel("event size $s$ [sliders that moved]")
    ax.set_ylabel("fraction of events [1]")
    fig.legend(loc="outside lower center", frameon=False, fontsize=7, ncol=2,
               columnspacing=1.0)
    return fig


def _measured_and_predicted(sp: StudyPlot, ax, measured, predicted):
    """Per series of points: the measured columns, labelled per series (error bars where a
    standard-error column is named), and the predicted columns, labelled once.

    ``measured``: (column, s.e.m. column or None, label, style); ``predicted``: (column,
    label, style); a style is a dict of matplotlib keywords.  Returns the last abscissae.
    """
    for i, (series_label, pts) in enumerate(sp.series):
        x = sp.x(pts)
        pre = (series_label + ": ") if series_label else ""
        for key, sem, label, style in measured:
            if sem is None:
                ax.plot(x, sp.col(pts, key), color=f"C{i}", label=pre + label, **style)
            else:
                ax.errorbar(x, sp.col(pts, key), sp.col(pts, sem), color=f"C{i}",
                            label=pre + label, **style)
        for key, label, style in predicted:
            ax.plot(x, sp.col(pts, key), color=f"C{i}", label=label if i == 0 else None, **style)
    return x


def fig_transition(sp: StudyPlot):
    """The observed transition angle against 2μ̄_s/(1 + e) and the exact-P₃ variant."""
    fig, ax = _fig_ax()
    x = _measured_and_predicted(
        sp, ax, [("alpha_t_observed", None, r"observed (P$_1$+P$_2$ rise)", dict(marker="o"))],
        [("alpha_t_stirling", r"$2\bar\mu_s/(1+e)$", dict(ls="--", lw=0.8)),
         ("alpha_t_p3", r"exact, P$_3$ deficit 10 %", dict(ls=":", lw=0.9))])
    ax.set_ylabel(r"transition angle $\alpha_t$ [rad]")
    return sp.finish(fig, ax, x)


def fig_bursts(sp: StudyPlot):
    """Early and late burst periods against their predictions (which depend on the point:
    Δμ, the angles of the early bursts)."""
    fig, ax = _fig_ax()
    x = _measured_and_predicted(
        sp, ax, [("early_period", "early_period_sem", "early (single sliders)",
                  dict(marker="o")),
                 ("late_period", "late_period_sem", r"late ($\geq$3 sliders)",
                  dict(marker="s", mfc="white", ls="--"))],
        [("early_pred", r"$2\Delta\mu/(1+\mu_s\tan\alpha)$", dict(lw=0.6, alpha=0.6)),
         ("late_pred", r"$\Delta\mu$", dict(ls=":", lw=0.9))])
    ax.set_ylabel(r"burst period $\Delta\alpha$ [rad]")
    return sp.finish(fig, ax, x)


def fig_sync(sp: StudyPlot):
    """The share of the displacement (and of the events) in events of separate groups."""
    fig, ax = _fig_ax()
    x = _measured_and_predicted(
        sp, ax, [("sync_share", "sync_share_sem", "displacement share", dict(marker="o")),
                 ("sync_event_share", None, "event share", dict(marker="x", ls=":"))], [])
    ax.set_ylabel("synchronised share [1]")
    return sp.finish(fig, ax, x)


def fig_alpha_c_paired(sp: StudyPlot):
    """α_c minus α_c at the first point, with the paired and the unpaired standard errors."""
    fig, ax = _fig_ax()
    for i, (label, pts) in enumerate(sp.series):
        x = sp.x(pts)
        d = [paired_difference(sp.rows[pts[0]], sp.rows[p], "alpha_c") for p in pts]
        m = np.array([v["mean"] for v in d])
        ax.errorbar(x, m, [v["sem"] for v in d], marker="o", color=f"C{i}", capsize=2,
                    label=(label + ": " if label else "") + "paired s.e. (same seeds)")
        ax.errorbar(x * (1.0 if sp.study.dims[0][0] != "n_sliders" else 1.04), m,
                    [v["sem_unpaired"] for v in d], fmt="none", color="0.6", lw=0.6,
                    capsize=1, label="unpaired s.e. (independent runs)" if i == 0 else None)
    ax.axhline(0, color="k", lw=0.5)
    first = _x(sp.study, sp.table, sp.series[0][1][0])
    symbol = (r"$\Delta\mu$" if sp.xlabel.startswith(r"$\Delta\mu") else
              LABELS.get(sp.study.dims[0][0], sp.study.dims[0][0]))
    ax.set_ylabel(rf"$\alpha_c - \alpha_c$({symbol} = {first:g}) [rad]")
    return sp.finish(fig, ax, x)


# name suffix of the file -> the function drawing it, in the order they are written
STUDY_FIGURES = {"alpha_c": fig_alpha_c, "event_sizes": fig_event_sizes,
                 "transition": fig_transition, "bursts": fig_bursts, "sync": fig_sync,
                 "alpha_c_paired": fig_alpha_c_paired}


def draw_study(path, out_dir, formats=("png", "pdf"), dpi: int = PNG_DPI,
               palette_png: bool = False, prefix: str | None = None) -> list[str]:
    """Draw every study figure of ``path`` into ``out_dir``; returns the files written."""
    sp = StudyPlot(path)
    prefix = prefix or "study_" + os.path.splitext(os.path.basename(os.fspath(path)))[0] \
        .removeprefix("study_")
    paths: list[str] = []
    with plt.rc_context(STYLE):
        for name, draw in STUDY_FIGURES.items():
            fig = draw(sp)
            paths.extend(save_figure(fig, out_dir, f"{prefix}_{name}", formats, dpi, palette_png))
            plt.close(fig)
    return paths


def check_study_file(path) -> None:
    """One-line errors for a file that is not a readable study."""
    p = os.fspath(path)
    probe = formats.probe_file(p)
    if probe.state == "missing":
        raise ValueError(f"--study {p!r} does not exist")
    if probe.state != "hdf5":
        raise ValueError(f"--study {p!r} is not a readable HDF5 file")
    if probe.format != formats.STUDY:
        raise ValueError(f"--study {p!r} is not a sliders study file (python -m sliders.study)")
