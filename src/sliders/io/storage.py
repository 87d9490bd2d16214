"""The ensemble's HDF5 file: its layout and a small file handler with two writers.

One file holds an ensemble of ``R`` realisations of one scene, one row per
realisation ``r`` (the seed of row ``r`` is ``realisation_seed(base_seed, r)``)::

    /                      attrs: format, format_version, scene (JSON of
                           Scene.to_dict()), software_version, base_seed,
                           realisations (R), backend, created (UTC, ISO 8601)
    /grids/<field>         the StatisticsGrids the statistics were binned on
    /realisations/seed     (R,) uint32, written when the file is created
    /realisations/done     (R,) uint8, 1 once the row below is complete
    /realisations/status   (R,) int8, sliders.status code (-1: not run);
                           attr "codes" = JSON {code: name}
    /realisations/alpha_c, n_events, slider_steps, wall_time   (R,)
    /realisations/statistics/<key>   (R, *shape): observables.realisation_statistics
    /realisations/row_crc32  (R, C) uint32: CRC-32 of row r of each of the C columns
                           named by its attr "columns", written before done[r]

Integrity (``safeio``): the root attributes carry a CRC-32 (``attrs_crc32``),
every grid and the seeds a CRC-32 attribute, every row its ``row_crc32``;
``read_header`` and ``read_rows`` verify them (the rows marked done) and
raise ``StorageError`` naming the damaged dataset.  A per-row digest rather
than HDF5's Fletcher32 filter: filters need chunked datasets, and parallel
HDF5 writes filtered datasets only collectively, while the ranks here write
their rows independently, whenever a realisation finishes.

Creation is atomic: the file is built (structure, seeds) under a temporary
name beside ``--out``, flushed, then published (hard link: fails if the
path appeared meanwhile; or rename over it for ``--overwrite``), so that an
existing file is never destroyed by a creation that fails half-way.

Every dataset is contiguous, allocated and filled when the file is created, so
that writing a row never touches HDF5 metadata: a row is raw bytes written in
place, then ``done[r] = 1``.  A process killed between two rows leaves a
readable file in which every row with ``done = 1`` is complete.

The handler (``EnsembleFile``) has two implementations with the same interface
and the same file content:

* ``MpioFile``: parallel h5py (``driver="mpio"``).  Every rank makes the same
  structural calls (file, groups, datasets and attributes are created
  collectively), then each rank writes its own rows independently.
* ``GatherFile``: rank 0 alone opens the file with plain (serial) h5py; the
  other ranks queue their rows (``outbox``) and the ensemble scheduler ships
  them to rank 0 with its "done" message, where ``apply`` writes them.  Used
  when h5py has no MPI support, with a single process, or when forced.
"""

from __future__ import annotations

import datetime
import json
import os
from collections import Counter
from dataclasses import dataclass, field
from typing import Any
import time

import numpy as np

from .. import status
from . import formats, safeio
from .h5tools import (ROW_DIGEST, StorageError, open_checked, damaged, done_mask, open_for_reading,
                      plain_attributes, row_damage)
from .._version import __version__
from ..scene import Scene

FORMAT = formats.ENSEMBLE
FORMAT_VERSION = 1
KNOWN_VERSIONS = (1,)  # format_version values this reader understands (a newer one is refused)
STORAGES = ("auto", "mpio", "gather")
NOT_RUN = -1  # status code of a row that has not been computed


class CollectiveFailure(StorageError):
    """A collective parallel-HDF5 call failed on this rank (e.g. disk full while creating
    the file): the other ranks may wait in it for ever, so the caller must MPI_Abort."""


