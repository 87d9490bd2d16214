"""The paper's ten figures, rebuilt from their captions (the images are missing).

One function per figure; each returns the matplotlib ``Figure`` and, unless
``out_dir`` is None, writes ``<name>.png`` (300 dpi) and ``<name>.pdf``
there.  Every figure is laid out for print, one column (3.4 in) wide with
fonts of 7-9 pt (``figure_style``).  ``PAPER_FIGURES`` names each one after
the figure of the paper it redraws; ``python -m sliders.figures --list``
prints that table:

====  ==============  ===========================  ==================================
Fig.  paper label     name                         function
====  ==============  ===========================  ==================================
1     fig:schema      ``fig01_sketch``             ``schematics.fig_sketch``
2     fig:small       ``fig02_scene_A``            ``fig_scene`` (N = 10, xi = 0)
3     fig:large_no    ``fig03_scene_B``            ``fig_scene`` (N = 400, xi = 0)
4     fig:large_wc    ``fig04_scene_C``            ``fig_scene`` (N = 400, xi = 0.001)
5     fig:schema_one  ``fig05_single_slider``      ``fig_single_slider``
6     fig:distrib1    ``fig06_force_pdf``          ``fig_force_pdf``
7     fig:distrib3    ``fig07_stopped_ratio``      ``fig_stopped_force_ratio``
8     fig:sch_d       ``fig08_histogram_model``    ``schematics.fig_histogram_model``
9     fig:distrib2    ``fig09_P_i``                ``fig_bin_heights``
10    fig:cumul       ``fig10_cumulated``          ``fig_cumulated_displacement``
====  ==============  ===========================  ==================================

The short names (``scene_A``, ``bin_heights`` ...) and the paper's labels
(``distrib2`` ...) are accepted by ``--only`` as well.  ``--animate`` writes
a GIF of a tilt instead (``animation.py``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .style import (COLUMN_WIDTH, DISPLACEMENT_CMAP, ORDER_CMAP, PNG_DPI,  # noqa: F401
                           STYLE, panel_label, save_figure)
import matplotlib.pyplot as plt  # noqa: E402  (after figure_style chose the backend)
from matplotlib import colors as mcolors  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.legend_handler import HandlerTuple  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402

from ..analysis import observables as ob  # noqa: E402
from ..analysis.summary import load_ensemble_summary  # noqa: E402,F401 - F.load_ensemble_summary
from ..io.storage import check_ensemble_file  # noqa: E402
from . import schematics  # noqa: E402
from .animation import animate_tilt, animation_scene  # noqa: E402
from .pushed_end import NAME as PUSHED_END, fig_pushed_end, pushed_end_run  # noqa: E402
from .study import check_study_file, draw_study  # noqa: E402
from ..analysis import model
from ..driver import run, tilt_realisations
from ..preparation import prepare
from ..scene import Scene


@dataclass(frozen=True)
class PaperFigure:
    """One figure of the paper: its number, its LaTeX label, what it shows, how it is made."""

    name: str
    number: int
    label: str
    shows: str
    kind: str  # "schematic" (from the model), "scene" (one run), "single", "statistics"
    aliases: tuple[str, ...] = ()


PAPER_FIGURES = (
    PaperFigure("fig01_sketch", 1, "fig:schema", "sketch of the system: sliders on the incline, "
                "springs of length l, cantilever springs to the upper plate", "schematic",
                ("sketch",)),
    PaperFigure("fig02_scene_A", 2, "fig:small", "scene A (N = 10, xi = 0): hot map of the "
                "displacements and F_t vs alpha", "scene", ("scene_A",)),
    PaperFigure("fig03_scene_B", 3, "fig:large_no", "scene B (N = 400, xi = 0): hot map and "
                "F_t vs alpha", "scene", ("scene_B",)),
    PaperFigure("fig04_scene_C", 4, "fig:large_wc", "scene C (N = 400, xi = 0.001): hot map and "
                "F_t vs alpha", "scene", ("scene_C",)),
    PaperFigure("fig05_single_slider", 5, "fig:schema_one", "F_t vs alpha of one slider between "
                "walls, with the model's rearrangement angles", "single", ("single_slider",)),
    PaperFigure("fig06_force_pdf", 6, "fig:distrib1", "PDF of F_t at several alpha (N = 100)",
                "statistics", ("force_pdf",)),
    PaperFigure("fig07_stopped_ratio", 7, "fig:distrib3", "PDF of F_t/F_t* of the sliders that "
                "moved, per alpha bin", "statistics", ("stopped_ratio",)),
    PaperFigure("fig08_histogram_model", 8, "fig:sch_d", "schematic bar histogram of the model: "
                "bins of 2 dmu, shift by one bin (red), return into bin 1 (blue)", "schematic",
                ("histogram_model",)),
    PaperFigure("fig09_P_i", 9, "fig:distrib2", "bin heights P_i(alpha) against the "
                "master-equation model and the crude model", "statistics",
                ("bin_heights", "P_i")),
    PaperFigure("fig10_cumulated", 10, "fig:cumul", "cumulated displacement A(alpha) and "
                "<dx> per rearrangement", "statistics", ("cumulated",)),
)
FIGURE_NAMES = tuple(f.name for f in PAPER_FIGURES)
STATISTICS_NAMES = tuple(f.name for f in PAPER_FIGURES if f.kind == "statistics")
SCENE_LETTERS = {"fig02_scene_A": "A", "fig03_scene_B": "B", "fig04_scene_C": "C"}


def figure_lookup() -> dict[str, str]:
    """Every accepted spelling -> the figure's name (names, short names, the paper's labels)."""
    out = {}
    for f in PAPER_FIGURES:
        for key in (f.name, f.label, f.label.split(":", 1)[1], f"fig{f.number}", *f.aliases):
            out[key.lower()] = f.name
    return out


def figure_list() -> str:
    """The table printed by ``--list``: name, figure of the paper, what it shows."""
    rows = [f"{f.name:<23} Fig. {f.number:<2} ({f.label}): {f.shows}" for f in PAPER_FIGURES]
    return "\n".join(rows)


# -----------------------------------------------------------------------------
# (a) scenes A, B, C
# -----------------------------------------------------------------------------


def hot_map_image(result, n_columns: int = 800, alpha_max: float | None = None,
                  event_width: float | None = None):
    """(N, n_columns) image of abs(displacement) per slider and angle pixel, and its extent.

    Each event paints a stripe of width ``event_width`` (in alpha) centred on
    its angle; where stripes overlap the larger displacement wins.  Auto
    width: 0.004 for N <= 20, else 2 pixels.
    """
    d = ob._need(result, "hot map").dense()
    n = result.scene.n_sliders
    a = np.asarray(result.alpha, dtype=float)
    if alpha_max is None:
        last = result.alpha_c if math.isfinite(result.alpha_c) else (a[-1] if a.size else 0.1)
        alpha_max = 1.03 * last
    pix = alpha_max / n_columns
    if event_width is None:
        event_width = 0.004 if n <= 20 else 2.0 * pix
    half = max(0, int(round(0.5 * event_width / pix)))
    img = np.zeros((n, n_columns))
    k_idx, s_idx = np.nonzero(d)
    vals = np.abs(d[k_idx, s_idx])
    cols = np.floor(a[k_idx] / pix).astype(int)
    for off in range(-half, half + 1):
        c = np.clip(cols + off, 0, n_columns - 1)
        np.maximum.at(img, (s_idx, c), vals)
    return img, (0.0, alpha_max, 0.5, n + 0.5)


def force_curves(result, n_grid: int = 200):
    """Per slider, the exact F_t(alpha) polyline from 0 to the last valid angle.

    Between events F_n = E_n + sin(alpha); at each event the force jumps.
    Returns (x, Y): x (M,) angles (event angles twice: before, after), Y (M, N).
    """
    a = np.asarray(result.alpha, dtype=float)
    after = ob.force_history(result)
    before = ob.force_before_events(result, after)
    limit, _ = ob.valid_limit(result)
    if not math.isfinite(limit):
        limit = a[-1] if a.size else 0.5
    grid = np.linspace(0.0, limit, n_grid)
    grid = grid[ob.valid_alphas(result, grid)]
    g_force = result.force_at(grid)
    x = np.concatenate([grid, a, a])
    k = np.arange(a.size, dtype=float)
    # at equal angles: before/after of each event in event order, then the grid
    # value (force_at gives the force after every event at that angle)
    order_key = np.concatenate([np.full(grid.size, np.inf), 2.0 * k, 2.0 * k + 1.0])
    y = np.vstack([g_force, before, after])
    key = np.lexsort((order_key, x))
    x, y = x[key], y[key]
    if math.isfinite(result.alpha_c) and result.status == "avalanche":
        # forces just before the avalanche, at alpha_c
        y_end = y[-1] + (math.sin(result.alpha_c) - math.sin(x[-1]))
        x = np.append(x, result.alpha_c)
        y = np.vstack([y, y_end[None, :]])
    return x, y


# a long chain's forces: the sliders drawn over the band start at these quantiles of F_t(0)
HIGHLIGHTED_QUANTILES = (0.1, 0.5, 0.9)
HIGHLIGHT_COLOURS = ("tab:blue", "tab:orange", "tab:green")


def _sliders_at_force_quantiles(start_force, quantiles) -> list[int]:
    """The sliders (0-based) whose force at alpha = 0 sits at these quantiles, low to high."""
    order = np.argsort(start_force, kind="stable")
    return [int(order[min(int(q * order.size), order.size - 1)]) for q in quantiles]


def _force_lines(fig, ax, x, y, cmap):
    """Every slider's F_t(alpha), coloured by its number, with a colour bar."""
    n = y.shape[1]
    lc = LineCollection([np.column_stack([x, y[:, j]]) for j in range(n)], cmap=cmap,
                        norm=mcolors.Normalize(vmin=1, vmax=max(n, 2)), linewidths=0.9)
    lc.set_array(np.arange(1, n + 1))
    ax.add_collection(lc)
    cb = fig.colorbar(lc, ax=ax, pad=0.02, fraction=0.06, aspect=15)
    cb.set_label("slider number $i$ [1]")


