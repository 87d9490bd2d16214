"""Whether a catalogue lies in the domain a forecaster was trained on.

A learned forecaster trusts what resembles its training catalogues and
nothing else.  ``DomainCheck`` holds two checks, each on numbers the
catalogue holds:

* the tilt reached against a high quantile of the training avalanche angles;
* a novelty detector (``sklearn.neighbors.LocalOutlierFactor(novelty=True)``
  after a ``StandardScaler``) on features that say what pile made the
  catalogue, read *through its measurement*: event rates are counted as if
  no event had been missed (divided by the share kept), and one rate counts
  only the events large enough (``COMMON_SIZE`` sliders) that every detection
  threshold of the training measurements records them.

One detector per class of measurement (``MEASUREMENT_CLASSES``): a catalogue
said to be complete is compared with complete training catalogues only, so
that a small pile, or one prepared without internal forces and silent up to a
tilt where every complete training catalogue has events, cannot pass for a
pile of which most events were missed.  Sizes in an arbitrary unit count no
sliders: those catalogues are compared on the features that need no unit
(``IN_SLIDERS`` left out).

The features are standardised, not mapped through their training quantiles:
a quantile transform clips every value beyond the training range to its
edge, and a catalogue far outside the range would sit on the edge, among
training cuts.
"""

from __future__ import annotations

import numpy as np

from .estimator import Estimator
from .evaluators import NoveltyDetector
from .features import n_sliders_estimate
from .integrity import Spec, require

#: events at least this large (sliders) are recorded by every training measurement's
#: detection threshold (``measurement.MEASUREMENT_RANGES["min_size"]`` goes up to 5)
COMMON_SIZE = 5.0
#: the recent window (radians of tilt before the cut) of the recent rates and sizes
RECENT = 0.05
#: what the novelty detector compares: the tilt; the event rates per radian (whole run,
#: recent; all events, and those of ``COMMON_SIZE`` sliders or more), as if none were missed;
#: the first event's tilt (absolute, and over the tilt reached) and the tilt since the last;
#: the sizes (largest over the mean, share above twice the mean, the largest, the share of
#: lone slips, the recent largest and mean)
DOMAIN_FEATURES = ("tilt", "log_rate", "log_rate_recent", "onset", "onset_ratio", "quiet",
                   "size_ratio_max", "share_large", "log_rate_common", "log_rate_common_recent",
                   "log_max_size", "share_one", "log_max_size_recent", "log_mean_size_recent")
#: the features that count sliders (NaN for sizes in an arbitrary unit)
IN_SLIDERS = ("log_rate_common", "log_rate_common_recent", "log_max_size", "share_one",
              "log_max_size_recent", "log_mean_size_recent")
#: fewest training cuts of a class of measurement for a detector of its own (fewer: the class
#: is checked on the tilt only, a density on so few cuts would flag its own kind)
MIN_CLASS_CUTS = 100
#: with the slider indices of the movers (``Learned(inputs="all")``): the number of sliders they
#: show (``features.n_sliders_estimate``), as a log
WITH_POSITIONS = DOMAIN_FEATURES + ("log_n_sliders",)
#: the classes of measurement with a detector each: sizes in sliders with no event missed and
#: every size detected; sizes in sliders otherwise; sizes in an arbitrary unit
MEASUREMENT_CLASSES = ("complete", "incomplete", "arbitrary")


def domain_features(cuts, names=DOMAIN_FEATURES) -> np.ndarray:
    """(n, len(names)) what the domain check compares, for every cut.

    Rates are events per radian of tilt divided by the share of events kept
    (``1 - missed_fraction``), as ``log(1 + rate)``; ``onset``: the tilt of
    the first event (the tilt reached if there is none); ``quiet``: the tilt
    since the last event (radians).  NaN where the catalogue's sizes are in
    an arbitrary unit and the feature counts sliders.
    """
    out = np.full((len(cuts), len(names)), np.nan)
    for i, (cat, m) in enumerate(zip(cuts.catalogues, cuts.measurements())):
        f = _features_of(cat, m)
        out[i] = [f.get(k, np.nan) for k in names]
    return out