@dataclass(frozen=True)
class Column:
    """One per-realisation dataset: ``/realisations/<name>``, shape ``(R, *shape)``."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype
    fill: Any = 0


@dataclass
class Layout:
    """Everything needed to create an ensemble file (identical on every rank)."""

    n_realisations: int
    columns: list[Column]
    seeds: np.ndarray  # (R,) uint32
    grids: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)

    def column(self, name: str) -> Column:
        """The column called ``name``."""
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(name)


BASE_COLUMNS = (
    Column("status", (), np.dtype(np.int8), NOT_RUN),
    Column("alpha_c", (), np.dtype(np.float64), np.nan),
    Column("n_events", (), np.dtype(np.int64), -1),
    Column("slider_steps", (), np.dtype(np.int64), -1),
    Column("wall_time", (), np.dtype(np.float64), np.nan),
)
STATISTICS = "statistics/"


def make_layout(n_realisations: int, seeds, grids: dict[str, np.ndarray],
                statistics: dict[str, tuple[tuple[int, ...], np.dtype]],
                attrs: dict[str, Any]) -> Layout:
    """The layout of an ensemble: base columns plus one column per statistic."""
    cols = list(BASE_COLUMNS)
    for key in sorted(statistics):
        shape, dtype = statistics[key]
        dtype = np.dtype(dtype)
        fill = np.nan if dtype.kind == "f" else 0
        cols.append(Column(STATISTICS + key, tuple(int(s) for s in shape), dtype, fill))
    return Layout(int(n_realisations), cols, np.asarray(seeds, dtype=np.uint32),
                  {k: np.asarray(v) for k, v in grids.items()}, dict(attrs))


def file_attributes(scene_dict: dict, base_seed: int, n_realisations: int, backend: str) -> dict:
    """Root attributes of a new ensemble file: format, scene (JSON), seeds, count, backend, versions."""
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "scene": json.dumps(scene_dict, sort_keys=True),
        "software_version": __version__,
        "base_seed": int(base_seed),
        "realisations": int(n_realisations),
        "backend": backend,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def h5py_has_mpi() -> bool:
    """True if h5py was built against parallel HDF5 (``driver='mpio'`` available)."""
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is a dependency
        return False
    return bool(h5py.get_config().mpi)


def choose_storage(requested: str, comm_size: int, have_mpi: bool) -> str:
    """``auto``: mpio with several ranks when h5py has MPI, gather otherwise."""
    if requested not in STORAGES:
        raise StorageError(f"--storage {requested!r} must be one of {STORAGES}")
    if requested == "auto":
        return "mpio" if (comm_size > 1 and have_mpi and h5py_has_mpi()) else "gather"
    if requested == "mpio":
        if not have_mpi:
            raise StorageError("--storage mpio needs mpi4py (run under mpirun)")
        if not h5py_has_mpi():
            raise StorageError("--storage mpio needs h5py built with parallel HDF5 "
                               "(h5py.get_config().mpi is False); use --storage gather")
    return requested


# ---------------------------------------------------------------------------
# structure: the same calls on every rank (mpio) or on rank 0 alone (gather)
# ---------------------------------------------------------------------------
def _dcpl():
    """Contiguous, allocated and filled at creation (parallel HDF5 forces this anyway)."""
    import h5py

    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    dcpl.set_fill_time(h5py.h5d.FILL_TIME_ALLOC)
    return dcpl


def create_structure(f, layout: Layout) -> None:
    """The layout's datasets in the open file or group ``f``: attributes (sealed), the grids
    (``/grids``, none if the layout has none), and every row dataset, allocated and filled
    (seeds, ``done``, ``row_crc32``, the columns).  Collective under mpio."""
    for k, v in layout.attrs.items():
        f.attrs[k] = v
    safeio.seal_attrs(f)
    if layout.grids:
        g = f.create_group("grids")
        for name in sorted(layout.grids):
            safeio.seal_dataset(g.create_dataset(name, data=layout.grids[name]),
                                layout.grids[name])
    rg = f.create_group("realisations")
    rg.create_group("statistics")
    R = layout.n_realisations
    seed = rg.create_dataset("seed", shape=(R,), dtype=np.uint32, dcpl=_dcpl())
    safeio.seal_dataset(seed, layout.seeds)
    digest = rg.create_dataset(ROW_DIGEST, shape=(R, len(layout.columns)), dtype=np.uint32,
                               fillvalue=0, dcpl=_dcpl())
    digest.attrs["columns"] = json.dumps([c.name for c in layout.columns])
    rg.create_dataset("done", shape=(R,), dtype=np.uint8, fillvalue=0, dcpl=_dcpl())
    for c in layout.columns:
        rg.create_dataset(c.name, shape=(R,) + c.shape, dtype=c.dtype, fillvalue=c.fill,
                          dcpl=_dcpl())
    rg["status"].attrs["codes"] = json.dumps({str(k): v for k, v in status.NAMES.items()})


def _check_structure(f, layout: Layout) -> None:
    """Refuse a file whose datasets do not match the layout (resume)."""
    rg = f["realisations"]
    R = layout.n_realisations
    for c in layout.columns:
        if c.name not in rg:
            raise StorageError(f"the file has no dataset /realisations/{c.name}; "
                               "it was written by another version of sliders")
        ds = rg[c.name]
        if ds.shape != (R,) + c.shape or ds.dtype != c.dtype:
            raise StorageError(
                f"/realisations/{c.name} has shape {ds.shape} {ds.dtype}, expected "
                f"{(R,) + c.shape} {c.dtype}; it was written by another version of sliders")


class EnsembleFile:
    """File handler of an ensemble (Dedalus style): create or resume, write rows, close.

    ``create`` and ``open_for_resume`` are collective over ``comm``; so is
    ``close``.  ``write_row``, ``mark_done`` and ``flush`` are local.
    """

    kind = "abstract"

    def __init__(self, path: str, layout: Layout, comm):
        self.path = os.fspath(path)
        self.layout = layout
        self.comm = comm
        self.file = None
        self._ds: dict = {}
        self.rows_written = 0
        self.write_seconds = 0.0  # time spent writing rows and flushing (cost of "flush per row")

    # -- construction ------------------------------------------------------
    @classmethod
    def create(cls, path, layout: Layout, comm, overwrite: bool = False) -> "EnsembleFile":
        """Create the file (refuses an existing one unless ``overwrite``)."""
        self = cls(path, layout, comm)
        # decided on rank 0, raised on every rank (never a collective open on some ranks only)
        start = None
        if comm.rank == 0:
            try:
                if os.path.exists(self.path) and not overwrite:
                    raise StorageError(f"{self.path!r} exists; pass --overwrite to replace it")
                check_space(self.path, layout)
                start = ("ok", safeio.temporary_beside(self.path))
            except StorageError as exc:
                start = ("error", str(exc))
            except OSError as exc:
                start = ("error", safeio.describe_os_error(exc, self.path))
        kind, tmp = comm.bcast(start, root=0)
        if kind == "error":
            raise StorageError(tmp)
        failure = None
        try:
            self._create(tmp)
        except Exception as exc:  # noqa: BLE001 - reported below, on every rank
            failure = safeio.os_reason(exc)
            if self.kind == "mpio":
                # the other ranks may be stuck in a collective call this rank left: no
                # further collective can be made; the caller must MPI_Abort
                self.abandon()
                if comm.rank == 0:
                    os.unlink(tmp)
                raise CollectiveFailure(failure) from None
        if comm.rank == 0 and failure is None:
            try:
                safeio.fsync_path(tmp)
                safeio.publish(tmp, self.path, overwrite)
            except FileExistsError:
                failure = "it was created by another process meanwhile"
            except OSError as exc:
                failure = safeio.os_reason(exc)
        if comm.rank == 0 and os.path.exists(tmp):
            os.unlink(tmp)
        failure = comm.bcast(failure, root=0) or failure
        if failure is not None:
            self.abandon()
            raise StorageError(failure)
        return self

    @classmethod
    def open_for_resume(cls, path, layout: Layout, comm) -> "EnsembleFile":
        """Open an existing file to complete its missing rows (layout already checked)."""
        self = cls(path, layout, comm)
        self._open()
        return self

    # -- rows --------------------------------------------------------------
    def write_row(self, r: int, row: dict[str, Any]) -> None:
        """Write realisation ``r``'s values (keys: the layout's column names)."""
        raise NotImplementedError

    def mark_done(self, r: int) -> None:
        """Set row ``r``'s ``done`` flag (after its data and checksums are written)."""
        raise NotImplementedError

    def flush(self) -> None:
        """Push written rows to the file."""
        raise NotImplementedError

    def close(self) -> None:
        """Close the file (collective over the ranks)."""
        raise NotImplementedError

    def abandon(self) -> None:
        """After a failed creation: close what can be closed, never crash.

        Parallel HDF5 1.10 segfaults when a file whose creation failed (disk
        full) is closed or garbage-collected; such a file is kept referenced
        (``ABANDONED``) until the process ends (by MPI_Abort: see CollectiveFailure)."""
        if self.file is None:
            return
        self._ds = {}
        if self.kind == "mpio":
            ABANDONED.append(self.file)
        else:
            try:
                self.file.close()
            except Exception:  # noqa: BLE001 - the failure is already being reported
                pass
        self.file = None

    # gather transport hooks (no-ops for mpio)
    def outbox(self) -> list | None:
        """Queued operations to ship to rank 0 (gather writer on ranks > 0)."""
        return None

    def apply(self, ops: list | None) -> None:
        """Rank 0: perform operations shipped by another rank."""
        if ops:
            raise StorageError(f"{self.kind} writer received rows from another rank")

    # -- helpers -------------------------------------------------------------
    def _row_arrays(self, row: dict[str, Any]) -> dict[str, np.ndarray]:
        out = {}
        names = {c.name for c in self.layout.columns}
        unknown = sorted(set(row) - names)
        if unknown:
            raise StorageError(f"row has unknown column(s) {unknown}")
        for c in self.layout.columns:
            if c.name not in row:
                raise StorageError(f"row lacks column {c.name!r}")
            v = np.asarray(row[c.name])
            if v.shape != c.shape:
                raise StorageError(f"column {c.name!r}: row shape {v.shape}, layout {c.shape}")
            out[c.name] = v.astype(c.dtype, casting="same_kind")
        return out

    def _bind(self) -> None:
        """Open every row dataset once, in the same order on every rank holding the file
        (dataset opens are collective in parallel HDF5 unless the object is not modified)."""
        rg = self.file["realisations"]
        self._ds = {c.name: rg[c.name] for c in self.layout.columns}
        self._ds["done"] = rg["done"]
        self._ds[ROW_DIGEST] = rg[ROW_DIGEST]

    def _write_local(self, r: int, row: dict[str, Any]) -> None:
        t = time.perf_counter()
        values = self._row_arrays(row)
        for name, v in values.items():
            self._ds[name][r] = v
        self._ds[ROW_DIGEST][r] = [safeio.crc32_of(values[c.name]) for c in self.layout.columns]
        self.rows_written += 1
        self.write_seconds += time.perf_counter() - t

    def _done_local(self, r: int) -> None:
        t = time.perf_counter()
        self._ds["done"][r] = 1
        self.write_seconds += time.perf_counter() - t


