"""Learned forecasters: gradient-boosted quantile regressors on catalogue features.

The target is ``log(alpha_c - edge)``, the remaining angle from the edge of the tilt
reached (``edge``: the tilt reached less ``EDGE_RESOLUTIONS`` angle errors, so that
the avalanche of a noisy catalogue may lie below its last, noisy, angle; quantiles are
equivariant under this monotone map, and the forecast stays above the tilt
reached).  One ``sklearn.ensemble.HistGradientBoostingRegressor`` with the
quantile loss per level of ``TRAINED_LEVELS``.  Trained on ``training_cuts``:
tilts drawn over the whole run, never at fixed leads, each catalogue degraded
by a measurement drawn from ``measurement.MEASUREMENT_RANGES`` (the
measurement is a feature, so ``predict`` told how a catalogue was measured
forecasts it as one of its kind).

Three layers beside the regressors, each a scikit-learn or crepes object when fitted
(read from a model file, each is the arrays its ``predict`` reads: ``evaluators``):

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
  the interval is widened to hold the conditioned climatology's and the
  training cuts' remaining angles from the tilt reached too, and
  said so (``fallback``);
* the fall-back: the conditioned climatology of the training avalanche angles.

The 80 % interval is the shortest one, in degrees, of the calibrated
distribution (``interval``): the remaining angle's distribution is skewed,
and near the avalanche, where the catalogue cannot tell a quarter of a degree
from two degrees, its central interval would stop short of the avalanche.

* ``Learned``: the catalogue's features only (``features.catalogue_features``);
  with ``inputs="angles_sizes"`` only those of the events' angles and sizes,
  with the recent gaps and the event-rate fits.
* ``Ceiling``: plus the K smallest distances of a slider to its threshold at
  the last stored angle before the cut, which only a simulation knows.
* ``ToldMuD``: plus the true ``mu_d``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .base import LEVELS, Forecaster, edge
from .baselines import Climatology, conditioned_quantiles
from ...io.catalogue import Catalogue
from .domain import DOMAIN_FEATURES, WITH_POSITIONS, DomainCheck
from .inverse_rate import LinearInverseRate, PointProcessInverseRate
from .features import (Cuts, camera_feature_names, n_sliders_estimate, SHORTEST_WINDOW, camera_feature_matrix, ceiling_features,
                       feature_matrix, training_cuts)
from .measurement import MEASUREMENT_FEATURES, MEASUREMENT_RANGES, RECORD_FEATURES, degrade_cuts
from .evaluators import QuantileTrees, ResidualTable
from .integrity import Spec, require

#: the levels at which a regressor is trained; the others are interpolated (in log remaining angle)
TRAINED_LEVELS = np.array([0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95])
#: what a learned forecaster sees: every feature, only those of the angles and sizes of the
#: events (no displacement, no slider positions: what any experiment records), or those and a
#: camera's displacements and positions in its own units (``features.camera_features``)
INPUTS = ("all", "angles_sizes", "camera")
#: where the conformal calibration's residuals come from when no validation set is given
CALIBRATIONS = ("out_of_fold", "held_out")
ANGLES_SIZES_FEATURES = ("tilt", "n_events", "last_event", "quiet", "first_event", "moves",
                         "max_size", "max_size_recent", "mean_size_recent", "since_largest",
                         "share_large", *MEASUREMENT_FEATURES)
#: the displacement-rate fits' best log remaining angles, as the camera's forecaster names them
CAMERA_FFM = ("ffm_disp_linear_log_remaining", "ffm_disp_ml_p_log_remaining")
#: what the camera's forecaster reads beyond the angles and sizes (``features.camera_features``)
CAMERA_FEATURES = (*CAMERA_FFM, *camera_feature_names())
#: features of the last fraction of a degree (the recent gaps, the shortest window, the
#: event-rate fits) that only the angles-and-sizes forecaster reads: the one of every feature
#: leans on the lone-slider pairs and its error 3° before the avalanche was no smaller with them
SHORT_RANGE_PREFIXES = ("gap_", "ffm_event_")
SHORT_RANGE_SUFFIX = f"_{SHORTEST_WINDOW:g}"
#: features that are angles: each also enters as its distance to the tilt reached
ANGLE_FEATURES = ("atan_mu_d_model", "atan_mu_s_model", "atan_mu_d_single")
#: bins of each feature in the boosting by default (the model file keeps every bin's threshold);
#: the forecaster of every feature takes 255, the most the boosting allows: its best feature,
#: mu_d from lone-slider pairs, is exact, and 63 bins of it are about a degree wide
MAX_BINS = 63
#: what the 80 % interval is: the central one (10 % to 90 % of the calibrated distribution), or
#: the shortest one in degrees (a low side of ``LOW_SHARES``, the high side the rest of the 20 %)
INTERVALS = ("central", "shortest")
#: the shares (%) of the calibrated distribution below the shortest 80 % interval tried
LOW_SHARES = np.arange(1.0, 10.5)
#: the calibrated distribution's percentiles read for every cut (the levels are interpolated;
#: those below 100 / (cuts of the smallest Mondrian bin + 1) are left out)
CPS_PERCENTILES = np.r_[0.5, np.arange(1.0, 100.0), 99.5]
#: the calibration's normalised residuals are kept to this binary step (2^-12 of the predicted
#: spread: nothing a percentile would show, and the model file's residuals then compress well)
RESIDUAL_STEP = 2.0 ** -12
#: fewest calibration cuts per Mondrian bin (the 0.5 % and 99.5 % percentiles read need 200)
MIN_PER_BIN = 200
#: the size classes a told number of sliders falls in (their inner edges): N < 50, 50-199, >= 200
TOLD_CLASSES = np.array([50.0, 200.0])
#: kinds of record calibrated apart (``record_category``): no size told or one of
#: ``TOLD_CLASSES``, each with exact or noisy angles
RECORD_CATEGORIES = 2 * (TOLD_CLASSES.size + 2)
#: share of the training rows held out for the calibration (``calibration="held_out"``)
CALIBRATION_SHARE = 0.25
#: folds of the training rows whose out-of-fold residuals calibrate (when no validation set is given)
CALIBRATION_FOLDS = 4


#: what a learned forecaster's measured alarm holds (``alarm_skill_``, set by
#: benchmarks/alarm_skill.py with its default threshold ``alarm_threshold_``): name -> range
ALARM_SKILL = {"hit_share": (0.0, 1.0), "false_alarm_share": (0.0, 1.0),
               "warning_median_deg": (0.0, 90.0), "warning_p10_deg": (0.0, 90.0),
               "within_deg": (0.0, 90.0), "piles": (1, 10 ** 9)}


def event_rate_fits() -> list:
    """The event-rate inverse-rate fits whose best remaining angle (log) the angles-and-sizes
    forecaster sees (a short-range feature: ``SHORT_RANGE_PREFIXES``)."""
    return [LinearInverseRate("events"), PointProcessInverseRate("events", None)]


def displacement_rate_fits() -> list:
    """The displacement-rate inverse-rate fits whose best remaining angle ``inputs="all"`` sees."""
    return [LinearInverseRate("displacement"), PointProcessInverseRate("displacement", None)]


def best_log_remaining(cuts, fits) -> np.ndarray:
    """(n, len(fits)) each fit's most likely log remaining angle for every cut (NaN: no fit)."""
    return np.array([[f.best_log_remaining(c) for f in fits]
                     for c in cuts.catalogues]).reshape(-1, len(fits))


