"""Every forecaster, in one place: what the evaluation fits, what ``predict --method`` offers,
what each one's fallback means.

A new forecaster is one ``Entry`` here (and its class): the evaluation, its
tables and figures, the alarm, the convergence example, the model file,
``predict --method`` and its fallback lines all read this list, and hold no
list of names of their own.

An entry names its class (``"module.Class"`` of this package) and its class is
imported when the entry makes a forecaster: the command line reads the
methods (``predict --method``) from here without importing the forecasters'
modules (their features and evaluators), which ``--help`` does not need; fitting
one imports scikit-learn (two seconds).
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass, field

#: the fallback of the forecasters that give the conditioned climatology when they cannot forecast
_FFM_FALLBACK = ("no acceleration of the rate in the last half of the tilt range seen (or fewer "
                 "than 10 events there): the conditioned climatology is given instead")
_LEARNED_FALLBACK = ("out of the training domain: the interval is widened to hold the conditioned "
                     "climatology's and the training's remaining angles too")


@dataclass(frozen=True)
class Entry:
    """One forecaster and where it takes part.

    Parameters
    ----------
    forecaster : str
        Its class, ``"module.Class"`` in ``sliders.analysis.forecast``.
    options : dict
        The arguments of its class beyond ``max_iter`` and ``random_state``.
    boosted : bool
        Its class takes ``max_iter`` (boosting iterations).
    seeded : bool
        Its class takes ``random_state``.
    alarm : bool
        Its alarm "the avalanche within delta" is judged (fast enough to run at every step).
    example : bool
        Drawn in the convergence example.
    band : bool
        Its 80 % band is drawn in the convergence example too.
    method : str, optional
        Its name for ``predict --method`` (and in the model file); None: evaluation only.
    fallback : str, optional
        What its forecast is when it cannot give its own (printed by ``predict``).
    colour, line : str
        How the figures draw it (matplotlib colour and line style; baselines grey).
    """

    forecaster: str
    options: dict = field(default_factory=dict)
    boosted: bool = False
    seeded: bool = False
    alarm: bool = False
    example: bool = False
    band: bool = False
    method: str | None = None
    fallback: str | None = None
    colour: str = "0.5"
    line: str = "-"

    def __post_init__(self):
        if self.method is not None and not self.fallback:
            raise ValueError(f"{self.forecaster} ({self.method}): a method a model file holds "
                             "says what its fallback is (Entry.fallback)")

    def make(self, max_iter: int, seed: int):
        """An unfitted forecaster with ``max_iter`` boosting iterations and random state ``seed``
        (each if its class takes it)."""
        module, _, name = self.forecaster.rpartition(".")
        cls = getattr(importlib.import_module(f"{__package__}.{module}"), name)
        return cls(**self.options, **({"max_iter": max_iter} if self.boosted else {}),
                   **({"random_state": seed} if self.seeded else {}))


FORECASTERS = (
    Entry("baselines.Climatology", colour="0.55", line=":"),
    Entry("baselines.ConditionedClimatology", alarm=True, example=True, band=True,
          method="conditioned", fallback="the conditioned climatology is the fallback itself",
          colour="0.35", line="--"),
    Entry("baselines.Now", colour="0.0", line=":"),
    Entry("baselines.LastEventPlusLead", seeded=True, colour="0.7", line="-."),
    Entry("inverse_rate.LinearInverseRate", {"rate": "events"}, method="ffm_ls_events",
          fallback=_FFM_FALLBACK, colour="#e6ab02"),
    Entry("inverse_rate.PointProcessInverseRate", {"rate": "events"}, method="ffm_ml_events",
          fallback=_FFM_FALLBACK, colour="#a6761d"),
    Entry("inverse_rate.LinearInverseRate", {"rate": "displacement"}, alarm=True, example=True,
          method="ffm_ls_disp", fallback=_FFM_FALLBACK, colour="#66a61e"),
    Entry("inverse_rate.PointProcessInverseRate", {"rate": "displacement"}, method="ffm_ml_disp",
          fallback=_FFM_FALLBACK, colour="#b2df8a"),
    Entry("inverse_rate.PointProcessInverseRate", {"rate": "displacement", "exponent": None},
          alarm=True, example=True, colour="#1b9e77"),
    Entry("physics.PaperRule", alarm=True, example=True, colour="#7570b3"),
    Entry("physics.ModelBased", seeded=True, alarm=True, example=True, method="model_based",
          fallback="no lone-slider slips (they need the displacement and first/last columns) "
                   "and too few early events to estimate mu_d: the conditioned climatology is "
                   "given instead", colour="#e7298a"),
    # with displacements and movers: a simulation's catalogue, trained on exact ones (degraded
    # catalogues break the lone-slider pairs it leans on), its features in fine bins (63 bins of
    # the exact lone-slider mu_d are a degree wide); calibrated out of fold in bins of the tilt
    # and the events so far like the other (on a quarter of the rows held out instead, its
    # coverage 12 degrees before the avalanche fell to 0.67-0.69 on 782 held-out rows); both
    # calibrate also in bins of the mean event size (which tracks the pile's number of sliders,
    # from 8 to 800 in the default prior) and, within those, of the predicted remaining angle
    Entry("learned.Learned", {"degrade": False, "max_bins": 255, "calibration_size_bins": 2,
                              "calibration_remaining_bins": 3},
          boosted=True, seeded=True, alarm=True, example=True, band=True, method="learned",
          fallback=_LEARNED_FALLBACK, colour="#d95f02"),
    # angles and sizes only, calibrated apart for exact and noisy angles (a noisy cut's remaining
    # angle is counted from below its tilt reached; pooled, the exact cuts' coverage a quarter
    # of a degree before the avalanche fell to 0.68, apart 0.73, on 1168 held-out rows)
    Entry("learned.Learned", {"inputs": "angles_sizes", "calibration_size_bins": 2,
                              "calibration_remaining_bins": 3, "calibration_by_record": True},
          boosted=True, seeded=True, alarm=True, example=True, method="learned_blind",
          fallback=_LEARNED_FALLBACK, colour="#fdae61"),
    # angles and sizes told the pile's number of sliders (predict --sliders): every training
    # cut told it, the number or a range around it, and calibrated apart by the size class told
    Entry("learned.Learned", {"inputs": "angles_sizes", "told_share": 1.0,
                              "calibration_by_record": True, "calibration_size_bins": 2,
                              "calibration_remaining_bins": 3},
          boosted=True, seeded=True, alarm=True, example=True, method="learned_sized",
          fallback=_LEARNED_FALLBACK, colour="#fd8d3c"),
    # a camera's catalogue: its displacements in any unit, read relative to the catalogue's
    # own (``features.camera_features``), trained on displacement units drawn over four decades;
    # mu_d from lone slips solved with the unit is exact when the angles are (fine bins, as
    # the forecaster of every feature)
    Entry("learned.Learned", {"inputs": "camera", "max_bins": 255, "calibration_size_bins": 2,
                              "calibration_remaining_bins": 3},
          boosted=True, seeded=True, alarm=True, example=True, method="learned_camera",
          fallback=_LEARNED_FALLBACK, colour="#e31a1c"),
    Entry("learned.Ceiling", {"degrade": False}, boosted=True, seeded=True, alarm=True,
          example=True, band=True, colour="#1f78b4"),
    Entry("learned.ToldMuD", {"degrade": False}, boosted=True, seeded=True, alarm=True,
          example=True, colour="#6a3d9a", line="--"),
)
#: the forecasters a model file holds, by their ``predict --method`` name
METHODS = tuple(e.method for e in FORECASTERS if e.method)


def fallback_of(method: str) -> str:
    """What the forecaster of ``method`` (a ``predict --method`` name) gives when it cannot
    forecast (``Entry.fallback``)."""
    return next(e.fallback for e in FORECASTERS if e.method == method)


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


@functools.cache
def by_name() -> dict:
    """``{forecaster name: Entry}`` of every forecaster, in the registry's order (one dict,
    made once: read it, do not change it)."""
    return {e.make(1, 0).name: e for e in FORECASTERS}


def names_where(flag: str) -> set:
    """The names of the forecasters whose ``Entry`` has ``flag`` set ("alarm", "example", "band")."""
    return {name for name, e in by_name().items() if getattr(e, flag)}


def method_of(forecaster) -> str:
    """The ``predict --method`` name of a fitted forecaster (its class and parameters)."""
    e = by_name().get(forecaster.name)
    if e is None or not e.method:
        raise KeyError(forecaster.name)
    return e.method
