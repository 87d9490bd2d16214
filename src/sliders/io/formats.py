"""Which sliders file a path holds: the format names, and one probe that never raises.

Every file the package writes names its kind in the root attribute ``format``.
Commands that take a file from the user (``figures --ensemble``, ``--study``)
probe it first, so that a missing file, a text file or a file of the other
kind gets one line saying so instead of an HDF5 traceback.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

TILT = "sliders.tilt"          # one run: Result.save (run_file)
ENSEMBLE = "sliders.ensemble"  # R realisations of one scene (storage)
STUDY = "sliders.study"        # R realisations at every point of a sweep (study_file)
PRIOR = "sliders.prior"        # R realisations drawn from a prior, with catalogues (prior_file)
KIND_NAMES = {TILT: "tilt file (one run)", ENSEMBLE: "ensemble file", STUDY: "study file",
              PRIOR: "prior ensemble file"}
READ_WITH = {TILT: "sliders.Result.load", ENSEMBLE: "sliders.io.storage.read_realisations",
             STUDY: "sliders.analysis.study_analysis.load_study_file",
             PRIOR: "sliders.io.prior_file.read_prior_ensemble"}


def kind_text(found) -> str:
    """How a file whose ``format`` attribute is ``found`` is named to the user:
    "is a sliders tilt file (one run; read it with ...)", or "is an HDF5 file not written by
    sliders"."""
    if found in KIND_NAMES:
        return f"is a sliders {KIND_NAMES[found]} (read it with {READ_WITH[found]})"
    if found is None:
        return "is an HDF5 file without a sliders format attribute (not written by sliders)"
    return f"is an HDF5 file of format {found!r} (not a sliders file this version knows)"


@dataclass(frozen=True)
class FileProbe:
    """What a path holds, as far as telling the user goes.

    ``state``: "missing", "directory", "unreadable" (the operating system
    refused to read it), "not_hdf5", "bad_hdf5" (an HDF5 signature that HDF5
    cannot open) or "hdf5".  ``reason``: the error's words for the two
    unreadable states.  ``format``: the root attribute ``format`` (None if
    absent).  ``ensemble_rows``: the file has /realisations/statistics and
    /realisations/done (the ensemble layout's rows).
    """

    state: str
    reason: str = ""
    format: str | None = None
    ensemble_rows: bool = False


def probe_file(path) -> FileProbe:
    """Look at ``path`` without trusting it (see ``FileProbe``)."""
    import h5py

    p = os.fspath(path)
    if not os.path.exists(p):
        return FileProbe("missing")
    if os.path.isdir(p):
        return FileProbe("directory")
    try:
        if not h5py.is_hdf5(p):
            return FileProbe("not_hdf5")
    except OSError as exc:
        return FileProbe("unreadable", str(exc.strerror or exc))
    try:
        with h5py.File(p, "r") as f:
            fmt = f.attrs.get("format")
            rows = "realisations/statistics" in f and "realisations/done" in f
    except OSError as exc:
        return FileProbe("bad_hdf5", str(exc))
    return FileProbe("hdf5", format=fmt.decode() if isinstance(fmt, bytes) else fmt,
                     ensemble_rows=rows)
