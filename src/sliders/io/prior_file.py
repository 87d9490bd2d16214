"""The prior-ensemble file (``python -m sliders.prior``): layout, writer, readers.

One file holds R rows, each a realisation whose material parameters were
drawn from a prior, with its whole event catalogue; every quantity is stored
once, with the named dimensions and coordinates xarray needs::

    /                       attrs: format = "sliders.prior", format_version = 2, prior (JSON of
                            the TOML), prior_digest, base_seed, realisations, backend,
                            parameters (JSON list of names), parameter_choices, ceiling_k,
                            software_version, created; provenance (title, history, ...)
    /row                    (R,) coordinate: the row number
    /ceiling_alpha          (G,) coordinate: the angles at which the ceiling was taken, rad
    /nearest, /event, /checksummed_column    dimensions without values (no storage)
    /realisations/          dims (row, ...): the ensemble layout (``storage``): seed, done,
                            status, alpha_c, n_events, slider_steps, wall_time, row_crc32, and
      <parameter>           each drawn or derived parameter (a coordinate of ``row``; strings:
                            index into the root attribute "parameter_choices")
      ceiling_distance      (row, ceiling_alpha, nearest) the K smallest distances
                            mu_s,n cos(alpha) - |F_n| (m g)
      event_start           where the row's events start in /events/*
      event_crc32           CRC-32 of the row's events (all five columns)
    /events/<column>        (event,) the catalogue columns (``catalogue.EVENT_COLUMNS``),
                            ``alpha`` a coordinate of ``event``

Writer: ``PriorFile``, the ensemble's ``GatherFile`` (rank 0 writes every
row; the other ranks ship theirs with their "done" message), which also
appends the row's events before the row (its ``event_start`` and
``event_crc32`` are then part of the row's checksummed values) and before
``done[r] = 1``.  While a run goes on, the events follow the order in which
the rows finished; a process killed between two rows leaves events past the
last row that no row points to: ignored by the readers, and a resume appends
after them.  The events are ragged, so they cannot go through parallel
HDF5's fixed, preallocated rows: the prior file is always written by rank 0
(``--storage gather``).

At the end of every run (``write_view``, rank 0, writers closed) the file is
put in row order: the done rows' events one row after the other, nothing
else.  The ordered file is written beside the old one and renamed over it
(atomic: a kill leaves the old file, which the next run orders), so the same
prior and seed give the same datasets whatever the number of ranks or
interruptions.  Format version 1 (a flat copy of everything at the root)
still reads; it is not resumed.
"""

from __future__ import annotations

import datetime
import json
import os
from dataclasses import replace
from typing import Any

import numpy as np

from .. import status
from ..parts.materials import MU_S_GAP
from . import formats, h5tools, safeio
from .catalogue import EVENT_COLUMNS, Catalogue, CatalogueSet
from .conventions import ENSEMBLE_ROW_VARIABLES, add_provenance
from .h5tools import (ROW_DIGEST, StorageError, open_checked, done_mask, open_for_reading, plain_attributes,
                      row_damage)
from .storage import BASE_COLUMNS, Column, GatherFile, Layout, create_structure
from .._version import __version__

FORMAT = formats.PRIOR
FORMAT_VERSION = 2
KNOWN_VERSIONS = (1, 2)  # 1: every quantity twice (groups and a root view); read, not resumed
PARAMETERS = ""  # prefix of the parameters' column names: they sit beside the other columns
PARAMETERS_V1 = "parameters/"
EVENTS = "events"
EVENT_CHUNK = 16384
FILE_EVENT_DTYPES = {"alpha": np.float64, "size": np.int32, "displacement": np.float64,
                     "first": np.int32, "last": np.int32}
EVENT_UNITS = {"alpha": ("rad", "tilt of the rearrangement"),
               "size": ("1", "distinct sliders that moved"),
               "displacement": ("g tau^2", "sum of the sliders' displacements"),
               "first": ("1", "first (up-slope) slider that moved, 0-based"),
               "last": ("1", "last (down-slope) slider that moved, 0-based")}
