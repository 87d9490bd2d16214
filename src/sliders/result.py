"""The record of one run, tilt or pushed end (its HDF5 form: ``sliders.io.run_file``)."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from .chain import ChainState
from .io.run_file import read_run_file, run_file_bytes, write_run_file
from .scene import Scene


@dataclass
class EventSparse:
    """Per-event values for the sliders that moved (CSR layout).

    Event k's entries are ``index[ptr[k]:ptr[k+1]]`` (slider numbers, 0-based,
    increasing) and ``value[ptr[k]:ptr[k+1]]``.
    """

    ptr: np.ndarray
    index: np.ndarray
    value: np.ndarray
    n_sliders: int

    def __repr__(self) -> str:
        """One line: the events, the sliders and the stored entries, not the arrays."""
        return (f"<EventSparse {self.n_events} events x {self.n_sliders} sliders, "
                f"{self.index.size} entries>")

    @property
    def n_events(self) -> int:
        """Number of events K."""
        return self.ptr.size - 1

    def event(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Slider numbers (0-based) and displacements (g tau^2) of the sliders that moved in event k."""
        a, b = self.ptr[k], self.ptr[k + 1]
        return self.index[a:b], self.value[a:b]

    def event_of_entry(self) -> np.ndarray:
        """Event number of every stored entry."""
        return np.repeat(np.arange(self.n_events), np.diff(self.ptr))

    def dense(self) -> np.ndarray:
        """Dense (K, N) array, zero where a slider did not move."""
        out = np.zeros((self.n_events, self.n_sliders))
        out[self.event_of_entry(), self.index] = self.value
        return out