def with_design(cuts, inputs: str = "all"):
    """The same cuts with their features computed once (shared by several forecasters).

    Their features and the inverse-rate fits that ``Learned(inputs=inputs)``
    reads: of the displacement rate for ``"all"``, of the event rate for
    ``"angles_sizes"``.
    """
    cache = {**cuts.cache, "features": feature_matrix(cuts)}
    if inputs in ("all", "camera"):
        cache["inverse_rate"] = best_log_remaining(cuts, displacement_rate_fits())
    if inputs in ("angles_sizes", "camera"):
        cache["inverse_rate_events"] = best_log_remaining(cuts, event_rate_fits())
    if inputs == "camera":
        cache["camera"] = camera_feature_matrix(cuts)
    return replace(cuts, cache=cache)


class Learned(Forecaster):
    """Quantile gradient boosting on the catalogue's features, conformally calibrated.

    Parameters
    ----------
    inputs : {"all", "angles_sizes"}
        Every catalogue feature but the short-range ones, or only those of
        the events' angles and sizes (``ANGLES_SIZES_FEATURES``, the event
        and move rates, the short-range ones: ``SHORT_RANGE_PREFIXES``).
    draws_per_row : int
        Random training cuts per training realisation.
    max_iter, learning_rate, max_leaf_nodes, min_samples_leaf, max_bins : int or float
        Of ``HistGradientBoostingRegressor``.
    degrade : bool
        Degrade every training cut by a measurement drawn from
        ``measurement.MEASUREMENT_RANGES``.
    told_share : float
        Share of the degraded training cuts told their pile's number of sliders
        (``measurement.tell_sliders``: the number, or a range around it).  A
        forecaster is trained told it (1) or not (0): told to some only, the
        trees send the cuts not told to one side of each split on it, and
        those lost coverage near the avalanche.
    calibration_bins, calibration_event_bins, calibration_size_bins, calibration_remaining_bins : int
        Mondrian bins of the tilt reached, in each of the events so far, in
        each of those of the mean event size so far (which tracks the pile's
        number of sliders, unknown to an experiment), and in each of those of
        the predicted remaining angle, in the conformal calibration (fewer
        when the calibration cuts are few).
    interval : {"shortest", "central"}
        The 80 % interval (the quantiles at 10 % and 90 %): the shortest one
        in degrees of the calibrated distribution, between its
        ``LOW_SHARES`` and 80 % above (the levels between warped
        piecewise linearly, the median kept), or its central one.  The
        remaining angle's distribution is skewed (most likely small, possibly
        large), so the shortest interval reaches further down and less far up.
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
                 max_bins: int = MAX_BINS, degrade: bool = True, told_share: float = 0.0,
                 calibration_bins: int = 4, calibration_event_bins: int = 4,
                 calibration_size_bins: int = 1, calibration_remaining_bins: int = 1,
                 calibration_by_record: bool = False, interval: str = "shortest",
                 calibration: str = "out_of_fold", domain_contamination: float = 0.03,
                 random_state: int = 0):
        self.inputs = inputs
        self.draws_per_row = draws_per_row
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.max_leaf_nodes = max_leaf_nodes
        self.min_samples_leaf = min_samples_leaf
        self.max_bins = max_bins
        self.degrade = degrade
        self.told_share = told_share
        self.calibration_bins = calibration_bins
        self.calibration_event_bins = calibration_event_bins
        self.calibration_size_bins = calibration_size_bins
        self.calibration_remaining_bins = calibration_remaining_bins
        self.calibration_by_record = calibration_by_record
        self.interval = interval
        self.calibration = calibration
        self.domain_contamination = domain_contamination
        self.random_state = random_state

    @property
    def name(self) -> str:
        """``learned`` (every feature), ``learned_blind`` (angles and sizes only),
        ``learned_sized`` (angles and sizes, told the pile's size) or ``learned_camera`` (a
        camera's units)."""
        if self.inputs == "angles_sizes" and self.told_share > 0:
            return "learned_sized"
        return {"all": "learned", "camera": "learned_camera"}.get(self.inputs, "learned_blind")

    @property
    def label(self) -> str:
        """The forecaster's name in tables and legends."""
        if self.name == "learned_sized":
            return "learned, angles + sizes, size told"
        return {"all": "learned, every feature", "camera": "learned, camera's units"}.get(
            self.inputs, "learned, angles + sizes only")

    def _selected(self, x, names):
        """The columns this forecaster may see: all but the short-range ones
        (``SHORT_RANGE_PREFIXES``), or those of angles and sizes only."""
        if self.inputs == "all":
            keep = [i for i, n in enumerate(names) if not n.startswith(SHORT_RANGE_PREFIXES)
                    and not n.endswith(SHORT_RANGE_SUFFIX)]
            return x[:, keep], [names[i] for i in keep]
        camera = CAMERA_FEATURES if self.inputs == "camera" else ()
        keep = [i for i, n in enumerate(names) if n in ANGLES_SIZES_FEATURES or n in camera
                or n.startswith(("events_", "moves_", "size_ratio_", *SHORT_RANGE_PREFIXES))
                and not n.startswith("moves_per_slider")]
        return x[:, keep], [names[i] for i in keep]

    def design(self, cuts) -> tuple[np.ndarray, list[str]]:
        """The regressor's input for ``cuts``: (n, F) and the feature names.

        The catalogue's and the measurement's features, the model's angles
        minus the tilt, and the best remaining angle (log) of the inverse-rate
        fits: of the displacement rate (``inputs="all"``), or of the event rate.
        """
        x, names = cuts.cache["features"] if "features" in cuts.cache else feature_matrix(cuts)
        t = cuts.tilt_now[:, None]
        extra = [x[:, names.index(a)][:, None] - t for a in ANGLE_FEATURES]
        x, names = np.hstack([x, *extra]), names + [f"{a}_minus_tilt" for a in ANGLE_FEATURES]
        if self.inputs == "all":
            ffm = (cuts.cache["inverse_rate"] if "inverse_rate" in cuts.cache
                   else best_log_remaining(cuts, displacement_rate_fits()))
            x = np.hstack([x, ffm])
            names = names + ["ffm_linear_disp_log_remaining", "ffm_ml_disp_p_log_remaining"]
            return self._selected(x, names)
        events = (cuts.cache["inverse_rate_events"] if "inverse_rate_events" in cuts.cache
                  else best_log_remaining(cuts, event_rate_fits()))
        x = np.hstack([x, events])
        names = names + ["ffm_event_linear_log_remaining", "ffm_event_ml_p_log_remaining"]
        if self.inputs == "camera":  # the displacement-rate fits need no unit (their weights
            # are displacements over their mean)
            ffm = (cuts.cache["inverse_rate"] if "inverse_rate" in cuts.cache
                   else best_log_remaining(cuts, displacement_rate_fits()))
            cam, cam_names = cuts.cache["camera"] if "camera" in cuts.cache else \
                camera_feature_matrix(cuts)
            x = np.hstack([x, ffm, cam])
            names = names + list(CAMERA_FFM) + cam_names
        return self._selected(x, names)

    @property
    def training_kind(self) -> tuple:
        """What ``training_cuts`` draws depends on: degraded or not, as a camera records them,
        the share told their pile's size.  Forecasters of one kind may share their cuts."""
        return self.degrade, self.inputs == "camera", self.told_share

    def training_cuts(self, train, rng):
        """Random cuts of ``train``, degraded if ``degrade``, with their features."""
        cuts = training_cuts(train, self.draws_per_row, rng)
        if self.degrade and self.inputs == "camera" and cuts.n_sliders is None:
            # a camera's positions are fractions of the pile: of the number the indices show
            cuts = replace(cuts, n_sliders=np.array([
                round(n) if np.isfinite(n := n_sliders_estimate(c)) else -1
                for c in cuts.catalogues], dtype=np.int64))
        if self.degrade:
            cuts = degrade_cuts(cuts, rng, camera=self.inputs == "camera",
                                told_share=self.told_share)
        return with_design(cuts, self.inputs)

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
        if self.interval not in INTERVALS:
            raise ValueError(f"interval={self.interval!r} must be one of {INTERVALS}")
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
        self.measurement_ranges_ = np.array([[np.nanmin(x[:, names.index(f)]),
                                               np.nanmax(x[:, names.index(f)])]
                                              for f in RECORD_FEATURES])
        self.columns_ = np.isfinite(x).any(axis=0)  # a feature never seen (e.g. no slider indices)
        self.feature_names_ = [n for n, k in zip(names, self.columns_) if k]
        y_log = np.log(np.maximum(cuts.alpha_c - edge(cuts), 1e-9))
        self.models_ = self._fit_regressors(x[:, self.columns_], y_log)
        self.climatology_ = Climatology().fit(train)
        self.remaining_quantiles_ = np.quantile(np.maximum(cuts.alpha_c - cuts.tilt_now, 0.0), LEVELS)
        self._fit_domain(cuts, rng, train.parameters.get("n_sliders"))
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
                part = x[~out]
                # a feature no cut of the other folds has (the boosting cannot bin a column of
                # NaN only) is held constant there: no tree splits on it
                part[:, ~np.isfinite(part).any(axis=0)] = 0.0
                models = self._fit_regressors(part, y_log[~out])
                z[out] = np.column_stack([m.predict(x[out]) for m in models])
            else:  # too few realisations for this fold: the regressors kept
                z[out] = np.column_stack([m.predict(x[out]) for m in self.models_])
        return np.sort(z, axis=1)
    def _regressor(self, level):
        from sklearn.ensemble import HistGradientBoostingRegressor

        return HistGradientBoostingRegressor(
            loss="quantile", quantile=float(level), max_iter=self.max_iter,
            learning_rate=self.learning_rate, max_leaf_nodes=self.max_leaf_nodes,
            min_samples_leaf=self.min_samples_leaf, max_bins=self.max_bins, early_stopping=False,
            random_state=self.random_state)

    def _fit_domain(self, cuts, rng, n_sliders=None):
        """The domain check (``domain.DomainCheck``) on the training cuts, as measured (with the
        number of sliders the movers' indices show, if the forecaster reads them)."""
        features = WITH_POSITIONS if self.inputs == "all" else DOMAIN_FEATURES
        self.domain_ = DomainCheck(features, contamination=self.domain_contamination,
                                   random_state=self.random_state).fit(
            cuts, self.climatology_.alpha_c_, order=rng.permutation(len(cuts)), n_sliders=n_sliders)

    def _fit_calibration(self, vcuts, z):
        """A Mondrian conformal predictive system on the calibration cuts (crepes).

        ``z``: their predicted log remaining angles (``_raw_log_remaining``
        or out of fold).  Residuals of the predicted median, normalised by the
        predicted spread (half the 10-90 % width), in nested bins of what the
        forecaster observes or predicts: the tilt reached, within each of its
        bins the events so far, within each of those the predicted remaining
        angle (edges at the calibration cuts' quantiles within their cell; as
        many bins as ``MIN_PER_BIN`` cuts per cell allow, up to
        ``calibration_bins``, ``calibration_event_bins`` and
        ``calibration_remaining_bins``), and the same with the mean event size so far
        (``calibration_size_bins``) nested between the events and the remaining angle.
        """
        from crepes import ConformalPredictiveSystem

        truth = np.log(np.maximum(vcuts.alpha_c - edge(vcuts), 1e-9))
        centre, spread = self._centre_spread(z)
        cells = len(vcuts) // MIN_PER_BIN
        tilt_bins = int(np.clip(cells, 1, self.calibration_bins))
        event_bins = int(np.clip(cells // tilt_bins, 1, self.calibration_event_bins))
        size_bins = int(np.clip(cells // (tilt_bins * event_bins), 1, self.calibration_size_bins))
        remaining_bins = int(np.clip(cells // (tilt_bins * event_bins * size_bins), 1,
                                     self.calibration_remaining_bins))
        if self.calibration_by_record:  # tilt edges within each kind of record
            self.calibration_edges_ = _nested_edges(vcuts.tilt_now, record_category(vcuts),
                                                    RECORD_CATEGORIES, tilt_bins)
        else:
            self.calibration_edges_ = _quantile_edges(vcuts.tilt_now, tilt_bins)
        tilt_bin = self._tilt_cell(vcuts)
        tilt_bins = _cells(self.calibration_edges_)
        events = _log_events(vcuts)
        self.calibration_event_edges_ = _nested_edges(events, tilt_bin, tilt_bins, event_bins)
        cell = _nested_cell(self.calibration_event_edges_, tilt_bin, events)
        sizes = _log_mean_size(vcuts)
        self.calibration_size_edges_ = _nested_edges(sizes, cell, tilt_bins * event_bins, size_bins)
        cell = _nested_cell(self.calibration_size_edges_, cell, sizes)
        self.calibration_remaining_edges_ = _nested_edges(centre, cell,
                                                          tilt_bins * event_bins * size_bins,
                                                          remaining_bins)
        bins = self._calibration_bin(vcuts, centre)
        self.calibration_counts_ = np.bincount(bins)
        # the percentiles every bin holds a residual below (crepes' lower index >= 0)
        fewest = self.calibration_counts_[self.calibration_counts_ > 0].min()
        self.percentiles_ = CPS_PERCENTILES[CPS_PERCENTILES >= 100.0 / (fewest + 1)]
        # normalised here (not by crepes' sigmas) so that they can be kept to RESIDUAL_STEP
        alphas = np.round((truth - centre) / spread / RESIDUAL_STEP) * RESIDUAL_STEP
        self.calibration_ = ConformalPredictiveSystem().fit(alphas, bins=bins)

    def _tilt_cell(self, cuts):
        """Each cut's bin of tilt reached (within its kind of record, if calibrated by it)."""
        if self.calibration_edges_.ndim == 2:
            return _nested_cell(self.calibration_edges_, record_category(cuts), cuts.tilt_now)
        return np.searchsorted(self.calibration_edges_, cuts.tilt_now)

    def _calibration_bin(self, cuts, centre):
        """Each cut's Mondrian category: its bin of tilt reached (within its kind of record), of
        events so far within it, of mean event size within that, and of predicted remaining
        angle (``centre``, log)."""
        cell = _nested_cell(self.calibration_event_edges_, self._tilt_cell(cuts),
                            _log_events(cuts))
        size_edges = getattr(self, "calibration_size_edges_", None)  # None: fitted without
        if size_edges is not None:
            cell = _nested_cell(size_edges, cell, _log_mean_size(cuts))
        return _nested_cell(self.calibration_remaining_edges_, cell, centre)

    def _percentiles(self, grid):
        """(n, len(LEVELS)) the calibrated distribution's percentiles reported at ``LEVELS``.

        ``grid``: each cut's log remaining angle at ``percentiles_`` (``CPS_PERCENTILES``
        that the smallest Mondrian bin resolves; beyond them, their ends).
        Central: the levels themselves.  Shortest: the low share ``p`` of
        ``LOW_SHARES`` whose interval [p, 80 + p] is shortest in angle, the
        levels mapped piecewise linearly through 10 % -> p, 50 % -> 50 %,
        90 % -> 80 + p.
        """
        central = np.tile(100.0 * LEVELS, (grid.shape[0], 1))
        if self.interval == "central":
            return central
        ends = np.array([np.interp(np.r_[LOW_SHARES, LOW_SHARES + 80.0], self.percentiles_, g)
                         for g in grid]).reshape(grid.shape[0], 2, LOW_SHARES.size)
        p = LOW_SHARES[np.argmin(np.exp(ends[:, 1]) - np.exp(ends[:, 0]), axis=1)]
        return np.array([np.interp(100.0 * LEVELS, [0.0, 10.0, 50.0, 90.0, 100.0],
                                   [0.0, s, 50.0, 80.0 + s, 100.0]) for s in p]).reshape(central.shape)

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

    def domain(self, cuts) -> tuple[np.ndarray, list[str]]:
        """Whether each cut lies in the training domain, and if not, why (one phrase).

        Out: the tilt reached above a high quantile of the training avalanche
        angles, or event rates and sizes that the novelty detector finds
        unlike every training cut's (``domain.DomainCheck``, which reads the
        catalogues and their measurement).
        """
        if not isinstance(getattr(self, "domain_", None), DomainCheck):
            raise AttributeError("the forecaster's domain check is of another version")
        inside, reasons = self.domain_.check(cuts)
        ranges = self.trained_measurement()
        for i, (cat, m) in enumerate(zip(cuts.catalogues, cuts.measurements())):
            why = [_outside(f, v, lo, hi) for f, v, (lo, hi)
                   in zip(RECORD_FEATURES, m.as_features(cat), ranges)
                   if np.isfinite(v) and not lo - 1e-9 - 1e-6 * abs(lo) <= v <= hi + 1e-9 + 1e-6 * abs(hi)]
            if why:
                inside[i] = False
                reasons[i] = "; ".join([r for r in (reasons[i],) if r] + why)
        return inside, reasons

    def trained_measurement(self) -> np.ndarray:
        """(len(RECORD_FEATURES), 2) the least and the largest value of each record
        feature over the training cuts: a catalogue measured outside them is out of the domain
        (the trees would read it as the nearest training measurement).

        Recorded by ``fit``; for a forecaster fitted before it was, the training
        measurement itself: the ranges ``measurement.draw_measurements`` draws from
        (``MEASUREMENT_RANGES``) when it degraded its training catalogues, else the
        exact record (no angle error, every size, nothing missed, sizes in sliders).
        """
        recorded = getattr(self, "measurement_ranges_", None)
        if recorded is not None:
            return recorded
        if not self.degrade:
            return np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
        r = MEASUREMENT_RANGES
        return np.array([[0.0, r["angle_resolution"][1]], [0.0, float(max(r["min_size"]))],
                         [0.0, r["missed_fraction"][1]], [0.0, float(r["p_arbitrary"] > 0)]])

    #: every fitted part a forecast reads, of the form ``fit`` writes (``integrity``)
    FIELDS = {"inputs": Spec("choice", of=INPUTS), "interval": Spec("choice", of=INTERVALS),
              "calibration": Spec("choice", of=CALIBRATIONS),
              "degrade": Spec("choice", of=(True, False)),
              "told_share": Spec("number", lo=0.0, hi=1.0),
              "calibration_by_record": Spec("choice", of=(True, False)),
              "climatology_": Spec("part", of=Climatology),
              "columns_": Spec("b"),
              "models_": Spec("list", n=TRAINED_LEVELS.size, of=Spec("part", of=QuantileTrees)),
              "measurement_ranges_": Spec("f", shape=(len(RECORD_FEATURES), 2), lo=0.0,
                                          increasing=True, optional=True),  # lo <= hi
              "remaining_quantiles_": Spec("f", shape=LEVELS.shape, lo=0.0, hi=np.pi / 2,
                                           increasing=True),
              "domain_": Spec("part", of=DomainCheck),
              "calibration_edges_": Spec("f", ndim=lambda f: 1 + f.calibration_by_record,
                                         finite=False, increasing=True),
              **{f"calibration_{k}_edges_": Spec("f", ndim=2, finite=False, increasing=True,
                                                 optional=k == "size")  # None: fitted without
                 for k in ("event", "size", "remaining")},
              "calibration_counts_": Spec("iu", lo=0, min_size=1),
              "percentiles_": Spec("f", lo=0.0, hi=100.0, min_size=3, increasing="strictly"),
              # the residuals were normalised before crepes saw them (kept to RESIDUAL_STEP)
              "calibration_": Spec("part", of=ResidualTable),
              "alarm_threshold_": Spec("number", lo=0.05, hi=0.95, optional=True),
              "alarm_skill_": Spec("dict", optional=True, of={
                  k: Spec("number", lo=lo, hi=hi) for k, (lo, hi) in ALARM_SKILL.items()})}

    def check_consistent(self) -> None:
        """What the declarations cannot say: the feature columns those of ``design``, the names
        those of the columns kept, each regressor of its level reading them, the tilt edges
        nested in ``RECORD_CATEGORIES`` kinds of record when calibrated by record, each nested
        edges one row per cell of those outside (``_cells``), the counts, percentiles and
        residual bins the calibration's, the alarm's threshold and skill both held or neither."""
        names = self.design(_probe_cuts())[1]
        kept = [n for n, k in zip(names, self.columns_) if k]
        require(self.columns_.size == len(names) and self.feature_names_ == kept,
                "the feature columns or names are not those of the forecaster's design")
        for level, m in zip(TRAINED_LEVELS, self.models_):
            require(m.n_features_in_ == len(kept) and m.quantile == level,
                    f"the regressor of level {level:g} reads {m.n_features_in_} features at "
                    f"level {m.quantile!r}")
        edges = self.calibration_edges_
        require(edges.ndim == 1 or edges.shape[0] == RECORD_CATEGORIES,
                f"the calibration's tilt edges are not nested in {RECORD_CATEGORIES} kinds of "
                "record")
        cells = _cells(edges)
        for inner in (self.calibration_event_edges_, getattr(self, "calibration_size_edges_", None),
                      self.calibration_remaining_edges_):
            if inner is not None:
                require(inner.shape[0] == cells, "the calibration's nested edges do not match")
                cells = _cells(inner)
        counts, cps = self.calibration_counts_, self.calibration_
        require(counts.size <= cells, "calibration counts of another number of bins")
        require(np.isin(self.percentiles_, CPS_PERCENTILES).all(),
                "the percentiles read are not the calibration's")
        require(cps.bins[-1] < counts.size and (cps.counts() == counts[cps.bins]).all(),
                "a calibration bin holds another number of residuals than counted")
        require((getattr(self, "alarm_threshold_", None) is None)
                == (getattr(self, "alarm_skill_", None) is None),
                "the alarm's threshold and its skill are not both held")

    def _quantiles(self, cuts):
        x, _ = self.design(cuts)
        z = self._raw_log_remaining(cuts, x)
        centre, spread = self._centre_spread(z)
        bins = self._calibration_bin(cuts, centre)
        # the normalised residuals' percentiles, scaled by each cut's spread
        unit = self.calibration_.predict(np.zeros(len(cuts)), bins=bins,
                                         lower_percentiles=self.percentiles_)
        unit = np.asarray(unit, dtype=float).reshape(len(cuts), self.percentiles_.size)
        grid = centre[:, None] + spread[:, None] * unit
        grid = np.sort(np.clip(grid, -20.0, 2.0), axis=1)
        percent = self._percentiles(grid)
        zc = np.array([np.interp(lv, self.percentiles_, g) for lv, g in
                       zip(percent, grid)]).reshape(len(cuts), LEVELS.size)
        q = edge(cuts)[:, None] + np.exp(zc)
        levels = percent / 100.0
        inside, _ = self.domain(cuts)
        out = ~inside
        if out.any():  # widened: the conditioned climatology's interval held too, and the
            # training cuts' remaining angles from the tilt reached (which still mean something
            # where the tilt is above every training avalanche angle)
            t = cuts.tilt_now[out]
            qc = conditioned_quantiles(self.climatology_.alpha_c_, t)[0]
            qr = t[:, None] + self.remaining_quantiles_[None, :]
            lower = np.minimum(np.minimum(q[out], qc), qr)
            upper = np.maximum(np.maximum(q[out], qc), qr)
            half = LEVELS < 0.5
            q[out] = np.where(half[None, :], lower, upper)
            levels[out] = LEVELS  # no distribution of its own: read at the nominal levels
        return q, out, levels


def _outside(feature: str, value: float, lo: float, hi: float) -> str:
    """Why a measurement feature's ``value`` lies outside the training's [lo, hi] (one phrase)."""
    if feature == "angle_resolution":
        return (f"an angle error of {np.degrees(value):g}°, outside the training measurements' "
                f"{np.degrees(lo):g}-{np.degrees(hi):g}°")
    if feature == "missed_fraction":
        return (f"a share of {value:g} of the events missed, outside the training measurements' "
                f"{lo:g}-{hi:g}")
    if feature == "size_arbitrary":
        return "sizes in an arbitrary unit, which no training catalogue had"
    return (f"a smallest size detected of {value:g} (in sliders, or over the median size in an "
            f"arbitrary unit), outside the training measurements' {lo:g}-{hi:g}")


def _probe_cuts():
    """One small complete catalogue (displacements, movers): ``design`` names every feature."""
    k = np.arange(12)
    cat = Catalogue(0.02 * (k + 1), 1 + k % 3, 0.01 * (1 + k % 2), k % 5, k % 5 + k % 3,
                    tilt_now=0.3)
    return Cuts.from_catalogues([cat])


def _quantile_edges(values, bins: int) -> np.ndarray:
    """(bins - 1,) inner edges splitting ``values`` into ``bins`` bins of about equal counts,
    each of at least ``MIN_PER_BIN`` (an edge that would leave fewer, e.g. between tied
    values, is dropped; its place padded with +inf, an empty bin no value reaches)."""
    values = np.sort(np.asarray(values, dtype=float))
    edges = []
    for e in np.quantile(values, np.linspace(0, 1, bins + 1)[1:-1]) if values.size else []:
        at_or_below = np.searchsorted(values, e, side="right")  # a value on an edge is below it
        below = at_or_below - np.searchsorted(values, edges[-1] if edges else -np.inf, side="right")
        above = values.size - at_or_below
        if below >= MIN_PER_BIN and above >= MIN_PER_BIN:
            edges.append(float(e))
    return np.array(edges + [np.inf] * (bins - 1 - len(edges)))


def _nested_edges(values, cell, cells: int, bins: int) -> np.ndarray:
    """(cells, bins - 1) ``_quantile_edges`` of ``values`` within each cell."""
    return np.array([_quantile_edges(values[cell == c], bins) for c in range(cells)]).reshape(
        cells, bins - 1)


def _cells(edges) -> int:
    """The number of bins of inner ``edges``: (bins - 1,), or (cells, bins - 1) nested."""
    return edges.size + 1 if edges.ndim == 1 else edges.shape[0] * (edges.shape[1] + 1)


def record_category(cuts) -> np.ndarray:
    """(n,) each cut's kind of record (``RECORD_CATEGORIES``): its size class told
    (``TOLD_CLASSES``, by the geometric middle of the range told; 0: not told), and whether
    its angles carry an error (``RECORD_CATEGORIES // 2`` added)."""
    out = []
    for m in cuts.measurements():
        told = 0
        if m.n_sliders is not None:
            middle = math.sqrt(m.n_sliders * (m.n_sliders_high or m.n_sliders))
            told = 1 + int(np.searchsorted(TOLD_CLASSES, middle, side="right"))
        out.append(told + (RECORD_CATEGORIES // 2 if m.angle_resolution > 0 else 0))
    return np.array(out, dtype=np.int64)


def _nested_bin(edges, cell, values) -> np.ndarray:
    """(n,) each value's bin within its cell's edges (``_nested_edges``)."""
    return np.array([np.searchsorted(edges[c], v) for c, v in zip(cell, values)], dtype=np.int64)


def _nested_cell(edges, cell, values) -> np.ndarray:
    """(n,) each value's cell among all those of nested ``edges``: its bin (``_nested_bin``)
    within its outer ``cell``, numbered on from the bins of the cells before it."""
    return cell * (edges.shape[1] + 1) + _nested_bin(edges, cell, values)


def _log_events(cuts) -> np.ndarray:
    """(n,) log(1 + the number of events so far) of each cut."""
    return np.log1p(np.array([len(c) for c in cuts.catalogues], dtype=float))


def _log_mean_size(cuts) -> np.ndarray:
    """(n,) log of the mean event size so far of each cut (0 without events), in the
    catalogue's own unit: it grows with the pile's number of sliders."""
    return np.log(np.array([float(np.mean(c.size)) if len(c) else 1.0 for c in cuts.catalogues]))


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
