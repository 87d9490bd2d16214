"""The fitted parts a forecast reads, as plain arrays evaluated with NumPy.

Training fits scikit-learn's and crepes's objects; a model file keeps only what
their ``predict`` reads, and these classes answer as those objects answered,
to the last bit:

* ``QuantileTrees``: a gradient-boosted quantile regressor
  (``HistGradientBoostingRegressor``): its baseline and every tree's nodes
  (feature, threshold, children, where a missing value goes, leaf value).
  The prediction is the baseline plus each tree's leaf, added tree after tree
  in the order of the boosting, as scikit-learn adds them;
* ``ResidualTable``: a Mondrian conformal predictive system (crepes): each
  bin's sorted residuals, read at a percentile by crepes's index rule;
* ``NoveltyDetector``: the domain check's imputer, standard scaler and local
  outlier factor: the medians, the means and scales, the scaled training
  points, each one's distance to its k-th neighbour and its reachability
  density, and the offset below which a score is novel.  The neighbours are
  found by brute force (a thousand points), the squared differences summed
  feature after feature as the k-d tree sums them.

Each is built from the fitted object once (``of``, which imports scikit-learn
or crepes: training only) and read back from its arrays (``arrays``,
``from_arrays``); it declares them (``FIELDS``, checked by
``integrity.check_fields`` with the forecaster that holds it) and checks what
a declaration cannot say in ``check_consistent``: a tree's children after
their parent and within its nodes, every node reached once, features within
the inputs, no NaN threshold.
"""

from __future__ import annotations

import numpy as np

from .integrity import (MAX_LEAF, MAX_NEIGHBOUR_POINTS, MAX_NODES, MAX_TREES, IntegrityError,
                        Spec, require)

#: the arrays of a ``QuantileTrees``, in the order ``arrays`` gives them
TREE_ARRAYS = ("baseline", "tree_start", "feature", "threshold", "left", "right",
               "missing_left", "leaf", "value")


class Arrays:
    """An evaluator read back from a model file's arrays: ``FIELDS`` names and declares them
    (``integrity.Spec``; a number is an array of one value), ``FILE_NAMES`` renames some."""

    FIELDS: dict = {}
    FILE_NAMES: dict = {}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str, used: set):
        """Back from the model file's ``arrays`` named ``prefix.NAME`` (each added to ``used``),
        each present and a number of one value; checked with the forecaster that holds it
        (``integrity.check_fields``)."""
        obj = cls.__new__(cls)
        for attr, spec in cls.FIELDS.items():
            name = f"{prefix}.{cls.FILE_NAMES.get(attr, attr)}"
            require(name in arrays, f"array {name!r} is missing")
            used.add(name)
            v = arrays[name]
            if spec.kind in ("number", "int"):
                require(v.shape == (1,), f"{name} has shape {v.shape}, not (1,)")
                v = v[0].item()
            setattr(obj, attr, v)
        return obj


def _nodes(trees) -> tuple:
    """(nodes,): the shape of each of the trees' node arrays."""
    return (int(trees.tree_start[-1]),)


