"""Forecasting the avalanche angle from the event catalogue (docs/forecasting.md).

Pure computation on ``sliders.io.catalogue`` objects: no running, no plotting.

* ``base``: the forecast's form (quantiles at ``LEVELS``), the ``Forecaster`` estimator;
* ``registry``: every forecaster in one list (evaluation, alarm, ``predict --method``);
* ``features``: catalogues cut at a tilt (``Cuts``), random training cuts, features;
* ``measurement``: how a catalogue was measured, and catalogues degraded the same way;
* ``baselines``: climatology, conditioned climatology, now, last event + lead;
* ``inverse_rate``: the failure forecast method, least squares and point process;
* ``physics``: the paper's half-angle rule and the model-based estimate of mu_d;
* ``learned``: gradient-boosted quantile regressors with a conformal calibration and a
  domain check, the ceiling and the told-mu_d variants;
* ``domain``: whether a catalogue, read through its measurement, is like the training ones;
* ``evaluation``: the split, the cuts at leads, the metrics with bootstrap intervals, the alarm.
"""

from .base import LEVELS, Forecast, ForecastError, Forecaster
from .baselines import Climatology, ConditionedClimatology, LastEventPlusLead, Now
from .features import Cuts, training_cuts
from .inverse_rate import LinearInverseRate, PointProcessInverseRate
from .measurement import Measurement

__all__ = ["LEVELS", "Forecast", "ForecastError", "Forecaster", "Climatology",
           "ConditionedClimatology", "LastEventPlusLead", "Now", "Cuts", "training_cuts",
           "LinearInverseRate", "PointProcessInverseRate", "Measurement"]
