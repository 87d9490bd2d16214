"""One row of a run file: a realisation of a scene, with its statistics.

``compute_row`` is the row of an ensemble (``runs.ensemble``) and of each
point of a study (``runs.study``, which adds statistics of its own); the
prior ensemble's rows (``runs.prior``) share ``status_code``.
"""

from __future__ import annotations

import signal
import time
from typing import Any

import numpy as np

from .. import status as status_codes
from .signals import Interrupted, StopFlag
from ..analysis.observables import realisation_statistics
from ..driver import realisation_scene, run
from ..io.storage import STATISTICS
from ..keyed_random import key_hash

STATUS_CODES = {name: code for code, name in status_codes.NAMES.items()}
UNKNOWN_STATUS = -2


def status_code(status: str) -> int:
    """The stored code of a run's end status (``sliders.status``; -2 for an unknown one)."""
    return STATUS_CODES.get(status, UNKNOWN_STATUS)


def run_interruptibly(scene, backend: str, progress, **options):
    """``run`` with ``StopFlag.computing`` set except inside the progress callback
    (``options``: more of ``run``'s keywords, such as ``state``)."""

    def callback(p):
        StopFlag.computing = False
        try:
            if progress is not None:
                progress(p)
        finally:
            StopFlag.computing = True

    StopFlag.computing = True
    try:
        if StopFlag.signum is not None:  # arrived just before
            raise Interrupted()
        return run(scene, backend=backend, progress=callback, **options)
    except KeyboardInterrupt:  # also when the kernel caught the signal itself: stop the run
        if StopFlag.signum is None:
            StopFlag.signum = signal.SIGINT
        raise
    finally:
        StopFlag.computing = False


def compute_row(scene, r: int, backend: str, grids, progress=None,
                first: int = 0, extra_statistics=None) -> dict[str, Any]:
    """Row ``r`` of a file starting at realisation ``first``: realisation ``first + r`` of the
    scene (base columns + statistics/<key>).  ``extra_statistics(result)`` -> {key: value}
    adds statistics of the caller's own (a study's burst periods and synchronisation)."""
    started = time.perf_counter()
    result = run_interruptibly(realisation_scene(scene, first + r), backend, progress)
    stats = {} if scene.record == "summary" else realisation_statistics(result, grids)
    if extra_statistics is not None:
        stats.update(extra_statistics(result))
    row: dict[str, Any] = {
        "status": status_code(result.status),
        "alpha_c": float(result.alpha_c),
        "n_events": int(result.n_events),
        "slider_steps": int(result.total_slider_steps),  # the avalanche event included
    }
    row.update({STATISTICS + k: v for k, v in stats.items()})
    row["wall_time"] = time.perf_counter() - started
    return row


def realisation_seeds(base_seed: int, first: int, count: int) -> np.ndarray:
    """The seeds of realisations ``first`` to ``first + count - 1`` (``keyed_random.realisation_seed``
    of each), as one uint32 array: 4 bytes a row."""
    index = np.arange(first, first + count, dtype=np.uint64).astype(np.uint32)
    return np.asarray(key_hash(base_seed, index, 0xFFFFFFFE, 0), dtype=np.uint32)
