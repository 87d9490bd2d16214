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
#: displacements in the model's unit (g tau^2), or in a camera's (pixels, mm: any positive scale)
DISPLACEMENT_UNITS = ("model", "arbitrary")
#: the movers' positions as slider indices (0 up-slope), as fractions of the pile's length
#: along the slope from its up-slope end (the centre of slider i of N at (i + 1/2) / N), or in
#: millimetres from that end (with the pile's length)
POSITION_UNITS = ("sliders", "fraction", "mm")
#: the ranges the training measurements are drawn from: angle error (radians, 0 with
#: probability ``p_exact``, else log-uniform), smallest detected size (sliders), share of
#: events missed (0 with probability ``p_exact``, else uniform), and the share of cuts
#: whose sizes are in an arbitrary unit (scaled by a log-uniform factor)
MEASUREMENT_RANGES = {"angle_resolution": (math.radians(0.02), math.radians(1.2)),
                      "min_size": (1, 2, 3, 5), "missed_fraction": (0.0, 0.6),
                      "size_scale": (0.3, 30.0), "p_exact": 0.35, "p_arbitrary": 0.3}
#: a camera's record (``draw_camera``): the displacement unit over four decades of the model's
#: (log-uniform), each event's displacement with a relative error (log-normal, 0 with
#: probability ``p_exact`` else uniform up to ``displacement_noise``), positions as fractions
CAMERA_RANGES = {"displacement_scale": (1e-2, 1e2), "displacement_noise": (0.0, 0.3)}
#: the pile's number of sliders told to the training cuts (``tell_sliders``): to a share
#: ``p_told`` of them (by default; a learned forecaster's ``told_share``), as the number itself
#: to a share ``p_exact`` of those, else as a range around it, each end up to
#: ``range_factor`` away (log-uniform)
SLIDERS_TOLD = {"p_told": 0.0, "p_exact": 0.4, "range_factor": 4.0}
#: the measurement's features, in order: how the catalogue was recorded (``RECORD_FEATURES``),
#: and the number of sliders told, as the logs of its range's ends (NaN when not told)
RECORD_FEATURES = ("angle_resolution", "min_size", "missed_fraction", "size_arbitrary")
TOLD_FEATURES = ("log_sliders_low", "log_sliders_high")
MEASUREMENT_FEATURES = (*RECORD_FEATURES, *TOLD_FEATURES)


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
        The number of sliders of the pile, if known (with ``n_sliders_high``: the
        least of a range).  A feature of the forecasters trained told it (as the
        logs of the range's ends); the domain check compares it with the training
        piles'.
    n_sliders_high : int, optional
        The largest number of sliders of the range told (None: ``n_sliders`` itself).
    displacement_unit : {"model", "arbitrary"}
        Displacements in g tau^2, or in a camera's unit (pixels, mm): then only
        displacements relative to the catalogue's own are used (``camera_features``).
    position_unit : {"sliders", "fraction", "mm"}
        The movers' positions (``first``, ``last``) as slider indices, as
        fractions of the pile's length from its up-slope end, or in millimetres
        from that end.
    pile_length : float, optional
        The pile's length along the slope in millimetres (with ``position_unit`` "mm").
    """

    angle_resolution: float = 0.0
    min_size: float = 1.0
    missed_fraction: float = 0.0
    size_unit: str = "sliders"
    n_sliders: int | None = None
    n_sliders_high: int | None = None
    displacement_unit: str = "model"
    position_unit: str = "sliders"
    pile_length: float | None = None

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
        high = self.n_sliders_high
        if high is not None and (self.n_sliders is None or isinstance(high, bool)
                                 or not isinstance(high, int) or high < self.n_sliders):
            raise ValueError(f"number of sliders {self.n_sliders!r}-{high!r} must be a range "
                             "of whole numbers, the first the least")
        if self.displacement_unit not in DISPLACEMENT_UNITS:
            raise ValueError(f"displacement unit {self.displacement_unit!r} must be one of "
                             f"{DISPLACEMENT_UNITS}")
        if self.position_unit not in POSITION_UNITS:
            raise ValueError(f"position unit {self.position_unit!r} must be one of {POSITION_UNITS}")
        mm = self.position_unit == "mm"
        length = self.pile_length
        if mm and (length is None or isinstance(length, bool) or not isinstance(length, (int, float))
                   or not math.isfinite(length) or length <= 0):
            raise ValueError(f"positions in mm need the pile's length in mm, a positive number "
                             f"(pile length {length!r})")
        if not mm and length is not None:
            raise ValueError("the pile's length converts positions in mm: give it with the "
                             "position unit mm")

    @property
    def camera(self) -> bool:
        """The displacements or the positions are a camera's (not the model's units)."""
        return self.displacement_unit == "arbitrary" or self.position_unit != "sliders"

    def in_model_units(self) -> "Measurement":
        """The same record with displacements in g tau^2 and positions as slider indices (a
        camera's catalogue read back in the model's units, or kept to its angles and sizes)."""
        return replace(self, displacement_unit="model", position_unit="sliders", pile_length=None)

    def position_fractions(self, positions: np.ndarray) -> np.ndarray:
        """A camera's positions as fractions of the pile's length (-1: unknown, kept)."""
        p = np.asarray(positions, dtype=float)
        if self.position_unit == "mm":
            return np.where(p >= 0, p / self.pile_length, -1.0)
        return p

    def as_features(self, catalogue: Catalogue) -> np.ndarray:
        """The measurement features of ``catalogue`` (``MEASUREMENT_FEATURES``).

        In an arbitrary unit the detection threshold is read against the
        catalogue's median size, the only scale the catalogue itself has.
        """
        arbitrary = self.size_unit == "arbitrary"
        m = self.min_size
        if arbitrary:
            med = float(np.median(catalogue.size)) if len(catalogue) else np.nan
            m = m / med if med > 0 else np.nan
        low = math.log(self.n_sliders) if self.n_sliders else np.nan
        high = math.log(self.n_sliders_high) if self.n_sliders_high else low
        return np.array([self.angle_resolution, m, self.missed_fraction, float(arbitrary), low,
                         high])


PERFECT = Measurement()


def degrade(catalogue: Catalogue, measurement: Measurement, rng: np.random.Generator,
            size_scale: float = 1.0, camera: tuple | None = None,
            n_sliders: int | None = None) -> Catalogue:
    """``catalogue`` as an experiment of ``measurement`` records it (a new catalogue).

    Events below ``min_size`` (in the measured unit: sliders times ``size_scale``) are dropped, then a share
    ``missed_fraction`` of the rest at random; each angle gets a Gaussian
    error of ``angle_resolution`` (sorted again, kept above 0; the tilt reached is then at
    least the last angle, which may lie above the true tilt, and above the avalanche);
    sizes are multiplied by ``size_scale`` (an arbitrary unit; rounded up to
    whole units, at least 1).  The displacement and the movers are kept for
    the events kept; ``camera`` = (scale, relative error): each displacement is
    multiplied by the scale and by a log-normal error of that relative size
    (``measurement.displacement_unit`` "arbitrary"), and with
    ``measurement.position_unit`` "fraction" the movers' indices become
    fractions of the pile's length, ``(i + 1/2) / n_sliders``.
    """
    keep = catalogue.size * size_scale >= measurement.min_size * (1 - 1e-9)
    if measurement.missed_fraction > 0:
        keep &= rng.random(len(catalogue)) >= measurement.missed_fraction
    alpha = catalogue.alpha[keep]
    tilt_now = catalogue.tilt_now
    if measurement.angle_resolution > 0 and alpha.size:
        alpha = alpha + rng.normal(0.0, measurement.angle_resolution, alpha.size)
        alpha = np.maximum(alpha, 0.0)
        tilt_now = max(tilt_now, float(alpha.max()))  # at least the last event seen
    order = np.argsort(alpha, kind="stable")
    size = catalogue.size[keep][order]
    if size_scale != 1.0:
        size = np.maximum(np.ceil(size * size_scale), 1)
    disp = catalogue.displacement[keep][order]
    if camera is not None:
        scale, noise = camera
        disp = disp * scale * (np.exp(rng.normal(0.0, noise, disp.size)) if noise > 0 else 1.0)
    first, last = catalogue.first[keep][order], catalogue.last[keep][order]
    if measurement.position_unit == "fraction":  # unknown without the number of sliders
        n = n_sliders if n_sliders is not None and n_sliders >= 1 else math.inf
        first, last = (np.where((i >= 0) & np.isfinite(n), (i + 0.5) / n, -1.0)
                       for i in (first, last))
    return Catalogue(alpha[order], size, disp, first, last, tilt_now=tilt_now)


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


def draw_camera(n: int, rng: np.random.Generator, ranges: dict | None = None) -> list:
    """``n`` cameras' (displacement scale, relative displacement error) from ``CAMERA_RANGES``."""
    r = CAMERA_RANGES if ranges is None else ranges
    lo, hi = r["displacement_scale"]
    scale = np.exp(rng.uniform(math.log(lo), math.log(hi), n))
    noise = np.where(rng.random(n) < MEASUREMENT_RANGES["p_exact"], 0.0,
                     rng.uniform(*r["displacement_noise"], n))
    return list(zip(scale.tolist(), noise.tolist()))