class MpioFile(EnsembleFile):
    """Parallel h5py: collective structure, independent row writes by every rank.

    Raw data of contiguous, early-allocated datasets goes straight to
    MPI_File_write_at (no HDF5 raw-data cache), and H5Fflush is collective in
    parallel HDF5, so ``flush`` is a no-op between rows: the bytes of a row
    are in the operating system once ``write_row``/``mark_done`` return.
    """

    kind = "mpio"

    def _create(self, tmp: str) -> None:
        import h5py

        self.file = h5py.File(tmp, "w", driver="mpio", comm=self.comm)
        create_structure(self.file, self.layout)
        if self.comm.rank == 0:
            self.file["realisations"]["seed"][:] = self.layout.seeds
        self.file.flush()  # collective: structure and seeds on disk before any row
        self._bind()

    def _open(self) -> None:
        import h5py

        self.file = h5py.File(self.path, "r+", driver="mpio", comm=self.comm)
        _check_structure(self.file, self.layout)
        self._bind()

    def write_row(self, r, row):
        """Write realisation ``r``'s row (a dict of arrays) at once, independently of the other ranks."""
        self._write_local(r, row)

    def mark_done(self, r):
        """Mark row ``r`` done (its digest checked on read): only then does a resume skip it."""
        self._done_local(r)

    def flush(self):
        """Nothing to do: a row's bytes reach the operating system when it is written."""
        pass

    def close(self):
        """Close the file on every rank (collective)."""
        if self.file is not None:
            self._ds = {}
            self.file.close()  # collective
            self.file = None


