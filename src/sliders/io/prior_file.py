"""The prior-ensemble file (``python -m sliders.prior``): layout, writer, readers, xarray view.

One file holds R rows, each a realisation whose material parameters were
drawn from a prior, with its whole event catalogue::

    /                       attrs: format = "sliders.prior", prior (JSON of the TOML), prior_digest,
                            base_seed, realisations, backend, parameters (JSON list of names),
                            ceiling_k, software_version, created; provenance (title, history, ...)
    /grids/ceiling_alpha    (G,) the angles at which the ceiling was taken, rad
    /realisations/          the ensemble layout (``storage``): seed, done, status, alpha_c,
                            n_events, slider_steps, wall_time, row_crc32, and
      parameters/<name>     (R,) each drawn or derived parameter (strings: index into
                            attr "choices")
      ceiling_distance      (R, G, K) the K smallest distances mu_s,n cos(alpha) - |F_n| (m g)
      event_start           (R,) where the row's events start in /events/*
      event_crc32           (R,) CRC-32 of the row's events (all five columns)
    /events/<column>        (E,) the catalogue columns (``catalogue.EVENT_COLUMNS``), rows
                            appended in the order they finished (resizable, chunked)
    /row, /event, ...       the xarray view (below), rewritten by rank 0 at the end of every run

Writer: ``PriorFile``, the ensemble's ``GatherFile`` (rank 0 writes every
row; the other ranks ship theirs with their "done" message), which also
appends the row's events before the row (its ``event_start`` and
``event_crc32`` are then part of the row's checksummed values) and before
``done[r] = 1``.  A process killed between two rows leaves events past the
last row that no row points to: ignored by the readers, and a resume appends
after them.  The events are ragged, so they cannot go through parallel HDF5's
fixed, preallocated rows: the prior file is always written by rank 0
(``--storage gather``).

The view: the finished rows in row order, so that the same prior and seed give
the same view whatever the number of ranks or interruptions.  Dimensions
``row`` (every row of the file), ``event`` (the done rows' events, in row
order), ``ceiling_alpha`` and ``nearest`` (the K smallest distances); the
parameters are coordinates of ``row``; units and long names on every variable.
"""

from __future__ import annotations

import datetime
import json
import os
from typing import Any

import numpy as np

from .. import status
from . import formats, safeio
from .catalogue import EVENT_COLUMNS, Catalogue, CatalogueSet
from .storage import (BASE_COLUMNS, ROW_DIGEST, Column, GatherFile, Layout, StorageError,
                      _done_mask, _open_for_reading, _plain, _row_damage)

FORMAT = formats.PRIOR
FORMAT_VERSION = 1
PARAMETERS = "parameters/"
EVENTS = "events"
FILE_EVENT_DTYPES = {"alpha": np.float64, "size": np.int32, "displacement": np.float64,
                     "first": np.int32, "last": np.int32}
EVENT_UNITS = {"alpha": ("rad", "tilt of the rearrangement"),
               "size": ("1", "distinct sliders that moved"),
               "displacement": ("g tau^2", "sum of the sliders' displacements"),
               "first": ("1", "first (up-slope) slider that moved, 0-based"),
               "last": ("1", "last (down-slope) slider that moved, 0-based")}
PARAMETER_UNITS = {"mu_d": ("1", "dynamic friction coefficient"),
                   "mu_s_mean": ("1", "mean static friction coefficient"),
                   "mu_s_minus_mu_d": ("1", "mu_s_mean - mu_d"),
                   "sigma_mu": ("1", "width of the static coefficients"),
                   "xi": ("1", "stiffness of the cantilever springs (units of k)"),
                   "n_sliders": ("1", "number of sliders N"),
                   "seed": ("1", "seed of the row's scene (realisation_seed(base_seed, row))")}
VIEW_NAMES = ("row", "event", "ceiling_alpha", "nearest", "event_row", "first_event",
              "n_events", "alpha_c", "status", "done", "ceiling_distance") + EVENT_COLUMNS


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
    from .._version import __version__

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
    return {c: np.asarray(getattr(catalogue, c), dtype=FILE_EVENT_DTYPES[c]) for c in EVENT_COLUMNS}


