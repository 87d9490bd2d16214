"""The posterior of a pile's material parameters from its catalogue (amortized inference).

A prior ensemble (``python -m sliders.prior``) holds, for every row, the
material drawn (mu_d, mu_s - mu_d, sigma_mu, xi, the number of sliders) and
the catalogue it made.  Cut at random tilts and measured as an experiment
would (``features.training_cuts``, ``measurement.degrade_cuts``, and half of
the cuts kept to their angles and sizes), those catalogues are samples of the
joint law of parameters and catalogues; ``ParameterPosterior`` learns, for
each parameter, the quantiles of its conditional law given the catalogue's
features (``features.feature_matrix``): one gradient-boosted quantile
regressor per parameter and level of ``POSTERIOR_LEVELS``.  Nothing is
simulated at inference: one catalogue's posterior is one pass through the
trees.

Each parameter is learned on the scale where its prior is flat: mu_d as it
is, the others as log10; ``xi``, which is exactly 0 for a share of the prior,
has its zero coded ``XI_ZERO_GAP`` decades below its smallest positive value,
so that its conditional quantiles hold the atom (P(xi = 0) is the
conditional CDF at the gap) and the quantiles given xi > 0 are read above it.
The number of sliders takes the prior's values: the CDF between their
midpoints gives each value's probability.

The calibration is conformal (split by realisation): rows held out of the fit
(``calibration_share``) are cut the same way, and every quantile is shifted
by the level's quantile of their residuals, in units of the predicted 10-90 %
spread, per class of catalogue (complete, or angles and sizes only).  Each
calibrated quantile then holds its level over the prior, the property
simulation-based calibration tests (``probability_integral``).  Between the
levels that CDF is linear, and below the lowest and above the highest it
reaches the prior's range: too coarse where a posterior is sharp.  The CDF
reported is that one mapped, per group of catalogue (``RECALIBRATION_GROUPS``)
and parameter, through the empirical CDF of the calibration realisations'
probability integral transforms (quantile recalibration), read at
``REPORTED_LEVELS``: medians, intervals, draws and ranks all use it.

mu_d is learned about an estimate where the catalogue gives one: from the
lone slips of a complete catalogue of exact angles, mu_d and the cantilevers'
xi solved together (``features.coupled_lone_slips``, exact whatever xi), or
failing that the lone-slider pairs that neglect xi (exact when xi = 0).

The domain check (``domain.DomainCheck``) is fitted on the training cuts and
its thresholds set on the calibration realisations' cuts (``domain_level`` of
them flagged): it is the prior predictive test of the command's check, and
the posterior predictive test compares a catalogue with piles simulated at
posterior draws (``posterior_check``).  ``given(catalogue)`` is one catalogue's posterior
(``CataloguePosterior``: ``sample``, ``cdf``, ``ppf``, ``summary``, ``contraction``); the
tests of its calibration are ``calibration``'s.
"""

from __future__ import annotations

import json
import math

import numpy as np
from scipy.special import ndtr, ndtri

from ...io.catalogue import Catalogue, CatalogueSet
from ...parts import materials
from .domain import DOMAIN_FEATURES, DomainCheck
from .estimator import Estimator
from .features import Cuts, coupled_lone_slips, feature_matrix, training_cuts
from .evaluators import QuantileTrees
from .integrity import IntegrityError, Spec, check_fields, require
from .measurement import PERFECT, RECORD_FEATURES, TOLD_FEATURES, degrade_cuts

#: the material parameters inferred, in order (``parts.materials``)
POSTERIOR_PARAMETERS = materials.NAMES
#: those learned as log10 (their priors are log-uniform, or a choice spread over decades)
LOG_PARAMETERS = materials.LOG_NAMES
#: the levels of the conditional quantiles learned: the median and the 50, 80 and 95 % intervals
POSTERIOR_LEVELS = np.array([0.025, 0.1, 0.25, 0.5, 0.75, 0.9, 0.975])
#: decades below the smallest positive xi of the prior at which xi = 0 is coded
XI_ZERO_GAP = 0.5
#: the classes of catalogue with their own conformal shifts: complete, or angles and sizes only
CATALOGUE_CLASSES = ("complete", "angles_sizes")
#: lone-slider pairs that must agree (``features.single_slider_mu_d``) for mu_d to be learned
#: about their estimate, in a complete catalogue of exact angles
REFERENCE_AGREE = 2
#: lone-slip pairs that must agree with mu_d and xi solved together
#: (``features.coupled_lone_slips``) for mu_d to be learned about that solution instead
COUPLED_AGREE = 4
#: the columns of ``features.coupled_lone_slips`` in ``design``
COUPLED_NAMES = ["coupled_mu_d", "coupled_xi", "coupled_agree"]
#: the points of the posterior's CDF its variance is computed on
VARIANCE_POINTS = 400
#: the levels of the quantile function a posterior reports (``quantiles``): every 1/80, the
#: learned ``POSTERIOR_LEVELS`` among them
REPORTED_LEVELS = np.arange(1, 80) / 80
#: the groups of catalogues with their own recalibration of every parameter's CDF: complete
#: ones whose lone slips give mu_d (``lone_slider_mu_d``), the other complete ones recorded
#: as they are (``measurement.PERFECT``) or measured, and those of angles and sizes only,
#: recorded as they are or measured
RECALIBRATION_GROUPS = ("complete_lone_slips", "complete_exact", "complete_measured",
                        "angles_sizes_exact", "angles_sizes_measured")
