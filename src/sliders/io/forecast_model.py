"""The model files' common ground: where the shipped ones are, their bounds and digests.

A model file (``io.model_arrays``: a zip of NumPy arrays and one JSON header,
built into estimators by ``analysis.forecast.model_file``) is read within
bounds: a regular file of at most ``MAX_MODEL_BYTES``, read once
(``read_model_bytes``); at most ``MAX_MEMBERS`` members, each and together
bounded (``MAX_MEMBER_BYTES``, ``MAX_INFLATED_BYTES``), its header at most
``MAX_TREE_BYTES``.  A file that fails is refused in one line naming it
(``ModelFileError``).  The provenance comes back with every string made
printable (``printable_tree``).

The default model ships inside the package (``sliders/data/``, found with
``importlib.resources``), never looked up in the current folder, and is
checked by its SHA-256 (``DEFAULT_MODEL_NAME + ".sha256"`` beside it), as is
the shipped posterior of ``infer`` (``DEFAULT_POSTERIOR_NAME``), a model file
of one entry.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import os
import pathlib
import stat

from .safeio import printable


#: the shipped model's file name inside the package's data folder
DEFAULT_MODEL_NAME = "default_forecaster.zip"
#: the shipped posterior of the pile's parameters (``infer``), a model file of one entry
DEFAULT_POSTERIOR_NAME = "default_posterior.zip"
#: the bounds of a model file (the shipped one: 3.4 MB, 8 members, 12 MB inflated)
MAX_MODEL_BYTES = 64 * 2**20
MAX_MEMBERS = 100_000
MAX_MEMBER_BYTES = 64 * 2**20
MAX_INFLATED_BYTES = 256 * 2**20
#: the most bytes of the JSON header (the shipped model's: 35 kB); a larger one would cost
#: gigabytes of Python objects before anything could be checked
MAX_TREE_BYTES = 16 * 2**20
#: the SHA-256 of the shipped model, in a file beside it
DIGEST_SUFFIX = ".sha256"
class ModelFileError(ValueError):
    """A model file that cannot be used: one line naming the file."""


def default_model_path() -> pathlib.Path:
    """The shipped default model: a ``pathlib.Path`` inside the installed package.

    Found with ``importlib.resources``; meson-python's editable install answers
    with a traversable of its own rather than a path, and there the file is
    the one beside this module's package (``sliders/data/``), the same place.
    """
    return shipped_path(DEFAULT_MODEL_NAME)


def default_posterior_path() -> pathlib.Path:
    """The shipped posterior of the pile's parameters (``infer``), beside the default model."""
    return shipped_path(DEFAULT_POSTERIOR_NAME)


def shipped_path(name: str) -> pathlib.Path:
    """The file ``name`` of the package's data folder (``default_model_path``)."""
    found = importlib.resources.files("sliders").joinpath("data", name)
    if isinstance(found, pathlib.Path):
        return found
    return pathlib.Path(__file__).resolve().parent.parent / "data" / name


def read_model_bytes(path) -> bytes:
    """The bytes of a model file: a regular file of at most ``MAX_MODEL_BYTES``, read once
    through one open descriptor (a device, a fifo, a folder or a larger file is refused from
    its status, before a byte is read)."""
    where = printable(path)
    try:
        with open(path, "rb") as fh:
            st = os.fstat(fh.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise ModelFileError(f"{where}: not a regular file (a model file is a zip "
                                     "archive on disk)")
            if st.st_size > MAX_MODEL_BYTES:
                raise ModelFileError(f"{where}: {st.st_size / 2**20:.0f} MB; a model file holds "
                                     f"at most {MAX_MODEL_BYTES // 2**20} MB")
            blob = fh.read(MAX_MODEL_BYTES + 1)
    except IsADirectoryError:
        raise ModelFileError(f"{where}: a folder, not a model file") from None
    except OSError as exc:
        raise ModelFileError(f"{where}: {exc.strerror or exc}") from None
    if len(blob) > MAX_MODEL_BYTES:  # grew while read
        raise ModelFileError(f"{where}: more than {MAX_MODEL_BYTES // 2**20} MB")
    return blob


def check_digest(path, blob: bytes) -> None:
    """The shipped model's bytes against the SHA-256 stored beside it (``DIGEST_SUFFIX``)."""
    recorded = pathlib.Path(str(path) + DIGEST_SUFFIX)
    try:
        expected = recorded.read_text(encoding="ascii").split()[0]
    except (OSError, UnicodeDecodeError, IndexError):
        raise ModelFileError(f"{printable(path)}: the shipped model's digest "
                             f"({recorded.name}) is missing; reinstall sliders") from None
    if hashlib.sha256(blob).hexdigest() != expected:
        raise ModelFileError(f"{printable(path)}: not the model shipped with this version (its "
                             "SHA-256 differs from the one recorded beside it); reinstall sliders")


def printable_tree(value):
    """``value`` (a provenance: dicts, lists, strings, numbers) with every string made printable."""
    if isinstance(value, dict):
        return {printable(k): printable_tree(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [printable_tree(v) for v in value]
    if isinstance(value, str):
        return printable(value)
    return value
