"""Forecasters from the paper's physics.

* ``PaperRule``: the paper's transition near half the avalanche angle.  The
  paper (and REPRODUCTION.md, statement 11) marks it where P_1 + P_2, the
  share of sliders within two bins of their threshold, leaves its linear
  trend by more than 3 standard errors on two angles in a row.  P_1 + P_2 is
  not in a catalogue; its catalogue image is the rate at which sliders are
  set moving (sliders near threshold per unit tilt), counted in bins of
  ``bin_width``.  Online: a line fitted on the bins so far, the transition at
  the first bin which, with the next, lies 3 prediction errors above it.
  Then ``alpha_c = c alpha_t`` with ``c`` from training runs.
* ``ModelBased``: ``alpha_c ~ atan(mu_d)`` (the avalanche bound of the
  paper; ``alpha_c - atan(mu_d)`` is small), with ``mu_d`` from the catalogue:
  a slider that slips alone twice while its neighbours rest obeys the exact
  form of the single-slider period, which gives ``mu_d`` from the two angles
  and displacements (``features.single_slider_mu_d``).  Without such pairs:
  ``mu_d = mu_s - Delta mu``, ``Delta mu`` from the lone slips' displacements
  ``(mu_s,n - mu_d) cos(alpha)`` and ``mu_s`` from the number of events up to
  ``features.EARLY_ANGLE``, which the crude limit of the model's P_1,
  ``(1 + alpha / (2 Delta mu)) / (2 mu_s)`` per slider and unit tilt, puts at
  ``N (a + a^2 / (4 Delta mu)) / (2 mu_s)``.
"""

from __future__ import annotations

import numpy as np

from .base import LEVELS, Forecaster, quantiles_of_sample
from .baselines import Climatology, conditioned_quantiles
from .features import catalogue_features, training_cuts
from .integrity import Spec

#: prediction errors above the trend that mark the transition (REPRODUCTION.md: 3)
DEPARTURE_SIGMAS = 3.0


def transition_angle(cat, bin_width: float = 0.01, min_bins: int = 6) -> float:
    """The transition seen online: where the rate of sliders set moving leaves its linear trend.

    Parameters
    ----------
    cat : Catalogue
        Events up to ``cat.tilt_now``; only complete bins are used.
    bin_width : float
        Bin of tilt, radians.
    min_bins : int
        Bins in the first trend fit.

    Returns
    -------
    float
        Centre of the first bin that, with the next one, lies more than
        ``DEPARTURE_SIGMAS`` prediction errors above the line fitted on the
        bins before it; NaN if none yet.
    """
    if len(cat) == 0:
        return np.nan
    a0 = np.floor(cat.alpha[0] / bin_width) * bin_width
    nb = int(np.floor((cat.tilt_now - a0) / bin_width + 1e-9))
    if nb < min_bins + 2:
        return np.nan
    edges = a0 + bin_width * np.arange(nb + 1)
    y, _ = np.histogram(cat.alpha, edges, weights=cat.size.astype(float))
    x = 0.5 * (edges[1:] + edges[:-1])
    # least squares on bins [0, k) for every k, from running sums
    n = np.arange(1, nb + 1, dtype=float)
    sx, sy = np.cumsum(x), np.cumsum(y)
    sxx, sxy, syy = np.cumsum(x * x), np.cumsum(x * y), np.cumsum(y * y)
    k = np.arange(min_bins, nb - 1)  # fit on [0, k), test bins k and k + 1
    m = n[k - 1]
    xm, ym = sx[k - 1] / m, sy[k - 1] / m
    cxx = sxx[k - 1] - m * xm * xm
    cxy = sxy[k - 1] - m * xm * ym
    cyy = syy[k - 1] - m * ym * ym
    slope = cxy / cxx
    s2 = np.maximum(cyy - slope * cxy, 0.0) / (m - 2)
    s2 = np.maximum(s2, np.maximum(ym, 1.0))  # at least the Poisson variance of a count
    dev = np.empty((k.size, 2))
    for j in (0, 1):
        xj = x[k + j]
        line = ym + slope * (xj - xm)
        err = np.sqrt(s2 * (1.0 + 1.0 / m + (xj - xm) ** 2 / cxx))
        dev[:, j] = (y[k + j] - line) / err
    hit = np.flatnonzero((dev[:, 0] > DEPARTURE_SIGMAS) & (dev[:, 1] > DEPARTURE_SIGMAS))
    return float(x[k[hit[0]]]) if hit.size else np.nan


