"""The bench picture of a forecast (``python -m sliders.forecast predict --plot out.png``).

One figure for the experimenter at the tilting plane: above, the catalogue
against tilt (the cumulative number of events, and each event's size as a stem on a
log scale); below, the forecast distribution of the avalanche angle (its density,
read from the quantiles, the interval shaded, the median marked); across both,
the tilt reached and the alarm's window.  The title says the forecast, P(within)
and the domain verdict; every angle is in degrees.
"""

from __future__ import annotations

import math
import os
import textwrap

import numpy as np

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402  (after the backend)
from matplotlib.ticker import FuncFormatter, NullFormatter  # noqa: E402

from ..analysis.forecast.base import LEVELS  # noqa: E402

#: the picture's size (inches) and resolution: read on a screen beside the bench
BENCH_SIZE = (7.0, 5.6)
BENCH_DPI = 110
FORECAST_COLOUR = "#d95f02"
OUT_COLOUR = "#b2182b"
IN_COLOUR = "#1b7837"


def _density(quantiles: np.ndarray, levels: np.ndarray):
    """Edges (degrees) and the piecewise-constant density (per degree) between quantiles."""
    q = np.degrees(np.asarray(quantiles, dtype=float))
    lv = np.asarray(levels, dtype=float)
    keep = np.concatenate([[True], np.diff(q) > 1e-9])
    q, lv = q[keep], lv[keep]
    if q.size < 2:
        return q, np.zeros(0)
    return q, np.diff(lv) / np.diff(q)


def bench_figure(catalogue, forecast, *, label: str, calibrated: bool, in_domain: bool,
                 domain_reason: str | None, probability: str, within: float,
                 size_unit: str = "sliders"):
    """The bench picture of ``forecast`` (a ``Forecast``) made from ``catalogue``.

    Parameters
    ----------
    catalogue : sliders.io.catalogue.Catalogue
        The events forecast from, at its tilt reached.
    forecast : sliders.analysis.forecast.base.Forecast
        The forecast drawn.
    label : str
        The forecaster's name, as the text output gives it.
    calibrated : bool
        Its interval is a calibrated 80 % interval (else: "widened, uncalibrated").
    in_domain : bool
        The domain verdict; ``domain_reason`` says why not.
    probability : str
        P(within) as printed (``"= 0.12"``, ``"< 0.05"``).
    within : float
        The alarm's horizon, radians.
    size_unit : str
        The sizes' unit ("sliders" or "arbitrary").

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=BENCH_SIZE, dpi=BENCH_DPI, layout="constrained")
    top, middle, bottom = fig.subplots(3, 1, sharex=True, height_ratios=(3, 1.4, 2.2))
    deg = np.degrees
    alpha, size = deg(catalogue.alpha), np.asarray(catalogue.size, dtype=float)
    tilt = math.degrees(forecast.tilt_now)
    lo, hi = (math.degrees(x) for x in forecast.interval)
    point = math.degrees(forecast.point)
    levels = LEVELS if forecast.levels is None else np.asarray(forecast.levels)
    edges, dens = _density(forecast.quantiles, levels)

    # the catalogue: cumulative events above, each event's size below it
    count = np.arange(1, alpha.size + 1)
    top.step(np.concatenate([[0.0], alpha, [tilt]]),
             np.concatenate([[0], count, [count[-1] if count.size else 0]]), where="post",
             color="0.2", lw=1.2, label="events so far")
    top.set_ylabel("events so far")
    top.set_ylim(bottom=0)
    unit = "sliders" if size_unit == "sliders" else "size unit"
    if alpha.size:
        middle.vlines(alpha, 0, size, color="#1f78b4", lw=0.8)
        middle.plot(alpha, size, "o", ms=2.5, color="#1f78b4")
        middle.set_yscale("log")
        middle.set_ylim(0.7 * size.min(), 1.5 * size.max())
        plain = FuncFormatter(lambda v, _: f"{v:g}")
        middle.yaxis.set_major_formatter(plain)
        # within a decade the minor ticks (2, 3, 5...) carry the numbers
        middle.yaxis.set_minor_formatter(plain if size.max() < 10 * size.min() else NullFormatter())
    middle.set_ylabel(f"event size\n({unit})")
    # the forecast: density from the quantiles, the interval, the median
    if dens.size:
        bottom.stairs(dens, edges, fill=True, color=FORECAST_COLOUR, alpha=0.25, lw=0)
        bottom.stairs(dens, edges, color=FORECAST_COLOUR, lw=1.0)
    interval_name = "80 % interval" if calibrated else "widened interval, uncalibrated"
    for ax in (top, middle, bottom):
        ax.axvspan(lo, hi, color=FORECAST_COLOUR, alpha=0.12, lw=0,
                   label=f"{interval_name} {lo:.2f}-{hi:.2f}°" if ax is bottom else None)
        ax.axvline(point, color=FORECAST_COLOUR, lw=1.4, ls="--",
                   label=f"median {point:.2f}°" if ax is bottom else None)
        ax.axvline(tilt, color="k", lw=1.4, label=f"tilt reached {tilt:.2f}°" if ax is top else None)
        ax.axvspan(tilt, tilt + math.degrees(within), color="0.5", alpha=0.18, lw=0, hatch="///",
                   label=(f"next {math.degrees(within):g}°: P(avalanche) {probability}"
                          if ax is bottom else None))
        ax.grid(alpha=0.25, lw=0.5)
    bottom.set_ylabel("forecast density (1/°)")
    bottom.set_ylim(bottom=0)
    bottom.set_xlabel("tilt of the plane (°)")
    right = max(hi, float(edges[-1]) if edges.size else hi, tilt + math.degrees(within))
    left = 0.0
    bottom.set_xlim(left, right + 0.04 * (right - left))
    top.legend(loc="upper left", fontsize=8, frameon=True, framealpha=0.9)
    bottom.legend(loc="upper left", fontsize=8, frameon=True, framealpha=0.9)

    verdict = ("in the training domain" if in_domain else
               "OUT OF THE TRAINING DOMAIN: " + (domain_reason or "?"))
    fig.suptitle(f"{label}\navalanche at {point:.2f}° ({interval_name} {lo:.2f}-{hi:.2f}°), "
                 f"P(within the next {math.degrees(within):g}°) {probability}",
                 fontsize=9.5)
    top.set_title("\n".join(textwrap.wrap(verdict, 95)), fontsize=8.5,
                  color=IN_COLOUR if in_domain else OUT_COLOUR, loc="left")
    return fig


def save_png(fig, target) -> None:
    """Write ``fig`` as a PNG to ``target`` (a path or a binary file)."""
    fig.savefig(target, format="png", dpi=BENCH_DPI)
