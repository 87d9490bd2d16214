"""A fitted forecaster read from a file, checked as data before it forecasts.

A model file (``io.model_arrays``) holds plain arrays, and they are whatever
the file holds: a child index past the node array reads outside it, a node
that is its own child never ends, a NaN leaf gives a NaN forecast.
``check_fitted`` (each forecaster's, built from the checks here) looks at every array a forecast reads, its type, shape, dtype and range,
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
#: most training points a novelty detector may keep (each search reads every one)
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
