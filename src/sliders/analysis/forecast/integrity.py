"""A fitted forecaster read from a file, checked as data before it forecasts.

A model file (``io.forecast_model``) names only allow-listed classes, but the
arrays inside them are whatever the file holds, and scikit-learn's compiled
tree walk and neighbour search trust them: a child index past the node array
reads outside it, a node that is its own child never ends, a NaN leaf gives a
NaN forecast.  ``check_fitted`` (each forecaster's, built from the checks
here) looks at every array a forecast reads, its type, shape, dtype and range,
and raises ``IntegrityError`` (one phrase: what is wrong, where) on the first
that is not of the form the forecaster writes.

What passes is a model of the right form, not the right model: a tree whose
leaves were changed to other finite values forecasts other finite angles
(the shipped model is also checked by its digest, ``io.forecast_model``).
This module imports nothing of the forecasters: each one's ``check_fitted``
(and ``baselines.check_climatology``, ``DomainCheck.check_fitted``) builds on it.
"""

from __future__ import annotations

import math

import numpy as np


#: bounds of a fitted model's parts (the shipped model: 700 trees of at most 29 nodes)
MAX_NODES = 1 << 16
MAX_TREES = 100_000
#: largest |leaf value| and |baseline| of a boosted tree (a log remaining angle: -20 to 2)
MAX_LEAF = 1e3
#: most training points a novelty detector may keep (its neighbour tree is rebuilt from them)
MAX_NEIGHBOUR_POINTS = 200_000


class IntegrityError(ValueError):
    """A fitted forecaster's part is not of the form the forecaster writes (one phrase)."""


def require(ok, what: str) -> None:
    """Raise ``IntegrityError(what)`` unless ``ok``."""
    if not ok:
        raise IntegrityError(what)


def check_array(a, what: str, ndim: int | None = 1, shape=None, kind: str = "f",
                finite: bool = True, lo: float | None = None, hi: float | None = None,
                increasing: bool = False, min_size: int = 0) -> np.ndarray:
    """``a`` as a NumPy array of dtype kind ``kind`` ("f", "i", "u", "b"; "iu": integers),
    ``ndim`` dimensions (or ``shape``), finite, in [lo, hi], non-decreasing along its last
    axis if ``increasing``; else ``IntegrityError`` naming ``what``."""
    require(isinstance(a, np.ndarray), f"{what} is a {type(a).__name__}, not an array")
    require(a.dtype.kind in kind, f"{what} has dtype {a.dtype}")
    if shape is not None:
        require(a.shape == tuple(shape), f"{what} has shape {a.shape}, not {tuple(shape)}")
    elif ndim is not None:
        require(a.ndim == ndim, f"{what} has {a.ndim} dimensions, not {ndim}")
    require(a.size >= min_size, f"{what} holds {a.size} values, fewer than {min_size}")
    if a.dtype.kind == "f":
        if finite:
            require(np.isfinite(a).all(), f"{what} holds NaN or infinite values")
        else:
            require(not np.isnan(a).any(), f"{what} holds NaN")
    if lo is not None and a.size:
        require(np.min(a) >= lo, f"{what} holds values below {lo:g}")
    if hi is not None and a.size:
        require(np.max(a) <= hi, f"{what} holds values above {hi:g}")
    if increasing and a.size:  # compared, not differenced: +inf padding follows +inf
        require((a[..., 1:] >= a[..., :-1]).all(), f"{what} is not increasing")
    return a


def check_int(v, what: str, lo: int, hi: int) -> int:
    """``v`` a whole number (not a bool) in [lo, hi]."""
    require(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
            and lo <= int(v) <= hi, f"{what} = {v!r} is not a whole number in [{lo}, {hi}]")
    return int(v)


def check_number(v, what: str, lo: float, hi: float) -> float:
    """``v`` a finite real number (not a bool) in [lo, hi]."""
    require(isinstance(v, (int, float, np.integer, np.floating))
            and not isinstance(v, (bool, np.bool_)) and math.isfinite(float(v))
            and lo <= float(v) <= hi, f"{what} = {v!r} is not a number in [{lo:g}, {hi:g}]")
    return float(v)