#: calibration cuts a group needs for its recalibration (fewer: the CDF is left as it is)
RECALIBRATION_MIN_CUTS = 200
#: the recalibration's cuts of each calibration realisation, in units of ``draws_per_row``
RECALIBRATION_DRAWS = 4
#: the level of the uniformity tests (``calibration.pit_is_off``, one calibration cut a
#: realisation)
#: that a group's PITs of a parameter under the conformal CDF must fail for that CDF to be
#: recalibrated: a map fitted where the CDF is already calibrated would only add its noise
RECALIBRATION_ALPHA = 0.05
#: the recalibration map's compositions (the atoms' uniform spread depends on the map)
RECALIBRATION_ROUNDS = 8
#: the share of a prior's range within which two values are one: a run of the reported
#: quantiles that close (a posterior sharper than that: mu_d from the lone slips) is an atom
ATOM_WIDTH = 1e-9
#: the central intervals whose share of the truths ``pit_is_off`` tests
CENTRAL_INTERVALS = (0.5, 0.8, 0.95)
#: the physical range of each parameter a posterior file may hold, in its own units: the friction
#: coefficients positive (mu_d > 0; mu_s - mu_d and sigma_mu, learned as log10, are positive
#: wherever they are finite), xi >= 0 (its zero coded below its range), and none so large
#: that a pile of it means nothing (a friction coefficient of 1000 is a tilt of 89.94 degrees)
PHYSICAL_RANGES = {m.name: m.physical_range for m in materials.MATERIALS}
#: the fewest decades below 1 a parameter learned as log10 may reach (10**-300 is a number)
LOG_FLOOR = -300.0


def recalibration_map(u, previous=REPORTED_LEVELS) -> np.ndarray:
    """(M,) the recalibration that makes the probability integral transforms ``u`` uniform:
    for each of ``REPORTED_LEVELS``, the probability of the CDF ``u`` were read on at which
    the CDF reported reaches it (the PITs' empirical quantile), composed with the map
    ``previous`` that CDF was already read through."""
    ends = np.concatenate([[0.0], REPORTED_LEVELS, [1.0]])
    return np.interp(np.quantile(u, REPORTED_LEVELS), ends,
                     np.concatenate([[0.0], previous, [1.0]]))


def recalibrated(u, recalibration) -> np.ndarray:
    """The probabilities ``u`` of a CDF through its ``recalibration``: the CDF reported."""
    return np.interp(u, np.concatenate([[0.0], recalibration, [1.0]]),
                     np.concatenate([[0.0], REPORTED_LEVELS, [1.0]]))


def interp_rows(x, xp, fp) -> np.ndarray:
    """``np.interp`` row by row, to the last bit: (n, k) points ``x`` on (n, K) or (K,) knots
    ``xp`` (increasing in each row) of (n, K) or (K,) values ``fp``."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    shared = np.ndim(xp) == 1
    xp, fp = (np.broadcast_to(np.asarray(a, dtype=float), (n, np.shape(a)[-1])) for a in (xp, fp))
    j = (np.searchsorted(xp[0], x, side="right") if shared
         else (xp[:, None, :] <= x[:, :, None]).sum(axis=2))
    j = np.clip(j - 1, 0, xp.shape[1] - 2)
    rows = np.arange(n)[:, None]
    x0, x1, f0, f1 = xp[rows, j], xp[rows, j + 1], fp[rows, j], fp[rows, j + 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (f1 - f0) / (x1 - x0) * (x - x0) + f0
    out = np.where(x == x0, f0, out)
    return np.where(x < xp[:, :1], fp[:, :1], np.where(x >= xp[:, -1:], fp[:, -1:], out))


def learned_scale(name: str, values, xi_zero_code: float = math.nan) -> np.ndarray:
    """``values`` of parameter ``name`` on the scale the regressors learn (xi = 0 coded)."""
    v = np.asarray(values, dtype=float)
    if name not in LOG_PARAMETERS:
        return v
    with np.errstate(divide="ignore"):
        out = np.log10(v)
    return np.where(v > 0, out, xi_zero_code) if name == "xi" else out


def design(cuts: Cuts) -> np.ndarray:
    """(n, F) what the regressors see: the catalogue's and the measurement's features
    (``features.feature_matrix``), mu_d and xi solved together from the lone-slip pairs and
    how many agree (``features.coupled_lone_slips``), whether the catalogue is complete, and
    whether its lone-slider pairs give mu_d (``lone_slider_mu_d``)."""
    x, names = record_features(cuts)
    coupled = np.array([coupled_lone_slips(c) for c in cuts.catalogues],
                       dtype=float).reshape(len(cuts), len(COUPLED_NAMES))
    x = np.hstack([x, coupled])
    complete = np.array([c.complete for c in cuts.catalogues], dtype=float)
    exact = np.isfinite(lone_slider_mu_d(x, names + COUPLED_NAMES)).astype(float)
    return np.hstack([x, complete[:, None], exact[:, None]])


def lone_slider_mu_d(x, names) -> np.ndarray:
    """(n,) mu_d from the lone-slip pairs of a catalogue of exact angles, NaN elsewhere: mu_d
    and xi solved together where ``COUPLED_AGREE`` pairs agree with them (exact whatever xi),
    else the estimate ``REFERENCE_AGREE`` pairs agree on neglecting xi (exact when xi = 0)."""
    exact_angles = x[:, names.index("angle_resolution")] == 0
    a = x[:, names.index("atan_mu_d_single")]
    single = (np.isfinite(a) & (x[:, names.index("single_slider_agree")] >= REFERENCE_AGREE)
              & exact_angles)
    c = x[:, names.index("coupled_mu_d")]
    coupled = (np.isfinite(c) & (x[:, names.index("coupled_agree")] >= COUPLED_AGREE)
               & exact_angles)
    return np.where(coupled, c, np.where(single, np.tan(np.where(single, a, 0.0)), np.nan))


def design_names() -> list[str]:
    """The names of ``design``'s columns."""
    one = Catalogue([0.1], [1], [0.0], [0], [0], 0.1)
    return (record_features(Cuts.from_catalogues([one]))[1] + COUPLED_NAMES
            + ["complete", "lone_slider_mu_d"])


