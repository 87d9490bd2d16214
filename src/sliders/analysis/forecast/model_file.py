"""The fitted forecasters' file: plain arrays, read as data, forecasting with NumPy.

A model file (``io.model_arrays``: a zip of NumPy arrays and one JSON header)
holds fitted estimators ``{method: estimator}`` as ``arrays.to_arrays`` writes
them, their provenance, and reference forecasts.  ``load_forecasters`` checks
its form (``io.model_arrays.ModelArchive``), builds each estimator from a
closed table of the package's classes with its fitted parts as NumPy
evaluators (``arrays.estimator_of``), runs each one's ``check_fitted`` (the
fitted parts its class declares, every tree, table and detector among them,
and its expected-accuracy table: ``integrity.check_fields``), and
recomputes the reference forecasts: a file whose arrays forecast otherwise is
refused.  Every refusal is one line naming the file (``ModelFileError``).  A
forecast builds only the estimators it uses (``lazy``: ``ModelForecasters``
reads, builds and checks each at its first use, the file's form at once).
Nothing here imports scikit-learn or crepes: training does, and converts its
fitted objects once (``forecasters_bytes``).

The shipped files (``sliders/data/``) are also checked by their SHA-256, in a
file beside each.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping

from ...io.forecast_model import (ModelFileError, check_digest,
                                  default_model_path, default_posterior_path, printable_tree,
                                  read_model_bytes)
from ...io.model_arrays import ModelArchive, model_arrays_bytes
from ...io.safeio import printable, publish_bytes
from .arrays import (ConversionError, check_references, estimator_of, model_file_parts,
                     references_of)
from .integrity import IntegrityError, require


def forecasters_bytes(estimators: dict, provenance: dict, where: str = "model") -> bytes:
    """The model file's bytes for fitted ``estimators`` (``{method: estimator}``, as fitted or
    as loaded) and their provenance; read back as ``load_forecasters`` reads it, so that a file
    whose arrays would forecast otherwise is never written."""
    try:
        header, arrays = model_file_parts(estimators, dict(provenance))
        blob = model_arrays_bytes(header, arrays)
    except (ConversionError, IntegrityError) as exc:
        raise ModelFileError(f"{printable(where)}: not written: {printable(str(exc))}") from None
    ModelForecasters(ModelArchive.open(where, blob)).all()
    return blob


def save_forecasters(path, estimators: dict, provenance: dict) -> int:
    """Write a model file atomically (``forecasters_bytes``); returns its size in bytes."""
    blob = forecasters_bytes(estimators, provenance, str(path))
    publish_bytes(str(path), blob, overwrite=True)
    return len(blob)


def load_forecasters(path, lazy: bool = False) -> tuple[dict, dict]:
    """The estimators (``{method: estimator}``) and the provenance of a model file, every one
    built and checked; ``lazy``: a ``ModelForecasters`` that builds and checks each when first
    used.  ``ModelFileError`` in one line."""
    blob = read_model_bytes(path)
    if pathlib.Path(path).resolve() in (default_model_path().resolve(),
                                        default_posterior_path().resolve()):
        check_digest(path, blob)
    models = ModelForecasters(ModelArchive.open(path, blob))
    return (models if lazy else models.all()), models.provenance


class ModelForecasters(Mapping):
    """A model file's estimators by method, each read, built and checked
    (``arrays.estimator_of``) and its reference forecasts reproduced at its first use; the
    file's form (``ModelArchive.open``), its provenance and each array's owner checked at once."""

    def __init__(self, archive: ModelArchive):
        self.archive, self.tree = archive, archive.header.get("content")
        self.provenance = archive.header.get("provenance")
        self._built, self._trusted, self._references = {}, set(), None
        self._checked(self._check_form)

    def _check_form(self) -> None:
        require(isinstance(self.provenance, dict), "no provenance table in its header")
        require(isinstance(self.tree, dict) and all(isinstance(m, str) and m.isidentifier()
                                                    for m in self.tree), "no table of estimators")
        self.provenance = printable_tree(self.provenance)
        for name in self.archive.schema:
            owner, _, part = name.partition(".")
            require(owner in (*self.tree, "reference"), f"array {name!r} is read by no part")
            require(owner != "reference" or part.split(".")[0] in (*self.tree, "catalogue"),
                    f"reference forecast {part!r} is of no estimator of the file")

    def __getitem__(self, method):
        if method not in self._trusted:
            if method not in self:
                raise KeyError(method)
            self._build([method])
            self._checked(self._reproduce, method)
            self._trusted.add(method)
        return self._built[method]

    def __contains__(self, method) -> bool:
        return isinstance(method, str) and method in self.tree

    def __iter__(self):
        return iter(self.tree)

    def __len__(self) -> int:
        return len(self.tree)

    def all(self) -> dict:
        """``{method: estimator}``: all built and checked, then their references reproduced."""
        self._build(self.tree)
        return {method: self[method] for method in self.tree}

    def _build(self, methods) -> None:
        for method in methods:
            if method not in self._built:
                self._built[method] = self._checked(self._estimator, method)

    def _estimator(self, method: str):
        return estimator_of(self.tree[method], method, self.archive.read(
            [n for n in self.archive.schema if n.split(".")[0] == method]))

    def _reproduce(self, method: str) -> None:
        if self._references is None:  # the reference catalogues, read at the first
            self._references = references_of(self.archive.read(
                [n for n in self.archive.schema if n.startswith("reference.")]))
        recorded, cuts = self._references
        check_references({method: self._built[method]}, {
            k: v for k, v in recorded.items() if k.split(".")[0] == method}, cuts)

    def _checked(self, step, *args):
        """``step(*args)``, every refusal one line naming the file (``ModelFileError``)."""
        try:
            return step(*args)
        except ModelFileError:
            raise
        except (IntegrityError, ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:
            again = (" (a part is missing: written by sliders "
                     f"{self.provenance.get('sliders', '?')}, whose forecasters this version "
                     "cannot use; train it again)"
                     if isinstance(exc, AttributeError) else "; refused")
            raise ModelFileError(f"{self.archive.where}: " +
                                 printable(" ".join(str(exc).split()) + again)) from None