def _force_band(fig, ax, ax_map, x, y, highlighted):
    """The range of all sliders' F_t (grey), its middle 80 % (darker), a few sliders over it."""
    ax.fill_between(x, y.min(axis=1), y.max(axis=1), color="0.85", lw=0, rasterized=True,
                    label=f"all {y.shape[1]} sliders (range)")
    lo, hi = np.percentile(y, [10, 90], axis=1)
    ax.fill_between(x, lo, hi, color="0.6", lw=0, rasterized=True,
                    label="middle 80 % of the sliders")
    for colour, j in zip(HIGHLIGHT_COLOURS, highlighted):
        ax.plot(x, y[:, j], "-", color=colour, lw=0.8, label=f"slider {j + 1}")
        ax_map.plot(1.0, j + 1, marker="<", ms=4, color=colour, clip_on=False,
                    transform=ax_map.get_yaxis_transform())
    # the same room on the right as panel (a)'s colour bar, so that both share their width
    fig.colorbar(plt.cm.ScalarMappable(), ax=ax, pad=0.02, fraction=0.06, aspect=15).ax \
        .set_visible(False)


def _force_limits(ax, sc, alpha_end, alpha_c):
    """Stability, arrest and sin(alpha), and a legend entry for the avalanche angle."""
    aa = np.linspace(0.0, alpha_end, 300)
    ax.plot(aa, sc.mu_s_mean * np.cos(aa), "k--", lw=0.9,
            label=r"$\bar\mu_s\cos\alpha$ (stability)")
    ax.plot(aa, (2 * sc.mu_d - sc.mu_s_mean) * np.cos(aa), "k--", lw=0.9, dashes=(1.5, 1.5),
            label=r"$(2\mu_d-\bar\mu_s)\cos\alpha$ (arrest)")
    ax.plot(aa, np.sin(aa), "k-.", lw=0.9, label=r"$\sin\alpha$")
    if alpha_c is not None:
        ax.plot([], [], "-", color="0.35", lw=0.8, label=rf"$\alpha_c={alpha_c:.3f}$ rad (avalanche)")
    ax.set_xlim(0.0, alpha_end)