PARAMETER_UNITS = {"mu_d": ("1", "dynamic friction coefficient"),
                   "mu_s_mean": ("1", "mean static friction coefficient"),
                   MU_S_GAP: ("1", "mu_s_mean - mu_d"),
                   "sigma_mu": ("1", "width of the static coefficients"),
                   "xi": ("1", "stiffness of the cantilever springs (units of k)"),
                   "n_sliders": ("1", "number of sliders N"),
                   "spring_length": ("g tau^2", "rest length of the springs"),
                   "initial_forces": ("1", "preparation (index into the root attribute "
                                           "parameter_choices)")}
ROW_UNITS = {**ENSEMBLE_ROW_VARIABLES,
             "ceiling_distance": ("m g", "K smallest distances mu_s,n cos(alpha) - |F_n| of a "
                                         "slider to its threshold"),
             "event_start": ("1", "index of the row's first event in /events"),
             "event_crc32": ("1", "CRC-32 of the row's events (all five columns)"),
             ROW_DIGEST: ("1", "CRC-32 of the row in each column (column names: attribute "
                               "'columns')")}


def prior_layout(n_rows: int, seeds, parameters: dict[str, np.dtype], ceiling_alpha,
                 ceiling_k: int, attrs: dict[str, Any]) -> Layout:
    """The file's layout: the ensemble's base columns, the parameters, the ceiling, the events' place.

    Parameters
    ----------
    n_rows : int
        R, the number of rows.
    seeds : array_like
        (R,) the rows' scene seeds.
    parameters : dict of str to numpy.dtype
        Each per-row parameter and its stored type (strings: an integer
        index into the choices, recorded by the runner in the attributes).
    ceiling_alpha : array_like
        (G,) the ceiling's angles, rad.
    ceiling_k : int
        K, the smallest distances kept at each angle.
    attrs : dict
        The root attributes (``prior_attributes``).
    """
    grid = np.asarray(ceiling_alpha, dtype=np.float64)
    cols = list(BASE_COLUMNS)
    cols += [Column(PARAMETERS + name, (), np.dtype(dt), np.nan if np.dtype(dt).kind == "f" else -1)
             for name, dt in sorted(parameters.items())]
    cols += [Column("ceiling_distance", (grid.size, int(ceiling_k)), np.dtype(np.float64), np.nan),
             Column("event_start", (), np.dtype(np.int64), -1),
             Column("event_crc32", (), np.dtype(np.uint32), 0)]
    return Layout(int(n_rows), cols, np.asarray(seeds, dtype=np.uint32),
                  {"ceiling_alpha": grid}, dict(attrs))


def prior_attributes(spec: dict, digest: str, base_seed: int, n_rows: int, backend: str,
                     parameter_names, ceiling_k: int) -> dict[str, Any]:
    """The root attributes of a new prior file (the prior as JSON, its digest, seed, versions)."""
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "prior": json.dumps(spec, sort_keys=True), "prior_digest": digest,
        "base_seed": int(base_seed), "realisations": int(n_rows), "backend": backend,
        "parameters": json.dumps(list(parameter_names)), "ceiling_k": int(ceiling_k),
        "software_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def _events_crc(events: dict[str, np.ndarray]) -> int:
    return safeio.crc32_of(np.concatenate([np.ascontiguousarray(events[c]).view(np.uint8)
                                           for c in EVENT_COLUMNS]))


def catalogue_events(catalogue: Catalogue) -> dict[str, np.ndarray]:
    """A catalogue's columns in the file's types (what a row carries to the writer)."""
    return file_events({c: getattr(catalogue, c) for c in EVENT_COLUMNS})


