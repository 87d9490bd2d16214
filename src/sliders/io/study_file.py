"""The study file (``python -m sliders.study``): layout, writers, readers, xarray view.

One file holds R realisations at every point of a parameter sweep::

    /                     attrs: format = "sliders.study", format_version = 2, study (JSON:
                          scene, axes, zip, realisations), study_digest, dims, n_points,
                          common_random_numbers, ...
    /points/p000/...      the ensemble layout (storage module) of point 0: grids (the
                          angles and bin edges; the scalars are in the point's scene),
                          realisations/{seed, done, status, alpha_c, ..., statistics/, row_crc32},
                          and the point's coordinates (alpha, force_bin, ...)
    /<axis>, /realisation coordinates (HDF5 dimension scales) of
    /alpha_c, /status, /n_events, /done   (dims..., realisation): virtual datasets showing
                          the points' rows (stored once), so that xarray opens the study as
                          one dataset

Every dataset has named dimension scales (``write_view``, rank 0 at the end of
every run).  Format version 1 (the root view a copy, scalar grids) still
reads; its view becomes virtual when it is resumed.

The writers are the ensemble's (``storage.MpioFile``, ``storage.GatherFile``)
with one group per point: row t of the run is realisation ``t % R`` of point
``t // R``.  The functions here take the study (``sliders.analysis.study_spec.Study``) as
given; what a point computes is the study module's business.
"""

from __future__ import annotations

import datetime
import json
import os
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from . import formats, h5tools, safeio
from .h5tools import (ROW_DIGEST, StorageError, open_checked, plain_attributes,
                      row_damage)
from .storage import GatherFile, Layout, MpioFile, create_structure
from .conventions import add_provenance, attach_dimensions, ensemble_coordinates, ensemble_variables
from .._version import __version__

FORMAT = formats.STUDY
FORMAT_VERSION = 2  # 2: the root view shows the points' rows (virtual), no scalar grids
KNOWN_VERSIONS = (1, 2)  # format_version values this reader understands (a newer one is refused)
CRN_TEXT = ("common random numbers: realisation r has seed realisation_seed(base_seed, r) at "
            "every point (the same disorder draws); differences between points are paired")
VIEW_COLUMNS = ("alpha_c", "n_events", "status", "done")


def point_name(p: int) -> str:
    """The HDF5 group name of point ``p`` under ``/points`` (``p000``, ``p001``, ...)."""
    return f"p{p:03d}"


def study_attributes(study, backend: str) -> dict[str, Any]:
    """The root attributes of a study file: the study, its digest, the dimensions, the backend."""
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
            # the grids without the scalars (mu_d, mu_s_mean, n_model_bins): the point's scene
            # holds them, and netCDF would take a scalar named like a study axis for that axis
            arrays = {k: v for k, v in lay.grids.items() if np.ndim(v)}
            create_structure(pts.create_group(name), replace(lay, grids=arrays))

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

    p = os.fspath(path)
    f = open_checked(p, FORMAT, KNOWN_VERSIONS)
    try:
        with f:
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
    with open_checked(path, FORMAT, KNOWN_VERSIONS) as f:
        return json.loads(f.attrs["study"])


def read_point_rows(path, p: int) -> dict[str, np.ndarray]:
    """Every /points/<p>/realisations dataset (``statistics/<key>`` names), R rows."""
    import h5py

    out: dict[str, np.ndarray] = {}
    with open_checked(path, FORMAT, KNOWN_VERSIONS) as f:
        rg = f["points"][point_name(p)]["realisations"]
        rg.visititems(lambda name, obj: out.__setitem__(name, obj[()])
                      if isinstance(obj, h5py.Dataset) else None)
    out["done"] = out["done"].astype(bool)
    return out


# ---------------------------------------------------------------------------
# the xarray view
# ---------------------------------------------------------------------------
VIEW_UNITS = {"alpha_c": ("rad", "avalanche angle (NaN if the run ended otherwise)"),
              "n_events": ("1", "number of rearrangements before the avalanche"),
              "status": ("1", "how the run ended (sliders.status code; -1: not run)"),
              "done": ("1", "1 when the realisation is complete")}
AXIS_UNITS = {"alpha_max": "rad", "incline": "rad", "dt": "tau", "spring_length": "g tau^2",
              "drive_max": "g tau^2"}


def write_view(path, study, statistics: dict) -> None:
    """Rank 0, file closed by the writers: named dimension scales on every dataset, and
    root variables (dims..., realisation) that show the points' rows (HDF5 virtual
    datasets: stored once, in the points' groups), so that
    ``xr.open_dataset(path, engine="h5netcdf")`` shows the axes as dimensions and
    ``xr.open_datatree`` every point with its grids as coordinates."""
    import h5py

    with h5py.File(os.fspath(path), "r+") as f:
        scales = _axis_scales(f, study)
        for c in VIEW_COLUMNS:
            if c in f and not f[c].is_virtual:  # a copy of the rows: shown instead
                del f[c]
            if c not in f:
                _point_view(f, c, study, scales)
        for p in range(len(study.points)):
            g = f["points"][point_name(p)]
            attach_dimensions(g, ensemble_variables(g, statistics), ensemble_coordinates(g),
                              inherited={"realisation": f["realisation"]})
        if "title" not in f.attrs:
            add_provenance(f, f"sliders study: {len(study.points)} points x "
                              f"{study.realisations} realisations", study.spec["scene"])
            safeio.seal_attrs(f)


def _axis_scales(f, study) -> list:
    """The study's axes and ``realisation`` as coordinates of the root (zipped axes: values
    along the first one's dimension)."""
    scales = []
    for d in study.dims:
        name = d[0]
        if name not in f:
            scale = h5tools.coordinate(f, name, np.asarray(study.axes[name]),
                                       AXIS_UNITS.get(name, "1"), f"scene parameter {name}")
            for other in d[1:]:
                ds = f.create_dataset(other, data=np.asarray(study.axes[other]))
                safeio.seal_dataset(ds, np.asarray(study.axes[other]))
                h5tools.attach(ds, scale)
                h5tools.describe(ds, AXIS_UNITS.get(other, "1"), f"scene parameter {other}")
        scales.append(f[name])
    if "realisation" not in f:
        h5tools.coordinate(f, "realisation", np.arange(study.realisations), "1",
                           "realisation (its seed is realisation_seed(base_seed, realisation) "
                           "at every point)")
    return scales + [f["realisation"]]


def _point_view(f, column: str, study, scales) -> None:
    """Root dataset ``column`` (dims..., realisation): a virtual dataset over the points' rows."""
    import h5py

    R = study.realisations
    first = f["points"][point_name(0)]["realisations"][column]
    layout = h5py.VirtualLayout(shape=tuple(study.shape) + (R,), dtype=first.dtype)
    for p in range(len(study.points)):
        src = f["points"][point_name(p)]["realisations"][column]
        layout[np.unravel_index(p, study.shape) + (slice(None),)] = \
            h5py.VirtualSource(".", src.name, shape=src.shape)
    ds = f.create_virtual_dataset(column, layout, fillvalue=first.fillvalue)
    h5tools.attach(ds, *scales)
    h5tools.describe(ds, *VIEW_UNITS[column])