class PriorFile(GatherFile):
    """The ensemble's gather writer, plus the row's ragged events appended before the row.

    A row is the layout's columns (``event_start`` and ``event_crc32`` are
    filled here) plus ``"events"``: the catalogue columns
    (``catalogue_events``).
    """

    kind = "gather"

    def _create(self, tmp: str) -> None:
        super()._create(tmp)
        if self.comm.rank == 0:
            g = self.file.create_group(EVENTS)
            for c in EVENT_COLUMNS:
                g.create_dataset(c, shape=(0,), maxshape=(None,), chunks=(8192,),
                                 dtype=FILE_EVENT_DTYPES[c])
            self.file.flush()

    def _open(self) -> None:
        super()._open()
        if self.comm.rank == 0 and EVENTS not in self.file:
            raise StorageError(f"{self.path!r} has no /{EVENTS} group; it is not a prior file")

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
        given = row.pop("events")
        events = {c: np.asarray(given[c], dtype=FILE_EVENT_DTYPES[c]) for c in EVENT_COLUMNS}
        g = self.file[EVENTS]
        start = g["alpha"].shape[0]
        k = events["alpha"].size
        for c in EVENT_COLUMNS:
            g[c].resize((start + k,))
            if k:
                g[c][start:start + k] = events[c]
        row["event_start"] = np.int64(start)
        row["event_crc32"] = np.uint32(_events_crc(events))
        self._write_local(r, row)


HANDLERS = {"gather": PriorFile}


# ---------------------------------------------------------------------------
# readers
# ---------------------------------------------------------------------------
def _read(path, with_events: bool = True) -> dict[str, Any]:
    """Attributes, grid, rows (checked) and the events of every done row (checked)."""
    import h5py

    p = os.fspath(path)
    where = repr(p)
    f = _open_for_reading(p)
    try:
        with f:
            safeio.check_header(f, FORMAT, where, StorageError, coordinates=False)
            attrs = {k: _plain(v) for k, v in f.attrs.items() if k != safeio.ATTRS_DIGEST}
            grid = safeio.read_checked(f["grids"]["ceiling_alpha"], where)
            rg = f["realisations"]
            rows: dict[str, np.ndarray] = {}
            rg.visititems(lambda name, obj: rows.__setitem__(name, obj[()])
                          if isinstance(obj, h5py.Dataset) else None)
            order = json.loads(rg[ROW_DIGEST].attrs["columns"])
            done = _done_mask(rows["done"], where)
            damaged = {r for r, _ in _row_damage(rows, order, done)}
            events = {c: f[EVENTS][c][()] for c in EVENT_COLUMNS} if with_events else None
    except StorageError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file: one line
        raise StorageError(f"{p!r} is damaged ({type(exc).__name__}: "
                           f"{' '.join(str(exc).split())})") from None
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
            "events": events, "choices": choices}


def read_prior_header(path) -> dict[str, Any]:
    """Root attributes, the done mask (rows and their events verified) and the damaged rows."""
    d = _read(path)
    return {"attrs": d["attrs"], "done": d["done"], "damaged": d["damaged"], "grid": d["grid"]}


def _parameters(d: dict) -> dict[str, np.ndarray]:
    out = {}
    for name, v in d["rows"].items():
        if not name.startswith(PARAMETERS):
            continue
        key = name[len(PARAMETERS):]
        if key in d["choices"]:
            names = np.array([str(x) for x in d["choices"][key]] + [""])
            v = names[np.where(v >= 0, v, -1)]
        out[key] = v
    out["seed"] = d["rows"]["seed"].astype(np.int64)
    return out


def _row_catalogue(d: dict, r: int) -> Catalogue:
    a, k = int(d["rows"]["event_start"][r]), int(d["rows"]["n_events"][r])
    return Catalogue(*(d["events"][c][a:a + k] for c in EVENT_COLUMNS))


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
        A file of ``python -m sliders.prior``.
    unfinished : bool
        Also return the rows not done (status "not_run", no events, NaN
        ceiling); ``attrs["done"]`` then says which rows are complete.

    Returns
    -------
    CatalogueSet
        Events, parameters (plus the row's ``seed``), ``alpha_c``, status,
        ``ceiling_alpha`` (G,), ``ceiling_distance`` (R, G, K); ``attrs``:
        the file's root attributes plus ``rows`` (the rows' indices in the
        file) and ``done``.
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
    attrs.update({"rows": rows, "done": done[rows]})
    return CatalogueSet.from_catalogues(catalogues, params, alpha_c, names, d["grid"], ceiling,
                                        attrs)