def create_prior_structure(f, layout: Layout, n_events: int = 0) -> None:
    """A new prior file's structure in the open (serial) file ``f``: the layout's rows,
    the coordinates and dimensions at the root, ``n_events`` events (not written), and
    every dataset's dimension scales, units and long name."""
    grid = np.asarray(layout.grids["ceiling_alpha"], dtype=np.float64)
    create_structure(f, replace(layout, grids={}))
    rg = f["realisations"]
    rg["seed"][:] = layout.seeds
    del rg["statistics"]  # a prior row has no binned statistics
    names = json.loads(rg[ROW_DIGEST].attrs["columns"])
    row = h5tools.coordinate(f, "row", np.arange(layout.n_realisations), "1",
                             "row of the prior ensemble")
    ceiling_alpha = h5tools.coordinate(f, "ceiling_alpha", grid, "rad",
                                       "angle at which the ceiling was taken")
    nearest = h5tools.dimension(f, "nearest", layout.column("ceiling_distance").shape[1])
    checksummed = h5tools.dimension(f, "checksummed_column", len(names))
    event = h5tools.dimension(f, "event", n_events, growing=True)
    parameters = sorted(n for n in names if n not in ROW_UNITS)
    for name in ["seed", "done", ROW_DIGEST] + names:
        ds = rg[name]
        h5tools.attach(ds, row, *{"ceiling_distance": (ceiling_alpha, nearest),
                                  ROW_DIGEST: (checksummed,)}.get(name, ()))
        if name in ROW_UNITS:
            h5tools.describe(ds, *ROW_UNITS[name], coordinates=" ".join(parameters))
        else:
            h5tools.describe(ds, *PARAMETER_UNITS.get(name, ("1", f"drawn parameter {name}")))
    g = f.create_group(EVENTS)
    for c in EVENT_COLUMNS:
        ds = g.create_dataset(c, shape=(n_events,), maxshape=(None,), chunks=(EVENT_CHUNK,),
                              dtype=FILE_EVENT_DTYPES[c], compression="gzip", shuffle=True)
        h5tools.attach(ds, event)
        h5tools.describe(ds, *EVENT_UNITS[c], coordinates=None if c == "alpha" else "alpha")


class PriorFile(GatherFile):
    """The ensemble's gather writer, plus the row's ragged events appended before the row.

    A row is the layout's columns (``event_start`` and ``event_crc32`` are
    filled here) plus ``"events"``: the catalogue columns
    (``catalogue_events``).
    """

    kind = "gather"

    def _create(self, tmp: str) -> None:
        if self.comm.rank == 0:
            import h5py

            self.file = h5py.File(tmp, "w")
            create_prior_structure(self.file, self.layout)
            self.file.flush()
            self._bind()

    def _open(self) -> None:
        if self.comm.rank == 0:
            import h5py

            version = None
            with h5py.File(self.path, "r") as f:
                version = f.attrs.get("format_version")
            if version != FORMAT_VERSION:
                raise StorageError(f"it has format_version {version} and --resume completes "
                                   f"format_version {FORMAT_VERSION} files only; start a new file "
                                   "(this one still reads)")
            super()._open()

    def write_row(self, r, row):
        """Rank 0: append the row's events, then write the row; other ranks queue both."""
        if self.comm.rank == 0:
            self._append(int(r), row)
        else:
            self._queue.append(("prior_row", int(r), row))

    def apply(self, ops):
        """Rank 0: write the rows and done marks another rank shipped, then flush."""
        for op, r, values in ops or ():
            if op == "prior_row":
                self._append(r, values)
            elif op == "done":
                self._done_local(r)
            else:  # pragma: no cover - protocol bug
                raise StorageError(f"prior writer received an unknown operation {op!r}")
        if ops:
            self.flush()

    def _append(self, r: int, row: dict[str, Any]) -> None:
        row = dict(row)
        events = file_events(row.pop("events"))
        start = append_events(self.file, events)
        row["event_start"] = np.int64(start)
        row["event_crc32"] = np.uint32(_events_crc(events))
        self._write_local(r, row)


def file_events(given: dict) -> dict[str, np.ndarray]:
    """Event columns in the file's types."""
    return {c: np.asarray(given[c], dtype=FILE_EVENT_DTYPES[c]) for c in EVENT_COLUMNS}


def append_events(f, events: dict[str, np.ndarray]) -> int:
    """Append events (``file_events``) to /events of the open file ``f``; where they start."""
    g = f[EVENTS]
    start = g["alpha"].shape[0]
    k = events["alpha"].size
    for c in EVENT_COLUMNS:
        g[c].resize((start + k,))
        if k:
            g[c][start:start + k] = events[c]
    f["event"].resize((start + k,))
    return start


