"""Learned forecasters: gradient-boosted quantile regressors on catalogue features.

The target is ``log(alpha_c - tilt_now)``, the remaining angle (quantiles are
equivariant under this monotone map, and the forecast stays above the tilt
reached).  One ``sklearn.ensemble.HistGradientBoostingRegressor`` with the
quantile loss per level of ``TRAINED_LEVELS``.  Trained on ``training_cuts``:
tilts drawn over the whole run, never at fixed leads, each catalogue degraded
by a measurement drawn from ``measurement.MEASUREMENT_RANGES`` (the
measurement is a feature, so ``predict`` told how a catalogue was measured
forecasts it as one of its kind).

Three layers beside the regressors, each a scikit-learn or crepes object:

* the calibration: a Mondrian conformal predictive system
  (``crepes.ConformalPredictiveSystem``), normalised by the predicted spread
  and conditioned on bins of the tilt reached and of the events so far: what
  the forecaster observes, never the lead, which it cannot know.  Its
  residuals are out of fold (``CALIBRATION_FOLDS`` regressors, each fitted
  without a fold of the training rows, predict that fold), so every training
  row calibrates and the regressors kept are fitted on every row; a
  ``validation`` set, when given, calibrates instead;
* the domain (``domain.DomainCheck``): a local outlier factor on the
  training cuts' event rates and sizes read through their measurement, and
  the tilt reached against the training avalanche angles.  Out of the domain
  the interval is widened to hold the conditioned climatology's too, and
  said so (``fallback``);
* the fall-back: the conditioned climatology of the training avalanche angles.

* ``Learned``: the catalogue's features only (``features.catalogue_features``);
  with ``inputs="angles_sizes"`` only those of the events' angles and sizes.
* ``Ceiling``: plus the K smallest distances of a slider to its threshold at
  the last stored angle before the cut, which only a simulation knows.
* ``ToldMuD``: plus the true ``mu_d``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .base import LEVELS, Forecaster
from .baselines import Climatology, conditioned_quantiles
from .domain import DOMAIN_FEATURES, WITH_POSITIONS, DomainCheck
from .inverse_rate import LinearInverseRate, PointProcessInverseRate
from .features import ceiling_features, feature_matrix, training_cuts
from .measurement import MEASUREMENT_FEATURES, degrade_cuts

#: the levels at which a regressor is trained; the others are interpolated (in log remaining angle)
TRAINED_LEVELS = np.array([0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95])
#: what a learned forecaster sees: every feature, or only those of the angles and sizes of
#: the events (no displacement, no slider positions: what any experiment records)
INPUTS = ("all", "angles_sizes")
#: where the conformal calibration's residuals come from when no validation set is given
CALIBRATIONS = ("out_of_fold", "held_out")
ANGLES_SIZES_FEATURES = ("tilt", "n_events", "last_event", "quiet", "first_event", "moves",
                         "max_size", "max_size_recent", "mean_size_recent", "since_largest",
                         "share_large", *MEASUREMENT_FEATURES)
#: features that are angles: each also enters as its distance to the tilt reached
ANGLE_FEATURES = ("atan_mu_d_model", "atan_mu_s_model", "atan_mu_d_single")
#: bins of each feature in the boosting (the model file keeps every bin's threshold)
MAX_BINS = 63
#: fewest calibration cuts per Mondrian bin (the 5 % and 95 % levels need 20 at least)
MIN_PER_BIN = 200
#: share of the training rows held out for the calibration (``calibration="held_out"``)
CALIBRATION_SHARE = 0.25
#: folds of the training rows whose out-of-fold residuals calibrate (when no validation set is given)
CALIBRATION_FOLDS = 4


def with_design(cuts, inverse_rate: bool = True):
    """The same cuts with their features computed once (shared by several forecasters).

    ``inverse_rate``: also the displacement-rate fits that ``Learned(inputs="all")`` reads.
    """
    cache = {**cuts.cache, "features": feature_matrix(cuts)}
    if inverse_rate:
        fits = [LinearInverseRate("displacement"), PointProcessInverseRate("displacement", None)]
        cache["inverse_rate"] = np.array([[f.best_log_remaining(c) for f in fits]
                                          for c in cuts.catalogues]).reshape(-1, 2)
    return replace(cuts, cache=cache)


class Learned(Forecaster):
    """Quantile gradient boosting on the catalogue's features, conformally calibrated.

    Parameters
    ----------
    inputs : {"all", "angles_sizes"}
        Every catalogue feature, or only those of the events' angles and
        sizes (``ANGLES_SIZES_FEATURES``, the event and move rates).
    draws_per_row : int
        Random training cuts per training realisation.
    max_iter, learning_rate, max_leaf_nodes, min_samples_leaf : int or float
        Of ``HistGradientBoostingRegressor``.
    degrade : bool
        Degrade every training cut by a measurement drawn from
        ``measurement.MEASUREMENT_RANGES``.
    calibration_bins, calibration_event_bins : int
        Mondrian bins of the tilt reached, and in each of the events so far,
        in the conformal calibration (fewer when the calibration cuts are few).
    calibration : {"out_of_fold", "held_out"}
        Without a ``validation`` set: calibrate on the training cuts' out-of-fold
        residuals, or hold ``CALIBRATION_SHARE`` of the training rows out for it.
    domain_contamination : float
        Share of training cuts the novelty detector counts as outliers.
    random_state : int
        Seeds the cuts, the degradations and the regressors.
    """

    def __init__(self, inputs: str = "all", draws_per_row: int = 10, max_iter: int = 200,
                 learning_rate: float = 0.08, max_leaf_nodes: int = 15, min_samples_leaf: int = 40,
                 degrade: bool = True, calibration_bins: int = 4, calibration_event_bins: int = 4,
                 calibration: str = "out_of_fold", domain_contamination: float = 0.03,
                 random_state: int = 0):
        self.inputs = inputs
        self.draws_per_row = draws_per_row
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.max_leaf_nodes = max_leaf_nodes
        self.min_samples_leaf = min_samples_leaf
        self.degrade = degrade
        self.calibration_bins = calibration_bins
        self.calibration_event_bins = calibration_event_bins
        self.calibration = calibration
        self.domain_contamination = domain_contamination
        self.random_state = random_state

    @property
    def name(self) -> str:
        """``learned`` (every feature) or ``learned_blind`` (angles and sizes only)."""
        return "learned" if self.inputs == "all" else "learned_blind"

    @property
    def label(self) -> str:
        """The forecaster's name in tables and legends."""
        return "learned (boosting)" if self.inputs == "all" else "learned, angles + sizes only"

    def _selected(self, x, names):
        """The columns this forecaster may see (all, or those of angles and sizes only)."""
        if self.inputs == "all":
            return x, names
        keep = [i for i, n in enumerate(names) if n in ANGLES_SIZES_FEATURES
                or n.startswith(("events_", "moves_", "size_ratio_"))
                and not n.startswith("moves_per_slider")]
        return x[:, keep], [names[i] for i in keep]

    def design(self, cuts) -> tuple[np.ndarray, list[str]]:
        """The regressor's input for ``cuts``: (n, F) and the feature names.

        The catalogue's and the measurement's features, the model's angles
        minus the tilt, and (every input) the best remaining angle (log) of
        the displacement-rate inverse-rate fits.
        """
        x, names = cuts.cache["features"] if "features" in cuts.cache else feature_matrix(cuts)
        t = cuts.tilt_now[:, None]
        extra = [x[:, names.index(a)][:, None] - t for a in ANGLE_FEATURES]
        x, names = np.hstack([x, *extra]), names + [f"{a}_minus_tilt" for a in ANGLE_FEATURES]
        if self.inputs == "all":
            ffm = (cuts.cache["inverse_rate"] if "inverse_rate" in cuts.cache
                   else with_design(cuts).cache["inverse_rate"])
            x = np.hstack([x, ffm])
            names = names + ["ffm_linear_disp_log_remaining", "ffm_ml_disp_p_log_remaining"]
        return self._selected(x, names)

    def training_cuts(self, train, rng):
        """Random cuts of ``train``, degraded if ``degrade``, with their features."""
        cuts = training_cuts(train, self.draws_per_row, rng)
        return with_design(degrade_cuts(cuts, rng) if self.degrade else cuts, self.inputs == "all")

    def fit(self, train, y=None, validation=None, cuts=None, validation_cuts=None):
        """Fit the regressors, the domain and the conformal calibration.

        Parameters
        ----------
        train : CatalogueSet
            Training realisations.
        validation : CatalogueSet, optional
            Realisations for the calibration; by default (``calibration``)
            the residuals of ``CALIBRATION_FOLDS`` out-of-fold regressors on
            ``train``'s own cuts, or ``CALIBRATION_SHARE`` of its rows held out.
        cuts, validation_cuts : Cuts, optional
            Cuts already drawn (``training_cuts``), shared by several forecasters.
        """
        if self.inputs not in INPUTS:
            raise ValueError(f"inputs={self.inputs!r} must be one of {INPUTS}")
        if self.calibration not in CALIBRATIONS:
            raise ValueError(f"calibration={self.calibration!r} must be one of {CALIBRATIONS}")
        rng = np.random.default_rng(self.random_state)
        if self.calibration == "held_out" and validation is None and validation_cuts is None:
            hold = rng.random(len(train)) < CALIBRATION_SHARE
            train, validation = train.subset(~hold), train.subset(hold)
        cuts = self.training_cuts(train, rng) if cuts is None else cuts
        held_out = validation is not None or validation_cuts is not None
        if held_out and validation_cuts is None:
            validation_cuts = self.training_cuts(validation, rng)
        x, names = self.design(cuts)
        self.columns_ = np.isfinite(x).any(axis=0)  # a feature never seen (e.g. no slider indices)
        self.feature_names_ = [n for n, k in zip(names, self.columns_) if k]
        y_log = np.log(np.maximum(cuts.alpha_c - cuts.tilt_now, 1e-9))
        self.models_ = self._fit_regressors(x[:, self.columns_], y_log)
        self.climatology_ = Climatology().fit(train)
        self._fit_domain(cuts, rng)
        if held_out:
            self._fit_calibration(validation_cuts, self._raw_log_remaining(validation_cuts))
            self.n_calibration_cuts_ = len(validation_cuts)
        else:
            self._fit_calibration(cuts, self._out_of_fold(cuts, x[:, self.columns_], y_log, rng))
            self.n_calibration_cuts_ = len(cuts)
        self.n_training_cuts_ = len(cuts)
        return self

    def _fit_regressors(self, x, y_log):
        """One quantile regressor of the log remaining angle per level of ``TRAINED_LEVELS``."""
        return [self._regressor(level).fit(x, y_log) for level in TRAINED_LEVELS]

    def _out_of_fold(self, cuts, x, y_log, rng):
        """(n, len(TRAINED_LEVELS)) each cut's log remaining angles by regressors fitted
        without its realisation's fold (folds of realisations, not of cuts)."""
        fold_of_row = rng.integers(0, CALIBRATION_FOLDS, int(cuts.row.max()) + 1)
        fold = fold_of_row[cuts.row]
        z = np.zeros((len(cuts), TRAINED_LEVELS.size))
        for k in range(CALIBRATION_FOLDS):
            out = fold == k
            if out.any() and (~out).any():
                models = self._fit_regressors(x[~out], y_log[~out])
                z[out] = np.column_stack([m.predict(x[out]) for m in models])
            else:  # too few realisations for this fold: the regressors kept
                z[out] = np.column_stack([m.predict(x[out]) for m in self.models_])
        return np.sort(z, axis=1)
    def _regressor(self, level):
        from sklearn.ensemble import HistGradientBoostingRegressor

        return HistGradientBoostingRegressor(
            loss="quantile", quantile=float(level), max_iter=self.max_iter,
            learning_rate=self.learning_rate, max_leaf_nodes=self.max_leaf_nodes,
            min_samples_leaf=self.min_samples_leaf, max_bins=MAX_BINS, early_stopping=False,
            random_state=self.random_state)

    def _fit_domain(self, cuts, rng):
        """The domain check (``domain.DomainCheck``) on the training cuts, as measured (with the
        number of sliders the movers' indices show, if the forecaster reads them)."""
        features = WITH_POSITIONS if self.inputs == "all" else DOMAIN_FEATURES
        self.domain_ = DomainCheck(features, contamination=self.domain_contamination,
                                   random_state=self.random_state).fit(
            cuts, self.climatology_.alpha_c_, order=rng.permutation(len(cuts)))

    def _fit_calibration(self, vcuts, z):
        """A Mondrian conformal predictive system on the calibration cuts (crepes).

        ``z``: their predicted log remaining angles (``_raw_log_remaining``
        or out of fold).  Residuals of the predicted median, normalised by the
        predicted spread (half the 10-90 % width), in bins of the tilt reached
        crossed with bins of the events so far (edges at the calibration cuts'
        quantiles; as many bins of tilt as ``MIN_PER_BIN`` cuts allow, up to
        ``calibration_bins``, then of events in each).
        """
        from crepes import ConformalPredictiveSystem

        truth = np.log(np.maximum(vcuts.alpha_c - vcuts.tilt_now, 1e-9))
        centre, spread = self._centre_spread(z)
        cells = len(vcuts) // MIN_PER_BIN
        tilt_bins = int(np.clip(cells, 1, self.calibration_bins))
        event_bins = int(np.clip(cells // tilt_bins, 1, self.calibration_event_bins))
        self.calibration_edges_ = np.quantile(vcuts.tilt_now, np.linspace(0, 1, tilt_bins + 1)[1:-1])
        self.calibration_event_edges_ = np.quantile(_log_events(vcuts),
                                                    np.linspace(0, 1, event_bins + 1)[1:-1])
        self.calibration_ = ConformalPredictiveSystem().fit(truth - centre, sigmas=spread,
                                                            bins=self._calibration_bin(vcuts))

    def _calibration_bin(self, cuts):
        """Each cut's Mondrian category: its bin of tilt reached times its bin of events so far."""
        tilt_bin = np.searchsorted(self.calibration_edges_, cuts.tilt_now)
        events_bin = np.searchsorted(self.calibration_event_edges_, _log_events(cuts))
        return tilt_bin * (self.calibration_event_edges_.size + 1) + events_bin

    @staticmethod
    def _centre_spread(z):
        k10, k50, k90 = (int(np.flatnonzero(np.isclose(TRAINED_LEVELS, v))[0]) for v in (0.1, 0.5, 0.9))
        return z[:, k50], np.maximum(0.5 * (z[:, k90] - z[:, k10]), 1e-3)

    def _raw_log_remaining(self, cuts, x=None):
        """(n, len(TRAINED_LEVELS)) the regressors' log remaining angles, sorted."""
        x = self.design(cuts)[0] if x is None else x
        if not len(cuts):
            return np.zeros((0, TRAINED_LEVELS.size))
        return np.sort(np.column_stack([m.predict(x[:, self.columns_]) for m in self.models_]), axis=1)

    def domain(self, cuts, x=None) -> tuple[np.ndarray, list[str]]:
        """Whether each cut lies in the training domain, and if not, why (one phrase).

        Out: the tilt reached above a high quantile of the training avalanche
        angles, or event rates and sizes that the novelty detector finds
        unlike every training cut's (``domain.DomainCheck``).  ``x``: unused,
        the check reads the catalogues and their measurement.
        """
        if not isinstance(getattr(self, "domain_", None), DomainCheck):
            raise AttributeError("the forecaster's domain check is of another version")
        return self.domain_.check(cuts)

    def _quantiles(self, cuts):
        x, _ = self.design(cuts)
        z = self._raw_log_remaining(cuts, x)
        centre, spread = self._centre_spread(z)
        zc = self.calibration_.predict(centre, sigmas=spread, bins=self._calibration_bin(cuts),
                                       lower_percentiles=100 * LEVELS)
        zc = np.asarray(zc, dtype=float).reshape(len(cuts), LEVELS.size)
        q = cuts.tilt_now[:, None] + np.exp(np.sort(np.clip(zc, -20.0, 2.0), axis=1))
        inside, _ = self.domain(cuts, x)
        out = ~inside
        if out.any():  # widened: the conditioned climatology's interval held too
            qc = conditioned_quantiles(self.climatology_.alpha_c_, cuts.tilt_now[out])[0]
            lower = np.minimum(q[out], qc)
            upper = np.maximum(q[out], qc)
            half = LEVELS < 0.5
            q[out] = np.where(half[None, :], lower, upper)
        return q, out


def _log_events(cuts) -> np.ndarray:
    """(n,) log(1 + the number of events so far) of each cut."""
    return np.log1p(np.array([len(c) for c in cuts.catalogues], dtype=float))


class Ceiling(Learned):
    """The learned forecaster also given every slider's distance to its threshold (simulation only)."""

    name = "ceiling"
    label = "ceiling (+ thresholds)"
    needs = ("ceiling",)

    def design(self, cuts):
        """Catalogue features plus log10 of the smallest threshold distances."""
        x, names = super().design(cuts)
        c, cn = ceiling_features(cuts)
        return np.hstack([x, c]), names + cn


class ToldMuD(Learned):
    """The learned forecaster also told the true ``mu_d`` (simulation only)."""

    name = "told_mu_d"
    label = "told μ_d"
    needs = ("mu_d",)

    def design(self, cuts):
        """Catalogue features plus atan(mu_d) and its distance to the tilt."""
        x, names = super().design(cuts)
        a = np.arctan(cuts.mu_d)[:, None]
        return np.hstack([x, a, a - cuts.tilt_now[:, None]]), names + ["atan_mu_d", "atan_mu_d_minus_tilt"]
