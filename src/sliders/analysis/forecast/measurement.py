"""How a catalogue was measured, and a simulated catalogue degraded the same way.

An experiment does not record the model's catalogue: its angles carry an
error, its smallest events go undetected, some events are missed, and its
sizes may be in grains, areas or pixels rather than sliders.  ``Measurement``
says all four; ``degrade`` applies them to a simulated catalogue; the
learned forecasters train on catalogues degraded by measurements drawn from
``MEASUREMENT_RANGES`` (``draw_measurements``) and see the measurement as
features (``Measurement.as_features``), so that ``predict`` told the truth
about a catalogue forecasts it as one of its own kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...io.catalogue import Catalogue

SIZE_UNITS = ("sliders", "arbitrary")
#: the ranges the training measurements are drawn from: angle error (radians, 0 with
#: probability ``p_exact``, else log-uniform), smallest detected size (sliders), share of
#: events missed (0 with probability ``p_exact``, else uniform), and the share of cuts
#: whose sizes are in an arbitrary unit (scaled by a log-uniform factor)
MEASUREMENT_RANGES = {"angle_resolution": (math.radians(0.02), math.radians(1.2)),
                      "min_size": (1, 2, 3, 5), "missed_fraction": (0.0, 0.6),
                      "size_scale": (0.3, 30.0), "p_exact": 0.35, "p_arbitrary": 0.3}
#: the measurement's features, in order
MEASUREMENT_FEATURES = ("angle_resolution", "min_size", "missed_fraction", "size_arbitrary")


@dataclass(frozen=True)
class Measurement:
    """What an experiment knows about how its catalogue was recorded.

    Parameters
    ----------
    angle_resolution : float
        Standard deviation of each event's angle error, radians (0: exact).
    min_size : float
        The smallest event size detected, in the catalogue's size unit.
    missed_fraction : float
        Share of events missed at random, in [0, 1).
    size_unit : {"sliders", "arbitrary"}
        Sizes count sliders moved, or are in an unknown unit (grains, area,
        pixels): then only size ratios are used.
    n_sliders : int, optional
        The number of sliders of the pile, if known.  Not a feature (the
        catalogue's own rates carry it); the domain check compares it with
        the training piles'.
    """

    angle_resolution: float = 0.0
    min_size: float = 1.0
    missed_fraction: float = 0.0
    size_unit: str = "sliders"
    n_sliders: int | None = None

    def __post_init__(self):
        if not (math.isfinite(self.angle_resolution) and self.angle_resolution >= 0):
            raise ValueError(f"angle resolution {self.angle_resolution!r} must be >= 0")
        if not (math.isfinite(self.min_size) and self.min_size > 0):
            raise ValueError(f"min size {self.min_size!r} must be > 0")
        if not 0.0 <= self.missed_fraction < 1.0:
            raise ValueError(f"missed fraction {self.missed_fraction!r} must be in [0, 1)")
        if self.size_unit not in SIZE_UNITS:
            raise ValueError(f"size unit {self.size_unit!r} must be one of {SIZE_UNITS}")
        if self.n_sliders is not None and (isinstance(self.n_sliders, bool)
                                           or not isinstance(self.n_sliders, int)
                                           or self.n_sliders < 1):
            raise ValueError(f"number of sliders {self.n_sliders!r} must be a whole number >= 1")

    def as_features(self, catalogue: Catalogue) -> np.ndarray:
        """The four measurement features of ``catalogue`` (``MEASUREMENT_FEATURES``).

        In an arbitrary unit the detection threshold is read against the
        catalogue's median size, the only scale the catalogue itself has.
        """
        arbitrary = self.size_unit == "arbitrary"
        m = self.min_size
        if arbitrary:
            med = float(np.median(catalogue.size)) if len(catalogue) else np.nan
            m = m / med if med > 0 else np.nan
        return np.array([self.angle_resolution, m, self.missed_fraction, float(arbitrary)])


PERFECT = Measurement()


def degrade(catalogue: Catalogue, measurement: Measurement, rng: np.random.Generator,
            size_scale: float = 1.0) -> Catalogue:
    """``catalogue`` as an experiment of ``measurement`` records it (a new catalogue).

    Events below ``min_size`` (in the measured unit: sliders times ``size_scale``) are dropped, then a share
    ``missed_fraction`` of the rest at random; each angle gets a Gaussian
    error of ``angle_resolution`` (sorted again, kept in [0, tilt reached]);
    sizes are multiplied by ``size_scale`` (an arbitrary unit; rounded up to
    whole units, at least 1).  The displacement and the movers are kept for
    the events kept.
    """
    keep = catalogue.size * size_scale >= measurement.min_size * (1 - 1e-9)
    if measurement.missed_fraction > 0:
        keep &= rng.random(len(catalogue)) >= measurement.missed_fraction
    alpha = catalogue.alpha[keep]
    if measurement.angle_resolution > 0 and alpha.size:
        alpha = alpha + rng.normal(0.0, measurement.angle_resolution, alpha.size)
        alpha = np.clip(alpha, 0.0, catalogue.tilt_now)
    order = np.argsort(alpha, kind="stable")
    size = catalogue.size[keep][order]
    if size_scale != 1.0:
        size = np.maximum(np.ceil(size * size_scale), 1)
    return Catalogue(alpha[order], size, catalogue.displacement[keep][order],
                     catalogue.first[keep][order], catalogue.last[keep][order],
                     tilt_now=catalogue.tilt_now)


def draw_measurements(n: int, rng: np.random.Generator, ranges: dict | None = None):
    """``n`` measurements drawn from ``ranges`` (``MEASUREMENT_RANGES``) and their size scales."""
    r = MEASUREMENT_RANGES if ranges is None else ranges
    lo, hi = r["angle_resolution"]
    res = np.where(rng.random(n) < r["p_exact"], 0.0,
                   np.exp(rng.uniform(math.log(lo), math.log(hi), n)))
    min_size = rng.choice(np.asarray(r["min_size"], dtype=float), n)
    min_size = np.where(rng.random(n) < r["p_exact"], 1.0, min_size)
    missed = np.where(rng.random(n) < r["p_exact"], 0.0, rng.uniform(*r["missed_fraction"], n))
    arbitrary = rng.random(n) < r["p_arbitrary"]
    s_lo, s_hi = r["size_scale"]
    scale = np.where(arbitrary, np.exp(rng.uniform(math.log(s_lo), math.log(s_hi), n)), 1.0)
    out = [Measurement(float(a), float(m * s), float(f), "arbitrary" if b else "sliders")
           for a, m, f, b, s in zip(res, min_size, missed, arbitrary, scale)]
    return out, scale


def degrade_cuts(cuts, rng: np.random.Generator, measurement: Measurement | None = None,
                 size_scale: float = 1.0):
    """New ``Cuts``: each catalogue degraded, by ``measurement`` or by one drawn per cut.

    The truth and the simulation's extras are kept; the measurements are
    recorded with the cuts, as ``predict`` is told them.
    """
    if measurement is None:
        meas, scales = draw_measurements(len(cuts), rng)
    else:
        meas, scales = [measurement] * len(cuts), np.full(len(cuts), size_scale)
    cats = [degrade(c, m, rng, float(s)) for c, m, s in zip(cuts.catalogues, meas, scales)]
    return replace(cuts, catalogues=cats, measurement=meas, cache={})