def record_features(cuts: Cuts) -> tuple[np.ndarray, list[str]]:
    """``features.feature_matrix`` without the number of sliders told (``TOLD_FEATURES``): the
    posterior infers N, it is not told it."""
    x, names = feature_matrix(cuts)
    keep = [i for i, n in enumerate(names) if n not in TOLD_FEATURES]
    return x[:, keep], [names[i] for i in keep]


def _n_p(p) -> tuple:
    """(the number of parameters,) of a posterior: the shape of its per-parameter arrays."""
    return (len(p.parameters_),)


class ParameterPosterior(Estimator):
    """Conditional quantiles of the material parameters given a catalogue, conformally calibrated.

    Parameters
    ----------
    draws_per_row : int
        Random cuts per training realisation (``features.training_cuts``).
    max_iter, learning_rate, max_leaf_nodes, min_samples_leaf, max_bins : int or float
        Of each ``HistGradientBoostingRegressor`` (quantile loss).
    degrade : bool
        Degrade the cuts by measurements drawn from ``measurement.MEASUREMENT_RANGES``.
    exact_share : float
        Share of the cuts kept as recorded (exact angles, every event), beside the
        measurements' own exact ones: the measurement is a feature, so its law in training
        changes no posterior, and the lone-slider pairs that give mu_d need exact angles.
    angles_sizes_share : float
        Share of the cuts kept to their angles and sizes.
    calibration_share : float
        Share of the realisations held out of the fit to calibrate (split by realisation).
    domain_level : float
        The prior predictive check's level: the share of the calibration realisations' cuts
        the domain check's novelty detectors flag (``DomainCheck.calibrate``).
    random_state : int
        Seeds the split, the cuts, the degradations and the regressors.

    Attributes
    ----------
    parameters_ : tuple of str
        The parameters inferred (those of ``POSTERIOR_PARAMETERS`` the prior draws).
    models_ : list of list
        ``models_[p][l]``: the regressor of parameter p at ``POSTERIOR_LEVELS[l]``.
    low_, high_ : numpy.ndarray
        (P,) the prior's range of each parameter, on the learned scale.
    prior_variance_ : numpy.ndarray
        (P,) the prior's variance on the learned scale (the contraction's reference).
    shifts_ : numpy.ndarray
        (classes, P, L) the conformal shifts, in units of the predicted 10-90 % spread.
    recalibration_ : numpy.ndarray
        (groups, P, M) the recalibration: the probability of the conformal CDF at which the
        CDF reported reaches each of ``REPORTED_LEVELS``, non-decreasing in [0, 1] (the
        levels themselves where a group's CDF was left as it is).
    copula_ : numpy.ndarray
        (P, P) the correlation of the parameters' normal scores about their posterior.
    xi_zero_code_ : float
        Where xi = 0 sits on the learned scale (NaN if xi is not inferred).
    n_sliders_values_ : numpy.ndarray
        The prior's numbers of sliders.
    domain_ : DomainCheck
        Whether a catalogue is like the training cuts.
    prior_ : str
        The prior's specification (JSON): the predictive check simulates its scene.
    n_calibration_realisations_ : int
        The realisations held out of the fit that calibrate it (``calibration`` among them).
    """

    def __init__(self, draws_per_row: int = 6, max_iter: int = 50, learning_rate: float = 0.1,
                 max_leaf_nodes: int = 15, min_samples_leaf: int = 40, max_bins: int = 63,
                 degrade: bool = True, exact_share: float = 0.5, angles_sizes_share: float = 0.3,
                 calibration_share: float = 0.2, domain_level: float = 0.005,
                 random_state: int = 0):
        self.draws_per_row = draws_per_row
        self.max_iter = max_iter
        self.learning_rate = learning_rate
        self.max_leaf_nodes = max_leaf_nodes
        self.min_samples_leaf = min_samples_leaf
        self.max_bins = max_bins
        self.degrade = degrade
        self.exact_share = exact_share
        self.angles_sizes_share = angles_sizes_share
        self.calibration_share = calibration_share
        self.domain_level = domain_level
        self.random_state = random_state

    # -- fit ------------------------------------------------------------------------------
    def cuts_of(self, cset, rng, draws: int | None = None) -> Cuts:
        """Random cuts of ``cset`` (``draws`` a realisation, ``draws_per_row`` unless given),
        degraded if ``degrade``, a share kept to angles and sizes."""
        cuts = training_cuts(cset, self.draws_per_row if draws is None else draws, rng)
        if self.degrade:
            kept = cuts.catalogues
            exact = rng.random(len(cuts)) < self.exact_share
            cuts = degrade_cuts(cuts, rng)
            cuts.catalogues = [k if e else c for k, c, e in zip(kept, cuts.catalogues, exact)]
            cuts.measurement = [PERFECT if e else m for m, e in zip(cuts.measurement, exact)]
        strip = rng.random(len(cuts)) < self.angles_sizes_share
        cuts.catalogues = [c.angles_and_sizes() if s else c for c, s in zip(cuts.catalogues, strip)]
        return cuts

    def targets(self, cset, rows) -> np.ndarray:
        """(n, P) the parameters of ``cset``'s rows ``rows`` on the learned scale."""
        return np.column_stack([learned_scale(p, np.asarray(cset.parameters[p])[rows],
                                              self.xi_zero_code_) for p in self.parameters_])

    def fit(self, train, y=None, calibration=None):
        """Fit the regressors on ``train`` (a ``CatalogueSet`` with its parameters), calibrate on
        its held-out realisations, and fit the domain check.

        ``calibration``, a ``CatalogueSet`` of the same prior drawn with another seed, joins
        the held-out realisations (none of its rows is fitted): the recalibration's map is
        an empirical CDF of theirs, and its noise falls as the square root of their number."""
        from threadpoolctl import threadpool_limits  # scikit-learn's, as the fit is

        # the trees' OpenMP threads on a shared machine wait for each other (20 s a fit, not 0.3)
        with threadpool_limits(limits=1, user_api="openmp"):
            return self._fit(train, calibration)

    def calibration_split(self, n: int):
        """The fit's generator and which of ``n`` training realisations it holds out of the
        fit to calibrate (the conformal shifts, the copula, the domain check's thresholds)."""
        rng = np.random.default_rng(self.random_state)
        return rng, rng.random(n) < self.calibration_share

    def _fit(self, train, calibration=None):
        rng, held = self.calibration_split(len(train))
        self.parameters_ = tuple(p for p in POSTERIOR_PARAMETERS if p in train.parameters)
        require(self.parameters_, "the prior file holds none of the material parameters")
        xi = np.asarray(train.parameters.get("xi", []), dtype=float)
        # below the smallest positive xi; a prior of xi = 0 alone has it below xi = 1
        self.xi_zero_code_ = (float(np.log10(xi[xi > 0].min() if (xi > 0).any() else 1.0)
                                    - XI_ZERO_GAP) if xi.size else math.nan)
        self.n_sliders_values_ = np.unique(np.asarray(train.parameters.get("n_sliders", [1]),
                                                      dtype=float))
        every = self.targets(train, np.arange(len(train)))
        self.low_, self.high_ = every.min(axis=0), every.max(axis=0)
        self.prior_variance_ = np.maximum(every.var(axis=0), 1e-12)
        fit_set, cal_set = train.subset(np.flatnonzero(~held)), train.subset(np.flatnonzero(held))
        if calibration is not None:
            missing = sorted(set(self.parameters_) - set(calibration.parameters))
            require(not missing, f"the calibration realisations lack {', '.join(missing)}")
            cal_set = CatalogueSet.joined([cal_set, calibration.subset(
                np.flatnonzero(np.isfinite(np.asarray(calibration.alpha_c, dtype=float))))])
        self.n_calibration_realisations_ = len(cal_set)
        cuts = self.cuts_of(fit_set, rng)
        x = design(cuts)
        self.mu_d_reference_ = float(np.median(np.asarray(train.parameters.get("mu_d", [0.0]))))
        y_fit = self.targets(fit_set, cuts.row) - self._offsets(x)
        self.n_features_in_ = x.shape[1]
        self.models_ = [[self._regressor(level).fit(x, y_fit[:, p]) for level in POSTERIOR_LEVELS]
                        for p in range(len(self.parameters_))]
        cal = self.cuts_of(cal_set, rng)
        self._calibrate(cal, self.targets(cal_set, cal.row))
        self._recalibrate(cal_set)
        self.domain_ = DomainCheck(DOMAIN_FEATURES, random_state=self.random_state).fit(
            cuts, fit_set.alpha_c, order=rng.permutation(len(cuts)),
            n_sliders=fit_set.parameters.get("n_sliders")).calibrate(cal, self.domain_level)
        self.prior_ = str(train.attrs.get("prior", "{}"))
        self.n_training_cuts_, self.n_calibration_cuts_ = len(cuts), len(cal)
        return self

    def _regressor(self, level: float):
        from sklearn.ensemble import HistGradientBoostingRegressor

        return HistGradientBoostingRegressor(
            loss="quantile", quantile=float(level), max_iter=self.max_iter,
            learning_rate=self.learning_rate, max_leaf_nodes=self.max_leaf_nodes,
            min_samples_leaf=self.min_samples_leaf, max_bins=self.max_bins,
            early_stopping=False, random_state=self.random_state)

    def _calibrate(self, cuts: Cuts, truth: np.ndarray) -> None:
        """The conformal shifts: per class of catalogue, parameter and level, the level's
        quantile of the held-out residuals over the predicted spread."""
        q = self._raw_quantiles(design(cuts))
        spread = self._spread(q)
        residual = (truth[:, :, None] - q) / spread[:, :, None]
        kind = self._class_of(cuts)
        self.shifts_ = np.zeros((len(CATALOGUE_CLASSES), len(self.parameters_),
                                 POSTERIOR_LEVELS.size))
        for k in range(len(CATALOGUE_CLASSES)):
            r = residual[kind == k]
            if len(r):
                n = len(r)
                # the finite-sample conformal level, moved away from the median
                lv = np.clip(np.where(POSTERIOR_LEVELS < 0.5,
                                      np.floor(POSTERIOR_LEVELS * (n + 1)) / n,
                                      np.ceil(POSTERIOR_LEVELS * (n + 1)) / n), 0.0, 1.0)
                self.shifts_[k] = np.stack([np.quantile(r[:, :, j], lv[j], axis=0)
                                            for j in range(lv.size)], axis=1)

    def _recalibrate(self, cal_set) -> None:
        """The recalibration of every parameter's CDF, then the copula.

        The calibration realisations ``cal_set`` are cut again (``RECALIBRATION_DRAWS`` times
        the fit's cuts, a generator of their own); per group of catalogue
        (``RECALIBRATION_GROUPS``) and parameter, the CDF the posterior reports is the
        conformal one mapped through the empirical CDF of the held-out truths' probability
        integral transforms (quantile recalibration), so that these are uniform, where the
        conformal CDF's are not (``pit_is_off``).  The atoms (xi = 0, each number of sliders,
        runs of equal quantiles) spread their PIT uniformly over their probability in the
        CDF reported, which the map changes: it is composed again
        ``RECALIBRATION_ROUNDS`` times on the PITs of the CDF it makes.  Between the learned
        levels the conformal CDF is linear, too coarse where a posterior is sharp (mu_d from
        the lone slips): the map resolves it to ``REPORTED_LEVELS``."""
        from .calibration import pit_is_off  # SciPy's statistics, needed by the fit only

        rng = np.random.default_rng([self.random_state, 1])
        cuts = self.cuts_of(cal_set, rng, self.draws_per_row * RECALIBRATION_DRAWS)
        truth = {p: np.asarray(cal_set.parameters[p])[cuts.row] for p in self.parameters_}
        x = design(cuts)
        conformal, group = self.conformal_quantiles(cuts, x), self._group_of(x)
        n_g, n_p = len(RECALIBRATION_GROUPS), len(self.parameters_)
        self.recalibration_ = np.tile(REPORTED_LEVELS, (n_g, n_p, 1))
        off = np.zeros((n_g, n_p), dtype=bool)  # the conformal CDFs that are off
        for round_ in range(RECALIBRATION_ROUNDS):
            u = self._pit(self._reported(conformal, group), truth, rng)
            for g in range(n_g):
                if (group == g).sum() < RECALIBRATION_MIN_CUTS:
                    continue
                if round_ == 0:  # one cut a realisation, independent PITs: off at all?
                    order = rng.permutation(np.flatnonzero(group == g))
                    one = order[np.unique(cuts.row[order], return_index=True)[1]]
                    off[g] = [pit_is_off(u[one, p], RECALIBRATION_ALPHA, CENTRAL_INTERVALS)
                              for p in range(n_p)]
                for p in np.flatnonzero(off[g]):
                    self.recalibration_[g, p] = recalibration_map(
                        u[group == g, p], self.recalibration_[g, p])
        self._fit_copula(self._pit(self._reported(conformal, group), truth, rng))

    def _fit_copula(self, u) -> None:
        """How the parameters vary together about their posterior: the correlation of the
        normal scores of ``u``, the held-out truths' posterior CDFs (a Gaussian copula, the
        same for every catalogue: the quantiles are learned one parameter at a time)."""
        u = np.clip(u, 1e-4, 1 - 1e-4)
        c = np.corrcoef(ndtri(u), rowvar=False) if len(u) > 2 else np.eye(u.shape[1])
        c = np.nan_to_num(np.atleast_2d(c), nan=0.0)
        np.fill_diagonal(c, 1.0)
        # kept positive definite: shrunk towards independence until its Cholesky factor exists
        for shrink in np.linspace(0.0, 1.0, 11):
            try:
                np.linalg.cholesky((1 - shrink) * c + shrink * np.eye(len(c)))
                break
            except np.linalg.LinAlgError:
                continue
        self.copula_ = (1 - shrink) * c + shrink * np.eye(len(c))

    # -- predict -----------------------------------------------------------------------------
    def _offsets(self, x) -> np.ndarray:
        """(n, P) what each parameter is learned about: mu_d about the lone-slider pairs'
        estimate where ``REFERENCE_AGREE`` of them agree in a complete catalogue of exact
        angles (there it is exact when xi = 0: the regressors learn the small remainder), else
        about the prior's median; the others about 0."""
        off = np.zeros((len(x), len(self.parameters_)))
        if "mu_d" in self.parameters_:
            mu_d = lone_slider_mu_d(x, design_names())
            off[:, self.parameters_.index("mu_d")] = np.where(np.isfinite(mu_d), mu_d,
                                                              self.mu_d_reference_)
        return off

    def _raw_quantiles(self, x) -> np.ndarray:
        # read from a model file: NumPy's trees (``evaluators.QuantileTrees``); while fitting,
        # scikit-learn's, under the fit's limit of its threads
        q = np.stack([np.column_stack([m.predict(x) for m in models])
                      for models in self.models_], axis=1)
        return np.sort(q + self._offsets(x)[:, :, None], axis=2)

    def _spread(self, q) -> np.ndarray:
        lo, hi = np.searchsorted(POSTERIOR_LEVELS, [0.1, 0.9])
        # a floor of a thousandth of the prior's range; a parameter the prior holds fixed
        # (no range) has its value for every quantile, and a unit spread keeps its shifts 0
        width = (self.high_ - self.low_)[None, :]
        return np.maximum(q[:, :, hi] - q[:, :, lo], np.where(width > 0, 1e-3 * width, 1.0))

    @staticmethod
    def _class_of(cuts: Cuts) -> np.ndarray:
        return np.array([0 if c.complete else 1 for c in cuts.catalogues])

    @staticmethod
    def _group_of(x) -> np.ndarray:
        """(n,) each cut's index in ``RECALIBRATION_GROUPS``, from its ``design`` row."""
        names = design_names()
        complete = x[:, names.index("complete")] > 0
        lone = x[:, names.index("lone_slider_mu_d")] > 0
        m = x[:, [names.index(k) for k in RECORD_FEATURES]]
        exact = (m == PERFECT.as_features(Catalogue([], [], [], [], []))[:len(RECORD_FEATURES)]).all(axis=1)
        return np.where(complete, np.where(lone, 0, np.where(exact, 1, 2)),
                        np.where(exact, 3, 4))

    def conformal_quantiles(self, cuts: Cuts, x=None) -> np.ndarray:
        """(n, P, L) the conformally calibrated quantiles of every parameter at
        ``POSTERIOR_LEVELS``, on the learned scale, within the prior's range."""
        q = self._raw_quantiles(design(cuts) if x is None else x)
        q = q + self.shifts_[self._class_of(cuts)] * self._spread(q)[:, :, None]
        return np.sort(np.clip(q, self.low_[None, :, None], self.high_[None, :, None]), axis=2)

    def quantiles(self, cuts: Cuts) -> np.ndarray:
        """(n, P, M) every parameter's posterior quantiles at ``REPORTED_LEVELS`` on the
        learned scale: the conformal quantile function (linear between the learned levels and
        out to the prior's range) at the levels the recalibration of the cut's group maps
        them to."""
        x = design(cuts)
        return self._reported(self.conformal_quantiles(cuts, x), self._group_of(x))

    def _reported(self, q, group) -> np.ndarray:
        levels = np.concatenate([[0.0], POSTERIOR_LEVELS, [1.0]])
        out = np.empty(q.shape[:2] + (REPORTED_LEVELS.size,))
        for p in range(q.shape[1]):
            knots = self._with_ends(q[:, p], p)
            for g in np.unique(group):
                at = group == g
                r = np.broadcast_to(self.recalibration_[g, p], (int(at.sum()), REPORTED_LEVELS.size))
                out[at, p] = interp_rows(r, levels, knots[at])
        return out

    def _with_ends(self, q, p: int) -> np.ndarray:
        """(n, K + 2) the quantiles ``q`` (n, K) of parameter ``p`` between its prior's ends."""
        n = len(q)
        return np.hstack([np.full((n, 1), self.low_[p]), q, np.full((n, 1), self.high_[p])])

    def knots(self, q_row: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
        """The CDF of parameter ``p`` for one cut: (values, probabilities), increasing, from
        the prior's low end (0) through the reported quantiles to its high end (1)."""
        x, u = self.knots_of(q_row[None], p)
        return x[0], u

    def knots_of(self, q, p: int) -> tuple[np.ndarray, np.ndarray]:
        """``knots`` of many cuts at once: (n, M + 2) values and the (M + 2,) probabilities."""
        x = np.maximum.accumulate(self._with_ends(q[:, p], p), axis=1)
        scale = np.maximum(1.0, np.abs(x).max(axis=1, keepdims=True))
        x = x + np.arange(x.shape[1]) * 1e-12 * scale
        return x, np.concatenate([[0.0], REPORTED_LEVELS, [1.0]])

    def cdf(self, q_row, p: int, value) -> np.ndarray:
        """P(parameter ``p`` <= ``value``) for one cut (learned scale)."""
        x, u = self.knots(q_row, p)
        return np.interp(value, x, u)

    def ppf(self, q_row, p: int, u) -> np.ndarray:
        """The inverse CDF of parameter ``p`` for one cut at probabilities ``u``."""
        x, lv = self.knots(q_row, p)
        return np.interp(u, lv, x)

    def xi_zero_edge(self) -> float:
        """On the learned scale, between xi = 0 and the smallest positive xi of the prior."""
        return self.xi_zero_code_ + XI_ZERO_GAP / 2

    def n_sliders_edges(self) -> np.ndarray:
        """log10 of the midpoints between the prior's numbers of sliders, with the range's ends."""
        v = np.log10(self.n_sliders_values_)
        return np.concatenate([[-np.inf], (v[1:] + v[:-1]) / 2, [np.inf]])

    def probability_integral(self, cuts: Cuts, truth: dict, rng) -> np.ndarray:
        """(n, P) each true parameter's posterior CDF (the rank of simulation-based
        calibration): uniform on [0, 1] when the posterior is calibrated.  The atoms (xi = 0,
        each number of sliders, and a run of equal quantiles where a posterior is sharper
        than ``ATOM_WIDTH`` of the prior's range) are spread uniformly over their
        probability."""
        return self._pit(self.quantiles(cuts), truth, rng)

    def _pit(self, q, truth: dict, rng) -> np.ndarray:
        lo, hi = self.pit_bounds(q, truth)
        out = lo.copy()
        for p in range(lo.shape[1]):
            for i in range(len(lo)):
                if hi[i, p] > lo[i, p]:
                    out[i, p] = rng.uniform(lo[i, p], hi[i, p])
        return out

    def pit_bounds(self, q, truth: dict) -> tuple[np.ndarray, np.ndarray]:
        """(n, P) twice: each true parameter's posterior CDF just below it and at it, given
        the reported quantiles ``q`` (``quantiles``): the probability integral transform is
        uniform between the two (an atom: xi = 0, each number of sliders, a run of equal
        quantiles within ``ATOM_WIDTH`` of the prior's range), one number where they meet."""
        lo, hi = np.zeros((2, len(q), len(self.parameters_)))
        for p, name in enumerate(self.parameters_):
            y = learned_scale(name, np.asarray(truth[name], dtype=float), self.xi_zero_code_)
            tol = ATOM_WIDTH * (self.high_[p] - self.low_[p])
            ends = np.column_stack([y - tol, y + tol])
            if name == "xi":
                zero = y <= self.xi_zero_edge()
                ends[zero] = [-np.inf, self.xi_zero_edge()]
            elif name == "n_sliders":
                e = np.clip(self.n_sliders_edges(), -1e9, 1e9)
                k = np.searchsorted(self.n_sliders_edges(), y) - 1
                ends = np.column_stack([e[k], e[k + 1]])
            x, u = self.knots_of(q, p)
            lo[:, p], hi[:, p] = interp_rows(ends, x, u).T
        return lo, hi

    def sample(self, q_row, n: int, rng) -> dict:
        """``n`` draws of every parameter for one cut, in the parameters' own units (xi = 0
        and the prior's numbers of sliders as they are drawn): each parameter's inverse CDF
        at uniform draws joined by the Gaussian copula ``copula_``."""
        z = rng.standard_normal((n, len(self.parameters_))) @ np.linalg.cholesky(self.copula_).T
        u = ndtr(z)
        return {name: self.physical(name, self.ppf(q_row, p, u[:, p]))
                for p, name in enumerate(self.parameters_)}

    def physical(self, name: str, y) -> np.ndarray:
        """Values of the learned scale in the parameter's own units."""
        y = np.asarray(y, dtype=float)
        if name == "mu_d":
            return y
        if name == "xi":  # the gap below the smallest positive xi belongs to it
            return np.where(y <= self.xi_zero_edge(), 0.0,
                            10.0 ** np.maximum(y, self.xi_zero_code_ + XI_ZERO_GAP))
        if name == "n_sliders":
            v = self.n_sliders_values_
            return v[np.argmin(np.abs(np.log10(v)[None, :] - y.reshape(-1, 1)), axis=1)].reshape(
                y.shape)
        return 10.0 ** y

    def summary(self, q_row) -> dict:
        """Every parameter's posterior for one cut: median, 80 % and 95 % intervals in its own
        units (mu_d also as atan(mu_d) in degrees; xi: P(xi = 0) and its quantiles given
        xi > 0; the number of sliders: each prior value's probability)."""
        out = {}
        for p, name in enumerate(self.parameters_):
            levels = np.array([0.5, 0.1, 0.9, 0.025, 0.975])
            d = {}
            if name == "xi" and math.isfinite(self.xi_zero_code_):
                p0 = float(self.cdf(q_row, p, self.xi_zero_edge()))
                d["p_zero"] = p0
                levels = p0 + (1.0 - p0) * levels if p0 < 1.0 - 1e-6 else None
            if levels is None:
                d.update(median=None, interval_80=None, interval_95=None)
            else:
                v = self.physical(name, self.ppf(q_row, p, levels))
                d.update(median=float(v[0]), interval_80=[float(v[1]), float(v[2])],
                         interval_95=[float(v[3]), float(v[4])])
            if name == "mu_d":
                deg = np.degrees(np.arctan(v))
                d["atan_deg"] = {"median": float(deg[0]), "interval_80": [float(deg[1]),
                                 float(deg[2])], "interval_95": [float(deg[3]), float(deg[4])]}
            if name == "n_sliders":
                c = self.cdf(q_row, p, np.clip(self.n_sliders_edges(), -1e9, 1e9))
                d["probabilities"] = {str(int(v)): float(pr) for v, pr in
                                      zip(self.n_sliders_values_, np.diff(c))}
            out[name] = d
        return out

    def contraction(self, q_row) -> dict:
        """1 - posterior variance / prior variance of every parameter (learned scale); None for
        a parameter the prior holds fixed: the prior, not the catalogue, tells it."""
        u = (np.arange(VARIANCE_POINTS) + 0.5) / VARIANCE_POINTS
        return {name: (float(1.0 - np.var(self.ppf(q_row, p, u)) / self.prior_variance_[p])
                       if self.high_[p] > self.low_[p] else None)
                for p, name in enumerate(self.parameters_)}

    def given(self, catalogue, measurement=PERFECT) -> "CataloguePosterior":
        """The posterior of one catalogue: ``catalogue`` a ``Catalogue`` at its tilt reached,
        recorded as ``measurement`` says, or the ``Cuts`` of one cut (``quantiles``)."""
        cuts = (catalogue if isinstance(catalogue, Cuts)
                else Cuts.from_catalogues([catalogue], measurement))
        return CataloguePosterior(self, self.quantiles(cuts)[0])

    def prior_range(self) -> dict:
        """Each parameter's prior range in its own units (xi: its positive range)."""
        out = {}
        for p, name in enumerate(self.parameters_):
            lo = self.low_[p] if name != "xi" else self.xi_zero_code_ + XI_ZERO_GAP
            out[name] = [float(v) for v in self.physical(name, np.array([lo, self.high_[p]]))]
        return out

    def domain(self, cuts: Cuts):
        """Whether each cut lies in the training domain, and if not why (``DomainCheck``)."""
        return self.domain_.check(cuts)

    def prior_spec(self) -> dict:
        """The prior's specification (the tables of its TOML)."""
        return json.loads(self.prior_)

    # -- the file's checks ----------------------------------------------------------------
    def _check_range(self, name: str, low: float, high: float) -> None:
        """The prior range [low, high] (learned scale) of parameter ``name`` within its
        ``PHYSICAL_RANGES`` (mu_d > 0, the others' log10 finite, above ``LOG_FLOOR``)."""
        lo, hi = PHYSICAL_RANGES[name]
        if name in LOG_PARAMETERS:
            floor = math.log10(lo) if lo > 0 else LOG_FLOOR
            ok, shown = floor - 1e-12 <= low and high <= math.log10(hi) + 1e-12, \
                f"10^{low:.6g} to 10^{high:.6g}"
        else:
            ok, shown = lo < low and high <= hi, f"{low:.6g} to {high:.6g}"
        require(ok, f"the prior range of {name}, {shown}, lies outside its physical range "
                    f"({f'{lo:g} to {hi:g}' if lo > 0 else f'above {lo:g}, at most {hi:g}'})")

    #: every part an inference reads, of the form ``fit`` writes (``integrity``)
    FIELDS = {"parameters_": Spec("tuple", min_size=1, of=Spec("choice", of=POSTERIOR_PARAMETERS)),
              "n_features_in_": Spec("int", lo=lambda p: len(design_names()),
                                     hi=lambda p: len(design_names())),
              "models_": Spec("list", n=lambda p: len(p.parameters_), of=Spec(
                  "list", n=POSTERIOR_LEVELS.size, of=Spec("part", of=QuantileTrees))),
              "low_": Spec("f", shape=_n_p), "high_": Spec("f", shape=_n_p),
              "prior_variance_": Spec("f", shape=_n_p, lo=1e-300),
              "shifts_": Spec("f", shape=lambda p: (len(CATALOGUE_CLASSES), len(p.parameters_),
                                                    POSTERIOR_LEVELS.size), lo=-1e3, hi=1e3),
              "recalibration_": Spec("f", shape=lambda p: (len(RECALIBRATION_GROUPS),
                                                           len(p.parameters_),
                                                           REPORTED_LEVELS.size),
                                     lo=0.0, hi=1.0, increasing=True),
              "n_sliders_values_": Spec("f", lo=1.0, increasing=True, min_size=1),
              "mu_d_reference_": Spec("number", lo=-1e3, hi=1e3),
              "xi_zero_code_": Spec("number", lo=LOG_FLOOR, hi=300.0,
                                    when=lambda p: "xi" in p.parameters_),
              "prior_": Spec("str"), "copula_": Spec("f", shape=lambda p: _n_p(p) * 2, lo=-1.0,
                                                     hi=1.0),
              "domain_": Spec("part", of=DomainCheck)}
    check_fitted = check_fields

    def check_consistent(self) -> None:
        """What the declarations cannot say: every regressor reading the posterior's features,
        the prior ranges within the physical ones (of the
        numbers of sliders, whole, if it is drawn), mu_d's reference and xi's zero code within
        theirs, the stored prior's tables, the copula a correlation matrix."""
        p = {name: k for k, name in enumerate(self.parameters_)}
        require(all(m.n_features_in_ == self.n_features_in_ for row in self.models_ for m in row),
                "a regressor reads another number of features than the posterior's")
        require((self.low_ <= self.high_).all(), "a prior range is reversed")
        for name, k in p.items():
            self._check_range(name, float(self.low_[k]), float(self.high_[k]))
        n, (lo, hi), k = self.n_sliders_values_, PHYSICAL_RANGES["n_sliders"], p.get("n_sliders")
        require(k is None or ((n == np.round(n)).all() and lo <= n.min() and n.max() <= hi
                              and (np.diff(n) > 0).all() and np.allclose(
                                  [self.low_[k], self.high_[k]], np.log10(n[[0, -1]]), atol=1e-9)),
                f"the numbers of sliders ({', '.join(f'{v:g}' for v in n[:4])}) are not whole "
                f"numbers from {lo:g} to {hi:g}, each once, whose log10 ends are the prior range "
                "of n_sliders")
        k = p.get("mu_d")
        require(k is None or self.low_[k] <= self.mu_d_reference_ <= self.high_[k],
                f"mu_d's reference {self.mu_d_reference_:g} lies outside its prior range")
        zero, low = self.xi_zero_code_, self.low_[p["xi"]] if "xi" in p else math.nan
        require("xi" not in p or zero - 1e-9 <= low <= zero + XI_ZERO_GAP + 1e-9,
                f"xi's zero code {self.xi_zero_code_:g} is not {XI_ZERO_GAP:g} decades below its "
                f"smallest positive value (the range starts at {low:g})")
        try:
            prior = json.loads(self.prior_)
        except ValueError:
            raise IntegrityError("the stored prior is not JSON") from None
        require(isinstance(prior, dict) and isinstance(prior.get("parameters"), dict)
                and isinstance(prior.get("scene", {}), dict),
                "the stored prior is not a prior's tables (parameters, scene)")
        c = self.copula_
        require(np.allclose(c, c.T) and np.allclose(np.diag(c), 1.0)
                and (np.linalg.eigvalsh(c) > 0).all(),
                "the copula is not a positive definite correlation matrix")


class CataloguePosterior:
    """The posterior of one catalogue's pile (``ParameterPosterior.given``): its draws, CDF,
    inverse CDF, summary and contraction, every value in the parameter's own units.

    Attributes
    ----------
    estimator : ParameterPosterior
        The fitted posterior.
    quantiles : numpy.ndarray
        (P, M) every parameter's reported quantiles for this catalogue (learned scale).
    """

    def __init__(self, estimator: ParameterPosterior, quantiles: np.ndarray):
        self.estimator = estimator
        self.quantiles = quantiles

    def __repr__(self) -> str:
        """One line: the parameters."""
        return f"<CataloguePosterior of {', '.join(self.estimator.parameters_)}>"

    @property
    def parameters(self) -> list[str]:
        """The parameters, in order."""
        return list(self.estimator.parameters_)

    def sample(self, n: int, rng) -> dict:
        """``n`` draws of every parameter, joined by the copula (``ParameterPosterior.sample``)."""
        return self.estimator.sample(self.quantiles, n, rng)

    def cdf(self, values: dict) -> dict:
        """P(parameter <= value) of each parameter of ``values`` (``{name: values}``, its own
        units)."""
        est = self.estimator
        return {name: est.cdf(self.quantiles, est.parameters_.index(name),
                              learned_scale(name, np.asarray(v, dtype=float), est.xi_zero_code_))
                for name, v in values.items()}

    def ppf(self, levels) -> dict:
        """Every parameter's values at the probabilities ``levels`` (the inverse CDF), in its
        own units."""
        est = self.estimator
        u = np.asarray(levels, dtype=float)
        return {name: est.physical(name, est.ppf(self.quantiles, p, u))
                for p, name in enumerate(est.parameters_)}

    def summary(self) -> dict:
        """Median, 80 % and 95 % intervals of every parameter (``ParameterPosterior.summary``)."""
        return self.estimator.summary(self.quantiles)

    def contraction(self) -> dict:
        """How much the catalogue narrowed each parameter's prior
        (``ParameterPosterior.contraction``)."""
        return self.estimator.contraction(self.quantiles)