def fig_scene(result, name: str = "scene", label: str = "", out_dir="figures",
              n_columns: int | None = None, event_width: float | None = None,
              cmap_map: str = DISPLACEMENT_CMAP, cmap_sliders: str = ORDER_CMAP):
    """Hot map of displacements and F_t vs alpha for one run (paper Figs. small, large_no, large_wc).

    (a) abs(Delta x_i) of every slider (row) in every event, at the event angle,
    log colour scale, the darker the larger (a map whose lightness falls
    monotonically, so this holds in greyscale); dashed line at alpha_c.
    (b) F_t vs alpha with the limits mu_s cos(alpha) and (2 mu_d - mu_s)
    cos(alpha) (dashed) and sin(alpha) (dash-dotted): for N <= 20 every
    slider, coloured by its number; for more, the range of all sliders as a
    grey band (and the middle 80 % darker) with three sliders drawn over it,
    those starting at the ``HIGHLIGHTED_QUANTILES`` of F_t(0), marked on (a).
    """
    sc = result.scene
    n = sc.n_sliders
    with plt.rc_context(STYLE):
        big = n > 50
        fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(COLUMN_WIDTH, 5.6 if big else 4.9),
                                       sharex=True,
                                       gridspec_kw={"height_ratios": (1.2, 1) if big else (1, 1)})
        if n_columns is None:
            # about 3 printed pixels per column at 300 dpi: a 2-column stripe per event stays visible
            n_columns = 250 if big else 800
        img, extent = hot_map_image(result, n_columns=n_columns, event_width=event_width)
        positive = img[img > 0]
        # colour range: 2nd to 97th percentile of the painted values (the
        # last events before the avalanche are far larger; they saturate)
        vmax = float(np.percentile(positive, 97)) if positive.size else 1.0
        vmin = float(np.percentile(positive, 2)) if positive.size else 1e-3
        vmin = min(max(vmin, 1e-4 * vmax), 0.5 * vmax)
        base = plt.get_cmap(cmap_map)
        # the palest tenth of the map is left out: it would vanish on white paper
        cmap = mcolors.LinearSegmentedColormap.from_list(
            cmap_map + "_trunc", base(np.linspace(0.12, 1.0, 256))).with_extremes(bad="white")
        shown = np.where(img > 0, img, np.nan)
        im = ax0.imshow(shown, origin="lower", aspect="auto", extent=extent, cmap=cmap,
                        norm=mcolors.LogNorm(vmin=vmin, vmax=vmax), interpolation="nearest")
        im.set_rasterized(True)
        has_ac = math.isfinite(result.alpha_c)
        if has_ac:
            for ax in (ax0, ax1):
                ax.axvline(result.alpha_c, color="0.35", ls="-", lw=0.8)
            ax0.text(result.alpha_c, 1.01, r"$\alpha_c$", transform=ax0.get_xaxis_transform(),
                     va="bottom", ha="center", fontsize=8)
        ax0.set_ylabel(r"slider $i$ [1]")
        ax0.set_ylim(0.5, n + 0.5)
        if n <= 20:
            ax0.set_yticks(np.arange(1, n + 1, 1 if n <= 10 else 2))
        cb0 = fig.colorbar(im, ax=ax0, pad=0.02, fraction=0.06, aspect=15, extend="both")
        cb0.set_label(r"$|\Delta\tilde x_i|$ (darker: larger) [$g\tau^2$]")
        cb0.ax.yaxis.set_minor_formatter(NullFormatter())
        panel_label(ax0, "(a)")

        x, y = force_curves(result)
        if n <= 20:
            _force_lines(fig, ax1, x, y, cmap_sliders)
        else:
            _force_band(fig, ax1, ax0, x, y, _sliders_at_force_quantiles(y[0], HIGHLIGHTED_QUANTILES))
        _force_limits(ax1, sc, extent[1], result.alpha_c if has_ac else None)
        lo = min(float(np.nanmin(y)), -sc.mu_s_mean) - 0.05
        ax1.set_ylim(lo, max(float(np.nanmax(y)), sc.mu_s_mean) + 0.05)
        ax1.set_xlabel(r"$\alpha$ [rad]")
        ax1.set_ylabel(r"$\tilde F_t$ [$mg$]")
        # below the panel: the force curves fill the whole plane
        fig.legend(*ax1.get_legend_handles_labels(), loc="outside lower center", ncol=2,
                   frameon=False, columnspacing=1.0)
        panel_label(ax1, "(b)")
        title = (f"{'Scene ' + label + ': ' if label else ''}$N={n}$, $\\xi={sc.xi:g}$, "
                 f"seed {sc.seed}, {result.n_events} events")
        ax0.set_title(title, pad=9)
    save_figure(fig, out_dir, name)
    return fig


# -----------------------------------------------------------------------------
# (b) single slider between walls
# -----------------------------------------------------------------------------


def single_slider_scene(seed: int = 3, alpha_max: float = 0.6, mu_s: float = 0.6,
                        mu_d: float = 0.55, dt: float = 1e-3):
    """The paper's single slider (N = 1 between walls) tilted to ``alpha_max`` (radians), time step ``dt`` (tau)."""
    return Scene(n_sliders=1, ends="walls", sigma_mu=0.0, mu_s_mean=mu_s, mu_d=mu_d, seed=seed,
                 alpha_max=alpha_max, record="forces", dt=dt)


def _draw_sketch(ax) -> None:
    """Tiny schematic: one block between two walls, joined by springs, on a line."""
    ax.set_xlim(0, 10)
    ax.set_ylim(-1.3, 3.0)
    ax.axis("off")
    ax.plot([0.3, 9.7], [0, 0], "k-", lw=1)
    for x0 in (0.3, 9.1):
        ax.add_patch(plt.Rectangle((x0, 0), 0.6, 2.6, facecolor="0.75", edgecolor="k",
                                   hatch="////", lw=0.8))
    ax.add_patch(plt.Rectangle((4.1, 0), 1.8, 1.6, facecolor="tab:orange", edgecolor="k", lw=0.8))

    def spring(x0, x1, yy):
        xs = np.linspace(x0, x1, 14)
        ys = yy + 0.25 * np.array([0] + [(-1) ** k for k in range(12)] + [0])
        ax.plot(xs, ys, "k-", lw=0.8)

    spring(0.9, 4.1, 0.8)
    spring(5.9, 9.1, 0.8)
    ax.text(5.0, 0.8, r"$m$", ha="center", va="center", fontsize=8)
    ax.text(2.5, 1.35, r"$k$", ha="center", fontsize=8)
    ax.text(7.5, 1.35, r"$k$", ha="center", fontsize=8)
    ax.annotate("", xy=(6.4, -0.55), xytext=(3.6, -0.55),
                arrowprops=dict(arrowstyle="->", lw=0.8))
    ax.text(6.6, -0.55, r"$x$", ha="left", va="center", fontsize=7)


