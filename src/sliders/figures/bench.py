"""The bench picture of a forecast (``python -m sliders.forecast predict --plot out.png``).

One figure for the experimenter at the tilting plane: above, the catalogue
against tilt (the cumulative number of events, and each event's size as a stem on a
log scale); below, the forecast distribution of the avalanche angle (its density,
read from the quantiles, the interval shaded, the median marked); across both,
the tilt reached and the alarm's window.  The title says the forecast, P(within)
and the domain verdict; every angle is in degrees.
"""

from __future__ import annotations

import datetime
import math
import os
import textwrap

import numpy as np

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402  (after the backend)
from matplotlib.ticker import (FuncFormatter, LogLocator, MaxNLocator,  # noqa: E402
                               NullFormatter)
from matplotlib.transforms import offset_copy  # noqa: E402

from ..analysis.forecast.base import LEVELS  # noqa: E402

#: the picture's size (inches) and resolution: read on a screen beside the bench
BENCH_SIZE = (7.0, 5.6)
BENCH_DPI = 110
FORECAST_COLOUR = "#d95f02"
OUT_COLOUR = "#b2182b"
IN_COLOUR = "#1b7837"
ALARM_COLOUR = "#c40000"
#: the live picture's status banner (inches, added to the figure's height)
BANNER_HEIGHT = 0.5
#: the longest file name the status line shows (longer ones keep their end)
STATUS_FILE_CHARS = 60
#: how far below the lowest panel the legend starts (points: under its ticks and label)
LEGEND_DROP = 30.0
#: the least ratio of the size axis's top to its bottom: a 1-2-5 sequence's widest gap is a
#: factor 2.5, so the axis holds two of its ticks (with fewer, matplotlib ticks it linearly)
SIZE_AXIS_RATIO = 6.5
#: the narrowest bin of the forecast density, as a share of the angle axis
MIN_BIN_SHARE = 0.015


def _density(quantiles: np.ndarray, levels: np.ndarray, min_width: float = 0.0):
    """Edges (degrees) and the piecewise-constant density (per degree) between quantiles.

    No bin is narrower than ``min_width`` degrees: quantiles piled within a hair of each
    other (a forecast out of the training domain, held at the tilt reached) share one bin
    of that width, the distribution function read between quantiles as a straight line
    (the density the quantiles make).  Without it their probability would be one spike
    too thin to see."""
    q = np.degrees(np.asarray(quantiles, dtype=float))
    lv = np.asarray(levels, dtype=float)
    keep = np.concatenate([[True], np.diff(q) > 1e-9])
    q, lv = q[keep], lv[keep]
    if q.size < 2:
        return q, np.zeros(0)
    if min_width > 0.0 and q[-1] - q[0] > min_width:
        edges = [q[0]]
        while q[-1] - edges[-1] > 1e-9:
            following = q[q > edges[-1] + 1e-9]
            edges.append(following[0] if following[0] - edges[-1] >= min_width
                         else min(edges[-1] + min_width, q[-1]))
        if len(edges) > 2 and edges[-1] - edges[-2] < min_width:
            del edges[-2]  # the last bin takes the narrow one before it
        q = np.array(edges)
        lv = np.interp(q, np.degrees(np.asarray(quantiles, dtype=float))[keep],
                       np.asarray(levels, dtype=float)[keep])
    return q, np.diff(lv) / np.diff(q)


def _size_axis_ticks(axis, low: float, high: float) -> None:
    """Log ticks of the size axis that do not overlap: 1-2-5 within a decade and a half,
    1-3 up to three decades, every decade beyond (the numbers plain, never 10^k)."""
    decades = math.log10(max(high / low, 1.0))
    subs = (1.0, 2.0, 5.0) if decades < 1.3 else (1.0, 3.0) if decades < 3.0 else (1.0,)
    axis.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=12))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_locator(LogLocator(base=10.0, subs=np.arange(2, 10), numticks=12))
    axis.set_minor_formatter(NullFormatter())