class QuantileTrees(Arrays):
    """The trees of one quantile regressor, as ``HistGradientBoostingRegressor.predict`` reads them.

    Parameters
    ----------
    baseline : float
        The boosting's starting value.
    tree_start : numpy.ndarray
        (trees + 1,) int64: tree t's nodes are ``tree_start[t]:tree_start[t + 1]``, its root the first.
    feature, left, right : numpy.ndarray
        (nodes,) int64: a split's feature, and its children's indices within its tree.
    threshold : numpy.ndarray
        (nodes,) float64: a value at or below it goes left.
    missing_left, leaf : numpy.ndarray
        (nodes,) bool: a missing value (NaN) goes left; the node is a leaf.
    value : numpy.ndarray
        (nodes,) float64: a leaf's value.
    n_features : int
        The inputs' width.
    quantile : float
        The level the regressor was fitted at.
    """

    FIELDS = {"baseline": Spec("number", lo=-MAX_LEAF, hi=MAX_LEAF),
              "quantile": Spec("number", lo=0.0, hi=1.0),
              "n_features_in_": Spec("int", lo=1, hi=1 << 20),
              "tree_start": Spec("i", lo=0, min_size=2),
              **{k: Spec(kind, shape=_nodes, finite=None) for k, kind in (
                  ("feature", "i"), ("threshold", "f"), ("left", "i"), ("right", "i"),
                  ("missing_left", "b"), ("leaf", "b"), ("value", "f"))}}
    FILE_NAMES = {"n_features_in_": "shape"}

    def __init__(self, baseline, tree_start, feature, threshold, left, right, missing_left, leaf,
                 value, n_features: int, quantile: float):
        self.baseline = baseline
        self.tree_start = tree_start
        self.feature, self.threshold = feature, threshold
        self.left, self.right = left, right
        self.missing_left, self.leaf, self.value = missing_left, leaf, value
        self.n_features_in_ = n_features
        self.quantile = quantile

    @classmethod
    def of(cls, model) -> "QuantileTrees":
        """The trees of a fitted ``HistGradientBoostingRegressor`` (quantile loss, numerical
        features, one tree per iteration)."""
        trees = [it[0].nodes for it in model._predictors]
        nodes = np.concatenate(trees)
        sizes = np.array([t.size for t in trees], dtype=np.int64)
        return cls(float(np.asarray(model._baseline_prediction).reshape(-1)[0]),
                   np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
                   nodes["feature_idx"].astype(np.int64), nodes["num_threshold"].astype(np.float64),
                   nodes["left"].astype(np.int64), nodes["right"].astype(np.int64),
                   nodes["missing_go_to_left"].astype(bool), nodes["is_leaf"].astype(bool),
                   nodes["value"].astype(np.float64), int(model.n_features_in_),
                   float(model.quantile))

    def arrays(self) -> dict:
        """``{name: array}`` of ``TREE_ARRAYS`` and the scalars (``from_arrays``)."""
        return {"baseline": np.array([self.baseline]), "tree_start": self.tree_start,
                "feature": self.feature, "threshold": self.threshold, "left": self.left,
                "right": self.right, "missing_left": self.missing_left, "leaf": self.leaf,
                "value": self.value,
                "shape": np.array([self.n_features_in_], dtype=np.int64),
                "quantile": np.array([self.quantile])}

    def first(self, n: int) -> "QuantileTrees":
        """The regressor of the first ``n`` trees (the boosting stopped after ``n`` iterations)."""
        end = int(self.tree_start[n])
        return QuantileTrees(self.baseline, self.tree_start[:n + 1].copy(),
                             *(getattr(self, k)[:end].copy() for k in TREE_ARRAYS[2:]),
                             self.n_features_in_, self.quantile)

    def check_consistent(self) -> None:
        """As ``predict`` walks the trees: 1 to ``MAX_TREES`` trees of 1 to ``MAX_NODES`` nodes,
        children after their parent and within the tree, every node but a root the child of
        exactly one split (so every walk ends), a split's feature within the inputs and its
        threshold not NaN (+-inf: every value one way), a leaf's value finite and bounded."""
        start, split = self.tree_start, ~self.leaf
        sizes = np.diff(start)
        require(start[0] == 0 and (sizes >= 1).all() and sizes.size <= MAX_TREES
                and (sizes <= MAX_NODES).all(),
                f"tree starts are not 1 to {MAX_TREES} trees of 1 to {MAX_NODES} nodes")
        first, size = np.repeat(start[:-1], sizes), np.repeat(sizes, sizes)
        index = np.arange(start[-1]) - first

        def none(bad, problem):
            if bad.any():
                raise IntegrityError(f"tree {np.searchsorted(start, np.argmax(bad), 'right') - 1}"
                                     f": {problem}")

        left, right, nf = self.left, self.right, self.n_features_in_
        none(split & ~((left > index) & (left < size) & (right > index) & (right < size)),
             "a child index points backwards or past the tree's nodes")
        parents = np.bincount(np.r_[(left + first)[split], (right + first)[split]],
                              minlength=start[-1])
        none(parents != (index != 0), "the nodes do not form one tree (a node with no parent "
                                      "or two)")
        none(split & ((self.feature < 0) | (self.feature >= nf)),
             f"a split reads a feature outside the {nf} features")
        none(split & np.isnan(self.threshold), "a NaN threshold")
        with np.errstate(invalid="ignore"):
            none(~split & ~(np.abs(self.value) <= MAX_LEAF),
                 f"a leaf value is NaN, infinite or beyond {MAX_LEAF:g}")

    def predict(self, x) -> np.ndarray:
        """(n,) the regressor's prediction for the rows of ``x`` (n, features)."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.n_features_in_:
            raise ValueError(f"{x.shape[1] if x.ndim == 2 else x.ndim} inputs where the trees "
                             f"read {self.n_features_in_}")
        rows = np.arange(x.shape[0])[:, None]
        node = np.broadcast_to(self.tree_start[:-1], (x.shape[0], self.tree_start.size - 1)).copy()
        base = self.tree_start[:-1][None, :]
        for _ in range(int(np.diff(self.tree_start).max(initial=0)) + 1):  # a walk's most steps
            walking = ~self.leaf[node]
            if not walking.any():
                break
            v = x[rows, self.feature[node]]
            left = np.where(np.isnan(v), self.missing_left[node], v <= self.threshold[node])
            step = base + np.where(left, self.left[node], self.right[node])
            node = np.where(walking, step, node)
        else:
            raise ValueError("a tree walk that does not end (a model file's trees unchecked)")
        leaves = self.value[node]
        out = np.zeros(x.shape[0]) + self.baseline
        for t in range(leaves.shape[1]):  # tree after tree, as the boosting adds them
            out += leaves[:, t]
        return out


class ResidualTable(Arrays):
    """A Mondrian conformal predictive system's residuals, as crepes's ``predict`` reads them.

    Parameters
    ----------
    bins : numpy.ndarray
        (b,) int64, increasing: the Mondrian bins that hold residuals.
    start : numpy.ndarray
        (b + 1,) int64: bin i's residuals are ``residuals[start[i]:start[i + 1]]``.
    residuals : numpy.ndarray
        float64, sorted within each bin.
    """

    normalized = False
    FIELDS = {"bins": Spec("i", lo=0, min_size=1, increasing="strictly"),
              "start": Spec("i", shape=lambda t: (t.bins.size + 1,), increasing="strictly"),
              "residuals": Spec("f", shape=lambda t: (t.start[-1],), lo=-1e6, hi=1e6)}

    def __init__(self, bins, start, residuals):
        self.bins, self.start, self.residuals = bins, start, residuals

    @classmethod
    def of(cls, cps) -> "ResidualTable":
        """The table of a fitted Mondrian ``crepes.ConformalPredictiveSystem`` (not normalised)."""
        values, alphas = cps.binned_alphas
        sizes = np.array([a.size for a in alphas], dtype=np.int64)
        return cls(np.asarray(values, dtype=np.int64), np.concatenate([[0], np.cumsum(sizes)]),
                   np.concatenate([np.asarray(a, dtype=np.float64) for a in alphas]))

    def arrays(self) -> dict:
        """``{name: array}`` of the table (``from_arrays``)."""
        return {"bins": self.bins, "start": self.start, "residuals": self.residuals}

    def check_consistent(self) -> None:
        """Each bin's residuals from 0 on, sorted."""
        require(self.start[0] == 0, "calibration bin starts do not start at 0")
        for i in range(self.bins.size):
            require((np.diff(self.residuals[self.start[i]:self.start[i + 1]]) >= 0).all(),
                    f"the residuals of bin {self.bins[i]} are not sorted")

    def counts(self) -> np.ndarray:
        """(b,) the residuals each bin holds."""
        return np.diff(self.start)

    def predict(self, y_hat, bins, lower_percentiles) -> np.ndarray:
        """(n, p) ``y_hat`` plus each row's bin's residual at each lower percentile, by crepes's
        index (``int(p / 100 * (count + 1)) - 1``; below the first residual: -inf; a row of a
        bin without residuals: 0)."""
        y_hat = np.asarray(y_hat, dtype=np.float64)
        bins = np.asarray(bins)
        pct = [float(p) for p in np.asarray(lower_percentiles, dtype=np.float64)]
        out = np.zeros((y_hat.size, len(pct)))
        for i, b in enumerate(self.bins):
            rows = np.flatnonzero(bins == b)
            if not rows.size:
                continue
            a = self.residuals[self.start[i]:self.start[i + 1]]
            index = np.array([int(p / 100 * (a.size + 1)) - 1 for p in pct])
            low = index < 0
            index[low] = 0
            out[rows] = y_hat[rows, None] + a[index][None, :]
            out[np.ix_(rows, np.flatnonzero(low))] = -np.inf
        return out


