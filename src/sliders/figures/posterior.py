"""The posterior of a pile's material as a corner plot: each parameter's marginal on the
diagonal, every pair below it, the prior's range shaded (``infer --plot``).

mu_d is drawn as atan(mu_d) in degrees (the angle a physicist reads), the
other parameters on the scale of their prior (log for mu_s - mu_d, sigma_mu,
xi and the number of sliders); xi's draws at 0 (its prior's atom) are drawn
at the left edge, with P(xi = 0) in the title.  True values, when known
(a simulated pile), are marked.

Each axis spans the prior's range, or, where the posterior is far narrower
(its central 95 % within ``ZOOM_SHARE`` of the prior's range, on the axis's
scale), the posterior with a margin: a posterior 0.1° wide is drawn as a
histogram, not as a line.  Beyond the prior's range the axis is hatched and the
prior's edges are drawn, so that a posterior piled against an edge reads as
such (its marginal's title says so, in red).  The predictive check's verdict
(``infer``'s ``check``) stands in the empty upper right of the figure.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.ticker import (FuncFormatter, MaxNLocator, NullFormatter, NullLocator,
                               ScalarFormatter)

from ..parts.materials import LOG_NAMES, MATERIALS

#: axis labels of the parameters
AXIS_LABELS = {m.name: m.axis_label for m in MATERIALS}
#: the parameters drawn on a log axis
LOG_AXES = LOG_NAMES
PRIOR_COLOUR, POSTERIOR_COLOUR, TRUTH_COLOUR = "0.88", "C0", "C3"
EDGE_COLOUR = "0.3"
#: an axis is fitted to the posterior when its central 95 % (these quantiles) spans less
#: than ``ZOOM_SHARE`` of the prior's range (on the axis's scale: degrees, or decades on a
#: log axis), with 40 % of that width as a margin on either side.  Not the 0.5-99.5 %
#: quantiles: the posterior's draws keep a few per cent spread over the whole prior (a sharp
#: posterior of a complete catalogue: 2 % beyond 1° of a 0.3° wide 95 % interval), whose
#: share off the axis the marginal's title gives
ZOOM_QUANTILES = (0.025, 0.975)
ZOOM_SHARE = 0.3
#: a posterior is "piled at the prior's edge" when this share of its draws lies in the
#: outer ``EDGE_BAND`` of the prior's range (a posterior as flat as the prior: 0.05)
EDGE_BAND, EDGE_SHARE = 0.05, 0.3
#: the verdict's colours: reproduced, not reproduced, undecided or skipped
VERDICT_COLOURS = {"reproduced": "#1b7837", "not reproduced": "#b2182b",
                   "undecided": "#8c6d00", "skipped": "0.35"}


def _shown(name: str, values, zero_at: float) -> np.ndarray:
    """Values as the axes show them: mu_d as atan in degrees, xi = 0 at ``zero_at``."""
    v = np.asarray(values, dtype=float)
    if name == "mu_d":
        return np.degrees(np.arctan(v))
    if name == "xi":
        return np.where(v > 0, v, zero_at)
    return v


def _prior_span(name: str, prior_range):
    lo, hi = (float(x) for x in prior_range)
    if name == "mu_d":
        return math.degrees(math.atan(lo)), math.degrees(math.atan(hi))
    return lo, hi


def _scale(name: str):
    """The axis's coordinate and back: log10 on a log axis, the value itself otherwise."""
    if name in LOG_AXES:
        return np.log10, lambda u: np.power(10.0, u)
    return (lambda v: np.asarray(v, dtype=float)), (lambda u: np.asarray(u, dtype=float))


def _limits(name: str, prior_range, shown=None, raw=None) -> tuple[tuple[float, float], bool]:
    """The axis's range and whether it is fitted to the posterior (``shown``: the draws as
    the axis shows them; ``raw``: in their own units, to find xi's atom at 0)."""
    lo, hi = _prior_span(name, prior_range)
    if name == "xi":
        lo = lo / 3.0  # room for the zeros, drawn at the left edge
    if name in LOG_AXES:
        full = (lo / 1.15, hi * 1.15)
    else:
        pad = 0.03 * (hi - lo)
        full = (lo - pad, hi + pad)
    if shown is None or np.size(shown) == 0:
        return full, False
    if name == "xi" and np.mean(np.asarray(raw, dtype=float) <= 0) > 0.005:
        return full, False  # the atom at 0 is drawn at the left edge: the whole range stays
    to, back = _scale(name)
    p0, p1 = (float(x) for x in to(_prior_span(name, prior_range)))
    a, b = (float(x) for x in np.quantile(to(np.asarray(shown, dtype=float)), ZOOM_QUANTILES))
    if not (np.isfinite(a) and np.isfinite(b)) or b - a >= ZOOM_SHARE * (p1 - p0):
        return full, False
    margin = max(0.4 * (b - a), (0.05 if name == "n_sliders" else 0.004) * (p1 - p0))
    return (float(back(a - margin)), float(back(b + margin))), True


