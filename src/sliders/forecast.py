"""Forecast the avalanche angle of a measured pile, from Python or from the command line::

    import sliders.forecast as sf
    model = sf.load()                       # the shipped forecaster, loaded once
    pred = model.predict("pile.csv", tilt_now="27.5deg", angle_resolution="0.1deg")
    pred.to_dict()                          # what ``predict --json`` prints
    print(pred)                             # the text output
    pred.plot("pile.png")                   # the bench picture
    post = model.infer("pile.csv")          # the posterior of the pile's material
    post.to_dict()                          # what ``infer --json`` prints

``python -m sliders.forecast`` runs the commands (``sliders.runs.forecast.cli``); ``predict``
is this API (``sliders.runs.forecast.predict``): one code path.
"""

from __future__ import annotations

import importlib
import sys

from ._forward import interrupted_while_starting, names_at_first_use

#: the API's names, each read from its module at first use: ``python -m sliders.forecast
#: predict --help`` imports neither the forecasters nor scikit-learn
_API = {
    "ForecastModel": ("runs.forecast.predict", "ForecastModel"),
    "Prediction": ("runs.forecast.predict", "Prediction"),
    "Inference": ("runs.forecast.infer", "Inference"),
    "InferenceModel": ("runs.forecast.infer", "InferenceModel"),
}

__all__ = ["load", "main", "ForecastModel", "Prediction", "Inference", "InferenceModel"]


__getattr__ = names_at_first_use(__name__, _API)


def _module(name: str):
    """``sliders.runs.forecast.NAME``."""
    return importlib.import_module(f"{__package__}.runs.forecast.{name}")


def load(path=None, posterior=None):
    """The forecasters of a model file, loaded once (default: the one shipped in the package).

    Parameters
    ----------
    path : str or os.PathLike, optional
        A model file written by ``python -m sliders.forecast train`` (or ``evaluate``).
    posterior : str or os.PathLike, optional
        A posterior file written by ``train --fit posterior`` (default: the shipped one),
        read at the first ``infer``.

    Returns
    -------
    InferenceModel
        A ``ForecastModel``: ``predict(catalogue, tilt_now=..., **measurement)`` gives a
        ``Prediction``, ``infer(catalogue, ...)`` an ``Inference``.

    Raises
    ------
    sliders.io.forecast_files.ForecastInputError
        The file is not a model file this version reads (one line naming it).
    """
    return _module("infer").load_inference_model(path, posterior)


def main(argv=None) -> int:
    """``python -m sliders.forecast``: the forecast commands (``sliders.runs.forecast.cli``)."""
    return _module("cli").main(argv)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # while the command's modules are imported, before its handler
        interrupted_while_starting("sliders.forecast")
