"""The record of one tilt run, and its HDF5 form."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from . import status
from .chain import ChainState, tangential_force as _tangential_force
from .scene import Scene

FORMAT_VERSION = 1


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
class TiltResult:
    """Everything a tilt run recorded.

    ``alpha`` is the angle of every completed rearrangement (increasing);
    ``alpha_c`` the avalanche angle (NaN if the run ended otherwise, see
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
        ``alpha`` (radians), ``n_moved``, ``n_stops``, ``n_steps``,
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
    <TiltResult Scene(n_sliders=10, seed=3): avalanche, alpha_c=0.5163 rad, 31 events, recorded displacements, backend fortran>
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
        """One line: the scene, how the run ended, alpha_c, the events and what was recorded."""
        end = (f"alpha_c={self.alpha_c:.4f} rad" if math.isfinite(self.alpha_c)
               else f"last event at alpha={self.alpha[-1]:.4f} rad" if self.n_events else "no event")
        if self.scene.loading == "pushed_end" and self.n_events:  # the drive is D, not an angle
            end = f"last event at driver position D={self.alpha[-1]:.4f} g tau^2"
        return (f"<TiltResult {self.scene!r}: {self.status}, {end}, {self.n_events} events, "
                f"recorded {self.scene.record}, backend {self.backend}>")

    def __getattr__(self, name):
        events = self.__dict__.get("events", {})
        if name in events:
            return events[name]
        raise AttributeError(name)

    @property
    def n_events(self) -> int:
        """Number of completed rearrangements (the avalanche event is not one)."""
        return int(self.events["alpha"].size)

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
        return _tangential_force(self.initial, self.scene.xi, self.scene.walls, self.alpha, du)

    def events_before(self, alphas) -> np.ndarray:
        """For each angle, how many rearrangements happened at or below it."""
        return np.searchsorted(self.alpha, np.asarray(alphas, dtype=float), side="right")

    def displacement_at(self, alphas) -> np.ndarray:
        """(G, N) displacement since preparation of the chain at rest at each angle."""
        alphas = np.asarray(alphas, dtype=float)
        after = np.vstack([self.initial.displacement[None, :], self.displacement_after()])
        return after[self.events_before(alphas)]

    def force_at(self, alphas) -> np.ndarray:
        """(G, N) tangential force of every slider at each angle (chain at rest there).

        Between events nothing moves, so F_n(alpha) = E_n + sin(alpha) with E_n
        the elastic force after the last rearrangement at or below alpha.
        Angles beyond the avalanche are meaningless (the chain is gone).
        """
        alphas = np.asarray(alphas, dtype=float)
        return _tangential_force(self.initial, self.scene.xi, self.scene.walls, alphas,
                                 self.displacement_at(alphas))

    def prepared_force(self) -> np.ndarray:
        """The drawn tangential forces at alpha = 0, before the coupling is switched on."""
        return self.initial.elastic_force0 + self.scene.xi * self.initial.cantilever_stretch0

    def start_force(self) -> np.ndarray:
        """F_t of every slider at alpha = 0 when the tilt starts (after any relaxation)."""
        return _tangential_force(self.initial, self.scene.xi, self.scene.walls, 0.0)

    # -- HDF5 ---------------------------------------------------------------
    def save(self, path: str | os.PathLike[str], overwrite: bool = True) -> None:
        """Write the run to an HDF5 file, atomically.

        The file is built in memory, written to a temporary file beside
        ``path``, flushed to the disk and renamed over it: an existing file is
        replaced only by a complete one (``overwrite=False``: never replaced,
        FileExistsError).  Every dataset and attribute set carries a CRC-32
        that ``load`` verifies, and the HDF5 user block (the file's first
        512 bytes, which HDF5 skips) a CRC-32 of the whole rest of the file:
        ``load`` checks it before HDF5 parses anything, so that damaged HDF5
        metadata cannot crash the process.
        """
        from .io.safeio import publish_bytes

        publish_bytes(path, self.to_bytes(), overwrite)

    def to_bytes(self) -> bytes:
        """The HDF5 file of the run, as bytes."""
        import io

        import h5py

        from . import __version__
        from .io.safeio import seal_attrs, seal_dataset

        def dataset(group, name, data):
            data = np.asarray(data)
            seal_dataset(group.create_dataset(name, data=data), data)

        buffer = io.BytesIO()
        with h5py.File(buffer, "w", userblock_size=WHOLE_FILE_BLOCK) as f:
            f.attrs["format"] = "sliders.tilt"
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["software_version"] = __version__
            f.attrs["scene"] = json.dumps(self.scene.to_dict())
            f.attrs["backend"] = self.backend
            f.attrs["status"] = self.status
            f.attrs["message"] = self.message
            f.attrs["alpha_c"] = self.alpha_c
            f.attrs["wall_time"] = self.wall_time
            f.attrs["relaxation"] = json.dumps(self.relaxation)
            f.attrs["final_event"] = json.dumps(self.final_event)
            ev = f.create_group("events")
            for name, values in self.events.items():
                dataset(ev, name, values)
            if self.displacement is not None:
                g = f.create_group("displacement")
                dataset(g, "ptr", self.displacement.ptr)
                dataset(g, "index", self.displacement.index.astype(np.int32))
                dataset(g, "value", self.displacement.value)
            for label, st in (("initial", self.initial), ("final", self.final)):
                g = f.create_group(label)
                for name in ("elastic_force0", "spring_extension0", "cantilever_stretch0",
                             "lattice_position0", "mu_s", "displacement", "n_stops"):
                    dataset(g, name, getattr(st, name))
                g.attrs["alpha"] = st.alpha
                seal_attrs(g)
            seal_attrs(f)
            from .io.conventions import describe_tilt_file

            # named dimensions, units, provenance: added after the seals, which
            # cover the data and the attributes that load() reads
            describe_tilt_file(f, self)
        return seal_whole_file(buffer.getvalue())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "TiltResult":
        """Read a saved run; every checksum is verified.

        A damaged or truncated file raises ``safeio.IntegrityError`` (an
        OSError) with one line naming the file and, for a flipped byte, the
        dataset; a file of another kind raises ValueError.
        """
        problem = whole_file_problem(path)
        if problem:
            from .io.safeio import IntegrityError

            raise IntegrityError(problem)
        return cls._load_checked(path)

    @classmethod
    def _load_checked(cls, path: str | os.PathLike[str]) -> "TiltResult":
        """``load`` without the whole-file check (per dataset and attribute set only)."""
        import h5py

        from .io.safeio import (IntegrityError, check_attrs, check_coordinates, describe_os_error,
                             read_checked)

        where = repr(os.fspath(path))
        try:
            f = h5py.File(path, "r")
        except FileNotFoundError as exc:
            raise FileNotFoundError(exc.errno, f"{where} does not exist") from None
        except OSError as exc:
            raise IntegrityError(f"{where} is not a readable HDF5 file ({exc})") from None
        try:
            with f:
                if f.attrs.get("format") != "sliders.tilt":
                    raise ValueError(f"{where} is not a sliders tilt file")
                check_attrs(f, where)
                check_coordinates(f, where)
                scene = Scene.from_dict(json.loads(f.attrs["scene"]))
                events = {name: read_checked(ds, where) for name, ds in f["events"].items()}
                disp = None
                if "displacement" in f:
                    g = f["displacement"]
                    disp = EventSparse(read_checked(g["ptr"], where),
                                       read_checked(g["index"], where).astype(np.int64),
                                       read_checked(g["value"], where), scene.n_sliders)
                states = {}
                for label in ("initial", "final"):
                    g = f[label]
                    check_attrs(g, where)
                    states[label] = ChainState(**{k: read_checked(g[k], where) for k in g},
                                               alpha=float(g.attrs["alpha"]))
                return cls(
                    scene=scene, backend=str(f.attrs["backend"]), status=str(f.attrs["status"]),
                    message=str(f.attrs["message"]), alpha_c=float(f.attrs["alpha_c"]),
                    events=events, displacement=disp, initial=states["initial"],
                    final=states["final"], relaxation=json.loads(f.attrs["relaxation"]),
                    wall_time=float(f.attrs["wall_time"]),
                    final_event=json.loads(f.attrs.get("final_event", "{}")),
                )
        except (IntegrityError, ValueError) as exc:
            if isinstance(exc, ValueError) and not str(exc).startswith(where):
                raise IntegrityError(f"{where} is damaged ({' '.join(str(exc).split())})") from None
            raise
        except OSError as exc:
            raise IntegrityError(f"{where} is damaged ({describe_os_error(exc, path)})") from None
        except Exception as exc:  # noqa: BLE001 - whatever HDF5 makes of a damaged file
            raise IntegrityError(f"{where} is damaged ({type(exc).__name__}: "
                                 f"{' '.join(str(exc).split())})") from None


# ---------------------------------------------------------------------------
# whole-file checksum in the HDF5 user block
# ---------------------------------------------------------------------------
WHOLE_FILE_BLOCK = 512  # bytes before the HDF5 superblock, which HDF5 leaves to the user
WHOLE_FILE_MAGIC = b"sliders.tilt whole-file crc32 "


def seal_whole_file(data: bytes) -> bytes:
    """Write the CRC-32 of everything after the user block into the user block."""
    import zlib

    out = bytearray(data)
    tag = WHOLE_FILE_MAGIC + b"%08x\n" % zlib.crc32(memoryview(out)[WHOLE_FILE_BLOCK:])
    out[:len(tag)] = tag
    return bytes(out)


def whole_file_problem(path) -> str | None:
    """One line if the file fails its whole-file checksum (then naming the damaged
    dataset when a sandboxed per-dataset check can), else None.  Files without
    the user-block checksum are left to the per-dataset checks."""
    import subprocess
    import sys
    import zlib

    where = repr(os.fspath(path))
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None  # the HDF5 open reports it, in its own words
    if not data.startswith(WHOLE_FILE_MAGIC):
        return None
    stored = data[len(WHOLE_FILE_MAGIC):len(WHOLE_FILE_MAGIC) + 8]
    if len(data) > WHOLE_FILE_BLOCK and stored == b"%08x" % zlib.crc32(data[WHOLE_FILE_BLOCK:]):
        return None
    # Damaged: say where if HDF5 can tell, in a child process (damaged metadata
    # can crash HDF5 1.10 itself).
    probe = ("import sys\nfrom sliders.result import TiltResult\ntry:\n"
             "    TiltResult._load_checked(sys.argv[1])\nexcept Exception as exc:\n"
             "    print(' '.join(str(exc).split()))\n")
    try:
        res = subprocess.run([sys.executable, "-c", probe, os.fspath(path)], capture_output=True,
                             text=True, timeout=120)
        named = res.stdout.strip() if res.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        named = ""
    if "checksum" in named or "damaged" in named:
        return named
    return f"{where} is damaged: it fails its whole-file checksum (in the HDF5 metadata)"

