"""Forecasting: the layer below the commands that forecasts a measured pile and infers its material.

* ``predict``: ``load_model`` reads a model file once; ``ForecastModel`` forecasts a catalogue
  (``predict``, a ``Prediction``) and follows a growing one (``follow``, a ``Follower``);
* ``infer``: the posterior of the pile's material (``PosteriorModel.infer``, an ``Inference``);
  ``InferenceModel``, the model ``load()`` gives, has ``predict``, ``infer`` and ``follow``;
* ``follower``: the live forecast's loop, its own stop conditions (a signal, ``until``,
  ``# avalanche``), data one way: file -> line reader -> catalogue reader -> forecast;
* ``alarm``: the live forecast's alarm, the run's score, the picture drawn aside;
* ``catalogue``: a measured catalogue read (CSV, columns, bytes) with its measurement;
* ``common``: the defaults, the probability's text, JSON values, the provenance.

The commands (``sliders.runs.forecast``) parse, call this layer and print;
``sliders.forecast`` is its front door.  Importing this package imports none of its modules:
``python -m sliders.forecast predict --help`` reads ``common``'s defaults only.
"""

from __future__ import annotations

__all__ = ["load", "ForecastModel", "Prediction", "Inference", "InferenceModel", "PileSimulation"]


def load(path=None, posterior=None, simulation=None):
    """The forecasters of a model file, loaded once (``infer.load_inference_model``; default:
    the model shipped in the package); ``posterior``: a posterior file, read at the first
    ``infer``; ``simulation``: how ``infer``'s predictive check makes piles."""
    from .infer import load_inference_model

    return load_inference_model(path, posterior, simulation)


def __getattr__(name: str):
    """The API's classes, imported at first use (their modules import NumPy)."""
    if name in ("ForecastModel", "Prediction"):
        from . import predict as module
    elif name in ("Inference", "InferenceModel", "PileSimulation"):
        from . import infer as module
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(module, name)