def single_slider_run(initial_force: float | None = 0.45, backend: str = "fortran",
                      seed: int = 3, alpha_max: float = 0.6):
    """Tilt one slider between walls (sigma_mu = 0) from a given force at alpha = 0.

    ``initial_force`` None keeps the random preparation of the scene; a value
    sets F_t(0) (the left wall spring at rest, the right one carrying it).
    """
    scene = single_slider_scene(seed=seed, alpha_max=alpha_max)
    state = prepare(scene)
    if initial_force is not None:
        f = float(initial_force)
        if abs(f) >= scene.mu_s_mean:
            raise ValueError(f"initial_force={f!r} must be stable, |f| < mu_s={scene.mu_s_mean}")
        state.elastic_force0[:] = f
        state.spring_extension0[:] = [0.0, f]
        state.lattice_position0[:] = 0.0
    return run(scene, backend=backend, state=state)


def fig_single_slider(result=None, backend: str = "fortran", out_dir="figures",
                      name: str = "single_slider", initial_force: float | None = 0.45,
                      seed: int = 3, alpha_max: float = 0.6, sketch: bool = True):
    """F_t vs alpha of one slider between walls (sigma_mu = 0), paper Fig. schema_one.

    Simulation (solid sawtooth) with the stability limit mu_s cos(alpha) and
    the arrest limit (2 mu_d - mu_s) cos(alpha) (dashed); the model's
    rearrangement angles (``model.single_slider_angles``) are marked on both
    limits (open circles: top of each drop, crosses: bottom).
    """
    if result is None:
        result = single_slider_run(initial_force, backend=backend, seed=seed, alpha_max=alpha_max)
    sc = result.scene
    mu_s = float(result.initial.mu_s[0])
    x, y = force_curves(result, n_grid=400)
    if result.status == "alpha_max":
        x = np.append(x, sc.alpha_max)
        y = np.vstack([y, y[-1] + (math.sin(sc.alpha_max) - math.sin(x[-2]))])
    pred = model.single_slider_angles(float(result.start_force()[0]), mu_s, sc.mu_d, sc.alpha_max)
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.9))
        aa = np.linspace(0.0, sc.alpha_max, 300)
        ax.plot(aa, mu_s * np.cos(aa), "k--", lw=0.9, label=r"$\mu_s\cos\alpha$ (stability)")
        ax.plot(aa, (2 * sc.mu_d - mu_s) * np.cos(aa), "k--", dashes=(1.5, 1.5), lw=0.9,
                label=r"$(2\mu_d-\mu_s)\cos\alpha$ (arrest)")
        ax.plot(x, y[:, 0], "-", color="tab:blue", lw=1.1, label="simulation")
        ax.plot(pred, mu_s * np.cos(pred), "o", mfc="none", mec="tab:red", ms=4, mew=0.8,
                label=f"model: start of a slip ({pred.size})")
        ax.plot(pred, (2 * sc.mu_d - mu_s) * np.cos(pred), "x", color="tab:red", ms=3.5, mew=0.8,
                label="model: end of a slip")
        ax.set_xlim(0, sc.alpha_max)
        # room below the sawtooth for the legend and the sketch
        lowest = min(float(np.min(y[x > 0.02 * sc.alpha_max, 0])) if x.size else 0.0,
                     (2 * sc.mu_d - mu_s) * math.cos(sc.alpha_max))
        ax.set_ylim(lowest - 0.2, max(float(np.max(y)), mu_s) + 0.01)
        ax.set_xlabel(r"$\alpha$ [rad]")
        ax.set_ylabel(r"$\tilde F_t$ [$mg$]")
        ax.legend(loc="lower left", frameon=True, framealpha=0.9, fontsize=7)
        sim = np.asarray(result.alpha)
        m = min(sim.size, pred.size)
        dev = float(np.max(np.abs(sim[:m] - pred[:m]))) if m else math.nan
        ax.set_title(f"one slider between walls, $\\mu_d={sc.mu_d:g}$, $\\mu_s={mu_s:g}$: "
                     f"{sim.size} slips,\nmax $|\\alpha_{{sim}}-\\alpha_{{model}}|$ = {dev:.1e} rad")
        if sketch:
            ins = ax.inset_axes([0.62, 0.02, 0.37, 0.25])
            _draw_sketch(ins)
    save_figure(fig, out_dir, name)
    return fig


# -----------------------------------------------------------------------------
# (c)-(f) statistics
# -----------------------------------------------------------------------------


def _alpha_colours(values, vmax, cmap="viridis"):
    norm = mcolors.Normalize(vmin=0.0, vmax=vmax)
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    return [sm.to_rgba(v) for v in values], sm


def _stats_title(summary, extra: str = "") -> str:
    g = summary.grids
    return (f"$N={summary.n_sliders}$, {summary.n_realisations} runs, $\\mu_d={g.mu_d:g}$, "
            f"$\\bar\\mu_s={g.mu_s_mean:g}$" + (f"\n{extra}" if extra else ""))


def _pick_alphas(summary, step: float = 0.05, min_fraction: float = 0.5):
    """Grid indices near 0, step, 2 step, ... where at least min_fraction of the runs are valid."""
    a = summary.alpha
    ok = summary.n_valid >= max(1, min_fraction * summary.n_realisations)
    out = []
    for t in np.arange(0.0, a[-1] + 1e-12, step):
        i = int(np.argmin(np.abs(a - t)))
        if ok[i] and i not in out:
            out.append(i)
    return out


def rebin_factor(n_bins: int, expected_per_bin: float, target: float = 40.0) -> int:
    """Smallest divisor f of n_bins with f * expected_per_bin >= target (n_bins at most)."""
    for f in range(1, n_bins + 1):
        if n_bins % f == 0 and f * expected_per_bin >= target:
            return f
    return n_bins