def check_choice(v, what: str, choices) -> None:
    """``v`` one of ``choices`` (compared by type and value)."""
    require(any(type(v) is type(c) and v == c for c in choices),
            f"{what} = {v!r} is not one of {tuple(choices)}")


def check_trees(trees, n_features: int, what: str) -> None:
    """Boosted trees' nodes (each a ``TreePredictor.nodes``), as scikit-learn's walk reads them;
    the first tree that fails is named (``what, tree i``).

    The record dtype is scikit-learn's own; every split's children lie after it
    in the array (so every walk moves forward and ends) and every node but the
    root is the child of exactly one split (a tree, every node reachable once);
    a split reads a feature below ``n_features``, by a threshold that is not
    NaN (+-inf: "every value one way", which scikit-learn writes), never by
    category; a leaf's value is finite and bounded (``MAX_LEAF``), its children
    unset (0, as scikit-learn leaves them).  The trees are checked together, as
    one array of every node: a model's hundreds of trees in a few array operations.
    """
    from sklearn.ensemble._hist_gradient_boosting.common import PREDICTOR_RECORD_DTYPE

    for i, nodes in enumerate(trees):
        require(isinstance(nodes, np.ndarray) and nodes.dtype == PREDICTOR_RECORD_DTYPE,
                f"{what}, tree {i}: nodes are not scikit-learn's tree records")
        require(nodes.ndim == 1 and 1 <= nodes.size <= MAX_NODES,
                f"{what}, tree {i}: {nodes.size} nodes (1 to {MAX_NODES})")
    sizes = np.array([nodes.size for nodes in trees], dtype=np.int64)
    starts = np.cumsum(sizes) - sizes
    nodes = np.concatenate(trees)
    n = np.repeat(sizes, sizes)  # each node's tree's size
    first = np.repeat(starts, sizes)  # each node's tree's first node
    index = np.arange(nodes.size) - first  # each node's index in its tree

    def none(bad, problem: str) -> None:
        if bad.any():
            tree = int(np.searchsorted(starts, np.argmax(bad), side="right") - 1)
            raise IntegrityError(f"{what}, tree {tree}: {problem}")

    leaf = nodes["is_leaf"]
    none(~np.isin(leaf, (0, 1)), "a node is neither leaf nor split")
    none(nodes["is_categorical"] != 0, "a categorical split (none is fitted)")
    none(~np.isin(nodes["missing_go_to_left"], (0, 1)), "a split sends missing values neither way")
    split = leaf == 0
    left, right = nodes["left"].astype(np.int64), nodes["right"].astype(np.int64)
    none(split & ~((left > index) & (left < n) & (right > index) & (right < n)),
         "a child index points backwards or past the tree's nodes")
    children = np.concatenate([(left + first)[split], (right + first)[split]])
    parents = np.bincount(children, minlength=nodes.size)
    none(parents != (index != 0), "the nodes do not form one tree (a node with no parent or two)")
    feature = nodes["feature_idx"]
    none(split & ((feature < 0) | (feature >= n_features)),
         f"a split reads a feature outside the {n_features} features")
    none(split & np.isnan(nodes["num_threshold"]), "a NaN threshold")
    value = nodes["value"]
    with np.errstate(invalid="ignore"):
        none(~split & ~(np.isfinite(value) & (np.abs(value) <= MAX_LEAF)),
             f"a leaf value is NaN, infinite or beyond {MAX_LEAF:g}")
    none(~split & ((left != 0) | (right != 0)), "a leaf has children")