class GatherFile(EnsembleFile):
    """Rank 0 writes with serial h5py and flushes after every row; others queue."""

    kind = "gather"

    def __init__(self, path, layout, comm):
        super().__init__(path, layout, comm)
        self._queue: list = []

    @classmethod
    def build(cls, path, layout: Layout) -> "GatherFile":
        """One process: the file's structure and seeds at ``path`` itself, open for rows.

        For a caller that publishes ``path`` (a temporary file of its own,
        ``safeio.temporary_beside``) only once it is complete (``sliders.merge``)."""
        self = cls(path, layout, _OneProcess())
        self._create(self.path)
        return self

    def _create(self, tmp: str) -> None:
        if self.comm.rank == 0:
            import h5py

            self.file = h5py.File(tmp, "w")
            create_structure(self.file, self.layout)
            self.file["realisations"]["seed"][:] = self.layout.seeds
            self.file.flush()
            self._bind()

    def _open(self) -> None:
        if self.comm.rank == 0:
            import h5py

            self.file = h5py.File(self.path, "r+")
            _check_structure(self.file, self.layout)
            self._bind()

    def write_row(self, r, row):
        """Write realisation ``r``'s row on rank 0; other ranks queue it for ``outbox``."""
        if self.comm.rank == 0:
            self._write_local(r, row)
        else:
            self._queue.append(("row", int(r), self._row_arrays(row)))

    def mark_done(self, r):
        """Mark row ``r`` done on rank 0; other ranks queue the mark for ``outbox``."""
        if self.comm.rank == 0:
            self._done_local(r)
        else:
            self._queue.append(("done", int(r), None))

    def flush(self):
        """Flush rank 0's file to the operating system (the time is added to ``write_seconds``)."""
        if self.comm.rank == 0 and self.file is not None:
            t = time.perf_counter()
            self.file.flush()
            self.write_seconds += time.perf_counter() - t

    def outbox(self):
        """The rows and done marks this rank queued since the last call (sent to rank 0)."""
        ops, self._queue = self._queue, []
        return ops

    def apply(self, ops):
        """On rank 0: write the rows and marks another rank's ``outbox`` gave, then flush."""
        for op, r, values in ops or ():
            if op == "row":
                self._write_local(r, values)
            else:
                self._done_local(r)
        if ops:
            self.flush()

    def close(self):
        """Close rank 0's file."""
        if self.file is not None:
            self._ds = {}
            self.file.close()
            self.file = None