def fig_force_pdf(summary, out_dir="figures", name: str = "force_pdf", step: float = 0.05,
                  rebin: int | None = None, title_extra: str = ""):
    """PDFs of F_t at several alpha, coloured by alpha, inset F_t < 0.4 (paper Fig. distrib1).

    ``rebin``: merge that many histogram bins for display (default: enough
    for about 40 forces per bin on the initial plateau).
    """
    g = summary.grids
    idx = _pick_alphas(summary, step)
    edges = g.force_edges
    nb = edges.size - 1
    if rebin is None:
        width = float(np.mean(np.diff(edges)))
        per_bin = summary.n_realisations * summary.n_sliders * width / (2.0 * g.mu_s_mean)
        rebin = rebin_factor(nb, per_bin)
    if nb % rebin:
        raise ValueError(f"rebin={rebin} must divide the number of force bins {nb}")
    w = np.diff(edges)
    pdfs = summary.force_pdf * w[None, :]
    pdfs = pdfs.reshape(pdfs.shape[0], nb // rebin, rebin).sum(axis=2)
    edges = edges[::rebin]
    pdfs = pdfs / np.diff(edges)[None, :]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.7))
        cols, sm = _alpha_colours(summary.alpha[idx], max(summary.alpha[idx[-1]], 1e-9) if idx else 1)
        ins = ax.inset_axes([0.1, 0.42, 0.48, 0.5])
        for c, i in zip(cols, idx):
            pdf = pdfs[i]
            ax.stairs(pdf, edges, color=c, lw=0.9)
            ins.stairs(pdf, edges, color=c, lw=0.8)
        plateau = 1.0 / (2.0 * g.mu_s_mean)
        ax.axhline(plateau, color="0.4", lw=0.6, ls=":")
        ins.axhline(plateau, color="0.4", lw=0.6, ls=":")
        ax.set_xlabel(r"$\tilde F_t$ [$mg$]")
        ax.set_ylabel(r"PDF of $\tilde F_t$ [$1/mg$]")
        ax.set_xlim(edges[0], edges[-1])
        top = np.nanmax(pdfs[idx]) if idx else 1.0
        ax.set_ylim(0, 1.05 * top)
        ins.set_xlim(edges[0], 0.4)
        ins.set_ylim(0, 1.6 * plateau)
        ins.set_title(r"zoom: $\tilde F_t<0.4$", fontsize=7, pad=2)
        ins.tick_params(labelsize=7, length=2, pad=1.5)
        ax.plot([], [], color="0.4", lw=0.6, ls=":", label=r"$1/(2\bar\mu_s)$ (flat start)")
        ax.legend(loc="center", bbox_to_anchor=(0.36, 0.27), frameon=False)
        cb = fig.colorbar(sm, ax=ax, pad=0.015)
        cb.set_label(r"$\alpha$ [rad]")
        ax.set_title(_stats_title(summary, (title_extra + ", " if title_extra else "")
                                  + f"bins of {np.diff(edges)[0]:.3g} $mg$"))
    save_figure(fig, out_dir, name)
    return fig


def fig_stopped_force_ratio(summary, out_dir="figures", name: str = "stopped_ratio",
                            xlim=(0.8, 1.3), min_count: int = 20, rebin: int = 2,
                            title_extra: str = ""):
    """PDF of F_t/F_t* for the sliders that moved, per alpha bin (paper Fig. distrib3).

    F_t* = (2 mu_d - mu_s_mean) cos(alpha); guides at 1 (single slider
    between walls) and mu_d/(2 mu_d - mu_s_mean) (F_t = mu_d cos alpha).
    Angle bins with fewer than ``min_count`` stopped sliders are not drawn;
    ``rebin`` ratio bins are merged for display (0.01 wide by default).
    """
    g = summary.grids
    nr = g.ratio_edges.size - 1
    if nr % rebin:
        raise ValueError(f"rebin={rebin} must divide the number of ratio bins {nr}")
    redges = g.ratio_edges[::rebin]
    pdfs = (summary.stopped_ratio_pdf * np.diff(g.ratio_edges)[None, :])
    pdfs = pdfs.reshape(pdfs.shape[0], nr // rebin, rebin).sum(axis=2) / np.diff(redges)[None, :]
    rmid = 0.5 * (redges[1:] + redges[:-1])
    centers = g.stop_alpha_centers
    keep = [j for j in range(centers.size) if summary.stopped_counts[j] >= min_count]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.7))
        cols, sm = _alpha_colours(centers, g.stop_alpha_edges[-1])
        for j in keep:
            ax.plot(rmid, pdfs[j], "-", color=cols[j], lw=1.0)
        high = g.mu_d / (2 * g.mu_d - g.mu_s_mean)
        ax.axvline(1.0, color="k", ls="--", lw=0.9,
                   label="1: single slider")
        ax.axvline(high, color="k", ls=":", lw=0.9,
                   label=f"{high:.2f}: " r"$\tilde F_t=\mu_d\cos\alpha$")
        ax.legend(loc="upper left", frameon=True, framealpha=0.9)
        ax.set_xlim(*xlim)
        ymax = np.nanmax(pdfs[keep]) if keep else 1.0
        ax.set_ylim(0, 1.12 * ymax)
        ax.set_xlabel(r"$\tilde F_t/\tilde F_t^*$,  $\tilde F_t^*=(2\mu_d-\bar\mu_s)\cos\alpha$ [1]")
        ax.set_ylabel("PDF (sliders that moved) [1]")
        cb = fig.colorbar(sm, ax=ax, pad=0.015)
        cb.set_label(r"$\alpha$ (bins of %.2g) [rad]" % np.diff(g.stop_alpha_edges)[0])
        ax.set_title(_stats_title(summary, title_extra))
    save_figure(fig, out_dir, name)
    return fig