HANDLERS = {"gather": PriorFile}


# ---------------------------------------------------------------------------
# readers
# ---------------------------------------------------------------------------
def _read(path, with_events: bool = True) -> dict[str, Any]:
    """Attributes, grid, rows (checked) and the events of every done row (checked)."""
    import h5py

    p = os.fspath(path)
    where = repr(p)
    f = open_checked(p, FORMAT, KNOWN_VERSIONS, where)
    try:
        with f:
            attrs = plain_attributes(f)
            grid = safeio.read_checked(f["ceiling_alpha"] if int(attrs["format_version"]) > 1
                                       else f["grids"]["ceiling_alpha"], where)
            rg = f["realisations"]
            rows: dict[str, np.ndarray] = {}
            rg.visititems(lambda name, obj: rows.__setitem__(name, obj[()])
                          if isinstance(obj, h5py.Dataset) else None)
            order = json.loads(rg[ROW_DIGEST].attrs["columns"])
            done = done_mask(rows["done"], where)
            damaged = {r for r, _ in row_damage(rows, order, done)}
            events = {c: f[EVENTS][c][()] for c in EVENT_COLUMNS} if with_events else None
    except StorageError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file: one line
        raise h5tools.damaged(p, exc) from None
    choices = json.loads(attrs.get("parameter_choices", "{}"))
    if events is not None:
        total = events["alpha"].size
        for r in np.flatnonzero(done):
            a, k = int(rows["event_start"][r]), int(rows["n_events"][r])
            if r in damaged or a < 0 or a + k > total:
                damaged.add(int(r))
                continue
            if _events_crc({c: events[c][a:a + k] for c in EVENT_COLUMNS}) != int(rows["event_crc32"][r]):
                damaged.add(int(r))
    done[sorted(damaged)] = False
    return {"attrs": attrs, "grid": grid, "rows": rows, "done": done, "damaged": sorted(damaged),
            "events": events, "choices": choices, "order": order}


#: the set's attribute of ``read_prior_ensemble`` holding each row's fingerprint
FINGERPRINTS = "row_fingerprints"


def _fingerprints(d: dict, rows) -> np.ndarray:
    """(n, 4) what identifies each of ``rows`` as a pile, from what the file records (no
    event is hashed again): its scene seed, its number of events, the CRC-32 of its events and
    its avalanche angle's bits.  Two rows of one fingerprint are one pile, simulated twice or
    copied; piles of independent draws differ in their seeds and their events."""
    r = d["rows"]
    alpha_c = np.ascontiguousarray(r["alpha_c"][rows], dtype=np.float64)
    return np.column_stack([r["seed"][rows].astype(np.uint64), r["n_events"][rows].astype(np.uint64),
                            r["event_crc32"][rows].astype(np.uint64), alpha_c.view(np.uint64)])


def read_prior_header(path) -> dict[str, Any]:
    """Root attributes, the done mask (rows and their events verified) and the damaged rows."""
    d = _read(path)
    return {"attrs": d["attrs"], "done": d["done"], "damaged": d["damaged"], "grid": d["grid"]}


def _parameters(d: dict) -> dict[str, np.ndarray]:
    prefix = PARAMETERS_V1 if int(d["attrs"]["format_version"]) == 1 else PARAMETERS
    out = {}
    for key in json.loads(d["attrs"]["parameters"]):
        v = d["rows"][prefix + key]
        if key in d["choices"]:
            names = np.array([str(x) for x in d["choices"][key]] + [""])
            v = names[np.where(v >= 0, v, -1)]
        out[key] = v
    out["seed"] = d["rows"]["seed"].astype(np.int64)
    return out


def _row_events(d: dict, r: int) -> dict[str, np.ndarray]:
    a, k = int(d["rows"]["event_start"][r]), int(d["rows"]["n_events"][r])
    return {c: d["events"][c][a:a + k] for c in EVENT_COLUMNS}


def _row_catalogue(d: dict, r: int) -> Catalogue:
    return Catalogue(**_row_events(d, r))


