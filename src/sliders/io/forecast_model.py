"""The fitted forecasters' file: data, never code.

A model file is a skops archive (``skops.io``: a zip of JSON and NumPy
arrays) of one dict::

    {"format": MODEL_FORMAT, "forecasters": {method: fitted forecaster},
     "provenance": {prior, rows, mode, versions, date, ...}}

Loading never runs code from the file: before anything is built, every type
the file names (``skops.io.get_untrusted_types``) must be on ``ALLOWED_TYPES``,
an explicit list of the classes the package writes; anything else (a pickle,
a zip naming another class or a function) is refused in one line, and only
then does ``skops.io.load`` build the objects, trusting exactly that list.

The default model ships inside the package (``sliders/data/``, found with
``importlib.resources``), never looked up in the current folder.
"""

from __future__ import annotations

import importlib.resources
import io
import pathlib
import zipfile
from .safeio import publish_bytes

MODEL_FORMAT = "sliders-forecaster-3"
#: the shipped model's file name inside the package's data folder
DEFAULT_MODEL_NAME = "default_forecaster.skops"
#: every type a model file may name beyond skops' own defaults
ALLOWED_TYPES = frozenset({
    "crepes.base.ConformalPredictiveSystem",
    "numpy.dtype",
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.ensemble._hist_gradient_boosting.binning._BinMapper",
    "sklearn.impute._base.SimpleImputer",
    "sklearn.preprocessing._data.QuantileTransformer",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.neighbors._lof.LocalOutlierFactor",
    "sklearn.neighbors._kd_tree.KDTree",
    "sklearn.metrics._dist_metrics.EuclideanDistance64",
    "sklearn.neighbors._ball_tree.BallTree",
    "sklearn.pipeline.Pipeline",
    "sliders.analysis.forecast.baselines.Climatology",
    "sliders.analysis.forecast.baselines.ConditionedClimatology",
    "sliders.analysis.forecast.domain.DomainCheck",
    "sliders.analysis.forecast.inverse_rate.LinearInverseRate",
    "sliders.analysis.forecast.inverse_rate.PointProcessInverseRate",
    "sliders.analysis.forecast.learned.Learned",
    "sliders.analysis.forecast.physics.ModelBased",
})


class ModelFileError(ValueError):
    """A model file that cannot be used: one line naming the file."""


def default_model_path() -> pathlib.Path:
    """The shipped default model: a ``pathlib.Path`` inside the installed package.

    Found with ``importlib.resources``; meson-python's editable install answers
    with a traversable of its own rather than a path, and there the file is
    the one beside this module's package (``sliders/data/``), the same place.
    """
    found = importlib.resources.files("sliders").joinpath("data", DEFAULT_MODEL_NAME)
    if isinstance(found, pathlib.Path):
        return found
    return pathlib.Path(__file__).resolve().parent.parent / "data" / DEFAULT_MODEL_NAME


def forecasters_bytes(forecasters: dict, provenance: dict, where: str = "model") -> bytes:
    """The model file's bytes for fitted forecasters (``{method: forecaster}``) and their provenance.

    Checked as ``load_forecasters`` reads it, so that a model naming a type
    off the allow-list is never written.
    """
    import skops.io as sio

    blob = sio.dumps({"format": MODEL_FORMAT, "forecasters": dict(forecasters),
                      "provenance": dict(provenance)}, compression=zipfile.ZIP_DEFLATED,
                     compresslevel=9)
    _check_types(blob, where)
    return blob


def save_forecasters(path: str, forecasters: dict, provenance: dict) -> int:
    """Write a model file atomically (``forecasters_bytes``); returns its size in bytes."""
    blob = forecasters_bytes(forecasters, provenance, path)
    publish_bytes(path, blob, overwrite=True)
    return len(blob)


def _check_types(blob: bytes, where) -> None:
    import skops.io as sio

    try:
        named = sio.get_untrusted_types(data=blob)
    except zipfile.BadZipFile as exc:  # a member's CRC-32 or its header does not match
        raise ModelFileError(f"{where}: damaged model file ({exc})") from None
    except Exception:  # noqa: BLE001 (whatever the archive holds: it is not a model file)
        raise ModelFileError(f"{where}: not a sliders model file (a skops archive)") from None
    refused = sorted(set(named) - ALLOWED_TYPES)
    if refused:
        raise ModelFileError(f"{where}: refused: the file names types that are not on the "
                             f"allow-list of forecaster files ({', '.join(refused[:3])}"
                             f"{', ...' if len(refused) > 3 else ''}); nothing was loaded")


def load_forecasters(path) -> tuple[dict, dict]:
    """The forecasters and the provenance of a model file; ``ModelFileError`` in one line.

    Nothing in the file runs: the types it names are checked against
    ``ALLOWED_TYPES`` before ``skops.io.load`` builds anything.
    """
    import skops.io as sio

    try:
        blob = path.read_bytes() if hasattr(path, "read_bytes") else open(path, "rb").read()
    except OSError as exc:
        raise ModelFileError(f"{path}: {exc.strerror or exc}") from None
    if not zipfile.is_zipfile(io.BytesIO(blob)):
        raise ModelFileError(f"{path}: refused: not a sliders model file (a skops archive; "
                             "a pickle is never loaded)")
    _check_types(blob, path)
    try:
        obj = sio.loads(blob, trusted=sorted(ALLOWED_TYPES))
    except Exception as exc:  # noqa: BLE001
        raise ModelFileError(f"{path}: damaged model file ({type(exc).__name__})") from None
    if isinstance(obj, dict) and str(obj.get("format", "")).startswith("sliders-forecaster-") \
            and obj["format"] != MODEL_FORMAT:
        raise ModelFileError(f"{path}: a model file of format {obj['format']}; this version reads "
                             f"{MODEL_FORMAT}: train it again")
    if not isinstance(obj, dict) or obj.get("format") != MODEL_FORMAT:
        raise ModelFileError(f"{path}: not a sliders model file of format {MODEL_FORMAT}")
    forecasters, prov = obj.get("forecasters"), obj.get("provenance")
    if not isinstance(forecasters, dict) or not isinstance(prov, dict):
        raise ModelFileError(f"{path}: not a sliders model file of format {MODEL_FORMAT}")
    return forecasters, prov
