"""The forecasters' common form: a predictive distribution of the avalanche angle.

Every forecaster answers with the quantiles of ``alpha_c`` at the levels
``LEVELS`` (5 % to 95 % in steps of 5 %).  From them: the point forecast (the
median), the 80 % interval (10 % and 90 %), the CRPS (from the quantile scores)
and the probability that the avalanche comes within the next ``delta`` of tilt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from ...io.forecast_files import ForecastInputError
from .estimator import Estimator
from .features import Cuts
from .integrity import check_fields

#: quantile levels of every forecast (uniform, so that twice their mean pinball
#: loss approximates the CRPS)
LEVELS = np.round(np.arange(1, 20) / 20.0, 2)
#: index of the median and of the 80 % interval's ends in ``LEVELS``
MEDIAN = int(np.flatnonzero(LEVELS == 0.5)[0])
LOWER = int(np.flatnonzero(LEVELS == 0.1)[0])
UPPER = int(np.flatnonzero(LEVELS == 0.9)[0])
#: nominal coverage of ``Forecast.interval``
NOMINAL_COVERAGE = 0.8


class ForecastError(ForecastInputError):
    """A forecaster cannot be used as asked (not fitted, missing simulation data, bad input):
    one line, bad input to a command (``ForecastInputError``)."""


@dataclass(frozen=True)
class Forecast:
    """One forecast of the avalanche angle.

    Parameters
    ----------
    quantiles : numpy.ndarray
        ``alpha_c`` (radians) at the levels ``LEVELS``, non-decreasing.
    tilt_now : float
        The tilt at which the forecast was made, radians.
    forecaster : str
        Name of the forecaster.
    fallback : bool
        True when the forecaster's own method gave no answer (e.g. an
        inverse-rate fit without acceleration) and it fell back on the
        conditioned climatology.
    levels : numpy.ndarray, optional
        The probability below each quantile, when not ``LEVELS``: a forecaster
        whose 80 % interval is not the central one (the learned ones: the
        shortest) reports the distribution's quantiles at these levels in the
        places of ``LEVELS``, so that ``interval`` is its interval and
        ``probability_within`` still reads the distribution itself.
    clipped : bool
        Set on construction: True when some quantile lay outside
        [``floor``, 90°], the angles an avalanche can come at (it has not
        come yet, and the incline cannot tilt past vertical), and was moved to
        that edge.
    floor : float, optional
        The least angle the avalanche may come at (default ``tilt_now``): below
        it by the angle error a noisy catalogue allows (``edge``).
    """

    quantiles: np.ndarray
    tilt_now: float
    forecaster: str
    fallback: bool = False
    levels: np.ndarray | None = None
    clipped: bool = False
    floor: float | None = None

    def __post_init__(self):
        q = np.asarray(self.quantiles, dtype=float)
        if not np.isfinite(q).all():
            raise ForecastError(f"forecaster {self.forecaster!r} gave no finite forecast")
        floor = self.tilt_now if self.floor is None else min(self.floor, self.tilt_now)
        inside = np.clip(q, floor, math.pi / 2)
        object.__setattr__(self, "quantiles", inside)
        object.__setattr__(self, "clipped", bool(self.clipped or not np.array_equal(inside, q)))

    @property
    def point(self) -> float:
        """The point forecast: the median, radians."""
        return float(self.quantiles[MEDIAN])

    @property
    def interval(self) -> tuple[float, float]:
        """The nominal 80 % predictive interval (10 % and 90 % quantiles), radians."""
        return float(self.quantiles[LOWER]), float(self.quantiles[UPPER])

    def probability_within(self, delta: float) -> float:
        """Probability that the avalanche comes before the tilt reaches ``tilt_now + delta``."""
        levels = None if self.levels is None else self.levels[None, :]
        return float(probability_within(self.quantiles[None, :], np.array([self.tilt_now]), delta,
                                        levels)[0])

    def as_dict(self, delta: float) -> dict:
        """The forecast as plain JSON-able values (radians), with the alarm for ``delta``."""
        return {"forecaster": self.forecaster, "alpha_c": self.point,
                "interval": list(self.interval), "coverage": NOMINAL_COVERAGE,
                "tilt_now": self.tilt_now, "within": delta,
                "probability_within": self.probability_within(delta),
                "fallback": self.fallback, "clipped": self.clipped}


#: how far below the tilt reached a noisy catalogue's avalanche may lie, in angle errors (its
#: last events' angles, which the tilt reached is at least, may each be this far too high)
EDGE_RESOLUTIONS = 3.0


def edge(cuts) -> np.ndarray:
    """(n,) the least tilt each cut's avalanche may lie at: the tilt reached, less
    ``EDGE_RESOLUTIONS`` of its measurement's angle errors (a noisy last event may lie above
    the avalanche; the tilt reached itself without an angle error)."""
    res = np.array([m.angle_resolution for m in cuts.measurements()], dtype=float)
    return np.maximum(cuts.tilt_now - EDGE_RESOLUTIONS * res, 0.0)


def check_catalogue(catalogue, measurement=None) -> None:
    """The catalogue as ``measurement`` (a ``measurement.Measurement``; None: a perfect record
    in sliders) says it was recorded, or ``ForecastError`` in one line naming the first event
    that cannot be.

    Every size is positive; in sliders a whole number, at least ``min_size``,
    and at most the sliders from the first to the last mover (``last - first
    + 1``) where those are known as slider indices; the first and last movers are known together
    and the first is not after the last.  In an arbitrary unit only the
    detection threshold binds the sizes (no size below ``min_size``).
    """
    size, first, last = catalogue.size.astype(float), catalogue.first, catalogue.last
    min_size = 1.0 if measurement is None else measurement.min_size
    unit = "sliders" if measurement is None else measurement.size_unit

    def refuse(bad, what):
        k = int(np.flatnonzero(bad)[0])
        raise ForecastError(f"event {k + 1} (the {k + 1}th in the catalogue): {what(k)}")

    if (bad := ~(np.isfinite(size) & (size > 0))).any():
        refuse(bad, lambda k: f"size {size[k]:g} is not a positive number")
    if (bad := size < min_size * (1 - 1e-9)).any():
        refuse(bad, lambda k: f"size {size[k]:g} is below the smallest size detected "
                              f"({min_size:g}): the catalogue and its measurement "
                              "disagree")
    if (bad := (first < 0) != (last < 0)).any():
        refuse(bad, lambda k: "one of its first and last movers is unknown, not both")
    if (bad := first > last).any():
        refuse(bad, lambda k: f"its first mover ({first[k]}) lies after its last ({last[k]})")
    if unit != "sliders":
        return
    if (bad := size != np.round(size)).any():
        refuse(bad, lambda k: f"size {size[k]:g} is not a whole number of sliders (sizes in "
                              "another unit: --size-unit arbitrary)")
    if measurement is not None and measurement.position_unit != "sliders":
        return  # a camera's positions hold no count of sliders
    if (bad := (first >= 0) & (size > last - first + 1)).any():
        refuse(bad, lambda k: f"{size[k]:g} sliders moved between slider {first[k]} and slider "
                              f"{last[k]}, which hold {last[k] - first[k] + 1}")


def probability_within(quantiles: np.ndarray, tilt_now: np.ndarray, delta: float,
                       levels: np.ndarray | None = None) -> np.ndarray:
    """P(alpha_c <= tilt_now + delta) from rows of quantiles at ``LEVELS`` (or at ``levels``,
    (n, len(LEVELS)), each row's own).

    The distribution function is interpolated linearly between the quantiles,
    from 0 at the lower end (the tilt reached, or the 5 % quantile if that is
    lower, minus the 5-10 % spacing) to 1 beyond the 95 % quantile by the
    same spacing as 90-95 %.
    """
    q = np.asarray(quantiles, dtype=float)
    t = np.asarray(tilt_now, dtype=float) + delta
    lo = np.minimum(q[:, :1] - (q[:, 1:2] - q[:, :1]), q[:, :1])
    hi = q[:, -1:] + (q[:, -1:] - q[:, -2:-1])
    xp = np.concatenate([lo, q, hi], axis=1)
    lv = np.broadcast_to(LEVELS if levels is None else np.asarray(levels, dtype=float), q.shape)
    fp = np.concatenate([np.zeros((q.shape[0], 1)), lv, np.ones((q.shape[0], 1))], axis=1)
    out = np.empty(q.shape[0])
    for i in range(q.shape[0]):
        x = xp[i]
        if x[-1] <= x[0]:  # a point mass
            out[i] = float(t[i] >= x[0])
        else:
            out[i] = np.interp(t[i], x, fp[i])
    return out


def quantiles_of_sample(values, weights=None) -> np.ndarray:
    """Quantiles at ``LEVELS`` of a sample (optionally weighted), the predictive form of an ensemble."""
    values = np.asarray(values, dtype=float)
    if weights is None:
        return np.quantile(values, LEVELS)
    return np.quantile(values, LEVELS, weights=np.asarray(weights, dtype=float),
                       method="inverted_cdf")


def quantiles_of_grid(grid: np.ndarray, log_density: np.ndarray) -> np.ndarray:
    """Quantiles at ``LEVELS`` of a distribution given on a sorted grid by its log density.

    Used for the likelihood profiles of the inverse-rate fits: the normalised
    likelihood over the grid is read as the predictive distribution (a flat
    prior on the grid's variable).
    """
    w = np.exp(log_density - np.nanmax(log_density))
    w = np.where(np.isfinite(w), w, 0.0)
    cdf = np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(grid))
    cdf = np.concatenate([[0.0], cdf]) / cdf[-1]
    return np.interp(LEVELS, cdf, grid)


def pinball_crps(quantiles: np.ndarray, truth: np.ndarray,
                 levels: np.ndarray | None = None) -> np.ndarray:
    """CRPS of each row of quantiles at ``LEVELS`` (or at each row's ``levels``) against the
    truth, from the quantile scores.

    CRPS = 2 * integral over levels of the pinball loss; the mean over the
    uniform ``LEVELS`` approximates the integral (the tails beyond 5 % and
    95 % left out), in radians.
    """
    q = np.asarray(quantiles, dtype=float)
    y = np.asarray(truth, dtype=float)[:, None]
    lv = LEVELS if levels is None else np.asarray(levels, dtype=float)
    diff = y - q
    loss = np.maximum(lv * diff, (lv - 1.0) * diff)
    return 2.0 * loss.mean(axis=1)


class Forecaster(Estimator):
    """A forecaster of ``alpha_c``: a scikit-learn estimator (``estimator.Estimator``), ``fit`` on
    training realisations.

    The scikit-learn rules hold: every parameter is an argument of
    ``__init__`` stored under its own name (``get_params``, ``clone``),
    randomness comes from ``random_state``, what ``fit`` learns ends in
    ``_``, and nothing is written into the inputs.  Subclasses set ``name``
    and ``label`` (class attributes, or properties of the parameters) and
    implement ``_quantiles``; those that learn override ``fit``.  ``needs``
    lists what beyond the catalogue a forecaster uses ("ceiling": every
    slider's distance to its threshold; "mu_d": the true dynamic friction),
    which only a simulation has.  ``registry.FORECASTERS`` lists them all.
    """

    name = "forecaster"
    label = "forecaster"
    needs: tuple[str, ...] = ()

    def fit(self, train, y=None, **fit_params) -> "Forecaster":
        """Learn from a training ``CatalogueSet`` (default: nothing to learn).

        Parameters
        ----------
        train : sliders.io.catalogue.CatalogueSet
            The training realisations (whole runs, avalanche reached).
        y : None
            Unused: the truth (``alpha_c``) is in ``train``.
        """
        return self

    def quantiles(self, cuts, levels: bool = False) -> tuple:
        """Forecasts of many cuts at once.

        Parameters
        ----------
        cuts : sliders.analysis.forecast.features.Cuts
            The catalogues as seen at their tilts (and the simulation's
            extras, for the forecasters that need them).
        levels : bool
            Also return the probability below each quantile.

        Returns
        -------
        quantiles : numpy.ndarray
            (n, len(LEVELS)) ``alpha_c`` in radians, sorted along axis 1:
            columns ``LOWER`` and ``UPPER`` are the 80 % interval.
        fallback : numpy.ndarray
            (n,) bool: where the method gave no answer of its own.
        levels : numpy.ndarray
            (n, len(LEVELS)) only if asked: ``LEVELS``, unless the forecaster's
            80 % interval is not the central one (``Forecast.levels``).
        """
        for need in self.needs:
            if getattr(cuts, need) is None:
                raise ForecastError(f"forecaster {self.name!r} needs {need!r}, which only a "
                                    "simulated catalogue set has")
        with np.errstate(all="ignore"):  # a degenerate catalogue: no fit, checked below
            q, fb, *lv = self._quantiles(cuts)
        q = np.sort(np.asarray(q, dtype=float), axis=1)
        fb = np.asarray(fb, dtype=bool).copy()
        bad = ~np.isfinite(q).all(axis=1)
        if bad.any():  # the method gave no finite answer: the conditioned climatology instead
            q[bad] = self._fallback_quantiles(cuts.tilt_now[bad])
            fb[bad] = True
            if lv:
                lv = [np.array(np.broadcast_to(lv[0], q.shape), dtype=float)]
                lv[0][bad] = LEVELS
        if not levels:
            return q, np.asarray(fb, dtype=bool)
        lv = np.array(np.broadcast_to(lv[0] if lv else LEVELS, q.shape), dtype=float)
        return q, np.asarray(fb, dtype=bool), lv

    def _fallback_quantiles(self, tilt_now: np.ndarray) -> np.ndarray:
        """(n, len(LEVELS)) the conditioned climatology of the training avalanche angles above
        each tilt: where a method gives no finite answer of its own."""
        clim = getattr(self, "climatology_", None)
        if clim is None:
            raise ForecastError(f"forecaster {self.name!r} gave no finite forecast and has no "
                                "climatology to fall back on")
        return clim.conditioned(tilt_now)

    def predict(self, catalogue, measurement=None) -> Forecast:
        """The forecast for one ``Catalogue`` (its ``tilt_now`` is the tilt reached).

        ``measurement``: how the catalogue was measured
        (``measurement.Measurement``; default: a perfect record in sliders);
        the catalogue must agree with it (``check_catalogue``).
        """
        check_catalogue(catalogue, measurement)

        cuts = Cuts.from_catalogues([catalogue], measurement)
        q, fb, lv = self.quantiles(cuts, levels=True)
        levels = None if np.array_equal(lv[0], LEVELS) else lv[0]
        return Forecast(q[0], float(catalogue.tilt_now), self.name, bool(fb[0]), levels,
                        floor=float(edge(cuts)[0]))

    def _quantiles(self, cuts):
        raise NotImplementedError

    #: ``check_fitted(where)``: every fitted part a forecast reads, as read from a model file,
    #: as its class declares them (``FIELDS``; ``integrity.check_fields``)
    check_fitted = check_fields
