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

The names below are imported from their modules when first read (``__getattr__``):
``registry`` is read by the command line's parser, which needs none of the
forecasters' modules (a forecast reads them; fitting one imports scikit-learn, two
seconds).
"""

import importlib

#: name -> the module of this package that defines it
_HOMES = {"LEVELS": "base", "Forecast": "base", "ForecastError": "base", "Forecaster": "base",
          "Climatology": "baselines", "ConditionedClimatology": "baselines",
          "LastEventPlusLead": "baselines", "Now": "baselines", "Cuts": "features",
          "training_cuts": "features", "LinearInverseRate": "inverse_rate",
          "PointProcessInverseRate": "inverse_rate", "Measurement": "measurement"}

__all__ = list(_HOMES)


def __getattr__(name: str):
    """``name`` of ``__all__``, from the module that defines it."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
