"""The study file (``python -m sliders.study``): layout, writers, readers, xarray view.

One file holds R realisations at every point of a parameter sweep::

    /                     attrs: format = "sliders.study", study (JSON: scene, axes, zip,
                          realisations), study_digest, dims, n_points, common_random_numbers, ...
    /points/p000/...      the ensemble layout (storage module) of point 0: grids,
                          realisations/{seed, done, status, alpha_c, ..., statistics/, row_crc32}
    /<axis>, /realisation coordinates (HDF5 dimension scales) of
    /alpha_c, /status, /n_events, /done   (dims..., realisation): written by rank 0 at the end
                          of every run, so that xarray opens the study as one dataset

The writers are the ensemble's (``storage.MpioFile``, ``storage.GatherFile``)
with one group per point: row t of the run is realisation ``t % R`` of point
``t // R``.  The functions here take the study (``sliders.study.Study``) as
given; what a point computes is the study module's business.
"""

from __future__ import annotations

import datetime
import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import formats, safeio
from .h5tools import (ROW_DIGEST, StorageError, damaged, open_for_reading, plain_attributes,
                      row_damage)
from .storage import GatherFile, Layout, MpioFile, create_structure

FORMAT = formats.STUDY
FORMAT_VERSION = 1
KNOWN_VERSIONS = (1,)  # format_version values this reader understands (a newer one is refused)
CRN_TEXT = ("common random numbers: realisation r has seed realisation_seed(base_seed, r) at "
            "every point (the same disorder draws); differences between points are paired")
VIEW_COLUMNS = ("alpha_c", "n_events", "status", "done")


def point_name(p: int) -> str:
    """The HDF5 group name of point ``p`` under ``/points`` (``p000``, ``p001``, ...)."""
    return f"p{p:03d}"


