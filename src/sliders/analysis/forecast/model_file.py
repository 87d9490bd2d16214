"""The fitted forecasters' file: plain arrays, read as data, forecasting with NumPy.

A model file (``io.model_arrays``: a zip of NumPy arrays and one JSON header)
holds fitted estimators ``{method: estimator}`` as ``arrays.to_arrays`` writes
them, their provenance, and reference forecasts.  ``load_forecasters`` reads
its form (``io.model_arrays.read_model_arrays``), builds each estimator from a
closed table of the package's classes with its fitted parts as NumPy
evaluators (``arrays.from_arrays``), runs each one's ``check_fitted`` (the
fitted parts its class declares, every tree, table and detector among them:
``integrity.check_fields``) and the check of its
expected-accuracy table (``io.forecast_model.check_accuracy_table``), and
recomputes the reference forecasts: a file whose arrays forecast otherwise is
refused.  Every refusal is one line naming the file (``ModelFileError``).
Nothing here imports scikit-learn or crepes: training does, and converts its
fitted objects once (``forecasters_bytes``).

The shipped files (``sliders/data/``) are also checked by their SHA-256, in a
file beside each.
"""

from __future__ import annotations

import pathlib

from ...io.forecast_model import (ModelFileError, check_accuracy_table, check_digest,
                                  default_model_path, default_posterior_path, printable_tree,
                                  read_model_bytes)
from ...io.model_arrays import model_arrays_bytes, read_model_arrays
from ...io.safeio import printable, publish_bytes
from .arrays import ConversionError, estimators_of, model_file_parts
from .integrity import IntegrityError


def forecasters_bytes(estimators: dict, provenance: dict, where: str = "model") -> bytes:
    """The model file's bytes for fitted ``estimators`` (``{method: estimator}``, as fitted or
    as loaded) and their provenance; read back as ``load_forecasters`` reads it, so that a file
    whose arrays would forecast otherwise is never written."""
    try:
        header, arrays = model_file_parts(estimators, dict(provenance))
        blob = model_arrays_bytes(header, arrays)
    except (ConversionError, IntegrityError) as exc:
        raise ModelFileError(f"{printable(where)}: not written: {printable(str(exc))}") from None
    _estimators_of_blob(blob, where)
    return blob


def save_forecasters(path, estimators: dict, provenance: dict) -> int:
    """Write a model file atomically (``forecasters_bytes``); returns its size in bytes."""
    blob = forecasters_bytes(estimators, provenance, str(path))
    publish_bytes(str(path), blob, overwrite=True)
    return len(blob)


def load_forecasters(path) -> tuple[dict, dict]:
    """The estimators and the provenance of a model file; ``ModelFileError`` in one line."""
    blob = read_model_bytes(path)
    if pathlib.Path(path).resolve() in (default_model_path().resolve(),
                                        default_posterior_path().resolve()):
        check_digest(path, blob)
    return _estimators_of_blob(blob, path)


def _estimators_of_blob(blob: bytes, path) -> tuple[dict, dict]:
    where = printable(str(path))
    header, arrays = read_model_arrays(path, blob)
    prov = header.get("provenance")
    if not isinstance(prov, dict):
        raise ModelFileError(f"{where}: no provenance table in its header")
    try:
        estimators = estimators_of(header, arrays)
    except AttributeError as exc:  # an estimator of a known class lacking a part: another version's
        raise ModelFileError(f"{where}: a part is missing ({printable(str(exc))}): written by "
                             f"sliders {printable(str(prov.get('sliders', '?')))}, whose "
                             "forecasters this version cannot use; train it again") from None
    except (IntegrityError, ValueError, TypeError, KeyError, IndexError) as exc:
        raise ModelFileError(f"{where}: {printable(' '.join(str(exc).split()))}; refused") \
            from None
    for method, e in estimators.items():
        try:
            check_accuracy_table(getattr(e, "expected_accuracy_", None))
        except ValueError as exc:
            raise ModelFileError(f"{where}: forecaster {printable(method)!r}: its expected-"
                                 f"accuracy table: {printable(str(exc))}; refused") from None
    return estimators, printable_tree(prov)
