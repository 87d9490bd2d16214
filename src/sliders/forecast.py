"""Forecast the avalanche angle of a measured pile, from Python or from the command line::

    import sliders.forecast as sf
    model = sf.load()                       # the shipped forecaster, loaded once
    pred = model.predict("pile.csv", tilt_now="27.5deg", angle_resolution="0.1deg")
    pred.to_dict()                          # what ``predict --json`` prints
    print(pred)                             # the text output
    pred.plot("pile.png")                   # the bench picture
    post = model.infer("pile.csv")          # the posterior of the pile's material
    post.to_dict()                          # what ``infer --json`` prints

``python -m sliders.forecast`` runs the commands (``sliders.runs.forecast.cli``); the API is
the forecasting layer's (``sliders.forecasting``), which the commands call: one code path.
Run as a command, this module imports the parser only (``--help`` reads no NumPy) and exits
before the API's imports below it.
"""

from __future__ import annotations

import sys

from ._forward import interrupted_while_starting

if __name__ == "__main__":
    try:
        from .runs.forecast.cli import main as _command

        sys.exit(_command())
    except KeyboardInterrupt:  # while the command's modules are imported, before its handler
        interrupted_while_starting("sliders.forecast")

# the API (not reached when run as a command)
from .forecasting.infer import Inference  # noqa: E402
from .forecasting.predict import ForecastModel, Prediction, load_model  # noqa: E402
from .runs.forecast.cli import main  # noqa: E402
from .runs.forecast.infer import CHECK_SIMULATION  # noqa: E402

__all__ = ["load", "main", "ForecastModel", "Prediction", "Inference"]


def load(path=None, posterior=None, lazy=False):
    """The forecasters of a model file, loaded once (default: the one shipped in the package).

    Parameters
    ----------
    path : str or os.PathLike, optional
        A model file written by ``python -m sliders.forecast train`` (or ``evaluate``).
    posterior : str or os.PathLike, optional
        A posterior file written by ``train --fit posterior`` (default: the shipped one),
        read at the first ``infer``.
    lazy : bool
        Check the file's form now and build, check and reproduce the reference forecasts of
        each forecaster at its first use (as the commands do: a one-shot forecast reads only
        the forecasters it uses); default: every forecaster now.

    Returns
    -------
    ForecastModel
        ``predict(catalogue, tilt_now=..., **measurement)`` gives a ``Prediction``,
        ``infer(catalogue, ...)`` an ``Inference``, ``follow(source, ...)`` a ``Follower``
        (its predictive check's piles made as the commands make them, ``CHECK_SIMULATION``).

    Raises
    ------
    sliders.io.forecast_files.ForecastInputError
        The file is not a model file this version reads (one line naming it); with ``lazy``,
        a forecaster refused at its first use raises ``sliders.io.forecast_model.ModelFileError``
        (one line naming the file).
    """
    return load_model(path, posterior, CHECK_SIMULATION, lazy)
