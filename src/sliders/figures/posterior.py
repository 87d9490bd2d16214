"""The posterior of a pile's material as a corner plot: each parameter's marginal on the
diagonal, every pair below it, the prior's range shaded (``infer --plot``).

mu_d is drawn as atan(mu_d) in degrees (the angle a physicist reads), the
other parameters on the scale of their prior (log for mu_s - mu_d, sigma_mu,
xi and the number of sliders); xi's draws at 0 (its prior's atom) are drawn
at the left edge, with P(xi = 0) in the title.  True values, when known
(a simulated pile), are marked.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.ticker import NullFormatter

#: axis labels of the parameters
AXIS_LABELS = {"mu_d": "atan(mu_d) [deg]", "mu_s_minus_mu_d": "mu_s - mu_d",
               "sigma_mu": "sigma_mu", "xi": "xi [units of k]", "n_sliders": "N (sliders)"}
#: the parameters drawn on a log axis
LOG_AXES = ("mu_s_minus_mu_d", "sigma_mu", "xi", "n_sliders")
PRIOR_COLOUR, POSTERIOR_COLOUR, TRUTH_COLOUR = "0.88", "C0", "C3"


def _shown(name: str, values, zero_at: float) -> np.ndarray:
    """Values as the axes show them: mu_d as atan in degrees, xi = 0 at ``zero_at``."""
    v = np.asarray(values, dtype=float)
    if name == "mu_d":
        return np.degrees(np.arctan(v))
    if name == "xi":
        return np.where(v > 0, v, zero_at)
    return v


def _limits(name: str, prior_range) -> tuple[float, float]:
    lo, hi = (float(x) for x in prior_range)
    if name == "mu_d":
        lo, hi = math.degrees(math.atan(lo)), math.degrees(math.atan(hi))
    if name == "xi":
        lo = lo / 3.0  # room for the zeros, drawn at the left edge
    if name in LOG_AXES:
        return lo / 1.15, hi * 1.15
    pad = 0.03 * (hi - lo)
    return lo - pad, hi + pad


def _bins(name: str, limits, n: int = 40) -> np.ndarray:
    lo, hi = limits
    return np.geomspace(lo, hi, n) if name in LOG_AXES else np.linspace(lo, hi, n)


def corner_figure(draws: dict, prior_range: dict, summary: dict | None = None,
                  truth: dict | None = None, title: str | None = None):
    """The corner plot of posterior ``draws`` (``{parameter: values}``, own units).

    Parameters
    ----------
    draws : dict
        Posterior draws of each parameter.
    prior_range : dict
        Each parameter's prior range (xi: its positive range), shaded.
    summary : dict, optional
        ``infer``'s parameters (their 80 % intervals are marked, xi's P(xi = 0) named).
    truth : dict, optional
        The true parameters of a simulated pile, marked in red.
    title : str, optional
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = [n for n in draws if n in prior_range]
    k = len(names)
    fig = Figure(figsize=(2.3 * k, 2.3 * k))
    axes = fig.subplots(k, k, squeeze=False)
    zero_at = float(prior_range["xi"][0]) / 2.0 if "xi" in prior_range else 0.0
    shown = {n: _shown(n, draws[n], zero_at) for n in names}
    limits = {n: _limits(n, prior_range[n]) for n in names}
    true = {n: float(_shown(n, [truth[n]], zero_at)[0]) for n in names
            if truth is not None and n in truth}
    for i, row in enumerate(names):
        for j, col in enumerate(names):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                _marginal(ax, row, shown[row], limits[row], prior_range[row],
                          (summary or {}).get(row), true.get(row), zero_at)
            else:
                _pair(ax, col, row, shown[col], shown[row], limits, prior_range,
                      (true.get(col), true.get(row)))
            ax.set_xlabel(AXIS_LABELS.get(col, col) if i == k - 1 else "", fontsize=8)
            ax.set_ylabel(AXIS_LABELS.get(row, row) if j == 0 and i > 0 else "", fontsize=8)
            ax.tick_params(which="both", labelsize=7, labelbottom=i == k - 1,
                           labelleft=j == 0 and i > 0)
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
    fig.suptitle(title or "posterior of the pile's material (shaded: the prior's range"
                 + ("; red: the true values)" if truth else ")"), fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _prior_span(name: str, prior_range):
    lo, hi = (float(x) for x in prior_range)
    if name == "mu_d":
        return math.degrees(math.atan(lo)), math.degrees(math.atan(hi))
    return lo, hi


def _marginal(ax, name, values, limits, prior_range, summary, truth, zero_at):
    lo, hi = _prior_span(name, prior_range)
    ax.axvspan(lo, hi, color=PRIOR_COLOUR, zorder=0)
    if name in LOG_AXES:
        ax.set_xscale("log")
    ax.hist(values, bins=_bins(name, limits), color=POSTERIOR_COLOUR, alpha=0.8,
            density=False)
    if summary and summary.get("interval_80"):
        for v in summary["interval_80"]:
            ax.axvline(float(_shown(name, [v], zero_at)[0]), color="k", lw=0.8, ls="--")
    if truth is not None:
        ax.axvline(truth, color=TRUTH_COLOUR, lw=1.5)
    ax.set_xlim(*limits)
    ax.set_yticks([])
    if name == "xi" and summary and summary.get("p_zero") is not None:
        ax.set_title(f"P(xi = 0) = {summary['p_zero']:.2f} (left bar)", fontsize=8)
    elif summary and summary.get("median") is not None:
        ax.set_title(f"median {_median_text(name, summary)}", fontsize=8)


def _median_text(name: str, summary: dict) -> str:
    if name == "mu_d":
        return f"{summary['atan_deg']['median']:.2f}°"
    if name == "n_sliders":
        return f"{summary['median']:.0f}"
    return f"{summary['median']:.3g}"


def _pair(ax, x_name, y_name, x, y, limits, prior_range, truth):
    (x0, x1), (y0, y1) = _prior_span(x_name, prior_range[x_name]), _prior_span(
        y_name, prior_range[y_name])
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color=PRIOR_COLOUR, zorder=0))
    if x_name in LOG_AXES:
        ax.set_xscale("log")
    if y_name in LOG_AXES:
        ax.set_yscale("log")
    ax.hist2d(x, y, bins=[_bins(x_name, limits[x_name], 30), _bins(y_name, limits[y_name], 30)],
              cmap="Blues", cmin=1)
    if truth[0] is not None and truth[1] is not None:
        ax.plot(truth[0], truth[1], marker="*", color=TRUTH_COLOUR, ms=9, mec="k", mew=0.5)
    ax.set_xlim(*limits[x_name])
    ax.set_ylim(*limits[y_name])
