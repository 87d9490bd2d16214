"""The paper's figures, rebuilt from their captions (the images are missing).

One function per figure; each returns the matplotlib ``Figure`` and, unless
``out_dir`` is None, writes ``<name>.png`` and ``<name>.pdf`` there.

=============================  =============================================
function                       paper figure
=============================  =============================================
``fig_scene``                  Figs. small / large_no / large_wc (scenes A,
                               B, C): hot map of displacements and F_t vs
                               alpha per slider
``fig_single_slider``          Fig. schema_one: F_t vs alpha of one slider
                               between walls, with the model's drop points
``fig_force_pdf``              Fig. distrib1: PDF of F_t at several alpha
``fig_stopped_force_ratio``    Fig. distrib3: PDF of F_t/F_t* of stopped
                               sliders
``fig_bin_heights``            Fig. distrib2: P_i vs alpha, model and crude
                               model
``fig_cumulated_displacement`` Fig. cumul: A(alpha) and <dx>(alpha)
=============================  =============================================

Command line: ``python -m sliders.figures [--out DIR] [--ensemble FILE.h5]
[--paper-size] [--backend fortran|numpy] [--only NAME ...]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Sequence

import numpy as np

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import colors as mcolors  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from . import observables as ob  # noqa: E402

FIGURE_NAMES = ("scene_A", "scene_B", "scene_C", "single_slider", "force_pdf",
                "stopped_ratio", "bin_heights", "cumulated")

PARAM_TEXT = (r"$l={l:g}$, $\mu_d={mu_d:g}$, $\bar\mu_s={mu_s:g}$, $\sigma_\mu={sigma:g}$")

STYLE = {
    "font.size": 9,
    "axes.labelsize": 10,
    "axes.titlesize": 9,
    "legend.fontsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "savefig.dpi": 200,
    "figure.dpi": 100,
    "pdf.fonttype": 42,
}


def _params(scene) -> str:
    return PARAM_TEXT.format(l=scene.spring_length, mu_d=scene.mu_d, mu_s=scene.mu_s_mean,
                             sigma=scene.sigma_mu)


def save_figure(fig, out_dir, name: str) -> list[str]:
    """Write ``name``.png and ``name``.pdf in ``out_dir`` (created); returns the paths."""
    if out_dir is None:
        return []
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        p = os.path.join(os.fspath(out_dir), f"{name}.{ext}")
        fig.savefig(p, bbox_inches="tight")
        paths.append(p)
    return paths


# -----------------------------------------------------------------------------
# (a) scenes A, B, C
# -----------------------------------------------------------------------------


def hot_map_image(result, n_columns: int = 800, alpha_max: float | None = None,
                  event_width: float | None = None):
    """(N, n_columns) image of |displacement| per slider and angle pixel, and its extent.

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


