"""Every forecaster of the registry fitted: the model file's (``fit_methods``), and the learned
ones on training cuts drawn once per kind of training catalogue (``fit_sharing_cuts``, which
the evaluation uses too).

Kept apart from ``registry``, which the command line reads without importing NumPy or
scikit-learn; this module imports both (through the learned forecaster).
"""

from __future__ import annotations

import time

import numpy as np

from .learned import CALIBRATION_SHARE
from .registry import FORECASTERS


def fit_sharing_cuts(f, train, validation, shared: dict, seed: int):
    """Fit a learned forecaster on training (and calibration) cuts drawn once per kind of
    training catalogue (exact or degraded; as a camera records it; told the pile's size or
    not: ``shared`` keeps them) for every learned forecaster of that kind.

    ``validation`` None: the forecaster calibrates on its training cuts, out of fold.
    """
    kind = f.training_kind
    if kind not in shared:
        shared[kind] = {"cuts": f.training_cuts(train, np.random.default_rng(seed))}
        if validation is not None:
            shared[kind]["validation_cuts"] = f.training_cuts(
                validation, np.random.default_rng(seed + 1))
    return f.fit(train, validation=validation, **shared[kind])


def fit_methods(train, max_iter: int = 200, seed: int = 0, log=None) -> dict:
    """Every forecaster a model file holds, fitted on ``train``: ``{method: forecaster}``.

    The learned forecasters draw their training cuts once per kind
    (``fit_sharing_cuts``) and calibrate out of fold on them, or on
    ``learned.CALIBRATION_SHARE`` of the rows held out (``calibration="held_out"``).
    """
    hold = np.random.default_rng(seed).random(len(train)) < CALIBRATION_SHARE
    rows_of = {"out_of_fold": (train, None),
               "held_out": (train.subset(~hold), train.subset(hold))}
    shared = {}
    out = {}
    for e in FORECASTERS:
        if not e.method:
            continue
        f = e.make(max_iter, seed)
        t = time.time()
        if hasattr(f, "training_cuts"):
            fit_sharing_cuts(f, *rows_of[f.calibration], shared, seed)
        else:
            f.fit(train)
        out[e.method] = f
        if log is not None:
            log(f"forecast: fitted {e.method} in {time.time() - t:.1f} s")
    return out