def status_lines(status: dict) -> tuple[list[str], list[str], bool]:
    """The status banner of a live picture: its left lines (the alarm's state, its
    threshold), its right lines (the time and rows of the update, the file), and whether
    the alarm is raised; from ``status``'s ``"alarm"`` (bool), ``"alarm_threshold"``,
    ``"time"`` (a datetime or ISO text), ``"rows"`` and ``"file"``, each where given."""
    alarm = status.get("alarm")
    threshold = status.get("alarm_threshold")
    left = [] if alarm is None else ["ALARM" if alarm else "no alarm"]
    if threshold is not None:
        left.append(f"alarm at P(within) ≥ {float(threshold):g}")
    update = []
    when = status.get("time")
    if when is not None:
        if isinstance(when, str):
            try:
                when = datetime.datetime.fromisoformat(when)
            except ValueError:
                pass
        if isinstance(when, datetime.datetime):
            zone = when.strftime(" %Z") if when.tzinfo is not None else ""
            when = when.strftime("%Y-%m-%d %H:%M:%S") + zone
        update.append(f"updated {when}")
    if status.get("rows") is not None:
        rows = int(status["rows"])
        update.append(f"{rows} row{'s' if rows != 1 else ''}")
    right = ["  ·  ".join(update)] if update else []
    if status.get("file"):
        name = os.fspath(status["file"])
        if len(name) > STATUS_FILE_CHARS:
            name = "…" + name[-(STATUS_FILE_CHARS - 1):]
        right.append(name)
    return left, right, bool(alarm)