# ---------------------------------------------------------------------------
# the xarray view
# ---------------------------------------------------------------------------
def write_view(path, scene: dict | None = None) -> None:
    """Rank 0, writers closed: the root datasets xarray opens (dims ``row``, ``event``,
    ``ceiling_alpha``, ``nearest``), the parameters as coordinates of ``row``, units,
    long names and provenance; derived from the checked rows and rewritten at every run's end.

    ``xr.open_dataset(path, engine="h5netcdf")`` shows it.
    """
    import h5py

    from .conventions import provenance

    d = _read(path)
    done = d["done"]
    R = done.size
    params = _parameters(d)
    order = np.flatnonzero(done)
    cats = [_row_catalogue(d, r) for r in order]
    counts = np.zeros(R, dtype=np.int64)
    counts[order] = [len(c) for c in cats]
    first_event = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    ev = {c: (np.concatenate([getattr(k, c) for k in cats]) if cats else np.zeros(0))
          .astype(FILE_EVENT_DTYPES[c]) for c in EVENT_COLUMNS}
    event_row = np.repeat(np.arange(R), counts)
    ceiling = d["rows"]["ceiling_distance"].copy()
    ceiling[~done] = np.nan
    K = ceiling.shape[2]
    coords = " ".join(sorted(params))
    with h5py.File(os.fspath(path), "r+") as f:
        for name in VIEW_NAMES + tuple(params):
            if name in f:
                del f[name]

        def put(name, data, dims, units, long_name, scale=False):
            ds = f.create_dataset(name, data=data)
            safeio.seal_dataset(ds, np.asarray(data))
            if scale:
                ds.make_scale(name)
            else:
                for i, dim in enumerate(dims):
                    ds.dims[i].attach_scale(f[dim])
            ds.attrs["units"], ds.attrs["long_name"] = units, long_name
            return ds

        put("row", np.arange(R), ("row",), "1", "row of the prior ensemble", scale=True)
        put("event", np.arange(event_row.size), ("event",), "1",
            "event of the done rows, in row order", scale=True)
        put("ceiling_alpha", d["grid"], (), "rad", "angle of the ceiling", scale=True)
        put("nearest", np.arange(K), (), "1", "rank of the distance (0: smallest)", scale=True)
        for c in EVENT_COLUMNS:
            put(c, ev[c], ("event",), *EVENT_UNITS[c])
        put("event_row", event_row, ("event",), "1", "row of the event")
        for name, v in params.items():
            units, long_name = PARAMETER_UNITS.get(name, ("1", f"drawn parameter {name}"))
            put(name, v.astype("S") if v.dtype.kind == "U" else v, ("row",), units, long_name)
        for name, data, units, long_name in (
                ("first_event", first_event, "1", "index of the row's first event"),
                ("n_events", counts, "1", "events of the row (0 unless done)"),
                ("alpha_c", np.where(done, d["rows"]["alpha_c"], np.nan), "rad",
                 "avalanche angle"),
                ("status", np.where(done, d["rows"]["status"], -1).astype(np.int8), "1",
                 "sliders.status code of the run (-1: not run); attr codes"),
                ("done", done.astype(np.uint8), "1", "1 if the row is complete")):
            ds = put(name, data, ("row",), units, long_name)
            ds.attrs["coordinates"] = coords
        f["status"].attrs["codes"] = json.dumps({str(k): v for k, v in status.NAMES.items()})
        ds = put("ceiling_distance", ceiling, ("row", "ceiling_alpha", "nearest"), "m g",
                 "K smallest distances mu_s,n cos(alpha) - |F_n| of a slider to its threshold")
        ds.attrs["coordinates"] = coords
        if "title" not in f.attrs:
            for k, v in provenance(f"sliders prior ensemble: {R} rows", scene).items():
                f.attrs["history" if k == "_history_line" else k] = v
            safeio.seal_attrs(f)