def fig_scene(result, name: str = "scene", label: str = "", out_dir="figures",
              n_columns: int = 800, event_width: float | None = None,
              cmap_map: str = "hot_r", cmap_sliders: str = "turbo"):
    """Hot map of displacements and F_t vs alpha for one run (paper Figs. small, large_no, large_wc).

    (a) |Delta x_i| of every slider (row) in every event, at the event angle,
    log colour scale, darker = larger; vertical dashed line at alpha_c.
    (b) F_t of every slider vs alpha coloured by slider number, with the
    limits mu_s cos(alpha) and (2 mu_d - mu_s) cos(alpha) (dashed) and
    sin(alpha) (dash-dotted).
    """
    sc = result.scene
    n = sc.n_sliders
    with plt.rc_context(STYLE):
        big = n > 50
        fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(6.4, 8.4 if big else 7.2), sharex=True,
                                       gridspec_kw={"hspace": 0.08,
                                                    "height_ratios": (1.35, 1) if big else (1, 1)})
        img, extent = hot_map_image(result, n_columns=n_columns, event_width=event_width)
        positive = img[img > 0]
        # colour range: 2nd to 97th percentile of the painted values (the
        # last events before the avalanche are far larger; they saturate)
        vmax = float(np.percentile(positive, 97)) if positive.size else 1.0
        vmin = float(np.percentile(positive, 2)) if positive.size else 1e-3
        vmin = min(max(vmin, 1e-4 * vmax), 0.5 * vmax)
        base = plt.get_cmap(cmap_map)
        cmap = mcolors.LinearSegmentedColormap.from_list(
            cmap_map + "_trunc", base(np.linspace(0.25, 1.0, 256))).with_extremes(bad="white")
        shown = np.where(img > 0, img, np.nan)
        im = ax0.imshow(shown, origin="lower", aspect="auto", extent=extent, cmap=cmap,
                        norm=mcolors.LogNorm(vmin=vmin, vmax=vmax), interpolation="nearest")
        im.set_rasterized(True)
        if math.isfinite(result.alpha_c):
            ax0.axvline(result.alpha_c, color="k", ls="--", lw=1.0)
            ax1.axvline(result.alpha_c, color="k", ls="--", lw=1.0)
            ax0.text(result.alpha_c, 1.005, r"$\alpha_c$", transform=ax0.get_xaxis_transform(),
                     va="bottom", ha="center", fontsize=9)
        ax0.set_ylabel(r"slider $i$")
        ax0.set_ylim(0.5, n + 0.5)
        if n <= 20:
            ax0.set_yticks(np.arange(1, n + 1))
        cb0 = fig.colorbar(im, ax=ax0, pad=0.015, fraction=0.05, extend="both")
        cb0.set_label(r"$|\Delta\tilde x_i|$")
        ax0.text(0.01, 0.97, "(a)", transform=ax0.transAxes, va="top", fontweight="bold")

        x, y = force_curves(result)
        segs = [np.column_stack([x, y[:, j]]) for j in range(n)]
        norm = mcolors.Normalize(vmin=1, vmax=max(n, 2))
        lc = LineCollection(segs, cmap=cmap_sliders, norm=norm,
                            linewidths=1.0 if n <= 20 else 0.35, alpha=1.0 if n <= 20 else 0.8)
        lc.set_array(np.arange(1, n + 1))
        lc.set_rasterized(n > 20)
        ax1.add_collection(lc)
        aa = np.linspace(0.0, extent[1], 300)
        ax1.plot(aa, sc.mu_s_mean * np.cos(aa), "k--", lw=1.0, label=r"$\bar\mu_s\cos\alpha$")
        ax1.plot(aa, (2 * sc.mu_d - sc.mu_s_mean) * np.cos(aa), "k--", lw=1.0, dashes=(2, 2),
                 label=r"$(2\mu_d-\bar\mu_s)\cos\alpha$")
        ax1.plot(aa, np.sin(aa), "k-.", lw=1.0, label=r"$\sin\alpha$")
        ax1.set_xlim(0.0, extent[1])
        lo = min(float(np.nanmin(y)), -sc.mu_s_mean) - 0.05
        ax1.set_ylim(lo, max(float(np.nanmax(y)), sc.mu_s_mean) + 0.05)
        ax1.set_xlabel(r"$\alpha$")
        ax1.set_ylabel(r"$\tilde F_t$")
        ax1.legend(loc="lower center", frameon=True, framealpha=0.9)
        cb1 = fig.colorbar(lc, ax=ax1, pad=0.015, fraction=0.05)
        cb1.set_label("slider number")
        ax1.text(0.01, 0.97, "(b)", transform=ax1.transAxes, va="top", fontweight="bold")
        ac = f"{result.alpha_c:.3f}" if math.isfinite(result.alpha_c) else "n/a"
        title = (f"{label + ': ' if label else ''}$N={n}$, $\\xi={sc.xi:g}$, " + _params(sc)
                 + f", seed {sc.seed}; {result.n_events} events, $\\alpha_c={ac}$")
        ax0.set_title(title, pad=14)
    save_figure(fig, out_dir, name)
    return fig


# -----------------------------------------------------------------------------
# (b) single slider between walls
# -----------------------------------------------------------------------------


def single_slider_scene(seed: int = 3, alpha_max: float = 0.6, mu_s: float = 0.6,
                        mu_d: float = 0.55, dt: float = 1e-3):
    from .scene import Scene

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
    from .driver import tilt
    from .preparation import prepare

    scene = single_slider_scene(seed=seed, alpha_max=alpha_max)
    state = prepare(scene)
    if initial_force is not None:
        f = float(initial_force)
        if abs(f) >= scene.mu_s_mean:
            raise ValueError(f"initial_force={f!r} must be stable, |f| < mu_s={scene.mu_s_mean}")
        state.elastic_force0[:] = f
        state.spring_extension0[:] = [0.0, f]
        state.lattice_position0[:] = 0.0
    return tilt(scene, backend=backend, state=state)