class NoveltyDetector(Arrays):
    """The domain check's detector: an imputer of medians, a standard scaler and a local outlier
    factor (``novelty=True``), as their ``predict`` reads them.

    Parameters
    ----------
    medians, mean, scale : numpy.ndarray
        (f,) the imputer's values for a missing feature, the scaler's mean and scale.
    points : numpy.ndarray
        (m, f) the training points, scaled.
    k_distance, density : numpy.ndarray
        (m,) each training point's distance to its ``n_neighbors``-th neighbour, and its local
        reachability density.
    n_neighbors : int
    offset : float
        A score below it is novel.
    """

    FIELDS = {"points": Spec("f", ndim=2),
              **{k: Spec("f", shape=lambda d: d.points.shape[1:], lo=lo)
                 for k, lo in (("medians", None), ("mean", None), ("scale", 1e-300))},
              "n_neighbors": Spec("int", lo=1, hi=lambda d: d.points.shape[0] - 1),
              **{k: Spec("f", shape=lambda d: d.points.shape[:1], lo=0.0)
                 for k in ("k_distance", "density")},
              "offset": Spec("number", lo=-1e300, hi=1e300)}

    def __init__(self, medians, mean, scale, points, k_distance, density, n_neighbors: int,
                 offset: float):
        self.medians, self.mean, self.scale = medians, mean, scale
        self.points, self.k_distance, self.density = points, k_distance, density
        self.n_neighbors = n_neighbors
        self.offset = offset

    @classmethod
    def of(cls, pipe) -> "NoveltyDetector":
        """The arrays of a fitted pipeline (``SimpleImputer``, ``StandardScaler``,
        ``LocalOutlierFactor(novelty=True)``)."""
        imputer, scaler, lof = (s for _, s in pipe.steps)
        k = lof.n_neighbors_
        return cls(np.asarray(imputer.statistics_, dtype=np.float64), scaler.mean_, scaler.scale_,
                   np.asarray(lof._fit_X, dtype=np.float64),
                   np.ascontiguousarray(lof._distances_fit_X_[:, k - 1]), lof._lrd, int(k),
                   float(lof.offset_))

    def arrays(self) -> dict:
        """``{name: array}`` of the detector and its two numbers (``from_arrays``)."""
        return {"medians": self.medians, "mean": self.mean, "scale": self.scale,
                "points": self.points, "k_distance": self.k_distance, "density": self.density,
                "n_neighbors": np.array([self.n_neighbors], dtype=np.int64),
                "offset": np.array([self.offset])}

    def check_consistent(self) -> None:
        """2 to ``MAX_NEIGHBOUR_POINTS`` training points of at least one feature."""
        require(2 <= len(self.points) <= MAX_NEIGHBOUR_POINTS and self.points.shape[1] >= 1,
                f"training points of shape {self.points.shape}")

    def score_samples(self, x) -> np.ndarray:
        """(n,) the local outlier factor's score of each row of ``x`` (higher: more usual), as
        the pipeline's ``score_samples``."""
        x = np.array(x, dtype=np.float64)
        x = np.where(np.isnan(x), self.medians[None, :], x)
        x = (x - self.mean) / self.scale
        d2 = np.zeros((x.shape[0], self.points.shape[0]))
        for j in range(x.shape[1]):  # summed feature after feature, as the k-d tree sums them
            diff = x[:, j, None] - self.points[None, :, j]
            d2 += diff * diff
        k = self.n_neighbors
        order = np.argsort(d2, axis=1, kind="stable")[:, :k]
        dist = np.sqrt(np.take_along_axis(d2, order, axis=1))
        reach = np.maximum(dist, self.k_distance[order])
        density = 1.0 / (np.mean(reach, axis=1) + 1e-10)
        return -np.mean(self.density[order] / density[:, None], axis=1)

    def predict(self, x) -> np.ndarray:
        """(n,) -1 where a row is novel (its score below the offset), else 1."""
        out = np.ones(len(x), dtype=int)
        out[self.score_samples(x) - self.offset < 0] = -1
        return out
