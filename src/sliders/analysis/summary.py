"""Ensemble statistics read back and averaged: the one reader the figures and the report share.

``sliders.io.storage`` reads the rows (and checks every checksum); this module
averages them with ``observables.combine``.  Readers of files stay in ``io``;
what is computed from them lives here.
"""

from __future__ import annotations

import os

from ..io.storage import EnsembleInputError, StorageError, check_ensemble_file, read_done_statistics
from .observables import StatisticsGrids, combine

__all__ = ["EnsembleInputError", "load_ensemble_summary", "load_summary"]


def load_summary(path):
    """The ensemble statistics of a file, over its rows marked done.

    Parameters
    ----------
    path : str or os.PathLike
        An ensemble file (``python -m sliders.ensemble``, ``python -m sliders.merge``).

    Returns
    -------
    summary : observables.EnsembleSummary
        Means over the realisations at rest at each angle: force PDF (per m g),
        P_i(alpha), A(alpha) (g tau^2), alpha_c (radians), event sizes.
    grids : observables.StatisticsGrids
        The angles (radians) and bin edges the rows were computed on.
    scene, info : Scene, dict
        As ``sliders.io.storage.read_done_statistics`` gives them.
    """
    stats, grid_arrays, scene, info = read_done_statistics(path)
    grids = StatisticsGrids.from_arrays(grid_arrays)
    return combine(stats, grids, scene.n_sliders), grids, scene, info


def load_ensemble_summary(path):
    """(EnsembleSummary, grids, scene dict) from an ensemble HDF5 file, or one line.

    Only rows marked done are used, every checksum is verified; a file that
    cannot give a summary raises ``EnsembleInputError`` (a ValueError) with
    one line: missing, not HDF5, a single run, another kind, damaged, no
    finished realisation.
    """
    check_ensemble_file(path)
    try:
        summary, grids, scene, info = load_summary(path)
    except (StorageError, KeyError, OSError) as exc:
        raise EnsembleInputError(f"{os.fspath(path)!r}: cannot read the ensemble ({exc})") \
            from None
    except ValueError as exc:  # e.g. combine() of zero finished rows
        raise EnsembleInputError(f"{os.fspath(path)!r}: {exc}") from None
    if info["n_done"] == 0:
        raise EnsembleInputError(f"{os.fspath(path)!r}: no finished realisation yet")
    return summary, grids, scene.to_dict()
