"""Files that explain themselves: dimension scales, units, long names, provenance.

Every HDF5 file the package writes is described after it is written:

* each axis of each dataset is attached to a named HDF5 dimension scale
  (``event``, ``slider``, ``realisation``, ``alpha``, ``force_bin``, ...), so
  that netCDF readers (xarray with ``engine="h5netcdf"``) see named
  dimensions instead of ``phony_dim_*``;
* the scales are coordinate variables in the root group, holding the axis
  values (angles, bin centres, realisation numbers), so a child group sees
  them as inherited dimensions (``xarray.open_datatree`` inherits them as
  coordinates);
* every dataset gets ``units`` and ``long_name`` attributes (the model's
  dimensionless units: forces in m g, lengths in g tau^2, times in tau);
* the root group gets CF-style provenance: ``title``, ``source`` (package and
  version), ``history`` (one line per command that wrote the file), creation
  time, the git commit when the package runs from a checkout, the Python,
  NumPy, h5py and HDF5 versions, and the scene as TOML.

Dimension scales are a serial HDF5 API: for a parallel (mpio) ensemble file
rank 0 describes the file after the collective close.  ``describe`` is
idempotent (a resumed or re-described file only gains a history line).

The variable tables below are the single place that says what every dataset
is; a new kind of file adds its table and calls ``describe``.
"""

from __future__ import annotations

import datetime
import functools
import json
import os
import shlex
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from . import h5tools
from .h5tools import Stored
from .._version import __version__

FORCE, LENGTH, TIME = "m g", "g tau^2", "tau"
ENERGY = "m g^2 tau^2"


@dataclass(frozen=True)
class Variable:
    """How one dataset is described in a file: named dimensions, units, long name."""
    dims: tuple[str, ...]
    units: str
    long_name: str
    coordinates: str | None = None  # CF: variables of the same group that label its axes


# ---------------------------------------------------------------------------
# tilt result file (Result.save)
# ---------------------------------------------------------------------------
TILT_EVENT_VARIABLES = {
    "alpha": ("rad", "tilt angle at which the rearrangement happened"),
    "n_moved": ("1", "number of distinct sliders that moved"),
    "n_stops": ("1", "number of stops (velocity zero crossings) during the event"),
    "n_steps": ("1", "accepted integration steps"),
    "slider_steps": ("1", "sum over integration steps of the number of moving sliders"),
    "duration": (TIME, "duration of the rearrangement"),
    "work_gravity": (ENERGY, "work of gravity during the event"),
    "elastic_change": (ENERGY, "change of elastic energy (springs and cantilevers)"),
    "dissipation": (ENERGY, "energy dissipated by dynamic friction"),
}
TILT_STATE_VARIABLES = {
    "elastic_force0": (FORCE, "prepared elastic force (springs and cantilever) at alpha = 0"),
    "spring_extension0": (LENGTH, "prepared extension of the spring to the next slider"),
    "cantilever_stretch0": (LENGTH, "prepared stretch of the cantilever spring"),
    "lattice_position0": (LENGTH, "prepared position u0_n + n l"),
    "mu_s": ("1", "static friction coefficient"),
    "displacement": (LENGTH, "displacement since preparation"),
    "n_stops": ("1", "stops so far (key of the next static-coefficient draw)"),
}


# the drive of a loading whose drive is not the tilt (format 1 stored it where the tilt's alpha is)
DRIVE_EVENT_VARIABLE = {"pushed_end": (LENGTH, "driver position D at which the rearrangement "
                                               "happened")}
INCLINE_EVENT_VARIABLE = ("rad", "incline angle at which the rearrangement happened")


def tilt_variables(h5file) -> dict[str, Variable]:
    """Dimensions, units and long name of every dataset of a run file (path: Variable)."""
    drive = DRIVE_EVENT_VARIABLE.get(json.loads(h5file.attrs["scene"]).get("loading"))
    if "events/drive" in h5file:  # format 2: the drive in its own column, a coordinate of event
        coordinate = "drive"
        events = dict(TILT_EVENT_VARIABLES, alpha=INCLINE_EVENT_VARIABLE,
                      drive=drive or TILT_EVENT_VARIABLES["alpha"])
    else:  # format 1: the drive under the tilt's name
        coordinate = "alpha"
        events = dict(TILT_EVENT_VARIABLES, **({"alpha": drive} if drive else {}))
    out = {f"events/{k}": Variable(("event",), u, ln, None if k == coordinate else coordinate)
           for k, (u, ln) in events.items()}
    out["displacement/ptr"] = Variable(("event_boundary",), "1",
                                       "start of each event's entries in index/value (CSR)")
    out["displacement/index"] = Variable(("entry",), "1", "slider that moved (0-based)")
    out["displacement/value"] = Variable(("entry",), LENGTH, "displacement of that slider in the event")
    for label in ("initial", "final"):
        for k, (u, ln) in TILT_STATE_VARIABLES.items():
            out[f"{label}/{k}"] = Variable(("slider",), u, f"{ln} ({label} state)")
    return out