def degrade_cuts(cuts, rng: np.random.Generator, measurement: Measurement | None = None,
                 size_scale: float = 1.0, camera: bool = False, told_share: float | None = None):
    """New ``Cuts``: each catalogue degraded, by ``measurement`` or by one drawn per cut.

    ``camera``: recorded by a camera too (``draw_camera``; positions as fractions of the
    pile's length, of the cuts' ``n_sliders``: unknown without them).  The truth and the simulation's
    extras are kept; the measurements are recorded with the cuts, as ``predict`` is told them.
    ``told_share``: the share of drawn measurements told their pile's size (default:
    ``SLIDERS_TOLD["p_told"]``).
    """
    if measurement is None:
        meas, scales = draw_measurements(len(cuts), rng)
    else:
        meas, scales = [measurement] * len(cuts), np.full(len(cuts), size_scale)
    cams = [None] * len(cuts)
    if camera:
        meas = [replace(m, displacement_unit="arbitrary", position_unit="fraction") for m in meas]
        cams = draw_camera(len(cuts), rng)
    n = np.full(len(cuts), -1) if cuts.n_sliders is None else np.asarray(cuts.n_sliders)
    cats = [degrade(c, m, rng, float(s), cam, int(k))
            for c, m, s, cam, k in zip(cuts.catalogues, meas, scales, cams, n)]
    if measurement is None and cuts.n_sliders is not None:
        meas = tell_sliders(meas, cuts.n_sliders, rng, None if told_share is None else
                            {**SLIDERS_TOLD, "p_told": told_share})
    return replace(cuts, catalogues=cats, measurement=meas, cache={})


def tell_sliders(measurements: list, n_sliders, rng: np.random.Generator,
                 told: dict | None = None) -> list:
    """``measurements`` with their piles' numbers of sliders told to some (``SLIDERS_TOLD``):
    the number itself, or a range holding it whose ends lie up to a factor away."""
    t = SLIDERS_TOLD if told is None else told
    k = len(measurements)
    tell = rng.random(k) < t["p_told"]
    exact = rng.random(k) < t["p_exact"]
    spread = np.exp(rng.uniform(0.0, math.log(t["range_factor"]), (k, 2)))
    out = []
    for m, n, y, e, (lo, hi) in zip(measurements, np.asarray(n_sliders).tolist(), tell, exact,
                                    spread.tolist()):
        if y and n >= 1:
            low, high = (n, n) if e else (max(1, math.floor(n / lo)), math.ceil(n * hi))
            m = replace(m, n_sliders=int(low), n_sliders_high=None if high == low else int(high))
        out.append(m)
    return out
