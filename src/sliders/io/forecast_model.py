"""The model files' common ground: where the shipped ones are, their bounds and digests.

A model file (``io.model_arrays``: a zip of NumPy arrays and one JSON header,
built into estimators by ``analysis.forecast.model_file``) is read within
bounds: a regular file of at most ``MAX_MODEL_BYTES``, read once
(``read_model_bytes``); at most ``MAX_MEMBERS`` members, each and together
bounded (``MAX_MEMBER_BYTES``, ``MAX_INFLATED_BYTES``), its header at most
``MAX_TREE_BYTES``.  A file that fails is refused in one line naming it
(``ModelFileError``).  The provenance comes back with every string made
printable (``printable_tree``); a forecaster's expected-accuracy table is
checked as ``predict`` reads it (``check_accuracy_table``).

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

import numpy as np

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


#: the columns of a forecaster's expected-accuracy table (``expected_accuracy_``, written by
#: ``analysis.forecast.evaluation.accuracy_table``, printed by ``predict``): one value per bin
#: of ``lead_edges_deg``, and the same over every held-out cut in ``overall`` (with ``rows``)
ACCURACY_COLUMNS = ("median_abs_deg", "coverage", "n")
#: the most bins of lead an expected-accuracy table may hold
MAX_ACCURACY_BINS = 1000


def check_accuracy_table(table) -> None:
    """A forecaster's expected-accuracy table (None or empty: it holds none) as ``predict``
    reads it, else ``ValueError`` saying what is wrong: every column present, one value per
    lead bin, the lead edges finite, from 0 up and increasing, the errors finite degrees in
    [0, 90], the coverages shares in [0, 1], the counts whole numbers from 0."""
    if table is None or (isinstance(table, dict) and not table):
        return
    if not isinstance(table, dict):
        raise ValueError(f"a {type(table).__name__}, not a table of columns")
    overall = table.get("overall") if isinstance(table.get("overall"), dict) else {}
    missing = [c for c in ("lead_edges_deg", *ACCURACY_COLUMNS, "overall") if c not in table]
    missing += [f"overall {c}" for c in (*ACCURACY_COLUMNS, "rows")
                if "overall" in table and c not in overall]
    if missing:
        raise ValueError(f"no column {', '.join(missing)}")
    edges = _column(table["lead_edges_deg"], "lead_edges_deg")
    if not 1 <= edges.size <= MAX_ACCURACY_BINS or (np.diff(edges) <= 0).any():
        raise ValueError(f"lead_edges_deg: {edges.size} edges, not 1 to {MAX_ACCURACY_BINS} "
                         "increasing from 0 up")
    for c in ACCURACY_COLUMNS:
        _column(table[c], c, edges.size, "lead bins")
    for c in (*ACCURACY_COLUMNS, "rows"):
        _column([overall[c]], f"overall {c}", column=c)
    cells = table.get("by_width")
    if cells is None:
        return
    if not isinstance(cells, dict) or any(c not in cells for c in ("width_edges_deg",
                                                                    *ACCURACY_COLUMNS)):
        raise ValueError("by_width: not a table of width edges and columns per lead bin")
    for c in ("width_edges_deg", *ACCURACY_COLUMNS):
        rows, first = cells[c], cells["width_edges_deg"][0]
        if not isinstance(rows, (list, tuple)) or len(rows) != edges.size:
            raise ValueError(f"by_width {c}: not one row per lead bin")
        width = len(first) + (c != "width_edges_deg") if isinstance(first, (list, tuple)) else 0
        for row in rows:
            if (np.diff(_column(row, f"by_width {c}", width, "width bins")) < 0).any() \
                    and c == "width_edges_deg":
                raise ValueError("by_width width_edges_deg: not increasing from 0 up")


def _column(values, what: str, size: int | None = None, per: str = "", column: str = ""):
    """``values`` (a list of plain numbers, or a 1-D array) as finite floats, ``size`` of them
    (one per ``per``), in the range of ``column`` (``what`` unless given): degrees, a share, a
    count, or from 0 up."""
    column = column or what.split()[-1]
    if not ((isinstance(values, (list, tuple)) and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            for v in values)) or (isinstance(values, np.ndarray) and values.ndim == 1
                                  and values.dtype.kind in "iuf")):
        raise ValueError(f"{what}: not a list of numbers")
    v = np.asarray(values, dtype=float)
    lo, hi = {"median_abs_deg": (0.0, 90.0), "coverage": (0.0, 1.0)}.get(column, (0.0, np.inf))
    for bad, why in ((lambda: not np.isfinite(v).all(), "NaN or infinite values"),
                     (lambda: size is not None and v.size != size,
                      f"{v.size} values for {size} {per}"),
                     (lambda: (v < lo).any() or (v > hi).any(), f"values outside [{lo:g}, {hi:g}]"
                      if hi < np.inf else "negative values"),
                     (lambda: column in ("n", "rows") and (v != np.round(v)).any(),
                      "counts that are not whole numbers")):
        if bad():
            raise ValueError(f"{what}: {why}")
    return v