class _OneProcess:
    """The communicator of a writer that is alone (rank 0 of 1)."""

    rank = 0
    size = 1


HANDLERS = {"mpio": MpioFile, "gather": GatherFile}
ABANDONED: list = []  # parallel files whose creation failed (see EnsembleFile.abandon)
SPACE_MARGIN = 1 << 18  # bytes of HDF5 metadata and slack beyond the datasets (~50 kB measured)


def row_bytes(columns) -> int:
    """Bytes of one row of these columns, with its seed, done flag and row checksums."""
    row = sum(int(np.prod(c.shape, dtype=np.int64)) * c.dtype.itemsize for c in columns)
    return row + 4 + 1 + 4 * len(columns)


def statistics_row_bytes(statistics: dict[str, tuple[tuple[int, ...], np.dtype]]) -> int:
    """``row_bytes`` of an ensemble row with these statistics (no layout, no seeds needed)."""
    return row_bytes(make_layout(0, [], {}, statistics, {}).columns)


def file_size_estimate(layout: Layout) -> int:
    """Bytes of an ensemble file: every dataset is allocated when the file is created."""
    grids = sum(np.asarray(g).nbytes for g in layout.grids.values())
    return layout.n_realisations * row_bytes(layout.columns) + grids + SPACE_MARGIN