def tilt_coordinates(h5file) -> dict[str, tuple[np.ndarray, str, str]]:
    """Coordinates of a tilt-result file's dimensions: name -> (values, units, long name)."""
    k = h5file["events/alpha"].shape[0] if "events/alpha" in h5file else 0
    n = h5file["initial/mu_s"].shape[0]
    coords = {
        "event": (np.arange(k), "1", "rearrangement number (0-based, in the order of the drive)"),
        "slider": (np.arange(n), "1", "slider number (0-based, up the chain)"),
    }
    if "displacement" in h5file:
        coords["event_boundary"] = (np.arange(k + 1), "1", "CSR boundary number")
        coords["entry"] = (np.arange(h5file["displacement/index"].shape[0]), "1",
                           "stored (event, slider) entry")
    return coords


# ---------------------------------------------------------------------------
# ensemble file (storage.py layout)
# ---------------------------------------------------------------------------
ENSEMBLE_ROW_VARIABLES = {
    "seed": ("1", "seed of the realisation (realisation_seed(scene seed, realisation))"),
    "done": ("1", "1 when the row holds a completed realisation"),
    "status": ("1", "how the run ended (codes in the attribute 'codes'; -1: not run)"),
    "alpha_c": ("rad", "avalanche angle (NaN if the run ended otherwise)"),
    "n_events": ("1", "number of rearrangements before the avalanche"),
    "slider_steps": ("1", "integration work of the run (slider-steps)"),
    "wall_time": ("s", "wall time of the realisation"),
}
ENSEMBLE_GRIDS = {
    "alpha": ("alpha", "rad", "angles at which the statistics are sampled"),
    "force_edges": ("force_edge", FORCE, "edges of the force histogram"),
    "ratio_edges": ("ratio_edge", "1", "edges of the F_t/F_t* histogram"),
    "stop_alpha_edges": ("stop_alpha_edge", "rad", "angle bins of the stopped-force ratios"),
    "n_model_bins": (None, "1", "nu(0): number of model bins"),
    "mu_s_mean": (None, "1", "mean static friction coefficient"),
    "mu_d": (None, "1", "dynamic friction coefficient"),
}


def _centres(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[1:] + edges[:-1])


def ensemble_variables(h5file, statistics: dict) -> dict[str, Variable]:
    """Dimensions, units and long name of every dataset of an ensemble file (path: Variable).

    ``statistics``: name -> (dims of a row, units, long name) of the per-realisation
    statistics, declared where each is defined (``analysis.observables.STATISTIC_CONVENTIONS``,
    and a study's own); a statistic of the file it does not declare is described as such.
    """
    out = {}
    for k, (dim, u, ln) in ENSEMBLE_GRIDS.items():
        out[f"grids/{k}"] = Variable((dim,) if dim else (), u, ln)
    for k, (u, ln) in ENSEMBLE_ROW_VARIABLES.items():
        out[f"realisations/{k}"] = Variable(("realisation",), u, ln)
    stats = h5file["realisations/statistics"] if "realisations/statistics" in h5file else {}
    for k in stats:
        dims, u, ln = statistics.get(k, ((), "1", f"{k.replace('_', ' ')} (not declared by "
                                                   "this version of sliders)"))
        if len(dims) != stats[k].ndim - 1:  # a statistic not declared here: index axes
            dims = tuple(f"{k}_axis{i}" for i in range(1, stats[k].ndim))
        out[f"realisations/statistics/{k}"] = Variable(("realisation",) + dims, u, ln)
    if "realisations/row_crc32" in h5file:
        out["realisations/row_crc32"] = Variable(
            ("realisation", "checksummed_column"), "1",
            "CRC-32 of the row in each column (column names: attribute 'columns')")
    return out