def read_prior_row(path, r: int) -> Catalogue:
    """Row ``r``'s catalogue (a small table: ``alpha``, ``size``, ``displacement``, ``first``, ``last``).

    Raises StorageError (one line) if the row is not done or fails its checksums.
    """
    d = _read(path)
    R = d["done"].size
    if not 0 <= r < R:
        raise StorageError(f"{os.fspath(path)!r} has rows 0 to {R - 1}, not {r}")
    if not d["done"][r]:
        why = "fails its checksums" if r in d["damaged"] else "is not done"
        raise StorageError(f"row {r} of {os.fspath(path)!r} {why}")
    return _row_catalogue(d, r)


def read_prior_ensemble(path, unfinished: bool = False) -> CatalogueSet:
    """The prior file as a ``CatalogueSet``: the done rows in row order (all rows if ``unfinished``).

    Parameters
    ----------
    path : str or os.PathLike
        A file of ``python -m sliders.prior`` (format version 1 or 2).
    unfinished : bool
        Also return the rows not done (status "not_run", no events, NaN
        ceiling); ``attrs["done"]`` then says which rows are complete.

    Returns
    -------
    CatalogueSet
        Events, parameters (plus the row's ``seed``), ``alpha_c``, status,
        ``ceiling_alpha`` (G,), ``ceiling_distance`` (R, G, K); ``attrs``:
        the file's root attributes plus ``rows`` (the rows' indices in the
        file), ``done`` and ``row_fingerprints`` (``FINGERPRINTS``: what
        identifies each row's pile, to find the same piles in two files).
    """
    d = _read(path)
    done = d["done"]
    rows = np.arange(done.size) if unfinished else np.flatnonzero(done)
    empty = Catalogue(*(np.zeros(0) for _ in EVENT_COLUMNS))
    catalogues = [_row_catalogue(d, r) if done[r] else empty for r in rows]
    params = {k: v[rows] for k, v in _parameters(d).items()}
    codes = d["rows"]["status"][rows]
    names = np.array([status.NAMES.get(int(c), "not_run" if c < 0 else "unknown") if done[r]
                      else "not_run" for r, c in zip(rows, codes)])
    ceiling = d["rows"]["ceiling_distance"][rows].copy()
    ceiling[~done[rows]] = np.nan
    alpha_c = np.where(done[rows], d["rows"]["alpha_c"][rows], np.nan)
    attrs = dict(d["attrs"])
    attrs.update({"rows": rows, "done": done[rows], FINGERPRINTS: _fingerprints(d, rows)})
    return CatalogueSet.from_catalogues(catalogues, params, alpha_c, names, d["grid"], ceiling,
                                        attrs)


# ---------------------------------------------------------------------------
# the events in row order, at the end of every run
# ---------------------------------------------------------------------------
def _in_row_order(d: dict) -> bool:
    """True if /events holds the done rows' events one row after the other and nothing else."""
    done = np.flatnonzero(d["done"])
    counts = d["rows"]["n_events"][done]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if done.size else counts
    return (np.array_equal(d["rows"]["event_start"][done], starts)
            and d["events"]["alpha"].size == int(counts.sum()))


def _layout_of(path, d: dict) -> tuple[Layout, dict]:
    """The layout a file was made with (its columns, seeds, grid and sealed attributes),
    and the root attributes added after the seal (provenance)."""
    with open_for_reading(path) as f:
        rg = f["realisations"]
        columns = [Column(n, rg[n].shape[1:], rg[n].dtype, rg[n].fillvalue) for n in d["order"]]
        sealed = json.loads(f.attrs[safeio.ATTRS_DIGEST])["names"]
        attrs = {k: f.attrs[k] for k in sealed}
        later = {k: f.attrs[k] for k in f.attrs if k not in sealed and k != safeio.ATTRS_DIGEST}
    return Layout(d["done"].size, columns, d["rows"]["seed"], {"ceiling_alpha": d["grid"]},
                  attrs), later