def check_room(path: str, n_rows: int, bytes_per_row: int) -> None:
    """Refuse at once (StorageError) ``n_rows`` rows that the file system of ``path`` cannot
    hold: checked before any per-row array (seeds, done mask) is made, so that an absurd
    count (``-R 99999999999999999999``) is refused in a blink instead of filling the memory."""
    need = int(n_rows) * int(bytes_per_row) + SPACE_MARGIN
    try:
        size, _, free = safeio.disk_usage(path)
    except OSError as exc:
        folder = os.path.dirname(safeio.resolve_target(path).real)
        raise StorageError(safeio.describe_os_error(exc, folder)) from None
    if need > free:
        whole = " (more than the whole file system holds)" if need > size else ""
        raise StorageError(f"{n_rows} rows of {bytes_per_row} bytes need about {need / 1e6:.3g} "
                           f"MB{whole}, and the file system of {path!r} has {free / 1e6:.3g} MB "
                           "free (No space left on device)")


def check_space(path: str, layout: Layout) -> None:
    """Refuse up front a file that does not fit on its file system (not half-way)."""
    need = file_size_estimate(layout)
    free = safeio.disk_usage(path).free
    if need > free:
        raise StorageError(f"it needs about {need / 1e6:.3g} MB and its file system has "
                           f"{free / 1e6:.3g} MB free (No space left on device)")


# ---------------------------------------------------------------------------
# reading (serial, any process)
# ---------------------------------------------------------------------------
def read_header(path) -> dict[str, Any]:
    """Attributes, grids, done mask and column shapes of an ensemble file (checksums verified)."""
    import h5py

    p = os.fspath(path)
    where = repr(p)
    f = open_for_reading(p)
    try:
        with f:
            safeio.check_header(f, FORMAT, where, StorageError, versions=KNOWN_VERSIONS)
            attrs = plain_attributes(f)
            grids = {k: safeio.read_checked(ds, where) for k, ds in f["grids"].items()}
            rg = f["realisations"]
            columns = {}
            rg.visititems(lambda name, obj: columns.__setitem__(name, (obj.shape[1:], obj.dtype))
                          if isinstance(obj, h5py.Dataset) else None)
            done = done_mask(rg["done"][()], where)
            seeds = safeio.read_checked(rg["seed"], where)
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file: one line
        raise damaged(p, exc) from None
    return {"attrs": attrs, "grids": grids, "columns": columns, "done": done, "seeds": seeds}


def read_rows(path) -> dict[str, np.ndarray]:
    """Every /realisations dataset as an array of R rows (``statistics/<key>`` names).

    The rows marked done are verified against ``row_crc32``: a damaged row
    raises StorageError naming the realisation and the file.
    """
    import h5py

    p = os.fspath(path)
    out: dict[str, np.ndarray] = {}
    f = open_checked(p, FORMAT, KNOWN_VERSIONS)
    try:
        with f:
            rg = f["realisations"]
            rg.visititems(lambda name, obj: out.__setitem__(name, obj[()])
                          if isinstance(obj, h5py.Dataset) else None)
            order = json.loads(rg[ROW_DIGEST].attrs["columns"])
        damage = row_damage(out, order, done_mask(out["done"], repr(p)))
        if damage:
            r, name = damage[0]
            raise StorageError(f"{p!r}: row {r} of dataset /realisations/{name} fails its "
                               "checksum (the file is damaged; --resume recomputes such rows)")
    except Exception as exc:  # noqa: BLE001
        raise damaged(p, exc) from None
    return out


def damaged_rows(path) -> list[int]:
    """The rows marked done whose values fail their checksums (``--resume`` recomputes them)."""
    p = os.fspath(path)
    f = open_checked(p, FORMAT, KNOWN_VERSIONS)
    try:
        with f:
            rg = f["realisations"]
            order = json.loads(rg[ROW_DIGEST].attrs["columns"])
            out = {name: rg[name][()] for name in order + ["done", ROW_DIGEST]}
        return sorted({r for r, _ in row_damage(out, order, done_mask(out["done"], repr(p)))})
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file: one line
        raise damaged(p, exc) from None


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------
def read_realisations(path) -> dict[str, Any]:
    """Every row of an ensemble file (R rows, done or not).

    Keys: ``seed``, ``done`` (bool), ``status`` (codes), ``status_name``,
    ``alpha_c``, ``n_events``, ``slider_steps``, ``wall_time`` and
    ``statistics`` ({key: (R, ...) array}).
    """
    rows = read_rows(path)
    out: dict[str, Any] = {k: v for k, v in rows.items() if not k.startswith(STATISTICS)}
    out["done"] = out["done"].astype(bool)
    out["status_name"] = np.array([status.NAMES.get(int(c), "not_run" if c < 0 else "unknown")
                                   for c in out["status"]])
    out["statistics"] = {k[len(STATISTICS):]: v for k, v in rows.items() if k.startswith(STATISTICS)}
    return out