@dataclass
class Result:
    """Everything a run recorded, tilt or pushed end.

    ``drive`` is the drive of every completed rearrangement (increasing): the
    tilt angle alpha, or for the pushed end the driver position D
    (``scene.loading.drive_label``); ``alpha`` is the incline's angle at
    each (the drive itself for the tilt, the fixed incline for the pushed
    end); ``alpha_c`` the avalanche angle (NaN if the run ended otherwise, see
    ``status``).  Per-event scalars: ``n_moved``, ``n_stops``, ``n_steps``,
    ``slider_steps``, ``duration`` (tau), ``work_gravity``, ``elastic_change``
    and ``dissipation``.  ``displacement`` holds the displacement of each
    slider that moved, per event (``.dense()`` for a (K, N) array); it is None
    when the scene records only a summary.  ``final_event`` is the work of the
    event that ended the run unfinished (the avalanche, the duration cap, an
    error): ``duration`` (tau), ``n_steps``, ``slider_steps``; empty if the
    run ended between events.

    Attributes
    ----------
    scene : Scene
        The run's scene.
    backend : str
        "fortran" or "numpy".
    status : str
        How the run ended: "avalanche", "alpha_max", "max_events",
        "event_duration_cap", "interrupted", ... (``sliders.status``).
    message : str
        The same in words.
    alpha_c : float
        Avalanche angle, radians (NaN unless ``status == "avalanche"``).
    events : dict of str to ndarray
        Per-event arrays of length K, also readable as attributes:
        ``drive`` (radians, or D in g tau^2), ``n_moved``, ``n_stops``, ``n_steps``,
        ``slider_steps``, ``duration`` (tau), ``work_gravity``,
        ``elastic_change``, ``dissipation`` (m g x g tau^2).
    displacement : EventSparse or None
        Displacement (g tau^2) of every slider that moved, per event.
    initial, final : ChainState
        The chain at the start of the tilt and at its end.
    relaxation : dict
        The relaxation at alpha = 0 when xi > 0: ``n_events``, ``n_moved``,
        ``slider_steps``.
    wall_time : float
        Seconds the run took.
    final_event : dict
        Work of the unfinished last event (see above).

    Examples
    --------
    >>> import sliders
    >>> sliders.tilt(sliders.Scene(n_sliders=10, seed=3))
    <Result Scene(n_sliders=10, seed=3): avalanche, alpha_c=0.5163 rad, 31 events, recorded displacements, backend fortran>
    """

    scene: Scene
    backend: str
    status: str
    message: str
    alpha_c: float
    events: dict[str, np.ndarray]
    displacement: EventSparse | None
    initial: ChainState
    final: ChainState
    relaxation: dict[str, float] = field(default_factory=dict)
    wall_time: float = math.nan
    final_event: dict[str, float] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line: the scene, how the run ended, alpha_c or the last drive, the events
        and what was recorded."""
        load = self.scene.loading
        end = (f"alpha_c={self.alpha_c:.4f} rad" if math.isfinite(self.alpha_c)
               else f"last event at {load.drive_label}={self.drive[-1]:.4f} {load.drive_unit}"
               if self.n_events else "no event")
        return (f"<Result {self.scene!r}: {self.status}, {end}, {self.n_events} events, "
                f"recorded {self.scene.record}, backend {self.backend}>")

    def __getattr__(self, name):
        events = self.__dict__.get("events", {})
        if name in events:
            return events[name]
        raise AttributeError(name)

    @property
    def drive(self) -> np.ndarray:
        """The drive of every completed rearrangement: the tilt angle alpha (rad), or the
        driver position D (g tau^2) of the pushed end; the event column ``drive``."""
        return self.events["drive"]

    @property
    def alpha(self) -> np.ndarray:
        """The incline's angle (rad) at every completed rearrangement: the drive itself
        for the tilt, the fixed incline for the pushed end (a run file's ``events/alpha``)."""
        return self.scene.loading.incline_at(self.drive)

    @property
    def n_events(self) -> int:
        """Number of completed rearrangements (the avalanche event is not one)."""
        return int(self.events["drive"].size)

    @property
    def total_slider_steps(self) -> int:
        """Integration work of the whole run: relaxation, events and the final event."""
        return (int(self.events["slider_steps"].sum()) + int(self.relaxation.get("slider_steps", 0))
                + int(self.final_event.get("slider_steps", 0)))

    @property
    def energy_residual(self) -> np.ndarray:
        """Work of gravity - elastic change - dissipation, per event."""
        e = self.events
        return e["work_gravity"] - e["elastic_change"] - e["dissipation"]

    def _forces(self, drives, displacement=None):
        """The scene's loading's forces (tilt or pushed end) on the initial chain."""
        sc = self.scene
        return sc.loading.forces(self.initial, sc.xi, sc.walls, drives, displacement)

    def _need_displacements(self, what: str) -> EventSparse:
        if self.displacement is None:
            raise ValueError(
                f"{what} needs the displacements: this run recorded only a summary "
                f"(scene.record={self.scene.record!r}); rerun with record='displacements' or 'forces'"
            )
        return self.displacement

    def displacement_after(self) -> np.ndarray:
        """(K, N) displacement since preparation after each event."""
        return self.initial.displacement + np.cumsum(self._need_displacements("displacement_after").dense(), axis=0)

    @property
    def tangential_force(self) -> np.ndarray:
        """(K, N) tangential force F_t of every slider just after each event."""
        du = self.displacement_after()
        return self._forces(self.drive, du)

    def events_before(self, alphas) -> np.ndarray:
        """For each angle (each drive), how many rearrangements happened at or below it."""
        return np.searchsorted(self.drive, np.asarray(alphas, dtype=float), side="right")

    def displacement_at(self, alphas) -> np.ndarray:
        """(G, N) displacement since preparation of the chain at rest at each angle."""
        alphas = np.asarray(alphas, dtype=float)
        after = np.vstack([self.initial.displacement[None, :], self.displacement_after()])
        return after[self.events_before(alphas)]

    def force_at(self, alphas) -> np.ndarray:
        """(G, N) tangential force of every slider at each angle (chain at rest there).

        Between events nothing moves, so F_n(alpha) = E_n + sin(alpha) with E_n
        the elastic force after the last rearrangement at or below alpha.
        Angles beyond the avalanche are meaningless (the chain is gone).  With
        loading='pushed_end' the angles are driver positions D, and slider 1
        also feels the driver's spring K (D - u_1).
        """
        alphas = np.asarray(alphas, dtype=float)
        return self._forces(alphas, self.displacement_at(alphas))

    def prepared_force(self) -> np.ndarray:
        """The drawn tangential forces at alpha = 0, before the coupling is switched on."""
        return self.initial.elastic_force0 + self.scene.xi * self.initial.cantilever_stretch0

    def start_force(self) -> np.ndarray:
        """F_t of every slider at alpha = 0 (pushed end: D = 0) when the loading
        starts (after any relaxation)."""
        return self._forces(0.0)

    # -- HDF5 (the layout, the writer and the reader: sliders.io.run_file) --
    def save(self, path: str | os.PathLike[str], overwrite: bool = True) -> None:
        """Write the run to an HDF5 file, atomically.

        The file is built in memory, written to a temporary file beside
        ``path``, flushed to the disk and renamed over it: an existing file is
        replaced only by a complete one (``overwrite=False``: never replaced,
        FileExistsError).  Every dataset and attribute set carries a CRC-32
        that ``load`` verifies, and the HDF5 user block (the file's first
        512 bytes, which HDF5 skips) a CRC-32 of the whole rest of the file:
        ``load`` checks it before HDF5 parses anything, so that damaged HDF5
        metadata cannot crash the process.  The layout: ``sliders.io.run_file``.
        While writing, the output is claimed (``sliders.io.filelock``): a run
        writing the same file makes this raise; temporary files of an earlier,
        killed save are removed (with a warning).  A symlink is written
        through: the file it names is replaced, the link stays.
        """
        write_run_file(path, self, overwrite)

    def to_bytes(self) -> bytes:
        """The HDF5 file of the run, as bytes."""
        return run_file_bytes(self)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Result":
        """Read a saved run; every checksum is verified.

        A damaged or truncated file raises ``safeio.IntegrityError`` (an
        OSError) with one line naming the file and, for a flipped byte, the
        dataset; a file of another kind raises ValueError.
        """
        fields = read_run_file(path)
        if fields["displacement"] is not None:
            fields["displacement"] = EventSparse(*fields["displacement"], fields["scene"].n_sliders)
        return cls(**fields)