def _write_in_row_order(f, layout: Layout, later_attrs: dict, d: dict) -> None:
    """Fill a new file's structure with ``d``'s rows, the done rows' events in row order."""
    done = d["done"]
    create_prior_structure(f, layout, 0)
    for k, v in later_attrs.items():
        f.attrs[k] = v
    rg = f["realisations"]
    rows = dict(d["rows"])
    rows["event_start"] = np.full(done.size, -1, dtype=np.int64)
    digest = rows[ROW_DIGEST].copy()
    j = d["order"].index("event_start")
    for r in np.flatnonzero(done):
        rows["event_start"][r] = append_events(f, _row_events(d, r))
        digest[r, j] = safeio.crc32_of(np.int64(rows["event_start"][r]))
    rows[ROW_DIGEST] = digest
    rows["done"] = done.astype(np.uint8)
    for name in d["order"] + ["done", ROW_DIGEST]:
        rg[name][...] = rows[name]


def write_view(path, scene: dict | None = None) -> None:
    """Rank 0, writers closed: put the file in row order (the done rows' events one row
    after the other, damaged rows marked not done) and add this run to its provenance.

    The ordered file is built beside ``path`` and renamed over it (atomic);
    a file already in row order only gains the history line.
    ``xr.open_datatree(path, engine="h5netcdf")`` shows it.
    """
    import h5py

    p = os.fspath(path)
    d = _read(p)
    title = f"sliders prior ensemble: {d['done'].size} rows"
    if _in_row_order(d) and not d["damaged"]:
        with h5py.File(p, "r+") as f:
            add_provenance(f, title, scene)
        return
    layout, later_attrs = _layout_of(p, d)
    tmp = safeio.temporary_beside(p)
    try:
        with h5py.File(tmp, "w") as f:
            _write_in_row_order(f, layout, later_attrs, d)
            add_provenance(f, title, scene)
        safeio.fsync_path(tmp)
        safeio.publish(tmp, p, overwrite=True)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def prior_seed(attrs: dict) -> int | None:
    """The seed a prior file's rows were drawn with (its attributes), None if it names none."""
    seed = json.loads(str(attrs.get("prior", "{}"))).get("prior", {}).get("seed")
    return None if seed is None else int(seed)


def same_draw(reference: dict, other: dict) -> bool:
    """Whether two prior files (their attributes) are one draw: the same prior (parameters
    and scene) and the same seed, so that their rows are the same piles (a copy, or the same
    prior run again)."""
    a, b = (json.loads(str(c.get("prior", "{}"))) for c in (reference, other))
    seed = prior_seed(reference)
    return (seed is not None and seed == prior_seed(other)
            and all(a.get(k) == b.get(k) for k in ("parameters", "scene")))


def shared_piles(reference: dict, other: dict) -> int:
    """How many of the done rows of the set of attributes ``other`` are piles of
    ``reference``'s (their fingerprints, ``FINGERPRINTS``, recorded by ``read_prior_ensemble``:
    seed, events' CRC-32, events, avalanche angle); 0 where either records none."""
    a, b = reference.get(FINGERPRINTS), other.get(FINGERPRINTS)
    if a is None or b is None or not len(a) or not len(b):
        return 0
    a, b = (np.ascontiguousarray(x, dtype=np.uint64) for x in (a, b))
    if "done" in reference:
        a = a[np.asarray(reference["done"], dtype=bool)]
    if "done" in other:
        b = b[np.asarray(other["done"], dtype=bool)]
    kind = np.dtype((np.void, 8 * a.shape[1]))
    return int(np.isin(b.view(kind).ravel(), a.view(kind).ravel()).sum())


def another_draw(reference: dict, other: dict, taken=()) -> str | None:
    """Why a prior file (attributes ``other``) is not a draw of the prior of ``reference``
    (the same parameters and scene) with a seed of its own (not ``reference``'s, nor one of
    ``taken``); None if it is.  Its rows are then new piles of the same law: independent of
    the reference's, as a calibration or a simulation-based calibration needs."""
    a, b = (json.loads(str(c.get("prior", "{}"))) for c in (reference, other))
    if any(a.get(k) != b.get(k) for k in ("parameters", "scene")):
        return "not the same prior (its parameters or scene differ)"
    seed = prior_seed(other)
    if seed is None:
        return "its prior names no seed"
    if seed == prior_seed(reference) or seed in set(taken):
        return f"drawn with seed {seed}, which is already used"
    return None