class EnsembleInputError(ValueError):
    """A path given as an ensemble file that cannot be used as one (one-line message)."""


def check_ensemble_file(path) -> None:
    """Raise ``EnsembleInputError`` unless ``path`` is an HDF5 ensemble file.

    Tells apart a missing file, a file that is not HDF5, a single-run file
    (``Result.save``: read it with ``Result.load``) and an HDF5 file
    of another kind.
    """
    p = os.fspath(path)
    probe = formats.probe_file(p)
    if probe.state == "missing":
        raise EnsembleInputError(f"ensemble file {p!r} does not exist")
    if probe.state == "directory":
        raise EnsembleInputError(f"ensemble file {p!r} is a directory")
    if probe.state == "unreadable":
        raise EnsembleInputError(f"ensemble file {p!r} cannot be read ({probe.reason})")
    if probe.state == "not_hdf5":
        raise EnsembleInputError(f"{p!r} is not an HDF5 file; --ensemble needs the file written by "
                                 "python -m sliders.ensemble")
    if probe.state == "bad_hdf5":
        raise EnsembleInputError(f"{p!r} is not a readable HDF5 file ({probe.reason})")
    if probe.format == formats.TILT:
        raise EnsembleInputError(f"{p!r} holds a single run, not an ensemble: read it with "
                                 f"sliders.Result.load({p!r}); --ensemble needs the file "
                                 "written by python -m sliders.ensemble")
    if not probe.ensemble_rows:
        raise EnsembleInputError(f"{p!r} is an HDF5 file but not a sliders ensemble file "
                                 f"(format attribute {probe.format!r}, no /realisations/statistics)")


def read_done_statistics(path):
    """The per-realisation statistics of the rows marked done, with what averages them needs.

    Parameters
    ----------
    path : str or os.PathLike
        An ensemble file (``python -m sliders.ensemble``, ``python -m sliders.merge``).

    Returns
    -------
    statistics : dict of str to numpy.ndarray
        ``/realisations/statistics/<key>`` over the done rows, shape ``(n_done, *shape)``.
    grids : dict of str to numpy.ndarray
        The angles (radians) and bin edges the rows were computed on
        (``StatisticsGrids.from_arrays`` rebuilds them).
    scene : Scene
        The ensemble's scene (realisation r has seed ``realisation_seed(scene.seed, r)``).
    info : dict
        The file attributes plus ``n_done``, ``n_realisations``, ``done``
        (mask), ``statuses`` ({name: count} over done rows) and ``wall_time``
        (sum over done rows, seconds of computing).

    ``sliders.analysis.summary.load_summary`` averages them.
    """
    head = read_header(path)
    rows = read_realisations(path)
    if not rows["statistics"]:
        raise ValueError(f"{os.fspath(path)!r} holds only the per-realisation summary (scene "
                         "record='summary'): no statistics; read_realisations gives alpha_c, "
                         "n_events and status per realisation")
    scene = Scene.from_stored(json.loads(head["attrs"]["scene"]))
    done = rows["done"]
    stats = {k: v[done] for k, v in rows["statistics"].items()}
    info = dict(head["attrs"])
    info.update({
        "n_done": int(done.sum()), "n_realisations": int(done.size), "done": done,
        "statuses": dict(Counter(str(s) for s in rows["status_name"][done])),
        "wall_time": float(np.sum(rows["wall_time"][done])),
    })
    return stats, head["grids"], scene, info