def study_attributes(study, backend: str) -> dict[str, Any]:
    """The root attributes of a study file: the study, its digest, the dimensions, the backend."""
    from .._version import __version__

    return {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "study": json.dumps(study.spec), "study_digest": study.digest,
        "dims": json.dumps(study.dims), "n_points": len(study.points),
        "realisations": study.realisations, "base_seed": study.base_seed, "backend": backend,
        "common_random_numbers": CRN_TEXT, "software_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


@dataclass
class StudyLayout(Layout):
    """The study file: one ensemble ``Layout`` per point, in group points/<name>."""

    points: list = field(default_factory=list)
    names: list = field(default_factory=list)
    per_point: int = 0


def study_layout(point_layouts: list[Layout], per_point: int, attrs: dict) -> StudyLayout:
    """The file's layout: the points' ensemble layouts under the study's root attributes."""
    biggest = max(point_layouts, key=lambda lay: sum(int(np.prod(c.shape)) for c in lay.columns))
    # n_realisations and columns only size the free-space check (an upper bound)
    return StudyLayout(len(point_layouts) * per_point, biggest.columns, np.zeros(0, np.uint32),
                       {}, attrs, points=point_layouts,
                       names=[point_name(p) for p in range(len(point_layouts))],
                       per_point=per_point)


# ---------------------------------------------------------------------------
# writers: the ensemble's, one group per point
# ---------------------------------------------------------------------------
class _StudyRows:
    """Row t of the run = realisation t % R of point t // R (group points/<name>)."""

    def __init__(self, path, layout, comm):
        super().__init__(path, layout, comm)
        self.study = layout
        self._point_ds: list = []

    def _structure(self, f) -> None:
        study = self.study
        for k, v in study.attrs.items():
            f.attrs[k] = v
        safeio.seal_attrs(f)
        pts = f.create_group("points")
        for name, lay in zip(study.names, study.points):
            create_structure(pts.create_group(name), lay)

    def _write_seeds(self) -> None:
        for name, lay in zip(self.study.names, self.study.points):
            self.file["points"][name]["realisations"]["seed"][:] = lay.seeds

    def _bind(self) -> None:
        self._point_ds = []
        for name, lay in zip(self.study.names, self.study.points):  # same order, every rank
            rg = self.file["points"][name]["realisations"]
            ds = {c.name: rg[c.name] for c in lay.columns}
            ds["done"], ds[ROW_DIGEST] = rg["done"], rg[ROW_DIGEST]
            self._point_ds.append(ds)

    def _select(self, t: int) -> int:
        p, r = divmod(int(t), self.study.per_point)
        self.layout = self.study.points[p]
        if self._point_ds:
            self._ds = self._point_ds[p]
        return r

    def write_row(self, t, row):
        """Write row ``t`` of the study (point ``t // R``, realisation ``t % R``) into its point's group."""
        self._select(t)
        super().write_row(t, row)

    def _write_local(self, t, row):
        super()._write_local(self._select(t), row)

    def _done_local(self, t):
        super()._done_local(self._select(t))

    def close(self):
        """Drop the per-point dataset handles, then close the file."""
        self._point_ds = []
        super().close()


class StudyMpioFile(_StudyRows, MpioFile):
    """Parallel h5py: every rank writes its own rows into the points' groups."""

    def _create(self, tmp):
        import h5py

        self.file = h5py.File(tmp, "w", driver="mpio", comm=self.comm)
        self._structure(self.file)
        if self.comm.rank == 0:
            self._write_seeds()
        self.file.flush()
        self._bind()

    def _open(self):
        import h5py

        self.file = h5py.File(self.path, "r+", driver="mpio", comm=self.comm)
        self._bind()


class StudyGatherFile(_StudyRows, GatherFile):
    """Rank 0 writes every row (shipped by the others with their "done" message)."""

    def _create(self, tmp):
        if self.comm.rank == 0:
            import h5py

            self.file = h5py.File(tmp, "w")
            self._structure(self.file)
            self._write_seeds()
            self.file.flush()
            self._bind()

    def _open(self):
        if self.comm.rank == 0:
            import h5py

            self.file = h5py.File(self.path, "r+")
            self._bind()


HANDLERS = {"mpio": StudyMpioFile, "gather": StudyGatherFile}


# ---------------------------------------------------------------------------
# readers
# ---------------------------------------------------------------------------
def read_study_header(path) -> dict[str, Any]:
    """Root attributes and, per point, its done mask (checksums of the rows verified)."""
    import h5py

    p = os.fspath(path)
    f = open_for_reading(p)
    try:
        with f:
            safeio.check_header(f, FORMAT, repr(p), StorageError, coordinates=False,
                                versions=KNOWN_VERSIONS)
            attrs = plain_attributes(f)
            done, damaged = [], []
            for name in sorted(f["points"]):
                rg = f["points"][name]["realisations"]
                order = json.loads(rg[ROW_DIGEST].attrs["columns"])
                out = {n: rg[n][()] for n in order + ["done", ROW_DIGEST]}
                d = out["done"].astype(bool)
                bad = sorted({r for r, _ in row_damage(out, order, d)})
                d[bad] = False
                done.append(d)
                damaged.append(bad)
    except StorageError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file: one line
        raise damaged(p, exc) from None
    return {"attrs": attrs, "done": done, "damaged": damaged}


def read_study_spec(path) -> dict[str, Any]:
    """The study as the file stores it (root attribute ``study``): scene, axes, zip, realisations."""
    with _open_checked(path) as f:
        return json.loads(f.attrs["study"])


def _open_checked(path):
    """The study file open for reading, its kind and version checked (StorageError, one line)."""
    p = os.fspath(path)
    f = open_for_reading(p)
    try:
        safeio.check_header(f, FORMAT, repr(p), StorageError, coordinates=False,
                            versions=KNOWN_VERSIONS)
    except Exception:
        f.close()
        raise
    return f


def read_point_rows(path, p: int) -> dict[str, np.ndarray]:
    """Every /points/<p>/realisations dataset (``statistics/<key>`` names), R rows."""
    import h5py

    out: dict[str, np.ndarray] = {}
    with _open_checked(path) as f:
        rg = f["points"][point_name(p)]["realisations"]
        rg.visititems(lambda name, obj: out.__setitem__(name, obj[()])
                      if isinstance(obj, h5py.Dataset) else None)
    out["done"] = out["done"].astype(bool)
    return out


# ---------------------------------------------------------------------------
# the xarray view
# ---------------------------------------------------------------------------
def write_view(path, study) -> None:
    """Rank 0, file closed by the writers: root datasets (dims..., realisation) with named
    dimension scales, so that ``xr.open_dataset(path, engine="h5netcdf")`` shows the axes
    as dimensions (derived from the checksummed rows, rewritten at the end of every run)."""
    import h5py

    from .conventions import provenance

    shape = study.shape + (study.realisations,)
    with h5py.File(os.fspath(path), "r+") as f:
        values = {c: [] for c in VIEW_COLUMNS}
        for p in range(len(study.points)):
            rg = f["points"][point_name(p)]["realisations"]
            for c in VIEW_COLUMNS:
                values[c].append(rg[c][()])
        scales = []
        for d in study.dims:
            name = d[0]
            if name not in f:
                ds = f.create_dataset(name, data=np.asarray(study.axes[name]))
                ds.make_scale(name)
                for other in d[1:]:  # zipped axes: values along the first one's dimension
                    f.create_dataset(other, data=np.asarray(study.axes[other])) \
                        .dims[0].attach_scale(ds)
            scales.append(f[name])
        if "realisation" not in f:
            f.create_dataset("realisation", data=np.arange(study.realisations)).make_scale(
                "realisation")
        scales.append(f["realisation"])
        for c in VIEW_COLUMNS:
            data = np.stack(values[c]).reshape(shape)
            if c in f:
                f[c][...] = data
            else:
                ds = f.create_dataset(c, data=data)
                for i, sc in enumerate(scales):
                    ds.dims[i].attach_scale(sc)
        if "title" not in f.attrs:
            for k, v in provenance(f"sliders study: {len(study.points)} points x "
                                   f"{study.realisations} realisations", study.spec["scene"]).items():
                f.attrs[k] = v
            safeio.seal_attrs(f)
