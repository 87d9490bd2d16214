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

import sys

from ._forward import interrupted_while_starting

try:
    from .runs.forecast.infer import Inference, InferenceModel, load_inference_model
    from .runs.forecast.predict import ForecastModel, Prediction
except KeyboardInterrupt:
    if __name__ != "__main__":
        raise
    interrupted_while_starting("sliders.forecast")

__all__ = ["load", "main", "ForecastModel", "Prediction", "Inference"]


def load(path=None, posterior=None) -> InferenceModel:
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
    return load_inference_model(path, posterior)


def main(argv=None) -> int:
    """``python -m sliders.forecast``: the forecast commands (``sliders.runs.forecast.cli``)."""
    from .runs.forecast.cli import main as cli_main

    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