def fig_single_slider(result=None, backend: str = "fortran", out_dir="figures",
                      name: str = "single_slider", initial_force: float | None = 0.45,
                      seed: int = 3, alpha_max: float = 0.6, sketch: bool = True):
    """F_t vs alpha of one slider between walls (sigma_mu = 0), paper Fig. schema_one.

    Simulation (solid sawtooth) with the stability limit mu_s cos(alpha) and
    the arrest limit (2 mu_d - mu_s) cos(alpha) (dashed); the model's
    rearrangement angles (``model.single_slider_angles``) are marked on both
    limits (open circles: top of each drop, crosses: bottom).
    """
    from . import model

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
        fig, ax = plt.subplots(figsize=(5.2, 3.8))
        aa = np.linspace(0.0, sc.alpha_max, 300)
        ax.plot(aa, mu_s * np.cos(aa), "k--", lw=1.0, label=r"$\mu_s\cos\alpha$ (stability)")
        ax.plot(aa, (2 * sc.mu_d - mu_s) * np.cos(aa), "k--", dashes=(2, 2), lw=1.0,
                label=r"$(2\mu_d-\mu_s)\cos\alpha$ (arrest)")
        ax.plot(x, y[:, 0], "-", color="tab:blue", lw=1.3, label="simulation")
        ax.plot(pred, mu_s * np.cos(pred), "o", mfc="none", mec="tab:red", ms=5,
                label=f"model $\\alpha^{{(i)}}$ ({pred.size})")
        ax.plot(pred, (2 * sc.mu_d - mu_s) * np.cos(pred), "x", color="tab:red", ms=4)
        ax.set_xlim(0, sc.alpha_max)
        # room below the sawtooth for the legend and the sketch
        lowest = min(float(np.min(y[x > 0.02 * sc.alpha_max, 0])) if x.size else 0.0,
                     (2 * sc.mu_d - mu_s) * math.cos(sc.alpha_max))
        ax.set_ylim(lowest - 0.13, max(float(np.max(y)), mu_s) + 0.01)
        ax.set_xlabel(r"$\alpha$")
        ax.set_ylabel(r"$\tilde F_t$")
        ax.legend(loc="lower left", frameon=True, framealpha=0.9)
        sim = np.asarray(result.alpha)
        m = min(sim.size, pred.size)
        dev = float(np.max(np.abs(sim[:m] - pred[:m]))) if m else math.nan
        ax.set_title(f"one slider between walls, $\\mu_d={sc.mu_d:g}$, $\\mu_s={mu_s:g}$, "
                     f"$\\sigma_\\mu=0$: {sim.size} events, max $|\\alpha_{{sim}}-\\alpha_{{model}}|"
                     f"={dev:.1e}$")
        if sketch:
            ins = ax.inset_axes([0.6, 0.02, 0.38, 0.24])
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
            f"$\\bar\\mu_s={g.mu_s_mean:g}$" + (f", {extra}" if extra else ""))


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
        fig, ax = plt.subplots(figsize=(5.6, 4.0))
        cols, sm = _alpha_colours(summary.alpha[idx], max(summary.alpha[idx[-1]], 1e-9) if idx else 1)
        ins = ax.inset_axes([0.08, 0.45, 0.45, 0.45])
        for c, i in zip(cols, idx):
            pdf = pdfs[i]
            ax.stairs(pdf, edges, color=c, lw=1.0)
            ins.stairs(pdf, edges, color=c, lw=0.9)
        plateau = 1.0 / (2.0 * g.mu_s_mean)
        ax.axhline(plateau, color="0.4", lw=0.6, ls=":")
        ins.axhline(plateau, color="0.4", lw=0.6, ls=":")
        ax.set_xlabel(r"$\tilde F_t$")
        ax.set_ylabel(r"PDF of $\tilde F_t$")
        ax.set_xlim(edges[0], edges[-1])
        top = np.nanmax(pdfs[idx]) if idx else 1.0
        ax.set_ylim(0, 1.05 * top)
        ins.set_xlim(edges[0], 0.4)
        ins.set_ylim(0, 1.6 * plateau)
        ins.set_title(r"$\tilde F_t<0.4$", fontsize=7, pad=2)
        ins.tick_params(labelsize=6)
        ins.text(0.98, 0.9, r"$1/(2\bar\mu_s)$", transform=ins.transAxes, ha="right", fontsize=6,
                 color="0.3")
        cb = fig.colorbar(sm, ax=ax, pad=0.015)
        cb.set_label(r"$\alpha$")
        ax.set_title(_stats_title(summary, (title_extra + "; " if title_extra else "")
                                  + f"bins of {np.diff(edges)[0]:.3g}"))
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
        fig, ax = plt.subplots(figsize=(5.6, 4.0))
        cols, sm = _alpha_colours(centers, g.stop_alpha_edges[-1])
        for j in keep:
            ax.plot(rmid, pdfs[j], "-", color=cols[j], lw=1.1)
        high = g.mu_d / (2 * g.mu_d - g.mu_s_mean)
        ax.axvline(1.0, color="k", ls="--", lw=0.9,
                   label=r"1: $\tilde F_t=(2\mu_d-\bar\mu_s)\cos\alpha$ (single slider)")
        ax.axvline(high, color="k", ls=":", lw=0.9,
                   label=f"$\\mu_d/(2\\mu_d-\\bar\\mu_s)={high:.2f}$: "
                         r"$\tilde F_t=\mu_d\cos\alpha$")
        ax.legend(loc="upper left", fontsize=7, frameon=True, framealpha=0.9)
        ax.set_xlim(*xlim)
        ymax = np.nanmax(pdfs[keep]) if keep else 1.0
        ax.set_ylim(0, 1.12 * ymax)
        ax.set_xlabel(r"$\tilde F_t/\tilde F_t^*$,  $\tilde F_t^*=(2\mu_d-\bar\mu_s)\cos\alpha$")
        ax.set_ylabel("PDF (sliders that moved)")
        cb = fig.colorbar(sm, ax=ax, pad=0.015)
        cb.set_label(r"$\alpha$ (bins of %.2g)" % np.diff(g.stop_alpha_edges)[0])
        ax.set_title(_stats_title(summary, title_extra))
    save_figure(fig, out_dir, name)
    return fig