def _bins(name: str, limits, n: int = 40) -> np.ndarray:
    lo, hi = limits
    return np.geomspace(lo, hi, n) if name in LOG_AXES else np.linspace(lo, hi, n)


def at_prior_edge(name: str, values, prior_range) -> str | None:
    """"lower" or "upper" if the posterior draws ``values`` (as the axis shows them) pile at
    that edge of the prior's range (``EDGE_SHARE`` of them in its outer ``EDGE_BAND``), else
    None.  xi's lower edge is its atom's side, never flagged."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return None
    to, _ = _scale(name)
    p0, p1 = (float(x) for x in to(_prior_span(name, prior_range)))
    u = to(v)
    band = EDGE_BAND * (p1 - p0)
    if np.mean(u >= p1 - band) >= EDGE_SHARE:
        return "upper"
    if name != "xi" and np.mean(u <= p0 + band) >= EDGE_SHARE:
        return "lower"
    return None


def verdict_of(check) -> tuple[str, str]:
    """The predictive check's verdict (``"reproduced"``, ``"not reproduced"``,
    ``"undecided"`` or ``"skipped"``) and its text, from ``infer``'s ``check`` (a dict, or
    None / "skipped" when it was not run)."""
    if check is None or check == "skipped":
        return "skipped", ("predictive check skipped (--no-check): nothing here says the "
                           "model reproduces this catalogue")
    said = check.get("verdict")
    reproduced = check.get("reproduced")
    if said == "undecided" or (said is None and reproduced is None):
        return "undecided", ("predictive check UNDECIDED: the simulated piles neither "
                             "reproduce this catalogue nor rule it out")
    if reproduced:
        p = [v for v in (check.get("p_values") or {}).values() if v is not None]
        least = f" (smallest p-value {min(p):.2g})" if p else ""
        return "reproduced", ("predictive check: REPRODUCED: the prior's piles make "
                              "catalogues like this one, and piles simulated at posterior "
                              f"draws reproduce it{least}")
    failed = [str(r.get("test", "")).replace("_", " ") for r in check.get("reasons") or []]
    why = f" ({' and '.join(failed)} test{'s' if len(failed) > 1 else ''} failed)" if failed \
        else ""
    return "not reproduced", ("predictive check: NOT REPRODUCED" + why + ": the model does "
                              "not make catalogues like this one; these parameters are not "
                              "to be trusted")


def corner_figure(draws: dict, prior_range: dict, summary: dict | None = None,
                  truth: dict | None = None, title: str | None = None, check=None):
    """The corner plot of posterior ``draws`` (``{parameter: values}``, own units).

    Parameters
    ----------
    draws : dict
        Posterior draws of each parameter.
    prior_range : dict
        Each parameter's prior range (xi: its positive range), shaded; beyond it hatched.
    summary : dict, optional
        ``infer``'s parameters (their 80 % intervals are marked, xi's P(xi = 0) named).
    truth : dict, optional
        The true parameters of a simulated pile, marked in red.
    title : str, optional
        The figure's title.
    check : dict or str, optional
        ``infer``'s predictive check (its ``check``), or ``"skipped"``: its verdict
        (``verdict_of``) is written on the figure; None: no verdict drawn.

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
    fitted = {n: _limits(n, prior_range[n], shown[n], draws[n]) for n in names}
    limits = {n: fitted[n][0] for n in names}
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
            _ticks(ax.xaxis, col, fitted[col][1])
            if i != j:
                _ticks(ax.yaxis, row, fitted[row][1])
            ax.tick_params(which="both", labelsize=7, labelbottom=i == k - 1,
                           labelleft=j == 0 and i > 0)
    zoomed = [AXIS_LABELS.get(n, n).split(" [")[0] for n in names if fitted[n][1]]
    fig.suptitle(title or "posterior of the pile's material (grey: the prior's range, hatched: "
                 "beyond it" + ("; red: the true values)" if truth else ")"), fontsize=10)
    if check is not None and k > 1:
        _verdict(axes[0, k - 1], check, zoomed)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _ticks(axis, name: str, zoomed: bool) -> None:
    """A fitted axis gets plain ticks of its own (a log axis within a decade has none)."""
    if zoomed:
        axis.set_major_locator(MaxNLocator(nbins=3, min_n_ticks=2))
        if name in LOG_AXES:
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
        else:
            plain = ScalarFormatter(useOffset=False)
            axis.set_major_formatter(plain)
        axis.set_minor_locator(NullLocator())
    axis.set_minor_formatter(NullFormatter())


