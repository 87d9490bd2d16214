"""The engine contract both backends implement (NumPy reference, Fortran kernel).

Declared once here:

* ``EVENT_SCHEMA``: the per-event scalar records, their type and meaning.
  The Fortran kernel stores them in two column buffers (reals, integers) in
  the order of this table; ``fortran/sliders_contract.f90`` holds the column
  numbers and tests/test_contract.py checks them against this table.
* ``REAL_PARAMETERS`` / ``INT_PARAMETERS``: the packed parameters of one
  kernel call (the f2py boundary takes two parameter arrays, not one argument
  per scene value), with ``pack_parameters`` filling them from a scene: the
  friction law and the loading pack their own (``packed()``), the rest are
  the scene's fields.  Their defaults are the scene's: the kernel has none.
* ``Chunk``: what one ``advance`` call returns, and ``join_chunks``, the one
  merge of consecutive chunks (the CSR pointers shifted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..parts.loading import LOADINGS

# Halvings of a crossing bracket, at most (sliders_crossing.max_halvings): a step
# of 1 tau closes to 3e-39 within them, so only a refine_tol below what the
# step can resolve reaches the bound.
MAX_HALVINGS = 128
# The message of status INTERRUPTED, from either backend and from the driver.
INTERRUPTED_MESSAGE = "interrupted by the user"


# name, dtype, meaning.  Order: the columns of each type in the kernel's buffers.
EVENT_SCHEMA = (
    ("drive", np.float64, "drive at which the rearrangement happened: the tilt's angle, or "
                          "the driver's position D for loading='pushed_end'"),
    ("n_moved", np.int64, "distinct sliders that moved"),
    ("n_stops", np.int64, "stops (velocity zero crossings) during the event"),
    ("n_steps", np.int64, "accepted integration steps"),
    ("slider_steps", np.int64, "sum over steps of the number of moving sliders"),
    ("duration", np.float64, "in tau"),
    ("work_gravity", np.float64, "work of the loading: sin(incline angle) * sum of "
                                 "displacements, plus the driver's spring on slider 1 for "
                                 "loading='pushed_end'"),
    ("elastic_change", np.float64, "change of elastic energy (springs + cantilevers)"),
    ("dissipation", np.float64, "mu_d cos(alpha) * path length"),
)
EVENT_FIELDS = tuple(name for name, _, _ in EVENT_SCHEMA)
EVENT_DTYPES = {name: dtype for name, dtype, _ in EVENT_SCHEMA}
REAL_FIELDS = tuple(name for name, dtype, _ in EVENT_SCHEMA if dtype == np.float64)
INT_FIELDS = tuple(name for name, dtype, _ in EVENT_SCHEMA if dtype == np.int64)

# The packed parameters of a kernel call, in order (1-based in Fortran): the
# scene's fields, the parts' flat keys, and "drive", the drive the call starts at.
REAL_PARAMETERS = ("xi", "mu_d", "mu_s_mean", "sigma_mu", "dt", "refine_tol",
                   "max_event_duration", "alpha_max", "force_tol", "drive",
                   "incline", "driver_stiffness", "drive_max")
INT_PARAMETERS = ("walls", "seed", "record_sparse", "relax_only", "max_events", "loading")
# The loading protocols' codes in the int parameter "loading" (sliders_contract:
# loading_tilt, loading_pushed_end), declared by each loading (``Loading.code``).
LOADING_CODES = {name: cls.code for name, cls in LOADINGS.items()}


def pack_parameters(scene, drive: float, record_sparse: bool, relax_only: bool,
                    max_events: int) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's two parameter arrays (float64, int64) for one call from ``drive``."""
    calls = {"drive": drive, "walls": int(scene.walls), "record_sparse": int(record_sparse),
             "relax_only": int(relax_only), "max_events": max_events,
             **scene.friction.packed(), **scene.loading.packed()}
    real = np.array([float(calls[k]) if k in calls else float(getattr(scene, k))
                     for k in REAL_PARAMETERS], dtype=np.float64)
    ints = np.array([int(calls[k]) if k in calls else int(getattr(scene, k))
                     for k in INT_PARAMETERS], dtype=np.int64)
    return real, ints


def refine_limit_message(scene, drive: float) -> str:
    """What a run ended by the bisection bound says (both backends)."""
    return (f"crossing refinement at {scene.loading.drive_label}={drive:.6f}: bracket still wider than "
            f"refine_tol={scene.refine_tol} tau after {MAX_HALVINGS} halvings of dt={scene.dt} "
            f"(below double precision; use a larger refine_tol)")


def empty_events() -> dict[str, np.ndarray]:
    """The event fields of a run with no events."""
    return {f: np.zeros(0, dtype=EVENT_DTYPES[f]) for f in EVENT_FIELDS}


def events_from_records(records: list[dict]) -> dict[str, np.ndarray]:
    """The event fields from per-event dicts, each field with its dtype."""
    return {f: np.array([r[f] for r in records], dtype=float).astype(EVENT_DTYPES[f])
            for f in EVENT_FIELDS}


@dataclass
class Chunk:
    """What one call of a backend's ``advance`` produced."""

    status: int
    events: dict[str, np.ndarray]
    sparse_ptr: np.ndarray  # events[k] moved sliders are entries ptr[k]:ptr[k+1]
    sparse_index: np.ndarray
    sparse_displacement: np.ndarray
    alpha_c: float = math.nan
    message: str = ""
    final_event: dict = field(default_factory=dict)  # work of an unfinished last event

    @property
    def n_events(self) -> int:
        """Number of events in this chunk."""
        return len(self.events["drive"])


def join_chunks(pieces: list[Chunk], status: int, alpha_c: float = math.nan, message: str = "",
                final_event: dict | None = None) -> Chunk:
    """One chunk from consecutive ones, ending with ``status`` (CSR pointers shifted)."""
    events = {f: np.concatenate([c.events[f] for c in pieces]).astype(EVENT_DTYPES[f])
              if pieces else empty_events()[f] for f in EVENT_FIELDS}
    ptr = [np.zeros(1, dtype=np.int64)]
    offset = 0
    for c in pieces:
        ptr.append(c.sparse_ptr[1:] + offset)
        offset += c.sparse_index.size
    index = [np.asarray(c.sparse_index, dtype=np.int64) for c in pieces]
    values = [np.asarray(c.sparse_displacement, dtype=float) for c in pieces]
    return Chunk(
        status, events, np.concatenate(ptr),
        np.concatenate(index) if index else np.zeros(0, np.int64),
        np.concatenate(values) if values else np.zeros(0),
        alpha_c, message, dict(final_event or {}),
    )