def fig_bin_heights(summary, out_dir="figures", name: str = "bin_heights",
                    bins: Sequence[int] | None = None, min_fraction: float = 0.5,
                    title_extra: str = ""):
    """Measured P_i(alpha) with the model (paper Fig. distrib2).

    Markers with standard-error bars: measured heights (counts / (N 2 dmu)),
    shown where at least ``min_fraction`` of the runs are still at rest.
    Solid: closed form of Eq. (model) (``model.bin_heights``, nu(0) bins);
    dashed: crude model Eq. (crude); vertical solid line: alpha_t (Stirling,
    Eq. cond); grey dash-dotted: the exact solution of Eq. (not_neg).
    """
    from . import model

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
        fig, ax = plt.subplots(figsize=(5.6, 4.2))
        for c, i in zip(colours, bins):
            ax.errorbar(a, summary.p_mean[ok, i - 1], yerr=summary.p_sem[ok, i - 1], fmt="o", ms=3,
                        color=c, capsize=1.5, lw=0.8, label=f"$P_{{{i}}}$")
            ax.plot(aa, closed[:, i - 1], "-", color=c, lw=1.0)
        ax.plot(aa, crude_p1, "--", color=colours[0], lw=1.0, label="crude model")
        ax.axhline(plateau, color="0.3", ls="--", lw=0.8)
        ax.axvline(at_s, color="k", ls="-", lw=1.0)
        ax.axvline(at_e, color="0.45", ls="-.", lw=1.0)
        ax.text(at_s, 0.99, f" $\\alpha_t={at_s:.3f}$\n (Stirling)", transform=ax.get_xaxis_transform(),
                va="top", ha="left", fontsize=7)
        ax.text(at_e, 0.99, f"exact $\\alpha_t={at_e:.3f}$ ", transform=ax.get_xaxis_transform(),
                va="top", ha="right", fontsize=7)
        ax.set_xlabel(r"$\alpha$")
        ax.set_ylabel(r"$P_i$")
        ax.set_xlim(0, summary.alpha[-1])
        ax.set_ylim(0, None)
        ax.legend(loc="center left", ncol=1, frameon=True, framealpha=0.9)
        ax.set_title(_stats_title(summary, title_extra + ("; " if title_extra else "")
                                  + "solid: model, dashed: crude model"))
    save_figure(fig, out_dir, name)
    return fig


CUMUL_FIT = (0.1, 0.45)


def _exponential_fit_line(ax, x, y, fit_range):
    """Fit y = prefactor exp(rate x) on fit_range and draw it dashed (if the
    fit succeeded); returns the fit (observables.exponential_fit)."""
    fit = ob.exponential_fit(x, y, *fit_range)
    if math.isfinite(fit["rate"]):
        xx = np.linspace(*fit_range, 50)
        ax.plot(xx, fit["prefactor"] * np.exp(fit["rate"] * xx), "k--", lw=1.0,
                label=f"$\\propto e^{{k\\alpha}}$, $k={fit['rate']:.1f}\\pm{fit['rate_err']:.1f}$")
    return fit