def _n_model_bins(h5file) -> int:
    """nu(0): the grid's scalar, or (a study point keeps no scalar grids) the statistic's width."""
    if "grids/n_model_bins" in h5file:
        return int(h5file["grids/n_model_bins"][()])
    counts = "realisations/statistics/model_bin_counts"
    return h5file[counts].shape[-1] if counts in h5file else 0


def ensemble_coordinates(h5file) -> dict[str, tuple[np.ndarray, str, str]]:
    """Coordinates of an ensemble file's dimensions (alpha in radians, force bins in m g, ...): name -> (values, units, long name)."""
    g = h5file["grids"]
    alpha = g["alpha"][()]
    fe, re_, se = g["force_edges"][()], g["ratio_edges"][()], g["stop_alpha_edges"][()]
    first = int(h5file.attrs.get("first_realisation", 0))
    n_rows = h5file["realisations/done"].shape[0]
    scene = json.loads(h5file.attrs["scene"])
    return {
        "realisation": (first + np.arange(n_rows), "1", "realisation number (its seed is "
                        "realisation_seed(scene seed, realisation))"),
        "alpha": (Stored("grids/alpha"), "rad", "tilt angle"),
        "force_edge": (Stored("grids/force_edges"), FORCE, "edge of a force bin"),
        "force_bin": (_centres(fe), FORCE, "tangential force F_t (bin centre)"),
        "ratio_edge": (Stored("grids/ratio_edges"), "1", "edge of an F_t/F_t* bin"),
        "ratio_bin": (_centres(re_), "1", "F_t/F_t* of a stopped slider (bin centre), "
                      "F_t* = (2 mu_d - mu_s_mean) cos alpha"),
        "stop_alpha_edge": (Stored("grids/stop_alpha_edges"), "rad", "edge of an event-angle bin"),
        "stop_alpha_bin": (_centres(se), "rad", "event angle (bin centre)"),
        "model_bin": (np.arange(1, _n_model_bins(h5file) + 1), "1",
                      "model bin i (width 2 dmu, counted down from mu_s_mean)"),
        "event_size": (np.arange(1, int(scene["n_sliders"]) + 1), "1",
                       "number of distinct sliders that moved in an event"),
        "alpha_interval": (Stored("grids/alpha", alpha.size - 1), "rad",
                           "lower end of the angle interval [alpha_g, alpha_g+1)"),
        **({"checksummed_column": (np.arange(h5file["realisations/row_crc32"].shape[1]), "1",
                                   "index into the attribute 'columns' of row_crc32")}
           if "realisations/row_crc32" in h5file else {}),
    }


