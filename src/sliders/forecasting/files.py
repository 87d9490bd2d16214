"""The model files the forecasting layer reads: the forecasters' (``predict.load_model``) and
the posterior's (``infer.load_posterior``), read as data through the model file's checks
(``analysis.forecast.model_file``, ``io.forecast_model``), every refusal one line."""

from __future__ import annotations

from ..analysis.forecast.model_file import load_forecasters
from ..io.forecast_files import ForecastInputError
from ..io.forecast_model import ModelFileError


def read_model_file(path, shipped_path, missing: str, lazy: bool = False):
    """``(models, provenance, path)`` of the model file ``path`` (None: the one shipped at
    ``shipped_path``, refused with ``missing`` if absent), read as data: ``models`` a
    ``model_file.ModelForecasters``, every estimator built and checked now, or with ``lazy``
    at its first use (whose refusals are ``ModelFileError``); every refusal here one line
    (``ForecastInputError``)."""
    if path is None:
        path = shipped_path
        if not path.is_file():
            raise ForecastInputError(f"{path}: {missing}")
    try:
        models, prov = load_forecasters(path, lazy=True)
        if not lazy:
            models.all()
    except ModelFileError as exc:
        raise ForecastInputError(str(exc)) from None
    return models, prov, path