def _features_of(cat, m) -> dict:
    """The domain features of one catalogue measured by ``m`` (``domain_features``)."""
    t = max(float(cat.tilt_now), 1e-6)
    kept = 1.0 - m.missed_fraction
    alpha, size = cat.alpha, cat.size.astype(float)
    n = alpha.size
    recent = alpha > t - RECENT
    mean = float(size.mean()) if n else np.nan
    onset = float(alpha[0]) if n else t
    f = {"tilt": t, "log_rate": np.log1p(n / kept / t), "log_n_sliders": np.log(n_sliders_estimate(cat)),
         "log_rate_recent": np.log1p(recent.sum() / kept / RECENT),
         "onset": onset, "onset_ratio": onset / t, "quiet": t - float(alpha[-1]) if n else t,
         "size_ratio_max": float(size.max()) / mean if n else np.nan,
         "share_large": float(np.mean(size > 2.0 * mean)) if n else np.nan}
    if m.size_unit == "arbitrary":
        return f
    common = size >= COMMON_SIZE
    f.update({"log_rate_common": np.log1p(common.sum() / kept / t),
              "log_rate_common_recent": np.log1p((common & recent).sum() / kept / RECENT),
              "log_max_size": np.log(float(size.max())) if n else 0.0,
              "share_one": float(np.mean(size == 1)) if n else np.nan,
              "log_max_size_recent": np.log(float(size[recent].max())) if recent.any() else 0.0,
              "log_mean_size_recent": np.log(float(size[recent].mean())) if recent.any() else 0.0})
    return f


def measurement_class(cuts) -> np.ndarray:
    """(n,) each cut's index in ``MEASUREMENT_CLASSES``."""
    return np.array([2 if m.size_unit == "arbitrary" else 0 if m.missed_fraction == 0
                     and m.min_size <= 1 else 1 for m in cuts.measurements()], dtype=int)


