"""Small HDF5 helpers shared by the file modules of ``sliders.io`` (ensemble, study, prior).

* ``open_for_reading(path)``: an HDF5 file open for reading, or one line
  (``StorageError``) saying why not: missing, busy, a directory, not HDF5.
* ``plain_value(v)``: an attribute as a plain Python value (str, int, float).
* ``done_mask(done, where)`` and ``row_damage(rows, order, done)``: which rows
  of a row-per-realisation layout are complete and which of those fail their
  CRC-32 (``ROW_DIGEST``).
* ``coordinate``, ``dimension``, ``attach``: named HDF5 dimension scales, so
  that netCDF readers (xarray, ``engine="h5netcdf"``) see named dimensions.
  A scale lives in a group that is an ancestor of every dataset using it
  (netCDF looks a dimension up in the dataset's group and its parents).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from . import safeio
from .filelock import current_holder

ROW_DIGEST = "row_crc32"
# netCDF-4's mark of a dimension that has a length but no coordinate values (no storage)
NOT_A_VARIABLE = "This is a netCDF dimension but not a netCDF variable."


class StorageError(RuntimeError):
    """The file cannot be created, opened or does not match the requested ensemble."""


def plain_value(v):
    """An HDF5 attribute as a plain Python value: bytes decoded, NumPy scalars unwrapped."""
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def plain_attributes(group) -> dict:
    """A group's attributes as plain values, without the attribute checksum."""
    return {k: plain_value(v) for k, v in group.attrs.items() if k != safeio.ATTRS_DIGEST}


def open_for_reading(path):
    """An HDF5 file open for reading, or StorageError in one line: missing, busy (another
    process writes it: HDF5's file lock, and the holder of its sliders claim named),
    unreadable, not HDF5."""
    import h5py

    p = os.fspath(path)
    if not os.path.exists(p):
        raise StorageError(f"{p!r} does not exist")
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        text = " ".join(str(exc).split())
        if "unable to lock file" in text or "errno = 11" in text:
            holder = current_holder(p) or "another process"
            raise StorageError(f"{p!r} is busy: {holder} is writing it (HDF5 locks a file "
                               "while it is written); read it once that run has finished") \
                from None
        if os.path.isdir(p):
            raise StorageError(f"{p!r} is a directory, not an HDF5 file") from None
        try:
            hdf5 = h5py.is_hdf5(p)
        except OSError:
            hdf5 = True
        if not hdf5:
            raise StorageError(f"{p!r} is not a readable HDF5 file (not HDF5 at all)") from None
        raise StorageError(f"{p!r} is not a readable HDF5 file ({text})") from None
    return f


def open_checked(path, file_format: str, versions, where: str | None = None):
    """An HDF5 file open for reading with its kind (``file_format``) and format version
    (one of ``versions``) checked: StorageError in one line, the file closed, if not."""
    p = os.fspath(path)
    f = open_for_reading(p)
    try:
        safeio.check_header(f, file_format, where or repr(p), StorageError, coordinates=False,
                            versions=versions)
    except Exception:
        f.close()
        raise
    return f


def damaged(path, exc: Exception) -> StorageError:
    """One line for a failure while reading ``path``: the error's own words for an
    integrity or storage error, else "is damaged (the HDF5 error)"."""
    text = " ".join(str(exc).split())
    if isinstance(exc, (StorageError, safeio.IntegrityError)):
        return StorageError(text)
    return StorageError(f"{os.fspath(path)!r} is damaged ({type(exc).__name__}: {text})")


def done_mask(done: np.ndarray, where: str) -> np.ndarray:
    """The ``done`` column as booleans; StorageError (naming ``where``) if it holds anything
    but 0 and 1."""
    if done.dtype != np.uint8 or not np.isin(done, (0, 1)).all():
        raise StorageError(f"{where}: /realisations/done holds values other than 0 and 1 "
                           "(the file is damaged)")
    return done.astype(bool)


def row_damage(rows: dict, order: list[str], done: np.ndarray) -> list[tuple[int, str]]:
    """(row, column) of every done row whose value fails its CRC-32.

    ``rows`` maps each column name (and ``ROW_DIGEST``) to its (R, ...) array;
    ``order`` names the columns in the order of ``rows[ROW_DIGEST]``'s second axis.
    """
    digests = rows[ROW_DIGEST]
    return [(int(r), name) for r in np.flatnonzero(done) for j, name in enumerate(order)
            if safeio.crc32_of(rows[name][r]) != int(digests[r, j])]


# ---------------------------------------------------------------------------
# dimension scales
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Stored:
    """Coordinate values the file already holds: the dataset ``path`` (relative to the
    group being described), its first ``stop`` entries if ``stop`` is given."""

    path: str
    stop: int | None = None


def view(group, name: str, source: Stored):
    """``group/name``: an HDF5 virtual dataset showing ``source`` of the same file, so
    that a coordinate equal to a stored grid is not stored a second time."""
    import h5py

    src = group[source.path]
    part = slice(None, source.stop)
    n = len(range(*part.indices(src.shape[0])))
    layout = h5py.VirtualLayout(shape=(n,) + src.shape[1:], dtype=src.dtype)
    layout[...] = h5py.VirtualSource(".", src.name, shape=src.shape)[part]
    return group.create_virtual_dataset(name, layout)


def coordinate(group, name: str, values, units: str, long_name: str):
    """A coordinate variable ``group/name`` (checksummed), made the dimension scale ``name``;
    ``values`` an array, or ``Stored`` (a virtual dataset showing what the file holds)."""
    if isinstance(values, Stored):
        ds = view(group, name, values)
        values = ds[()]
    else:
        values = np.asarray(values)
        ds = group.create_dataset(name, data=values)
    safeio.seal_dataset(ds, values)
    ds.make_scale(name)
    ds.attrs["units"], ds.attrs["long_name"] = units, long_name
    return ds


def dimension(group, name: str, size: int, growing: bool = False):
    """A dimension ``group/name`` of ``size`` entries without coordinate values.

    It takes no room in the file (netCDF-4's "dimension but not variable":
    a dataset never written, so never allocated).  ``growing``: resizable,
    for a dimension whose datasets are appended to (``resize_dimension``).
    """
    if growing:
        ds = group.create_dataset(name, shape=(size,), maxshape=(None,), chunks=(1024,),
                                  dtype=np.float32)
    else:
        ds = group.create_dataset(name, shape=(size,), dtype=np.float32)
    ds.make_scale(f"{NOT_A_VARIABLE}{size:10d}")
    return ds


def attach(ds, *scales) -> None:
    """Attach one dimension scale to each axis of ``ds`` (None leaves an axis as it is)."""
    for axis, scale in enumerate(scales):
        if scale is not None and len(ds.dims[axis]) == 0:
            ds.dims[axis].attach_scale(scale)


def describe(ds, units: str, long_name: str, coordinates: str | None = None) -> None:
    """Give ``ds`` its ``units``, ``long_name`` and (CF) ``coordinates`` attributes."""
    ds.attrs["units"], ds.attrs["long_name"] = units, long_name
    if coordinates:
        ds.attrs["coordinates"] = coordinates
