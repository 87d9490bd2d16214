"""The paper's two schematic figures, drawn from the model's own quantities.

* ``fig_sketch`` (Fig. 1, fig:schema): the chain on the incline at angle
  alpha, the springs of natural length l between neighbours, the cantilever
  springs to the upper plate, whose anchors x_n^(c) follow the barycentre
  (Eq. bary), the slider labels n = 1 ... N and a position x_n.  The
  positions are those of a prepared chain (``preparation.prepare``).
* ``fig_histogram_model`` (Fig. 8, fig:sch_d): the bar histogram of the
  master-equation model at a chosen alpha (nu(alpha) bins of width 2 dmu
  counted down from mu_s), with the shift of every bin
  by one as alpha grows (red solid arrows) and the return into bin 1 after a
  rearrangement (blue dashed arrow).
"""

from __future__ import annotations

import math

import numpy as np

from .style import COLUMN_WIDTH, STYLE, save_figure
import matplotlib.pyplot as plt  # noqa: E402  (after figure_style chose the backend)
from matplotlib.patches import FancyArrowPatch, Polygon  # noqa: E402
from ..analysis import model
from ..preparation import prepare
from ..scene import Scene

# -----------------------------------------------------------------------------
# Fig. 1: the system
# -----------------------------------------------------------------------------

SKETCH_SLIDERS = 5
# The prepared deviations x_n - x_n^(c) are a few % of l: magnified so that
# the tilted cantilever springs (the coupling) can be seen.
DEVIATION_MAGNIFICATION = 4.0


def sketch_chain(n_sliders: int = SKETCH_SLIDERS, seed: int = 2, xi: float = 0.001):
    """Positions x_n, plate anchors x_n^(c) and l* of a prepared free chain (``preparation``).

    x_n^(c) = mean(x) + (n - (N+1)/2) l*, l* = (x_N - x_1)/(N - 1): the plate
    moves with the barycentre (paper Eq. bary).
    """
    scene = Scene(n_sliders=n_sliders, xi=xi, seed=seed)
    x = np.asarray(prepare(scene).lattice_position0, dtype=float)
    l_star = (x[-1] - x[0]) / (n_sliders - 1)
    n = np.arange(1, n_sliders + 1)
    anchors = x.mean() + (n - (n_sliders + 1) / 2.0) * l_star
    return scene, x, anchors, l_star


def _zigzag(p0, p1, turns: int = 6, width: float = 0.09):
    """Points of a spring drawn from p0 to p1 (straight leads, ``turns`` zigzags)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    length = float(np.hypot(*d))
    u = d / length
    v = np.array([-u[1], u[0]])
    lead = 0.15 * length
    t = np.linspace(lead, length - lead, 2 * turns + 1)
    offs = width * np.array([0.0] + [(-1) ** k for k in range(2 * turns - 1)] + [0.0])
    pts = [p0] + [p0 + ti * u + oi * v for ti, oi in zip(t, offs)] + [p1]
    return np.array(pts)


def _sketch_sliders(ax, at, s, s_anchor, size, p_lo):
    """The blocks at slope positions ``s``, their springs, and their cantilevers to the plate."""
    w, h = size
    n_sliders = len(s)
    for j in range(n_sliders):
        c = s[j]
        corners = [at(c - w / 2, 0), at(c + w / 2, 0), at(c + w / 2, h), at(c - w / 2, h)]
        ax.add_patch(Polygon(corners, closed=True, facecolor="tab:orange", edgecolor="k",
                             lw=0.7, zorder=3))
        ax.text(*at(c, h / 2), f"{j + 1}" if j < n_sliders - 1 else "$N$", ha="center",
                va="center", fontsize=7, zorder=4)
        # cantilever spring from the slider's top to its anchor x_n^(c) on the plate
        z = _zigzag(at(c, h), at(s_anchor[j], p_lo), turns=4, width=0.06)
        ax.plot(z[:, 0], z[:, 1], "k-", lw=0.6)
        if j < n_sliders - 1:
            z = _zigzag(at(c + w / 2, h / 2), at(s[j + 1] - w / 2, h / 2), turns=4, width=0.06)
            ax.plot(z[:, 0], z[:, 1], "k-", lw=0.6)


def _sketch_centre_and_gravity(ax, at, s, h, plate):
    """The plate's centre above the barycentre of the sliders, and the weight m g."""
    p_lo, p_hi = plate
    centre = float(np.mean(s))
    ax.plot(*np.array([at(centre, h + 0.03), at(centre, p_lo)]).T, ls=(0, (2, 2)),
            color="tab:blue", lw=0.7)
    ax.plot(*at(centre, h + 0.03), marker="o", ms=2.5, color="tab:blue", zorder=5)
    ax.annotate("plate centre above\nthe barycentre", xy=at(centre, p_hi),
                xytext=at(centre + 0.9, p_hi + 0.5), fontsize=7, ha="left", va="center",
                color="tab:blue", arrowprops=dict(arrowstyle="-", lw=0.5, color="tab:blue"))
    g0 = at(s[-1] + 0.75, h + 0.55)
    ax.annotate("", xy=g0 + np.array([0.0, -0.45]), xytext=g0,
                arrowprops=dict(arrowstyle="->", lw=0.7))
    ax.text(g0[0] + 0.06, g0[1] - 0.22, r"$mg$", ha="left", va="center", fontsize=7)