def check_boosting(model, n_features: int, what: str) -> None:
    """A fitted ``HistGradientBoostingRegressor`` with the quantile loss, as ``predict`` reads it:
    no categorical features, ``n_features`` inputs, one tree per iteration, every tree
    checked (``check_trees``)."""
    from sklearn.ensemble import HistGradientBoostingRegressor
    from sklearn.ensemble._hist_gradient_boosting.predictor import TreePredictor

    require(type(model) is HistGradientBoostingRegressor,
            f"{what} is a {type(model).__name__}, not a gradient boosting regressor")
    require(model.loss == "quantile" and type(model._loss).__name__ == "PinballLoss",
            f"{what} is not a quantile regressor")
    require(getattr(model, "_preprocessor", None) is None
            and getattr(model, "is_categorical_", None) is None
            and not getattr(model, "_in_fit", False), f"{what} has categorical features")
    check_int(model.n_features_in_, f"{what}: n_features_in_", n_features, n_features)
    check_int(model.n_trees_per_iteration_, f"{what}: trees per iteration", 1, 1)
    check_array(model._baseline_prediction, f"{what}: baseline", shape=(1, 1), lo=-MAX_LEAF,
                hi=MAX_LEAF)
    categorical = check_array(model._bin_mapper.is_categorical_, f"{what}: categorical flags",
                              shape=(n_features,), kind="uib")
    require(not categorical.any(), f"{what} has categorical features")
    trees = model._predictors
    require(isinstance(trees, list) and 1 <= len(trees) <= MAX_TREES,
            f"{what}: not a list of 1 to {MAX_TREES} iterations")
    for i, it in enumerate(trees):
        require(isinstance(it, list) and len(it) == 1 and type(it[0]) is TreePredictor,
                f"{what}: iteration {i} is not one tree")
        check_array(it[0].raw_left_cat_bitsets, f"{what}, tree {i}: category bitsets", ndim=2,
                    kind="u")
    check_trees([it[0].nodes for it in trees], n_features, what)


def check_novelty_detector(pipe, n_features: int, what: str) -> None:
    """A domain check's detector (imputer, standard scaler, local outlier factor on
    ``n_features``): every array finite and of its shape; the neighbour tree is rebuilt
    from the checked training points (the file's own tree is never searched)."""
    from sklearn import impute, neighbors, pipeline, preprocessing

    require(type(pipe) is pipeline.Pipeline and len(pipe.steps) == 3
            and [type(s) for _, s in pipe.steps] == [impute.SimpleImputer,
                                                       preprocessing.StandardScaler,
                                                       neighbors.LocalOutlierFactor],
            f"{what} is not an imputer, a scaler and a local outlier factor")
    imputer, scaler, lof = (s for _, s in pipe.steps)
    check_array(imputer.statistics_, f"{what}: imputer", shape=(n_features,))
    require(imputer.indicator_ is None and imputer.n_features_in_ == n_features,
            f"{what}: imputer of another form")
    check_array(scaler.mean_, f"{what}: scaler mean", shape=(n_features,))
    check_array(scaler.scale_, f"{what}: scaler scale", shape=(n_features,), lo=1e-300)
    require(scaler.n_features_in_ == n_features and scaler.with_mean and scaler.with_std,
            f"{what}: scaler of another form")
    x = check_array(lof._fit_X, f"{what}: training points", ndim=2)
    n = x.shape[0]
    require(x.shape[1] == n_features and 2 <= n <= MAX_NEIGHBOUR_POINTS,
            f"{what}: training points of shape {x.shape}")
    k = check_int(lof.n_neighbors_, f"{what}: neighbours", 1, n - 1)
    check_array(lof._distances_fit_X_, f"{what}: neighbour distances", shape=(n, k), lo=0.0)
    check_array(lof._lrd, f"{what}: reachability densities", shape=(n,), lo=0.0)
    check_array(lof.negative_outlier_factor_, f"{what}: outlier factors", shape=(n,))
    check_number(lof.offset_, f"{what}: offset", -1e300, 1e300)
    require(lof.novelty is True and lof.n_samples_fit_ == n and lof.n_features_in_ == n_features
            and lof.effective_metric_ == "euclidean" and lof._fit_method == "kd_tree",
            f"{what}: local outlier factor of another form")
    leaf = check_int(lof.leaf_size, f"{what}: leaf size", 1, 10_000)
    lof._tree = neighbors.KDTree(x, leaf_size=leaf)
