"""Every forecaster, in one place: what the evaluation fits, what ``predict --method`` offers.

A new forecaster is one ``Entry`` here (and its class): the evaluation, its
tables and figures, the alarm, the convergence example, the model file and
``predict --method`` all read this list, and hold no list of names of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .baselines import Climatology, ConditionedClimatology, LastEventPlusLead, Now
from .inverse_rate import LinearInverseRate, PointProcessInverseRate
from .learned import Ceiling, Learned, ToldMuD
from .physics import ModelBased, PaperRule


@dataclass(frozen=True)
class Entry:
    """One forecaster and where it takes part.

    Parameters
    ----------
    make : callable
        ``make(max_iter, seed)`` -> an unfitted forecaster.
    alarm : bool
        Its alarm "the avalanche within delta" is judged (fast enough to run at every step).
    example : bool
        Drawn in the convergence example.
    method : str, optional
        Its name for ``predict --method`` (and in the model file); None: evaluation only.
    """

    make: Callable
    alarm: bool = False
    example: bool = False
    method: str | None = None


FORECASTERS = (
    Entry(lambda it, s: Climatology()),
    Entry(lambda it, s: ConditionedClimatology(), alarm=True, example=True, method="conditioned"),
    Entry(lambda it, s: Now()),
    Entry(lambda it, s: LastEventPlusLead(random_state=s)),
    Entry(lambda it, s: LinearInverseRate("events"), method="ffm_ls_events"),
    Entry(lambda it, s: PointProcessInverseRate("events"), method="ffm_ml_events"),
    Entry(lambda it, s: LinearInverseRate("displacement"), alarm=True, example=True,
          method="ffm_ls_disp"),
    Entry(lambda it, s: PointProcessInverseRate("displacement"), method="ffm_ml_disp"),
    Entry(lambda it, s: PointProcessInverseRate("displacement", None), alarm=True, example=True),
    Entry(lambda it, s: PaperRule(), alarm=True, example=True),
    Entry(lambda it, s: ModelBased(random_state=s), alarm=True, example=True, method="model_based"),
    # with displacements and movers: a simulation's catalogue, trained on exact ones (degraded
    # catalogues break the lone-slider pairs it leans on), its features in fine bins (63 bins of
    # the exact lone-slider mu_d are a degree wide); calibrated out of fold in bins of the tilt
    # and the events so far like the other (on a quarter of the rows held out instead, its
    # coverage 12 degrees before the avalanche fell to 0.67-0.69 on 782 held-out rows); both
    # calibrate also in bins of the mean event size (which tracks the pile's number of sliders,
    # from 8 to 800 in the default prior) and, within those, of the predicted remaining angle
    Entry(lambda it, s: Learned(max_iter=it, degrade=False, max_bins=255, calibration_size_bins=2,
                                calibration_remaining_bins=3, random_state=s),
          alarm=True, example=True, method="learned"),
    Entry(lambda it, s: Learned(inputs="angles_sizes", max_iter=it, calibration_size_bins=2,
                                calibration_remaining_bins=3, random_state=s), alarm=True,
          example=True, method="learned_blind"),
    Entry(lambda it, s: Ceiling(max_iter=it, degrade=False, random_state=s), alarm=True,
          example=True),
    Entry(lambda it, s: ToldMuD(max_iter=it, degrade=False, random_state=s), alarm=True,
          example=True),
)
#: the forecasters a model file holds, by their ``predict --method`` name
METHODS = tuple(e.method for e in FORECASTERS if e.method)


def make_forecasters(has_ceiling: bool = False, max_iter: int = 200, seed: int = 0,
                     methods_only: bool = False) -> list:
    """Unfitted forecasters of ``FORECASTERS`` (those needing the ceiling only if the data hold it).

    ``methods_only``: only those a model file holds (``Entry.method``).
    """
    out = []
    for e in FORECASTERS:
        if methods_only and e.method is None:
            continue
        f = e.make(max_iter, seed)
        if "ceiling" in f.needs and not has_ceiling:
            continue
        out.append(f)
    return out


def names_where(flag: str) -> set:
    """The names of the forecasters whose ``Entry`` has ``flag`` set ("alarm", "example")."""
    return {e.make(1, 0).name for e in FORECASTERS if getattr(e, flag)}


def method_of(forecaster) -> str:
    """The ``predict --method`` name of a fitted forecaster (its class and parameters)."""
    for e in FORECASTERS:
        if e.method and e.make(1, 0).name == forecaster.name:
            return e.method
    raise KeyError(forecaster.name)


def fit_sharing_cuts(f, train, validation, shared: dict, seed: int):
    """Fit a learned forecaster on training (and calibration) cuts drawn once per kind of
    training catalogue (exact or degraded: ``shared`` keeps them) for every learned forecaster.

    ``validation`` None: the forecaster calibrates on its training cuts, out of fold.
    """
    import numpy as np

    if f.degrade not in shared:
        shared[f.degrade] = {"cuts": f.training_cuts(train, np.random.default_rng(seed))}
        if validation is not None:
            shared[f.degrade]["validation_cuts"] = f.training_cuts(
                validation, np.random.default_rng(seed + 1))
    return f.fit(train, validation=validation, **shared[f.degrade])


def fit_methods(train, max_iter: int = 200, seed: int = 0, log=None) -> dict:
    """Every forecaster a model file holds, fitted on ``train``: ``{method: forecaster}``.

    The learned forecasters draw their training cuts once per kind
    (``fit_sharing_cuts``) and calibrate out of fold on them, or on
    ``learned.CALIBRATION_SHARE`` of the rows held out (``calibration="held_out"``).
    """
    import time

    import numpy as np

    from .learned import CALIBRATION_SHARE

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