class DomainCheck(Estimator):
    """The training domain of a forecaster: the top tilt and a novelty detector per measurement.

    Parameters
    ----------
    features : tuple of str
        The features the novelty detectors compare (``DOMAIN_FEATURES``).
    tilt_quantile : float
        The tilt reached is out of the domain above this quantile of the
        training avalanche angles.
    contamination : float
        Share of training cuts each novelty detector counts as outliers.
    n_neighbors : int
        Neighbours of the local outlier factor (the model file keeps their
        distances for every training cut it keeps).
    max_samples : int
        Training cuts each detector learns from (a random subset: the model
        file keeps them, with each one's distance to its k-th neighbour and its density).
    random_state : int
        Seeds the subset (unless ``fit`` is given an order).

    Attributes
    ----------
    detectors_ : list
        Per ``MEASUREMENT_CLASSES``: a fitted pipeline (imputer, standard scaler,
        local outlier factor; read from a model file, its arrays as
        ``evaluators.NoveltyDetector``), or None with fewer than ``MIN_CLASS_CUTS``
        training cuts of that class.
    top_tilt_ : float
        The highest tilt reached inside the domain, radians.
    n_sliders_range_ : numpy.ndarray or None
        The fewest and most sliders of the training piles (None if not given
        to ``fit``): a catalogue whose measurement names its pile's number of
        sliders outside them is out of the domain.
    """

    #: per MEASUREMENT_CLASSES a detector or None; a top tilt in (0, 90°]; 1 <= sliders
    FIELDS = {"detectors_": Spec("list", n=len(MEASUREMENT_CLASSES),
                                 of=Spec("part", of=NoveltyDetector, optional=True)),
              "top_tilt_": Spec("number", lo=1e-9, hi=np.pi / 2),
              "tilt_quantile": Spec("number", lo=0.0, hi=1.0),
              "n_sliders_range_": Spec("f", shape=(2,), lo=1.0, optional=True)}

    def __init__(self, features: tuple = DOMAIN_FEATURES, tilt_quantile: float = 0.995,
                 contamination: float = 0.03, n_neighbors: int = 35, max_samples: int = 1000,
                 random_state: int = 0):
        self.features = features
        self.tilt_quantile = tilt_quantile
        self.contamination = contamination
        self.n_neighbors = n_neighbors
        self.max_samples = max_samples
        self.random_state = random_state

    def fit(self, cuts, alpha_c, order=None, n_sliders=None):
        """Learn the domain from training ``cuts`` (``features.Cuts``, measured as recorded) and
        the training avalanche angles ``alpha_c``; ``order``: a permutation of the cuts whose
        first ``max_samples`` of each measurement class are kept (default: drawn from ``random_state``);
        ``n_sliders``: the training piles' numbers of sliders, if known.
        """
        unknown = sorted(set(self.features) - set(WITH_POSITIONS))
        if unknown:
            raise ValueError(f"unknown domain features {unknown}; known: {WITH_POSITIONS}")
        x, kind = domain_features(cuts, self.features), measurement_class(cuts)
        if order is None:
            order = np.random.default_rng(self.random_state).permutation(len(cuts))
        order = np.asarray(order, dtype=int)
        self.detectors_ = []
        for k, label in enumerate(MEASUREMENT_CLASSES):
            rows = order[kind[order] == k][:self.max_samples]
            self.detectors_.append(self._detector().fit(x[rows][:, self._columns(label)])
                                   if rows.size >= max(MIN_CLASS_CUTS, self.n_neighbors + 1)
                                   else None)
        self.top_tilt_ = float(np.quantile(np.asarray(alpha_c, dtype=float), self.tilt_quantile))
        n = None if n_sliders is None else np.asarray(n_sliders, dtype=float)
        self.n_sliders_range_ = None if n is None or not n.size else np.array([n.min(), n.max()])
        return self

    def calibrate(self, cuts, level: float, fewest: int = 200):
        """Set each novelty detector's threshold so that it flags the share ``level`` of the
        calibration ``cuts`` of its measurement class (cuts of realisations the detector did not
        learn from; the finite-sample quantile, rounded towards fewer flags); a class with fewer
        than ``fewest`` calibration cuts keeps the threshold of ``contamination``."""
        x, kind = domain_features(cuts, self.features), measurement_class(cuts)
        for k, label in enumerate(MEASUREMENT_CLASSES):
            rows = np.flatnonzero(kind == k)
            det = self.detectors_[k]
            if det is None or rows.size < fewest:
                continue
            scores = np.sort(det.score_samples(x[rows][:, self._columns(label)]))
            j = int(np.floor(level * (rows.size + 1))) - 1
            # flagged: a score below the offset; the j+1 lowest calibration scores are flagged
            offset = float(np.nextafter(scores[j], np.inf)) if j >= 0 else float(scores[0])
            if isinstance(det, NoveltyDetector):  # read from a model file
                det.offset = offset
            else:
                det.steps[-1][1].offset_ = offset
        return self

    def _columns(self, label) -> list:
        """The features the detector of measurement class ``label`` compares."""
        return [i for i, f in enumerate(self.features) if label != "arbitrary" or f not in IN_SLIDERS]

    def _detector(self):
        from sklearn import impute, neighbors, pipeline, preprocessing

        return pipeline.make_pipeline(
            impute.SimpleImputer(strategy="median", keep_empty_features=True),
            preprocessing.StandardScaler(),
            neighbors.LocalOutlierFactor(n_neighbors=self.n_neighbors, novelty=True,
                                         contamination=self.contamination))

    def novel(self, cuts) -> np.ndarray:
        """(n,) True where a cut is unlike every training cut of its measurement class."""
        x, kind = domain_features(cuts, self.features), measurement_class(cuts)
        out = np.zeros(len(cuts), dtype=bool)
        for k, label in enumerate(MEASUREMENT_CLASSES):
            rows = kind == k
            if rows.any() and self.detectors_[k] is not None:
                out[rows] = self.detectors_[k].predict(x[rows][:, self._columns(label)]) < 0
        return out

    def check(self, cuts) -> tuple[np.ndarray, list[str]]:
        """Whether each cut lies in the domain, and if not, why (one phrase each)."""
        novel = self.novel(cuts)
        high = cuts.tilt_now > self.top_tilt_
        # the size told, a number or a range: outside when no size of it is a training pile's
        told = [(m.n_sliders, m.n_sliders_high or m.n_sliders) for m in cuts.measurements()]
        span = self.n_sliders_range_
        other = np.array([span is not None and lo is not None and (hi < span[0] or lo > span[1])
                          for lo, hi in told], dtype=bool)
        reasons = []
        for h, nv, t, o, (lo, hi) in zip(high, novel, cuts.tilt_now, other, told):
            why = []
            if o:
                why.append(f"a pile of {lo if hi == lo else f'{lo}-{hi}'} sliders, outside the "
                           f"training piles' {span[0]:.0f}-{span[1]:.0f}")
            if h:
                why.append(f"the tilt reached ({np.degrees(t):.2f}°) is above "
                           f"{100 * self.tilt_quantile:g} % of the training avalanche angles "
                           f"({np.degrees(self.top_tilt_):.2f}°)")
            if nv:
                why.append("the catalogue's event rates and sizes, read through its measurement, "
                           "are unlike every training catalogue's (local outlier factor)")
            reasons.append("; ".join(why))
        return ~(high | novel | other), reasons

    def check_consistent(self) -> None:
        """Known features, each detector of the width of its class's, a range of sliders
        not reversed."""
        require(isinstance(self.features, tuple) and len(set(self.features)) == len(self.features)
                and set(self.features) <= set(WITH_POSITIONS), "unknown features")
        for label, det in zip(MEASUREMENT_CLASSES, self.detectors_):
            require(det is None or det.points.shape[1] == len(self._columns(label)),
                    f"the {label} detector reads other features than its class's")
        span = self.n_sliders_range_
        require(span is None or span[0] <= span[1], "the range of sliders is reversed")