def fig_cumulated_displacement(data, out_dir="figures", name: str = "cumulated",
                               fit_range=CUMUL_FIT, title_extra: str = ""):
    """(a) A(alpha) on a log scale, (b) <dx> per rearrangement vs alpha (paper Fig. cumul).

    ``data``: an ``EnsembleSummary`` or a list of ``TiltResult`` (then (b)
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
        fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(5.2, 6.2), sharex=True,
                                       gridspec_kw={"hspace": 0.08})
        A = summary.cumulated_mean
        sel = ok & (A > 0)
        ax0.errorbar(a[sel], A[sel], yerr=summary.cumulated_sem[sel], fmt="o", ms=3, capsize=1.5,
                     lw=0.8, color="tab:blue", label=r"$\langle A\rangle$ (mean $\pm$ s.e.)")
        fa = _exponential_fit_line(ax0, a[sel], A[sel], fit_range)
        ax0.set_yscale("log")
        ax0.set_ylabel(r"$A$")
        ax0.legend(loc="lower right")
        ax0.text(0.01, 0.97, "(a)", transform=ax0.transAxes, va="top", fontweight="bold")

        if results is not None:
            ea = np.concatenate([np.asarray(r.alpha) for r in results])
            ed = np.concatenate([ob.mean_event_displacement(r) for r in results])
            pos = ed > 0
            ax1.plot(ea[pos], ed[pos], ".", color="0.6", ms=2, label="single events",
                     rasterized=True)
        mid = summary.alpha_mid
        mdx = summary.event_mean_displacement
        fb = {"rate": math.nan}
        if mdx is not None:
            okm = np.isfinite(mdx) & (mdx > 0)
            ax1.plot(mid[okm], mdx[okm], "o", ms=3, color="tab:red",
                     label=r"$\langle\Delta\tilde x\rangle$ (mean per $\alpha$ bin)")
            fb = _exponential_fit_line(ax1, mid[okm], mdx[okm], fit_range)
        ax1.set_yscale("log")
        ax1.set_xlabel(r"$\alpha$")
        ax1.set_ylabel(r"$\langle\Delta\tilde x\rangle$")
        ax1.legend(loc="upper left", bbox_to_anchor=(0.06, 1.0))
        ax1.text(0.01, 0.97, "(b)", transform=ax1.transAxes, va="top", fontweight="bold")
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
        "scene_A": dict(n_sliders=10, xi=0.0, seed=1, label="A"),
        "scene_B": dict(n_sliders=big, xi=0.0, seed=1, label="B"),
        "scene_C": dict(n_sliders=big, xi=0.001, seed=1, label="C"),
    }


def run_scene(n_sliders: int, xi: float, seed: int, backend: str = "fortran", **kw):
    from .driver import tilt
    from .scene import Scene

    return tilt(Scene(n_sliders=n_sliders, xi=xi, seed=seed, record="displacements", **kw),
                backend=backend)


def run_ensemble(n_sliders: int = 100, runs: int = 20, base_seed: int = 0, xi: float = 0.0,
                 backend: str = "fortran", keep_results: bool = False, progress=None):
    """Serial ensemble: (summary, results or None).  Seeds keyed_random.realisation_seed(base, r)."""
    from .keyed_random import realisation_seed
    from .scene import Scene

    grids = ob.default_grids(Scene(n_sliders=n_sliders, xi=xi))
    rows, results = [], []
    for r in range(runs):
        res = run_scene(n_sliders, xi, realisation_seed(base_seed, r), backend=backend)
        rows.append(ob.realisation_statistics(res, grids))
        if keep_results:
            results.append(res)
        if progress is not None:
            progress(r + 1, runs, res)
    summary = ob.combine(ob.stack_rows(rows), grids, n_sliders)
    return summary, (results if keep_results else None)


def load_ensemble_summary(path, prefer_package: bool = True):
    """(EnsembleSummary, grids, scene dict) from an ensemble HDF5 file.

    Uses ``sliders.ensemble.load_summary`` when the package provides it, else
    reads the agreed layout: grids in /grids/<field>, rows in
    /realisations/statistics/<key>, done mask /realisations/done, scene JSON
    in the root attribute "scene".  Only rows with done = 1 are used.
    """
    load_summary = None
    if prefer_package:
        try:
            from .ensemble import load_summary  # type: ignore[attr-defined]
        except ImportError:
            pass
    if load_summary is not None:
        out = load_summary(path)
        if isinstance(out, tuple) and len(out) >= 2:
            scene = out[2] if len(out) > 2 else None
            return out[0], out[1], (scene.to_dict() if hasattr(scene, "to_dict") else scene)
    import h5py

    with h5py.File(os.fspath(path), "r") as f:
        scene = json.loads(f.attrs["scene"]) if "scene" in f.attrs else {}
        done = f["realisations/done"][()].astype(bool)
        rows = {k: ds[()][done] for k, ds in f["realisations/statistics"].items()}
        if "grids" in f:
            grids = ob.StatisticsGrids.from_arrays({k: ds[()] for k, ds in f["grids"].items()})
        else:
            from .scene import Scene

            grids = ob.default_grids(Scene.from_dict(scene))
    if not done.any():
        raise ValueError(f"{os.fspath(path)!r}: no finished realisation (done mask all 0)")
    n = int(scene.get("n_sliders", rows["event_size_counts"].shape[-1]))
    return ob.combine(rows, grids, n), grids, scene


# -----------------------------------------------------------------------------
# command line
# -----------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sliders.figures",
        description="Rebuild the paper's figures (PNG + PDF). Fast defaults; --paper-size "
                    "for the paper's sizes (scenes B, C: N=400; statistics: 20 runs of N=100).")
    p.add_argument("--out", default="figures", metavar="DIR", help="output directory (figures/)")
    p.add_argument("--ensemble", metavar="FILE.h5",
                   help="statistics figures from this ensemble file (python -m sliders.ensemble)")
    p.add_argument("--paper-size", action="store_true", help="the paper's sizes")
    p.add_argument("--backend", choices=("fortran", "numpy"), default="fortran")
    p.add_argument("--only", nargs="+", choices=FIGURE_NAMES, metavar="NAME",
                   help=f"only these figures, among {', '.join(FIGURE_NAMES)}")
    p.add_argument("--runs", type=int, default=None, help="realisations for the statistics "
                   "(default 20 with Fortran or --paper-size, 4 with numpy)")
    p.add_argument("--n-sliders", type=int, default=None, help="N for the statistics "
                   "(default 100 with Fortran or --paper-size, 30 with numpy)")
    p.add_argument("--seed", type=int, default=0, help="base seed of the statistics ensemble")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    names = list(args.only) if args.only else list(FIGURE_NAMES)
    big = args.paper_size or args.backend == "fortran"
    runs = args.runs if args.runs is not None else (20 if big else 4)
    n_stats = args.n_sliders if args.n_sliders is not None else (100 if big else 30)
    out = args.out
    t_all = time.perf_counter()

    def done(name, t0, note=""):
        print(f"{name}: {time.perf_counter() - t0:.1f} s{(' ' + note) if note else ''} -> "
              f"{os.path.join(out, name)}.png/.pdf", flush=True)

    setups = scene_setups(args.paper_size, args.backend)
    for name in names:
        if name in setups:
            t0 = time.perf_counter()
            s = dict(setups[name])
            label = s.pop("label")
            res = run_scene(backend=args.backend, **s)
            fig = fig_scene(res, name=name, label=label, out_dir=out)
            plt.close(fig)
            done(name, t0, f"(N={s['n_sliders']}, xi={s['xi']:g}, {res.n_events} events, "
                           f"alpha_c={res.alpha_c:.4f})")
    if "single_slider" in names:
        t0 = time.perf_counter()
        plt.close(fig_single_slider(backend=args.backend, out_dir=out))
        done("single_slider", t0)

    stats = [n for n in names if n in ("force_pdf", "stopped_ratio", "bin_heights", "cumulated")]
    if stats:
        t0 = time.perf_counter()
        results = None
        if args.ensemble:
            summary, _, scene = load_ensemble_summary(args.ensemble)
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
        makers = {
            "force_pdf": lambda: fig_force_pdf(summary, out_dir=out, title_extra=extra),
            "stopped_ratio": lambda: fig_stopped_force_ratio(summary, out_dir=out, title_extra=extra),
            "bin_heights": lambda: fig_bin_heights(summary, out_dir=out, title_extra=extra),
            "cumulated": lambda: fig_cumulated_displacement(results if results else summary,
                                                            out_dir=out, title_extra=extra),
        }
        for name in stats:
            t1 = time.perf_counter()
            plt.close(makers[name]())
            done(name, t1)
    print(f"all figures: {time.perf_counter() - t_all:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