def bench_figure(catalogue, forecast, *, label: str, calibrated: bool, in_domain: bool,
                 domain_reason: str | None, probability: str, within: float,
                 size_unit: str = "sliders", size_label: str | None = None,
                 status: dict | None = None, interval_name: str | None = None):
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
    size_label : str, optional
        The sizes' unit as the axis names it (``"mm²"``, ``"grains"``); default: "sliders",
        or "CSV's unit" for arbitrary sizes.
    status : dict, optional
        A live picture's state, drawn as a banner above the panels (red when the alarm is
        raised): ``"alarm"`` (bool), ``"alarm_threshold"`` (float), ``"time"`` (a datetime
        or ISO text), ``"rows"`` (int), ``"file"`` (text), each optional.
    interval_name : str, optional
        What the interval is called, as the text output calls it (default: "80 % interval"
        when ``calibrated``, else "interval, uncalibrated").

    Returns
    -------
    matplotlib.figure.Figure
    """
    width, height = BENCH_SIZE
    fig = Figure(figsize=(width, height + (BANNER_HEIGHT if status is not None else 0.0)),
                 dpi=BENCH_DPI, layout="constrained")
    ratios = (3, 1.4, 2.2)
    grid = fig.add_gridspec(len(ratios) + (status is not None), 1,
                            height_ratios=((BANNER_HEIGHT / height * sum(ratios),) if status
                                           is not None else ()) + ratios)
    first = 1 if status is not None else 0
    top = fig.add_subplot(grid[first])
    middle = fig.add_subplot(grid[first + 1], sharex=top)
    bottom = fig.add_subplot(grid[first + 2], sharex=top)
    for ax in (top, middle):
        ax.tick_params(labelbottom=False)
    deg = np.degrees
    alpha, size = deg(catalogue.alpha), np.asarray(catalogue.size, dtype=float)
    tilt = math.degrees(forecast.tilt_now)
    lo, hi = (math.degrees(x) for x in forecast.interval)
    point = math.degrees(forecast.point)
    levels = LEVELS if forecast.levels is None else np.asarray(forecast.levels)
    right = max(hi, math.degrees(float(np.max(forecast.quantiles))), tilt + math.degrees(within))
    left = 0.0
    edges, dens = _density(forecast.quantiles, levels, MIN_BIN_SHARE * (right - left))

    _catalogue_panels(top, middle, alpha, size, tilt, size_label or (
        "sliders" if size_unit == "sliders" else "CSV's unit"))
    _forecast_panel(bottom, forecast, edges, dens)
    if interval_name is None:
        interval_name = "80 % interval" if calibrated else "interval, uncalibrated"
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
    bottom.set_ylim(0, 1.08 * float(dens.max()) if dens.size and dens.max() > 0 else 1.0)
    bottom.set_xlabel("tilt of the plane (°)")
    bottom.set_xlim(left, right + 0.04 * (right - left))
    _legend_below(fig, top, bottom)

    verdict = ("in the training domain" if in_domain else
               "OUT OF THE TRAINING DOMAIN: " + (domain_reason or "?"))
    fig.suptitle(f"{label}\navalanche at {point:.2f}° ({interval_name} {lo:.2f}-{hi:.2f}°), "
                 f"P(within the next {math.degrees(within):g}°) {probability}",
                 fontsize=9.5)
    top.set_title("\n".join(textwrap.wrap(verdict, 95)), fontsize=8.5,
                  color=IN_COLOUR if in_domain else OUT_COLOUR, loc="left")
    if status is not None:
        _banner(fig.add_subplot(grid[0]), status)
    return fig


def _catalogue_panels(top, middle, alpha, size, tilt: float, unit: str) -> None:
    """The catalogue: the cumulative count of events (``top``), each event's size below it
    (``middle``, log), in ``unit``."""
    count = np.arange(1, alpha.size + 1)
    top.step(np.concatenate([[0.0], alpha, [tilt]]),
             np.concatenate([[0], count, [count[-1] if count.size else 0]]), where="post",
             color="0.2", lw=1.2)
    top.set_ylabel("events so far")
    top.set_ylim(0, max(1, alpha.size) * 1.06)
    top.yaxis.set_major_locator(MaxNLocator(nbins=6, integer=True, min_n_ticks=2))
    middle.set_yscale("log")
    if alpha.size:
        middle.vlines(alpha, 0, size, color="#1f78b4", lw=0.8)
        middle.plot(alpha, size, "o", ms=2.5, color="#1f78b4")
        low, high = 0.7 * size.min(), 1.5 * size.max()
        if high / low < SIZE_AXIS_RATIO:  # two 1-2-5 ticks at least (fewer: linear ones)
            widen = math.sqrt(SIZE_AXIS_RATIO * low / high)
            low, high = low / widen, high * widen
        middle.set_ylim(low, high)
        _size_axis_ticks(middle.yaxis, low, high)
    middle.set_ylabel(f"event size\n({unit})")


def _forecast_panel(bottom, forecast, edges, dens) -> None:
    """The forecast: its density from the quantiles, and each quantile (5 %, 10 % ... 95 %) as
    a tick on the axis, to read where the probability lies even where the density is too low
    to see."""
    if dens.size:
        bottom.stairs(dens, edges, fill=True, color=FORECAST_COLOUR, alpha=0.35, lw=0)
        bottom.stairs(dens, edges, color=FORECAST_COLOUR, lw=1.2)
    bottom.plot(np.degrees(np.asarray(forecast.quantiles, dtype=float)),
                np.zeros(np.size(forecast.quantiles)), "|", color=FORECAST_COLOUR, ms=9,
                mew=1.0, clip_on=False, zorder=5)


def _legend_below(fig, top, bottom) -> None:
    """One legend of the top and bottom panels' entries, under the bottom panel's axis label,
    never on the data."""
    handles, labels = [], []
    for ax in (top, bottom):
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    bottom.legend(handles, labels, loc="upper center", ncol=2, fontsize=8, frameon=False,
                  bbox_to_anchor=(0.5, 0.0), borderaxespad=0.0,
                  bbox_transform=offset_copy(bottom.transAxes, fig=fig, y=-LEGEND_DROP,
                                             units="points"))


def _banner(ax, status: dict) -> None:
    """The live picture's status banner: the alarm's state and threshold at the left (white
    on red when the alarm is raised), the update's time and rows and the file at the right."""
    left, right, alarm = status_lines(status)
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_facecolor(ALARM_COLOUR if alarm else "0.92")
    ink = "white" if alarm else "0.1"
    for x, ha, lines in ((0.008, "left", left), (0.992, "right", right)):
        for k, text in enumerate(lines):
            y = 0.5 if len(lines) == 1 else 0.72 - 0.46 * k
            big = ha == "left" and k == 0 and status.get("alarm") is not None
            ax.text(x, y, text, transform=ax.transAxes, ha=ha, va="center", color=ink,
                    fontsize=11 if big else 8, fontweight="bold" if big else "normal",
                    gid="status", in_layout=False)


def save_png(fig, target) -> None:
    """Write ``fig`` as a PNG to ``target`` (a path or a binary file)."""
    fig.savefig(target, format="png", dpi=BENCH_DPI)