def fig_sketch(alpha: float = 0.22, out_dir="figures", name: str = "fig01_sketch",
               n_sliders: int = SKETCH_SLIDERS):
    """Fig. 1: sketch of the system, from a prepared chain of ``n_sliders`` at tilt ``alpha``."""
    scene, x, anchors, l_star = sketch_chain(n_sliders)
    spacing = 1.0  # drawing units per l*
    # along the slope (down-slope positive, as x), in drawing units
    s = (np.arange(n_sliders) + DEVIATION_MAGNIFICATION * (x - anchors) / l_star) * spacing
    s_anchor = np.arange(n_sliders) * spacing
    w, h, plate_h = 0.42, 0.30, 1.05
    ca, sa = math.cos(alpha), math.sin(alpha)
    origin = np.array([0.0, (n_sliders + 0.2) * sa])

    def at(along, up):
        """Drawing point of slope coordinates (along: down the slope, up: off the incline)."""
        return origin + along * np.array([ca, -sa]) + up * np.array([sa, ca])

    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.0))
        ax.set_aspect("equal")
        ax.axis("off")
        start, stop = -0.75, n_sliders - 1 + 1.7
        # the incline and the ground
        base = at(stop, 0.0)
        ax.add_patch(Polygon([at(start, 0.0), base, (at(start, 0.0)[0], base[1])],
                             closed=True, facecolor="0.92", edgecolor="k", lw=0.8))
        arc = np.linspace(math.pi - alpha, math.pi, 30)
        r = 0.7
        ax.plot(base[0] + r * np.cos(arc), base[1] + r * np.sin(arc), "k-", lw=0.6)
        ax.text(base[0] - r - 0.05, base[1] + 0.03, r"$\alpha$", ha="right", va="bottom")
        # the upper plate, parallel to the incline
        p_lo, p_hi = plate_h, plate_h + 0.12
        ax.add_patch(Polygon([at(start + 0.2, p_lo), at(stop - 0.9, p_lo), at(stop - 0.9, p_hi),
                              at(start + 0.2, p_hi)], closed=True, facecolor="0.8",
                             edgecolor="k", lw=0.7, hatch="////"))
        ax.text(*at(start + 0.25, p_hi + 0.06), "upper plate", rotation=-math.degrees(alpha),
                rotation_mode="anchor", ha="left", va="bottom", fontsize=7)
        _sketch_sliders(ax, at, s, s_anchor, (w, h), p_lo)
        # inside the incline: the x axis (down the slope), x_n at slider 4, l between 1 and 2
        x_end = s[-1] + 0.45
        ax.annotate("", xy=at(x_end, -0.12), xytext=at(start + 0.1, -0.12),
                    arrowprops=dict(arrowstyle="->", lw=0.6, shrinkA=0, shrinkB=0),
                    annotation_clip=False)
        ax.text(*at(x_end - 0.05, -0.2), r"$x$", ha="center", va="top", fontsize=8)
        ax.plot(*np.array([at(s[3], -0.19), at(s[3], -0.05)]).T, "k-", lw=0.8)
        ax.text(*at(s[3], -0.22), r"$x_n$", ha="center", va="top", fontsize=7)
        ax.annotate("", xy=at(s[1], -0.55), xytext=at(s[0], -0.55),
                    arrowprops=dict(arrowstyle="<->", lw=0.6, shrinkA=0, shrinkB=0))
        ax.text(*at(0.5 * (s[0] + s[1]), -0.66), r"$l$ (rest length)", ha="center", va="top",
                fontsize=7)
        ax.text(*at(0.5 * (s[0] + s[1]), h / 2 + 0.16), r"$k$", ha="center", va="center",
                fontsize=7)
        ax.text(*at(s_anchor[1] + 0.12, 0.62 * plate_h), r"$k_c=\xi k$", ha="left",
                va="center", fontsize=7)
        ax.plot(*at(s_anchor[3], p_lo), "o", ms=2.5, color="k", zorder=5)
        ax.text(*at(s_anchor[3] + 0.08, p_lo - 0.08), r"$x_n^{(c)}$", ha="left", va="top",
                fontsize=7)
        _sketch_centre_and_gravity(ax, at, s, h, (p_lo, p_hi))
        ax.text(at(start, 0.0)[0], base[1] - 0.06, f"$N={n_sliders}$ drawn; deviations "
                f"$x_n-x_n^{{(c)}}$ magnified $\\times{DEVIATION_MAGNIFICATION:g}$", fontsize=7,
                ha="left", va="top")
        ax.autoscale_view()
        ax.margins(0.01)
    save_figure(fig, out_dir, name)
    return fig


# -----------------------------------------------------------------------------
# Fig. 8 (sch_d): the model's bar histogram
# -----------------------------------------------------------------------------