# ---------------------------------------------------------------------------
# provenance
# ---------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the checkout the package runs from ("+dirty" if changed), else None."""
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        head = subprocess.run(["git", "-C", here, "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=5)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", here, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty else "")


def command_line() -> str:
    """The command that runs this process, as a shell line."""
    argv = list(getattr(sys, "orig_argv", None) or [sys.executable] + sys.argv)
    argv[0] = os.path.basename(argv[0])
    return shlex.join(argv)


def scene_toml(scene: dict) -> str:
    """The scene as a TOML ``[scene]`` table (``Scene.from_toml`` reads it back)."""
    lines = ["[scene]"]
    for k in sorted(scene):
        v = scene[k]
        if v is None:
            continue
        if isinstance(v, bool):
            text = "true" if v else "false"
        elif isinstance(v, (int, np.integer)):
            text = str(int(v))
        elif isinstance(v, (float, np.floating)):
            text = repr(float(v))  # TOML spells inf and nan the same way
        else:
            text = json.dumps(str(v))
        lines.append(f"{k} = {text}")
    return "\n".join(lines) + "\n"


def provenance(title: str, scene: dict | None) -> dict[str, str]:
    """Root attributes every file carries: title, source, history (this command), date, git commit, versions, the scene as TOML."""
    import h5py

    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    out = {
        "title": title,
        "source": f"sliders {__version__} (chain of frictional sliders on an incline)",
        "date_created": now,
        "python_version": sys.version.split()[0],
        "numpy_version": np.__version__,
        "h5py_version": h5py.__version__,
        "hdf5_version": h5py.version.hdf5_version,
        "_history_line": f"{now}: {command_line()}",
    }
    commit = git_commit()
    if commit:
        out["git_commit"] = commit
    if scene is not None:
        out["scene_toml"] = scene_toml(scene)
    return out


# ---------------------------------------------------------------------------
# writing the description
# ---------------------------------------------------------------------------
def describe(h5file, variables: dict[str, Variable], coordinates: dict, title: str,
             scene: dict | None) -> None:
    """Attach scales, units and long names, and add provenance, to an open (serial) h5py file."""
    attach_dimensions(h5file, variables, coordinates)
    add_provenance(h5file, title, scene)


def attach_dimensions(group, variables: dict[str, Variable], coordinates: dict,
                      inherited: dict | None = None) -> None:
    """Create the coordinates (scales) in ``group`` and attach them to every variable's axes,
    with units and long names; ``inherited``: scales of a parent group, used as they are.

    ``coordinates``: name -> (values or ``h5tools.Stored``, units, long name).  An axis
    no table names gets a numbered scale of its own.
    """
    scales = dict(inherited or {})
    for name, (values, units, long_name) in coordinates.items():
        if name in scales:
            continue
        if name not in group:
            h5tools.coordinate(group, name, values, units, long_name)
        scales[name] = group[name]
    for path, var in variables.items():
        if path not in group:
            continue
        ds = group[path]
        for axis, dim in enumerate(var.dims):
            if dim not in scales:  # an axis the tables do not name: number its entries
                scales[dim] = h5tools.coordinate(group, dim, np.arange(ds.shape[axis]), "1",
                                                 f"index of {dim}")
        h5tools.attach(ds, *(scales[dim] for dim in var.dims))
        h5tools.describe(ds, var.units, var.long_name, var.coordinates)


def add_provenance(h5file, title: str, scene: dict | None) -> None:
    """Write ``provenance`` into the root attributes of an open (serial) h5py file: the
    first creation time is kept (a later writer sets ``date_modified``) and this command
    becomes the last line of ``history``."""
    prov = provenance(title, scene)
    history_line = prov.pop("_history_line")
    old = h5file.attrs.get("history", "")
    old = old.decode() if isinstance(old, bytes) else str(old)
    if "date_created" in h5file.attrs:  # keep the first creation time; note later writers
        prov["date_modified"] = prov.pop("date_created")
    for k, v in prov.items():
        h5file.attrs[k] = v
    h5file.attrs["history"] = (old + "\n" if old else "") + history_line


def describe_tilt_file(h5file, result) -> None:
    """Describe a tilt result file (called by ``Result.save`` on its open file)."""
    s = result.scene
    describe(h5file, tilt_variables(h5file), tilt_coordinates(h5file),
             f"sliders tilt run: N = {s.n_sliders}, xi = {s.xi:g}, seed = {s.seed} "
             f"({result.backend}, {result.status})", s.to_dict())


# Free space below which a resumed, already described file is left as it is: HDF5
# 1.10 can crash while closing a file whose metadata write failed (a full disk),
# and the finished rows matter more than one more history line.
RESUME_HISTORY_MIN_FREE = 1 << 20


def describe_ensemble_file(path, statistics: dict,
                           earlier_history: str | None = None) -> bool | str:
    """Describe an ensemble file (one process, no writer holding it): True, or why not.

    ``statistics``: as ``ensemble_variables``'s.  ``earlier_history``: the history of the
    files this one was made from (the chunks of a merge), written before this command's line.
    """
    import h5py

    try:
        with h5py.File(os.fspath(path), "r") as f:
            described = "title" in f.attrs
        if described:
            st = os.statvfs(os.path.dirname(os.path.abspath(path)))
            if st.f_bavail * st.f_frsize < RESUME_HISTORY_MIN_FREE:
                return True  # nearly full disk: keep the description, skip the history line
        with h5py.File(os.fspath(path), "r+") as f:
            if earlier_history is not None:
                f.attrs["history"] = earlier_history
            _describe_ensemble(f, statistics)
    except (OSError, KeyError, ValueError) as exc:
        return " ".join(str(exc).split()) or type(exc).__name__
    return True


def _describe_ensemble(f, statistics: dict) -> None:
    scene = json.loads(f.attrs["scene"])
    first = int(f.attrs.get("first_realisation", 0))
    n = int(f.attrs["realisations"])
    part = f" (realisations {first}..{first + n - 1})" if first else ""
    describe(f, ensemble_variables(f, statistics), ensemble_coordinates(f),
             f"sliders ensemble: {n} realisations{part} of N = {scene['n_sliders']}, "
             f"xi = {scene['xi']:g}", scene)