def fig_bin_heights(summary, out_dir="figures", name: str = "bin_heights",
                    bins: Sequence[int] | None = None, min_fraction: float = 0.5,
                    title_extra: str = ""):
    """Measured P_i(alpha) with the model (paper Fig. distrib2).

    Markers with standard-error bars: measured heights (counts / (N 2 dmu)),
    shown where at least ``min_fraction`` of the runs are still at rest.
    Solid: the closed form, the paper's Eq. (18) (``model.bin_heights``, nu(0)
    bins); dashed: the crude model, Eq. (19); vertical solid line: alpha_t by
    Stirling, Eq. (21); grey dash-dotted: the exact solution of Eq. (20).  Every
    line has a legend entry: one legend for the bins, one for the line styles.
    """
    g = summary.grids
    nu = g.n_model_bins
    if bins is None:
        bins = [1, 2, 3, 4, nu]
    ok = summary.n_valid >= max(1, min_fraction * summary.n_realisations)
    a = summary.alpha[ok]
    aa = np.linspace(0.0, summary.alpha[-1], 300)
    closed = model.bin_heights(aa, g.mu_s_mean, g.mu_d)
    crude_p1, plateau = model.crude_bin_heights(aa, g.mu_s_mean, g.mu_d)
    at_s = model.transition_angle_stirling(g.mu_s_mean)
    at_e = model.transition_angle_exact(g.mu_s_mean, g.mu_d)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 3.6))
        bin_handles = []
        for c, i in zip(colours, bins):
            ax.errorbar(a, summary.p_mean[ok, i - 1], yerr=summary.p_sem[ok, i - 1], fmt="o",
                        ms=2.5, color=c, capsize=1.2, lw=0.7, mew=0)
            ax.plot(aa, closed[:, i - 1], "-", color=c, lw=0.9)
            bin_handles.append((Line2D([], [], marker="o", ms=2.5, ls="none", color=c),
                                Line2D([], [], ls="-", lw=0.9, color=c)))
        ax.plot(aa, crude_p1, "--", color="0.25", lw=0.9)
        ax.axhline(plateau, color="0.25", ls="--", lw=0.9)
        ax.axvline(at_s, color="k", ls="-", lw=0.9)
        ax.axvline(at_e, color="0.45", ls="-.", lw=0.9)
        ax.set_xlabel(r"$\alpha$ [rad]")
        ax.set_ylabel(r"$P_i$ [$1/mg$]")
        ax.set_xlim(0, summary.alpha[-1])
        ax.set_ylim(0, None)
        first = ax.legend(bin_handles, [f"$P_{{{i}}}$" + (r" ($i=\nu$)" if i == nu else "")
                                        for i in bins],
                          loc="upper left", frameon=True, framealpha=0.9,
                          handler_map={tuple: HandlerTuple(ndivide=1)}, title="bin: data, model",
                          title_fontsize=7)
        ax.add_artist(first)
        style = [Line2D([], [], marker="o", ms=2.5, ls="none", color="0.3"),
                 Line2D([], [], ls="-", lw=0.9, color="0.3"),
                 Line2D([], [], ls="--", lw=0.9, color="0.25"),
                 Line2D([], [], ls="-", lw=0.9, color="k"),
                 Line2D([], [], ls="-.", lw=0.9, color="0.45")]
        ax.legend(style, ["simulation (mean $\\pm$ s.e.)", "master equation, Eq. (18)",
                          "crude model, Eq. (19):\n$P_1$ and plateau $P_{i\\neq1}$",
                          f"$\\alpha_t={at_s:.3f}$ rad, Eq. (21)\n(Stirling)",
                          f"$\\alpha_t={at_e:.3f}$ rad, exact\nsolution of Eq. (20)"],
                  loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False,
                  columnspacing=1.0)
        ax.set_title(_stats_title(summary, title_extra))
    save_figure(fig, out_dir, name)
    return fig


CUMUL_FIT = (0.1, 0.45)


def _exponential_fit_line(ax, x, y, fit_range):
    """Fit y = prefactor exp(rate x) on fit_range and draw it dashed (if the
    fit succeeded); returns the fit (observables.exponential_fit)."""
    fit = ob.exponential_fit(x, y, *fit_range)
    if math.isfinite(fit["rate"]):
        xx = np.linspace(*fit_range, 50)
        ax.plot(xx, fit["prefactor"] * np.exp(fit["rate"] * xx), "k--", lw=0.9,
                label=f"$\\propto e^{{k\\alpha}}$, $k={fit['rate']:.1f}\\pm{fit['rate_err']:.1f}$ "
                      r"rad$^{-1}$")
    return fit


def fig_cumulated_displacement(data, out_dir="figures", name: str = "cumulated",
                               fit_range=CUMUL_FIT, title_extra: str = ""):
    """(a) A(alpha) on a log scale, (b) <dx> per rearrangement vs alpha (paper Fig. cumul).

    ``data``: an ``EnsembleSummary`` or a list of ``Result`` (then (b)
    also shows every event as a grey dot).  Exponential fits on
    ``fit_range`` (dashed), rates in the legends.
    """
    results = None
    if isinstance(data, ob.EnsembleSummary):
        summary = data
    else:
        results = list(data)
        summary = ob.summary_from_results(results)
    a = summary.alpha
    ok = summary.n_valid >= max(1, 0.5 * summary.n_realisations)
    with plt.rc_context(STYLE):
        fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(COLUMN_WIDTH, 4.4), sharex=True)
        A = summary.cumulated_mean
        sel = ok & (A > 0)
        ax0.errorbar(a[sel], A[sel], yerr=summary.cumulated_sem[sel], fmt="o", ms=2.5,
                     capsize=1.2, lw=0.7, mew=0, color="tab:blue", label=r"$\langle A\rangle$ (mean $\pm$ s.e.)")
        fa = _exponential_fit_line(ax0, a[sel], A[sel], fit_range)
        ax0.set_yscale("log")
        ax0.set_ylabel(r"$A$ [$g\tau^2$]")
        ax0.legend(loc="lower right")
        panel_label(ax0, "(a)")

        if results is not None:
            ea = np.concatenate([np.asarray(r.alpha) for r in results])
            ed = np.concatenate([ob.mean_event_displacement(r) for r in results])
            pos = ed > 0
            ax1.plot(ea[pos], ed[pos], ".", color="0.65", ms=1.5, mew=0, label="single events",
                     rasterized=True)
        mid = summary.alpha_mid
        mdx = summary.event_mean_displacement
        fb = {"rate": math.nan}
        if mdx is not None:
            okm = np.isfinite(mdx) & (mdx > 0)
            ax1.plot(mid[okm], mdx[okm], "o", ms=2.5, mew=0, color="tab:red",
                     label=r"$\langle\Delta\tilde x\rangle$ (mean per $\alpha$ bin)")
            fb = _exponential_fit_line(ax1, mid[okm], mdx[okm], fit_range)
        ax1.set_yscale("log")
        ax1.set_xlabel(r"$\alpha$ [rad]")
        ax1.set_ylabel(r"$\langle\Delta\tilde x\rangle$ [$g\tau^2$]")
        ax1.legend(loc="upper left", bbox_to_anchor=(0.06, 1.0), frameon=True, framealpha=0.9)
        panel_label(ax1, "(b)")
        ax1.set_xlim(0, a[ok][-1] if ok.any() else a[-1])
        ax0.set_title(_stats_title(summary, title_extra))
    fig.fits = {"cumulated": fa, "event_displacement": fb}
    save_figure(fig, out_dir, name)
    return fig