def histogram_model_bins(alpha: float, mu_s_mean: float = 0.6, mu_d: float = 0.55):
    """Bins of the model at ``alpha``: (upper edges, lower edges, heights P_i, nu, lower bound).

    Bin i (1 ... nu(alpha)) holds ]mu_s - 2 i dmu, mu_s - 2 (i-1) dmu]; the
    last one includes the lower bound sin(alpha) - mu_s of the forces.  The
    heights are the master equations integrated with nu(alpha) bins
    (``model.integrate_master_equations(variable_nu=True)``), which conserves
    probability: sum_i 2 dmu P_i = 1.
    """
    dmu = mu_s_mean - mu_d
    nu = int(model.n_bins(alpha, mu_s_mean, mu_d))
    heights = np.asarray(model.integrate_master_equations([alpha], mu_s_mean, mu_d,
                                                          variable_nu=True)[0, :nu], dtype=float)
    i = np.arange(1, nu + 1)
    upper = mu_s_mean - 2.0 * dmu * (i - 1)
    lower = upper - 2.0 * dmu
    return upper, lower, heights, nu, math.sin(alpha) - mu_s_mean


def fig_histogram_model(alpha: float = 0.15, mu_s_mean: float = 0.6, mu_d: float = 0.55,
                        out_dir="figures", name: str = "fig08_histogram_model"):
    """Fig. 8 (sch_d): the model's bar histogram of F_t at ``alpha`` and its evolution.

    Red solid arrows: as alpha grows by d(alpha), every bin i > 1 feeds bin
    i - 1; blue dashed arrow: the sliders of bin 1 lose stability,
    rearrange and land back in bin 1.
    """
    upper, lower, heights, nu, low_bound = histogram_model_bins(alpha, mu_s_mean, mu_d)
    dmu = mu_s_mean - mu_d
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.45))
        ax.bar(lower, heights, width=2.0 * dmu, align="edge", color="0.82", edgecolor="k",
               lw=0.6, label=f"$P_i(\\alpha)$, model, $\\nu(\\alpha)={nu}$ bins")
        top = float(heights.max())
        for j in range(nu):
            ax.text(0.5 * (upper[j] + lower[j]), -0.035 * top, f"{j + 1}", ha="center", va="top",
                    fontsize=7)
        # red solid: bin i -> i-1 (towards larger forces) as alpha grows
        for j in range(1, nu):
            x0 = 0.5 * (upper[j] + lower[j])
            x1 = 0.5 * (upper[j - 1] + lower[j - 1])
            y = heights[j] + 0.04 * top
            ax.add_patch(FancyArrowPatch((x0 - 0.2 * dmu, y), (x1 + 0.1 * dmu, y),
                                         connectionstyle="arc3,rad=-0.5", arrowstyle="-|>",
                                         mutation_scale=6, lw=0.8, color="tab:red", zorder=4))
        # blue dashed: bin 1 loses stability beyond mu_s and returns into bin 1
        xb = 0.5 * (upper[0] + lower[0])
        ax.add_patch(FancyArrowPatch((xb + 0.3 * dmu, heights[0] + 0.03 * top),
                                     (xb - 0.2 * dmu, 0.75 * heights[0]),
                                     connectionstyle="arc3,rad=-1.3", arrowstyle="-|>",
                                     mutation_scale=6, lw=0.8, color="tab:blue", ls="--",
                                     zorder=4))
        ax.text(mu_s_mean + 0.02 * dmu, heights[0] * 1.12, "unstable", color="tab:blue",
                fontsize=7, ha="left", va="bottom")
        ax.plot([], [], "-", color="tab:red", lw=0.8,
                label=r"$\delta\alpha$: bin $i\to i-1$")
        ax.plot([], [], "--", color="tab:blue", lw=0.8,
                label=r"bin 1: rearranges, back into bin 1")
        ax.axvline(mu_s_mean, color="k", ls=":", lw=0.7)
        ax.axvline(low_bound, color="0.4", ls="-.", lw=0.7,
                   label=r"lower bound $\sin\alpha-\bar\mu_s$")
        ax.text(mu_s_mean, 1.42 * top, r" $\bar\mu_s$", ha="left", va="top", fontsize=7)
        ax.set_xlim(lower[-1] - 0.02, mu_s_mean + 0.12)
        ax.set_ylim(-0.12 * top, 1.45 * top)
        ax.set_yticks([0, 0.5, 1.0, 1.5] if top > 1.0 else [0, 0.5, 1.0])
        ax.set_xlabel(r"$\tilde F_t$ (bins of width $2\Delta\mu$, numbered from $\bar\mu_s$) [$mg$]")
        ax.set_ylabel(r"$P_i$ [$1/mg$]")
        ax.legend(loc="upper left", frameon=True, framealpha=0.9)
        ax.set_title(f"model at $\\alpha={alpha:g}$ rad: $\\bar\\mu_s={mu_s_mean:g}$, "
                     f"$\\mu_d={mu_d:g}$, $2\\Delta\\mu={2 * dmu:.2g}$", pad=2)
    save_figure(fig, out_dir, name)
    return fig
