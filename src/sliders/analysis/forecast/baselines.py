"""The baselines every forecaster is compared with.

* ``Climatology``: the prior's ``alpha_c`` distribution, the data ignored.
* ``ConditionedClimatology``: the same, restricted to ``alpha_c`` above the
  tilt reached (what was seen: the avalanche has not come yet).
* ``Now``: ``alpha_c = alpha_obs``; perfect at the end, useless early.
* ``LastEventPlusLead``: the last event's angle plus the lead, last event to
  avalanche, of training cuts (its median as the point).
"""

from __future__ import annotations

import numpy as np

from .base import LEVELS, Forecaster, ForecastError, quantiles_of_sample
from .features import training_cuts
from .integrity import Spec

#: fewest training avalanche angles above the tilt for the conditioned climatology
MIN_ABOVE = 5


def _finite_alpha_c(train) -> np.ndarray:
    a = np.asarray(train.alpha_c, dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        raise ForecastError("the training set has no realisation that reached the avalanche")
    return np.sort(a)


class Climatology(Forecaster):
    """The prior's distribution of ``alpha_c`` (training realisations), whatever was seen."""

    name = "climatology"
    label = "climatology"
    #: sorted avalanche angles in (0, 90°), more than the conditioned climatology's MIN_ABOVE
    FIELDS = {"alpha_c_": Spec("f", lo=1e-9, hi=np.pi / 2, increasing=True, min_size=MIN_ABOVE + 1),
              "quantiles_": Spec("f", shape=LEVELS.shape, lo=0.0, hi=np.pi / 2, increasing=True)}

    def fit(self, train, y=None):
        """Keep the training realisations' avalanche angles."""
        self.alpha_c_ = _finite_alpha_c(train)
        self.quantiles_ = quantiles_of_sample(self.alpha_c_)
        return self

    def _quantiles(self, cuts):
        return np.tile(self.quantiles_, (len(cuts), 1)), np.zeros(len(cuts), bool)

    def conditioned(self, tilt_now) -> np.ndarray:
        """(n, len(LEVELS)) the conditioned climatology above each tilt (``conditioned_quantiles``)."""
        return conditioned_quantiles(self.alpha_c_, tilt_now)[0]


def conditioned_quantiles(alpha_c_sorted: np.ndarray, tilt_now: np.ndarray):
    """Quantiles of the training ``alpha_c`` above each tilt, and where fewer than ``MIN_ABOVE`` were.

    Where too few training angles lie above the tilt, the forecast is the
    tilt plus the remaining angle of the ``MIN_ABOVE`` largest training
    angles above their own neighbours' tilt (so that it stays above the tilt).
    """
    t = np.asarray(tilt_now, dtype=float)
    out = np.empty((t.size, LEVELS.size))
    short = np.zeros(t.size, bool)
    start = np.searchsorted(alpha_c_sorted, t, side="right")
    for i, (ti, s) in enumerate(zip(t, start)):
        above = alpha_c_sorted[s:]
        if above.size >= MIN_ABOVE:
            out[i] = quantiles_of_sample(above)
        else:
            short[i] = True
            top = alpha_c_sorted[-MIN_ABOVE:]
            out[i] = ti + quantiles_of_sample(top - alpha_c_sorted[-MIN_ABOVE - 1]
                                              if alpha_c_sorted.size > MIN_ABOVE else top * 0)
    return out, short


class ConditionedClimatology(Climatology):
    """The prior's ``alpha_c`` restricted to values above the tilt reached."""

    name = "conditioned"
    label = "conditioned climatology"

    def _quantiles(self, cuts):
        q, _ = conditioned_quantiles(self.alpha_c_, cuts.tilt_now)
        return q, np.zeros(len(cuts), bool)


class Now(Forecaster):
    """``alpha_c = alpha_obs``: the avalanche now (a point mass at the tilt reached)."""

    name = "now"
    label = "now"

    def _quantiles(self, cuts):
        return np.repeat(cuts.tilt_now[:, None], LEVELS.size, axis=1), np.zeros(len(cuts), bool)


class LastEventPlusLead(Forecaster):
    """The last event's angle plus the training cuts' lead from their last event to the avalanche.

    Parameters
    ----------
    draws_per_row : int
        Random cuts per training realisation (``training_cuts``).
    random_state : int
        Seeds the cuts.
    """

    name = "last_plus_lead"
    label = "last event + median lead"

    def __init__(self, draws_per_row: int = 20, random_state: int = 0):
        self.draws_per_row = draws_per_row
        self.random_state = random_state

    def fit(self, train, y=None):
        """Measure the lead, last event to avalanche, on random cuts of the training runs."""
        cuts = training_cuts(train, self.draws_per_row, np.random.default_rng(self.random_state))
        self.lead_quantiles_ = quantiles_of_sample(cuts.alpha_c - cuts.last_event)
        return self

    def _quantiles(self, cuts):
        q = cuts.last_event[:, None] + self.lead_quantiles_[None, :]
        return np.maximum(q, cuts.tilt_now[:, None]), np.zeros(len(cuts), bool)