class PaperRule(Forecaster):
    """``alpha_c = c * alpha_t``, the transition detected online, ``c`` calibrated on training runs.

    Parameters
    ----------
    bin_width : float
        Bin of tilt of ``transition_angle``, radians.
    """

    name = "paper_rule"
    label = "paper's rule (c α_t)"

    def __init__(self, bin_width: float = 0.01):
        self.bin_width = bin_width

    def fit(self, train, y=None):
        """Measure ``c = alpha_c / alpha_t`` on the training runs (whole catalogues)."""
        self.climatology_ = Climatology().fit(train)
        ratios = []
        for i in np.flatnonzero(np.isfinite(train.alpha_c)):
            at = transition_angle(train.catalogue(int(i)), self.bin_width)
            if np.isfinite(at):
                ratios.append(train.alpha_c[i] / at)
        self.ratios_ = np.array(ratios)
        self.detected_share_ = self.ratios_.size / max(int(np.isfinite(train.alpha_c).sum()), 1)
        self.c_quantiles_ = quantiles_of_sample(self.ratios_) if self.ratios_.size else None
        return self

    def _quantiles(self, cuts):
        t = cuts.tilt_now
        q, _ = conditioned_quantiles(self.climatology_.alpha_c_, t)
        fb = np.ones(len(cuts), bool)
        if self.c_quantiles_ is None:
            return q, fb
        for i, cat in enumerate(cuts.catalogues):
            at = transition_angle(cat, self.bin_width)
            if np.isfinite(at):
                q[i] = np.maximum(at * self.c_quantiles_, t[i])
                fb[i] = False
        return q, fb


class ModelBased(Forecaster):
    """``alpha_c ~ atan(mu_d)``, with ``mu_d`` from the catalogue by the paper's single-slider physics.

    ``mu_d`` is the value on which most lone-slider pairs agree
    (``features.single_slider_mu_d``, ``features.densest_value``); where no
    pair exists, the cruder estimate from the early event rate and the
    single-slider displacements (``atan_mu_d_model``).  The interval: the
    spread of ``alpha_c - atan(mu_d_hat)`` on training cuts, separately for
    estimates on which at least ``MIN_AGREE`` pairs agree, on which fewer do,
    and the crude ones.

    Parameters
    ----------
    draws_per_row : int
        Random training cuts per training realisation.
    random_state : int
        Seeds the cuts.
    """

    name = "model_based"
    label = "model-based (μ_d from lone slips)"

    #: agreeing pairs that make an estimate "firm"
    MIN_AGREE = 3
    #: the climatology to fall back on; the residual quantiles of each kind of estimate
    FIELDS = {"climatology_": Spec("part", of=Climatology),
              "residual_quantiles_": Spec("dict", keys=("0", "1", "2"), of=Spec(
                  "f", shape=LEVELS.shape, lo=-np.pi / 2, hi=np.pi / 2, increasing=True))}

    def __init__(self, draws_per_row: int = 5, random_state: int = 0):
        self.draws_per_row = draws_per_row
        self.random_state = random_state

    @classmethod
    def estimate(cls, cats) -> tuple[np.ndarray, np.ndarray]:
        """atan of the estimated mu_d of each catalogue, and its kind (0 firm, 1 loose, 2 crude, -1 none)."""
        est, kind = np.full(len(cats), np.nan), np.full(len(cats), -1)
        for i, c in enumerate(cats):
            f = catalogue_features(c)
            if np.isfinite(f["atan_mu_d_single"]):
                est[i] = f["atan_mu_d_single"]
                kind[i] = 0 if f["single_slider_agree"] >= cls.MIN_AGREE else 1
            elif np.isfinite(f["atan_mu_d_model"]):
                est[i], kind[i] = f["atan_mu_d_model"], 2
        return est, kind

    def fit(self, train, y=None):
        """Residuals ``alpha_c - atan(mu_d_hat)`` on random training cuts, per kind of estimate."""
        self.climatology_ = Climatology().fit(train)
        cuts = training_cuts(train, self.draws_per_row, np.random.default_rng(self.random_state))
        est, kind = self.estimate(cuts.catalogues)
        self.residual_quantiles_ = {}
        for k in (0, 1, 2):
            m = kind == k
            if m.sum() >= 10:  # keyed by str: a model file's dict keys are names
                self.residual_quantiles_[str(k)] = quantiles_of_sample(cuts.alpha_c[m] - est[m])
        return self

    def _quantiles(self, cuts):
        t = cuts.tilt_now
        q, _ = conditioned_quantiles(self.climatology_.alpha_c_, t)
        fb = np.ones(len(cuts), bool)
        est, kind = self.estimate(cuts.catalogues)
        for k, res in self.residual_quantiles_.items():
            m = kind == int(k)
            q[m] = np.maximum(est[m, None] + res[None, :], t[m, None])
            fb[m] = False
        return q, fb
