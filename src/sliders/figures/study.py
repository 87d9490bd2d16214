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
from ..analysis.study_analysis import load_study_file, paired_difference, point_summary

LABELS = {"n_sliders": "N", "xi": r"$\xi$", "mu_d": r"$\mu_d$", "mu_s_mean": r"$\bar\mu_s$",
          "sigma_mu": r"$\sigma_\mu$"}


def _axis_label(study) -> str:
    d = study.dims[0]
    if d == ["mu_d"] and "mu_s_mean" not in study.axes:
        return r"$\Delta\mu = \bar\mu_s - \mu_d$"
    return ", ".join(LABELS.get(n, n) for n in d)


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
    from matplotlib.ticker import NullFormatter, NullLocator

    ax.xaxis.set_minor_locator(NullLocator())  # one labelled tick per point, nothing between
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xticks(list(xs), [f"{x:g}" for x in xs])


def draw_study(path, out_dir, formats=("png", "pdf"), dpi: int = PNG_DPI,
               palette_png: bool = False, prefix: str | None = None) -> list[str]:
    """Draw every study figure of ``path`` into ``out_dir``; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    study, rows = load_study_file(path)
    table = [point_summary(study, p, r) for p, r in enumerate(rows)]
    prefix = prefix or "study_" + os.path.splitext(os.path.basename(os.fspath(path)))[0] \
        .removeprefix("study_")
    xlabel = _axis_label(study)
    series = _series(study)
    paths: list[str] = []

    def fig_ax(h=2.3):
        return plt.subplots(figsize=(COLUMN_WIDTH, h))

    def finish(fig, ax, name, xs):
        _xscale(ax, study, xs)
        ax.set_xlabel(xlabel)
        if len(ax.get_legend_handles_labels()[0]):
            ax.legend(frameon=False, fontsize=6, loc="best")
        paths.extend(save_figure(fig, out_dir, f"{prefix}_{name}", formats, dpi, palette_png))
        plt.close(fig)

    def col(pts, key):
        return np.array([table[p][key] for p in pts], dtype=float)

    with plt.rc_context(STYLE):
        # alpha_c, spread and bounds
        fig, ax = fig_ax()
        for i, (label, pts) in enumerate(series):
            x = np.array([_x(study, table, p) for p in pts])
            m, s, e = col(pts, "alpha_c_mean"), col(pts, "alpha_c_std"), col(pts, "alpha_c_sem")
            ax.fill_between(x, m - s, m + s, alpha=0.2, color=f"C{i}", lw=0)
            ax.errorbar(x, m, e, marker="o", color=f"C{i}",
                        label=(label + ": " if label else "") + r"$\alpha_c$ (mean, ±1 sd)")
            ax.plot(x, col(pts, "bound_low"), "--", color=f"C{i}", lw=0.7,
                    label=r"atan $\mu_d$" if i == 0 else None)
            ax.plot(x, col(pts, "bound_high"), "k:", lw=0.9,
                    label=r"atan $\bar\mu_s$" if i == 0 else None)
        ax.set_ylabel(r"avalanche angle $\alpha_c$")
        finish(fig, ax, "alpha_c", x)

        # event-size distribution, one line per point
        fig, ax = fig_ax(2.5)
        cmap = plt.get_cmap(ORDER_CMAP)
        for j, p in enumerate(range(len(table))):
            pdf = table[p]["event_size_pdf"]
            if pdf is None:
                continue
            s = np.arange(1, pdf.size + 1)
            keep = pdf > 0
            lab = ", ".join(f"{LABELS.get(k, k)}={v:g}" for k, v in study.points[p].items())
            ax.loglog(s[keep], pdf[keep], marker=".", lw=0.6, ms=2,
                      color=cmap(j / max(len(table) - 1, 1)), label=lab)
        ax.set_xlabel("event size s (sliders that moved)")
        ax.set_ylabel("fraction of events")
        ax.legend(frameon=False, fontsize=5.5, ncol=2)
        paths.extend(save_figure(fig, out_dir, f"{prefix}_event_sizes", formats, dpi, palette_png))
        plt.close(fig)

        # transition angle
        fig, ax = fig_ax()
        for i, (label, pts) in enumerate(series):
            x = np.array([_x(study, table, p) for p in pts])
            ax.plot(x, col(pts, "alpha_t_observed"), "o-", color=f"C{i}",
                    label=(label + ": " if label else "") + r"observed (P$_1$+P$_2$ rise)")
            ax.plot(x, col(pts, "alpha_t_stirling"), "--", color=f"C{i}", lw=0.8,
                    label=r"$2\bar\mu_s/(1+e)$" if i == 0 else None)
            ax.plot(x, col(pts, "alpha_t_p3"), ":", color=f"C{i}", lw=0.9,
                    label=r"exact, P$_3$ deficit 10 %" if i == 0 else None)
        ax.set_ylabel(r"transition angle $\alpha_t$")
        finish(fig, ax, "transition", x)

        # burst periods
        fig, ax = fig_ax()
        for i, (label, pts) in enumerate(series):
            x = np.array([_x(study, table, p) for p in pts])
            pre = (label + ": ") if label else ""
            ax.errorbar(x, col(pts, "early_period"), col(pts, "early_period_sem"), marker="o",
                        color=f"C{i}", label=pre + "early (single sliders)")
            ax.errorbar(x, col(pts, "late_period"), col(pts, "late_period_sem"), marker="s",
                        color=f"C{i}", mfc="white", ls="--", label=pre + r"late ($\geq$3 sliders)")
            # the predictions depend on the point (dmu, the angles of the early bursts)
            ax.plot(x, col(pts, "early_pred"), "-", color=f"C{i}", lw=0.6, alpha=0.6,
                    label=r"$2\Delta\mu/(1+\mu_s\tan\alpha)$" if i == 0 else None)
            ax.plot(x, col(pts, "late_pred"), ":", color=f"C{i}", lw=0.9,
                    label=r"$\Delta\mu$" if i == 0 else None)
        ax.set_ylabel(r"burst period $\Delta\alpha$")
        finish(fig, ax, "bursts", x)

        # synchronisation share
        fig, ax = fig_ax()
        for i, (label, pts) in enumerate(series):
            x = np.array([_x(study, table, p) for p in pts])
            ax.errorbar(x, col(pts, "sync_share"), col(pts, "sync_share_sem"), marker="o",
                        color=f"C{i}", label=(label + ": " if label else "") + "displacement share")
            ax.plot(x, col(pts, "sync_event_share"), "x:", color=f"C{i}",
                    label=(label + ": " if label else "") + "event share")
        ax.set_ylabel("multi-region (synchronised) share")
        finish(fig, ax, "sync", x)

        # paired differences of alpha_c to the first point of each series
        fig, ax = fig_ax()
        for i, (label, pts) in enumerate(series):
            x = np.array([_x(study, table, p) for p in pts])
            d = [paired_difference(rows[pts[0]], rows[p], "alpha_c") for p in pts]
            m = np.array([v["mean"] for v in d])
            ax.errorbar(x, m, [v["sem"] for v in d], marker="o", color=f"C{i}", capsize=2,
                        label=(label + ": " if label else "") + "paired s.e. (same seeds)")
            ax.errorbar(x * (1.0 if study.dims[0][0] != "n_sliders" else 1.04), m,
                        [v["sem_unpaired"] for v in d], fmt="none", color="0.6", lw=0.6,
                        capsize=1, label="unpaired s.e. (independent runs)" if i == 0 else None)
        ax.axhline(0, color="k", lw=0.5)
        first = _x(study, table, series[0][1][0])
        symbol = (r"$\Delta\mu$" if xlabel.startswith(r"$\Delta\mu") else
                  LABELS.get(study.dims[0][0], study.dims[0][0]))
        ax.set_ylabel(rf"$\alpha_c - \alpha_c$({symbol} = {first:g})")
        finish(fig, ax, "alpha_c_paired", x)
    return paths


def check_study_file(path) -> None:
    """One-line errors for a file that is not a readable study."""
    from ..io import formats

    p = os.fspath(path)
    probe = formats.probe_file(p)
    if probe.state == "missing":
        raise ValueError(f"--study {p!r} does not exist")
    if probe.state != "hdf5":
        raise ValueError(f"--study {p!r} is not a readable HDF5 file")
    if probe.format != formats.STUDY:
        raise ValueError(f"--study {p!r} is not a sliders study file (python -m sliders.study)")