def _verdict(ax, check, zoomed) -> None:
    """The check's verdict in the empty upper right corner (a box of its colour), and which
    axes are fitted to the posterior."""
    kind, text = verdict_of(check)
    lines = textwrap.wrap(text, 46)
    if zoomed:
        lines += [""] + textwrap.wrap("fitted to the posterior (not the prior's range): "
                                      + ", ".join(zoomed), 52)
    ax.text(1.0, 1.0, "\n".join(lines), transform=ax.transAxes, ha="right", va="top",
            multialignment="left",
            fontsize=9, color="white" if kind != "skipped" else "0.1",
            fontweight="bold" if kind == "not reproduced" else "normal", gid="verdict",
            in_layout=False,
            bbox=dict(boxstyle="round,pad=0.5",
                      facecolor=VERDICT_COLOURS[kind] if kind != "skipped" else "0.9",
                      edgecolor="none"))


def _beyond_prior(ax, lo: float, hi: float, limits, vertical: bool) -> None:
    """Hatch the axis beyond the prior's range [lo, hi] and draw its edges."""
    span = ax.axvspan if vertical else ax.axhspan
    line = ax.axvline if vertical else ax.axhline
    if limits[0] < lo:
        span(limits[0], lo, facecolor="white", edgecolor="0.6", hatch="////", lw=0, zorder=0)
    if limits[1] > hi:
        span(hi, limits[1], facecolor="white", edgecolor="0.6", hatch="////", lw=0, zorder=0)
    for edge in (lo, hi):
        if limits[0] < edge < limits[1]:
            line(edge, color=EDGE_COLOUR, lw=1.0, zorder=1)


def _marginal(ax, name, values, limits, prior_range, summary, truth, zero_at):
    lo, hi = _prior_span(name, prior_range)
    ax.axvspan(lo, hi, color=PRIOR_COLOUR, zorder=0)
    _beyond_prior(ax, lo if name != "xi" else limits[0], hi, limits, True)
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
    edge = at_prior_edge(name, values[values != zero_at] if name == "xi" else values,
                         prior_range)
    if name == "xi" and summary and summary.get("p_zero") is not None:
        text = f"P(xi = 0) = {summary['p_zero']:.2f} (left bar)"
    elif summary and summary.get("median") is not None:
        text = f"median {_median_text(name, summary)}"
    else:
        text = ""
    off = float(np.mean((values < limits[0]) | (values > limits[1])))
    if off >= 0.005:
        text = f"{text}\n{100 * off:.0f} % of the draws off this axis".strip()
    if edge is not None:
        text = f"{text}\npiled at the prior's {edge} edge".strip()
    if text:
        ax.set_title(text, fontsize=8, color=TRUTH_COLOUR if edge else "k",
                     fontweight="bold" if edge else "normal")


def _median_text(name: str, summary: dict) -> str:
    if name == "mu_d":
        return f"{summary['atan_deg']['median']:.2f}°"
    if name == "n_sliders":
        return f"{summary['median']:.0f}"
    return f"{summary['median']:.3g}"


def _pair(ax, x_name, y_name, x, y, limits, prior_range, truth):
    (x0, x1), (y0, y1) = _prior_span(x_name, prior_range[x_name]), _prior_span(
        y_name, prior_range[y_name])
    if x_name == "xi":
        x0 = limits[x_name][0]
    if y_name == "xi":
        y0 = limits[y_name][0]
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color=PRIOR_COLOUR, zorder=0))
    if x_name in LOG_AXES:
        ax.set_xscale("log")
    if y_name in LOG_AXES:
        ax.set_yscale("log")
    for (lo, hi), name, vertical in (((x0, x1), x_name, True), ((y0, y1), y_name, False)):
        lim = limits[name]
        line = ax.axvline if vertical else ax.axhline
        for edge in (lo, hi):
            if lim[0] < edge < lim[1] and edge != lim[0]:
                line(edge, color=EDGE_COLOUR, lw=0.8, zorder=1)
    ax.hist2d(x, y, bins=[_bins(x_name, limits[x_name], 30), _bins(y_name, limits[y_name], 30)],
              cmap="Blues", cmin=1)
    if truth[0] is not None and truth[1] is not None:
        ax.plot(truth[0], truth[1], marker="*", color=TRUTH_COLOUR, ms=9, mec="k", mew=0.5)
    ax.set_xlim(*limits[x_name])
    ax.set_ylim(*limits[y_name])