# -----------------------------------------------------------------------------
# data: runs and ensemble files
# -----------------------------------------------------------------------------


def scene_setups(paper_size: bool = False, backend: str = "fortran") -> dict[str, dict]:
    """Scenes A, B, C of the paper (Sec. III).  Small chains unless paper-size or Fortran."""
    big = 400 if (paper_size or backend == "fortran") else 60
    return {
        "fig02_scene_A": dict(n_sliders=10, xi=0.0, seed=1, label="A"),
        "fig03_scene_B": dict(n_sliders=big, xi=0.0, seed=1, label="B"),
        "fig04_scene_C": dict(n_sliders=big, xi=0.001, seed=1, label="C"),
    }


def run_scene(n_sliders: int, xi: float, seed: int, backend: str = "fortran", **kw):
    """Tilt one scene of N sliders to the avalanche; ``kw`` are further Scene fields.  Returns the Result."""
    return run(Scene(n_sliders=n_sliders, xi=xi, seed=seed, record="displacements", **kw),
                backend=backend)


def run_ensemble(n_sliders: int = 100, runs: int = 20, base_seed: int = 0, xi: float = 0.0,
                 backend: str = "fortran", keep_results: bool = False, progress=None):
    """Serial ensemble: (summary, results or None).  Seeds keyed_random.realisation_seed(base, r)."""
    scene = Scene(n_sliders=n_sliders, xi=xi, seed=base_seed, record="displacements")
    grids = ob.default_grids(scene)
    rows, results = [], []
    for r, res in tilt_realisations(scene, runs, backend=backend):
        rows.append(ob.realisation_statistics(res, grids))
        if keep_results:
            results.append(res)
        if progress is not None:
            progress(r + 1, runs, res)
    summary = ob.combine(ob.stack_rows(rows), grids, n_sliders)
    return summary, (results if keep_results else None)


class FigureInputError(ValueError):
    """A name or option given to the figures command that cannot be used (one-line message)."""


# -----------------------------------------------------------------------------
# command line
# -----------------------------------------------------------------------------


GALLERY_DIR = os.path.join("docs", "figures")


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad option in one line (no usage block)."""

    def error(self, message):
        """Print one line and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m sliders.figures``."""
    p = _Parser(
        prog="python -m sliders.figures",
        description="Rebuild the paper's figures. Every figure is drawn for print: one column "
                    f"({COLUMN_WIDTH} in) wide, fonts of 7-9 pt, written as a vector PDF and a "
                    f"PNG at --dpi ({PNG_DPI}). --paper-size sets the paper's system sizes (scenes "
                    "B, C: N = 400; statistics: 20 runs of N = 100). --list names the figure of "
                    "the paper each one is.")
    p.add_argument("--out", default=None, metavar="DIR",
                   help=f"output directory (figures/; {GALLERY_DIR}/ with --gallery)")
    p.add_argument("--ensemble", metavar="FILE.h5",
                   help="statistics figures from this ensemble file (python -m sliders.ensemble); "
                        "scenes A, B, C are then drawn only if named in --only")
    p.add_argument("--study", metavar="FILE.h5",
                   help="the figures of a study file (python -m sliders.study) against its axes")
    p.add_argument("--paper-size", action="store_true", help="the paper's system sizes")
    p.add_argument("--backend", choices=("fortran", "numpy"), default="fortran",
                   help="tilt backend, one of {fortran, numpy} (default fortran)")
    p.add_argument("--only", nargs="+", metavar="NAME",
                   help="only these figures (see --list; short names such as bin_heights and the "
                        "paper's labels such as distrib2 work too)")
    p.add_argument("--list", action="store_true",
                   help="print which figure of the paper each name is, and exit")
    p.add_argument("--dpi", type=int, default=PNG_DPI, help=f"PNG resolution (default {PNG_DPI})")
    p.add_argument("--runs", type=int, default=None, help="realisations for the statistics "
                   "(default 20 with Fortran or --paper-size, 4 with numpy)")
    p.add_argument("--n-sliders", type=int, default=None, help="N for the statistics "
                   "(default 100 with Fortran or --paper-size, 30 with numpy)")
    p.add_argument("--seed", type=int, default=0, help="base seed of the statistics ensemble")
    p.add_argument("--animate", action="store_true",
                   help="write only a GIF of a tilt (scene A, or --scene): the forces against the "
                        "stability limits as alpha grows, events flashing")
    p.add_argument("--scene", metavar="FILE.toml", help="scene file for --animate (default: "
                   "scene A, N = 10)")
    p.add_argument("--gallery", action="store_true",
                   help=f"rebuild the gallery: the ten figures at --paper-size plus the animation, "
                        f"PNG only, into {GALLERY_DIR}/ (or --out)")
    return p


def resolve_names(requested: Sequence[str] | None, ensemble: bool) -> list[str]:
    """The figures to draw, in the paper's order.

    Default: all ten; with an ensemble file, all but the three scenes (each
    a fresh simulation) unless they are named.  Raises ``FigureInputError``
    listing the valid names on an unknown one.
    """
    if not requested:
        return [n for n in FIGURE_NAMES if not (ensemble and n in SCENE_LETTERS)]
    lookup = figure_lookup()
    lookup[PUSHED_END] = PUSHED_END  # beyond the paper: drawn only when named
    unknown = [r for r in requested if r.lower() not in lookup]
    if unknown:
        raise FigureInputError(f"unknown figure name(s) {', '.join(unknown)}; valid names: "
                               f"{', '.join(FIGURE_NAMES + (PUSHED_END,))} (see --list)")
    wanted = {lookup[r.lower()] for r in requested}
    return [n for n in FIGURE_NAMES + (PUSHED_END,) if n in wanted]


def _check_args(args) -> None:
    for opt in ("runs", "n_sliders"):
        v = getattr(args, opt)
        if v is not None and v < (1 if opt == "runs" else 2):
            raise FigureInputError(f"--{opt.replace('_', '-')} must be at least "
                                   f"{1 if opt == 'runs' else 2}, got {v}")
    if not 50 <= args.dpi <= 2400:
        raise FigureInputError(f"--dpi must lie in [50, 2400], got {args.dpi}")
    if args.scene and not args.animate:
        raise FigureInputError("--scene is for --animate (the figures use the paper's scenes)")


def _schematic(name):
    def draw(backend):
        return getattr(schematics, name)(out_dir=None)
    return draw


# The figures drawn from the model alone (no run of the chain, or one small fixed run),
# name -> function(backend) returning the Figure, and the statistics figures, name ->
# function(summary, results or None, title_extra).  The scenes are fig_scene of one run.
MODEL_FIGURES = {
    "fig01_sketch": _schematic("fig_sketch"),
    "fig08_histogram_model": _schematic("fig_histogram_model"),
    "fig05_single_slider": lambda backend: fig_single_slider(backend=backend, out_dir=None),
    PUSHED_END: lambda backend: fig_pushed_end(pushed_end_run(backend=backend), out_dir=None),
}
STATISTICS_FIGURES = {
    "fig06_force_pdf": lambda summary, results, extra: fig_force_pdf(
        summary, out_dir=None, title_extra=extra),
    "fig07_stopped_ratio": lambda summary, results, extra: fig_stopped_force_ratio(
        summary, out_dir=None, title_extra=extra),
    "fig09_P_i": lambda summary, results, extra: fig_bin_heights(
        summary, out_dir=None, title_extra=extra),
    "fig10_cumulated": lambda summary, results, extra: fig_cumulated_displacement(
        results if results else summary, out_dir=None, title_extra=extra),
}


def draw_figures(names, out, args, formats=("png", "pdf"), palette_png: bool = False) -> None:
    """Draw the named figures into ``out`` (progress on stdout)."""
    big = args.paper_size or args.backend == "fortran"
    runs = args.runs if args.runs is not None else (20 if big else 4)
    n_stats = args.n_sliders if args.n_sliders is not None else (100 if big else 30)

    def save(fig, name, t0, note=""):
        paths = save_figure(fig, out, name, formats=formats, dpi=args.dpi, palette_png=palette_png)
        plt.close(fig)
        print(f"{name}: {time.perf_counter() - t0:.1f} s{(' ' + note) if note else ''} -> "
              f"{', '.join(paths)}", flush=True)

    setups = scene_setups(args.paper_size, args.backend)
    for name in names:
        t0 = time.perf_counter()
        if name in MODEL_FIGURES:
            save(MODEL_FIGURES[name](args.backend), name, t0)
        elif name in setups:
            s = dict(setups[name])
            label = s.pop("label")
            res = run_scene(backend=args.backend, **s)
            save(fig_scene(res, name=name, label=label, out_dir=None), name, t0,
                 f"(N={s['n_sliders']}, xi={s['xi']:g}, {res.n_events} events, "
                 f"alpha_c={res.alpha_c:.4f})")

    stats = [n for n in names if n in STATISTICS_NAMES]
    if not stats:
        return
    t0 = time.perf_counter()
    results = None
    if args.ensemble:
        summary, _, _ = load_ensemble_summary(args.ensemble)
        extra = f"ensemble {os.path.basename(args.ensemble)}"
    else:
        def prog(i, total, res):
            print(f"  statistics run {i}/{total}: alpha_c={res.alpha_c:.4f}, "
                  f"{res.n_events} events", flush=True)

        summary, results = run_ensemble(n_stats, runs, base_seed=args.seed, backend=args.backend,
                                        keep_results=True, progress=prog)
        extra = ""
    print(f"statistics: {summary.n_realisations} runs of N={summary.n_sliders} "
          f"({time.perf_counter() - t0:.1f} s)", flush=True)
    for name in stats:
        t1 = time.perf_counter()
        save(STATISTICS_FIGURES[name](summary, results, extra), name, t1)


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders.figures`` with ``argv``; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.list:
        print(figure_list())
        return 0
    t_all = time.perf_counter()
    try:
        _check_args(args)
        if args.animate and not args.gallery:
            out = args.out or "figures"
            path = animate_tilt(animation_scene(args.scene), out_dir=out, backend=args.backend)
            print(f"animation -> {path} ({os.path.getsize(path) / 1e3:.0f} kB, "
                  f"{time.perf_counter() - t_all:.1f} s)", flush=True)
            return 0
        if args.study:
            check_study_file(args.study)
            for path in draw_study(args.study, args.out or "figures", dpi=args.dpi):
                print(path, flush=True)
            return 0
        if args.ensemble:
            check_ensemble_file(args.ensemble)
        names = resolve_names(args.only, bool(args.ensemble))
        if args.gallery:
            args.paper_size = True
            out = args.out or GALLERY_DIR
            draw_figures(names, out, args, formats=("png",), palette_png=True)
            path = animate_tilt(animation_scene(None), out_dir=out, backend=args.backend)
            print(f"animation -> {path} ({os.path.getsize(path) / 1e3:.0f} kB)", flush=True)
        else:
            draw_figures(names, args.out or "figures", args)
    except (FigureInputError, ValueError) as exc:
        # ValueError covers SceneError and the validation of the figure functions
        print(f"python -m sliders.figures: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. an output directory that cannot be written
        print(f"python -m sliders.figures: error: {exc}", file=sys.stderr)
        return 2
    print(f"all figures: {time.perf_counter() - t_all:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
