"""Event catalogues: what an experiment records of a tilt run, and many of them as ragged columns.

An experimenter sees the rearrangements, not the forces or the friction
coefficients.  Per event a catalogue keeps:

================  =======  ==========================================================
column            dtype    meaning
================  =======  ==========================================================
``alpha``         float64  tilt of the rearrangement, radians (increasing)
``size``          int64    distinct sliders that moved (float64: a measured size in
                           an arbitrary unit, an area or a volume, when not whole)
``displacement``  float64  sum of the sliders' displacements, g tau^2
``first``         int64    first (up-slope) slider that moved, 0-based (-1: unknown;
                           float64: a camera's position, a fraction of the pile's length)
``last``          int64    last (down-slope) slider that moved, 0-based (-1: unknown)
================  =======  ==========================================================

``CatalogueSet`` holds many realisations as ragged arrays (``offsets`` plus
flat columns), with the parameters drawn for each row, ``alpha_c`` and the
status: the in-memory form of a prior ensemble (the file:
``sliders.io.prior_file``) and what the forecasters train and test on.
This module is plain NumPy: it neither runs nor plots.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EVENT_COLUMNS = ("alpha", "size", "displacement", "first", "last")
EVENT_DTYPES = {"alpha": np.float64, "size": np.int64, "displacement": np.float64,
                "first": np.int64, "last": np.int64}


def _whole(values) -> bool:
    """Whether a column holds whole numbers only (a size in sliders, a slider index)."""
    v = np.asarray(values)
    return v.dtype.kind in "iub" or bool(np.all(v == np.round(v)))


@dataclass
class Catalogue:
    """One realisation's events, as an experiment records them (see the module's table).

    Parameters
    ----------
    alpha, size, displacement, first, last : numpy.ndarray
        The per-event columns, one entry per rearrangement, ``alpha`` increasing.
    tilt_now : float, optional
        The tilt reached when the catalogue was taken (radians); at least the
        last event's angle.  None: the last event's angle (0 if there is none).
    """

    alpha: np.ndarray
    size: np.ndarray
    displacement: np.ndarray
    first: np.ndarray
    last: np.ndarray
    tilt_now: float | None = None

    def __post_init__(self):
        for name in EVENT_COLUMNS:
            dtype = EVENT_DTYPES[name] if _whole(getattr(self, name)) else np.float64
            setattr(self, name, np.asarray(getattr(self, name), dtype=dtype))
        n = self.alpha.size
        if any(getattr(self, c).shape != (n,) for c in EVENT_COLUMNS):
            raise ValueError("catalogue columns must be 1-d and of one length")
        if n and np.any(np.diff(self.alpha) < 0):
            raise ValueError("catalogue angles must be increasing")
        last = float(self.alpha[-1]) if n else 0.0
        if self.tilt_now is None:
            self.tilt_now = last
        elif self.tilt_now < last:
            raise ValueError(f"tilt_now={self.tilt_now!r} is below the last event ({last!r})")

    def __len__(self) -> int:
        """Number of events."""
        return int(self.alpha.size)

    def __repr__(self) -> str:
        """One line: the events and the tilt reached."""
        return f"<Catalogue {len(self)} events up to tilt {self.tilt_now:.4f} rad>"

    @property
    def complete(self) -> bool:
        """Every displacement and every mover known (an empty catalogue is complete)."""
        return (not np.isnan(self.displacement).any() and bool((self.first >= 0).all())
                and bool((self.last >= 0).all()))

    def angles_and_sizes(self) -> "Catalogue":
        """The catalogue of its angles and sizes only: displacements 0, movers -1 (unknown),
        as a record without those columns is read."""
        n = len(self)
        return Catalogue(self.alpha, self.size, np.zeros(n), np.full(n, -1), np.full(n, -1),
                         self.tilt_now)

    def cut(self, alpha_obs: float) -> "Catalogue":
        """The catalogue as seen at tilt ``alpha_obs``: the events at angles <= ``alpha_obs``."""
        k = int(np.searchsorted(self.alpha, alpha_obs, side="right"))
        return Catalogue(*(getattr(self, c)[:k] for c in EVENT_COLUMNS),
                         tilt_now=max(float(alpha_obs), float(self.alpha[k - 1]) if k else 0.0))

    @classmethod
    def from_result(cls, result) -> "Catalogue":
        """The catalogue of a ``Result`` (its completed events; the run's last tilt as ``tilt_now``).

        The total displacement of an event is its work of gravity over
        sin(alpha) (``work_gravity = sin(alpha) * sum of displacements``); the
        first and last sliders need the recorded displacements
        (``record="displacements"`` or ``"forces"``), else they are -1.
        """
        ev = result.events
        alpha = np.asarray(ev["drive"], dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            disp = np.where(alpha > 0, ev["work_gravity"] / np.sin(alpha), 0.0)
        first = np.full(alpha.size, -1, dtype=np.int64)
        last = np.full(alpha.size, -1, dtype=np.int64)
        sparse = result.displacement
        if sparse is not None and sparse.n_events == alpha.size and alpha.size:
            counts = np.diff(sparse.ptr)
            moved = counts > 0
            starts = sparse.ptr[:-1][moved]
            ends = sparse.ptr[1:][moved] - 1
            first[moved] = sparse.index[starts]  # indices are increasing within an event
            last[moved] = sparse.index[ends]
            disp = np.add.reduceat(sparse.value, sparse.ptr[:-1]) if moved.all() else disp
        return cls(alpha, np.asarray(ev["n_moved"]), disp, first, last)


@dataclass
class CatalogueSet:
    """Many realisations' catalogues as ragged columns, with what each row was drawn from.

    Row ``i``'s events are ``columns[c][offsets[i]:offsets[i + 1]]``.

    Parameters
    ----------
    offsets : numpy.ndarray
        (R + 1,) int64, ``offsets[0] == 0``, non-decreasing.
    columns : dict of str to numpy.ndarray
        The flat event columns of ``EVENT_COLUMNS``, each (offsets[-1],).
    parameters : dict of str to numpy.ndarray
        Per row, (R,): at least ``mu_d``, ``mu_s_mean``, ``sigma_mu``, ``xi``,
        ``n_sliders`` (the drawn material), and any other drawn parameter;
        a prior file (``read_prior_ensemble``) adds ``initial_forces`` (the
        preparation, str: "uniform", "zero" or "history") and the row's scene ``seed``.
    alpha_c : numpy.ndarray
        (R,) the avalanche angle, radians (NaN unless the status is "avalanche").
    status : numpy.ndarray
        (R,) the run's status name (``sliders.status.NAMES``), as str.
    ceiling_alpha : numpy.ndarray, optional
        (G,) the angles at which the simulation's own state was kept.
    ceiling_distance : numpy.ndarray, optional
        (R, G, K): at each of those angles, the K smallest distances of a
        slider to its threshold, ``mu_s,n cos(alpha) - |F_n|`` in m g,
        increasing (NaN past the avalanche): what only a simulation knows.
    attrs : dict
        Provenance (prior, seed, versions, command).
    """

    offsets: np.ndarray
    columns: dict
    parameters: dict
    alpha_c: np.ndarray
    status: np.ndarray
    ceiling_alpha: np.ndarray | None = None
    ceiling_distance: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)

    def __len__(self) -> int:
        """Number of rows (realisations)."""
        return int(self.offsets.size - 1)

    def __repr__(self) -> str:
        """One line: rows, events, parameters."""
        return (f"<CatalogueSet {len(self)} rows, {int(self.offsets[-1])} events, "
                f"parameters {sorted(self.parameters)}>")

    def catalogue(self, i: int) -> Catalogue:
        """Row ``i``'s whole catalogue (every event up to the end of the run)."""
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        return Catalogue(*(self.columns[c][a:b] for c in EVENT_COLUMNS))

    def subset(self, rows) -> "CatalogueSet":
        """The rows ``rows`` (indices or a boolean mask), in that order, as a new set."""
        rows = np.arange(len(self))[np.asarray(rows)]
        counts = np.diff(self.offsets)[rows]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        take = (np.concatenate([np.arange(self.offsets[i], self.offsets[i + 1]) for i in rows])
                if rows.size else np.zeros(0, dtype=np.int64)).astype(np.int64)
        return CatalogueSet(
            offsets, {c: v[take] for c, v in self.columns.items()},
            {k: v[rows] for k, v in self.parameters.items()}, self.alpha_c[rows],
            self.status[rows], self.ceiling_alpha,
            None if self.ceiling_distance is None else self.ceiling_distance[rows],
            dict(self.attrs))

    @classmethod
    def joined(cls, sets) -> "CatalogueSet":
        """One set of the rows of ``sets``, in order: the parameters they have in common, no
        ceiling, the first set's provenance with every set's prior digest."""
        sets = list(sets)
        if len(sets) == 1:
            return sets[0]
        common = set.intersection(*(set(s.parameters) for s in sets))
        return cls.from_catalogues(
            [s.catalogue(i) for s in sets for i in range(len(s))],
            {k: np.concatenate([np.asarray(s.parameters[k]) for s in sets]) for k in sorted(common)},
            np.concatenate([s.alpha_c for s in sets]), np.concatenate([s.status for s in sets]),
            attrs=sets[0].attrs | {"prior_digest": "+".join(str(s.attrs.get("prior_digest", ""))
                                                             for s in sets)})

    @classmethod
    def from_catalogues(cls, catalogues, parameters: dict, alpha_c, status,
                        ceiling_alpha=None, ceiling_distance=None, attrs=None) -> "CatalogueSet":
        """Stack per-row ``Catalogue`` objects into ragged columns."""
        catalogues = list(catalogues)
        offsets = np.concatenate([[0], np.cumsum([len(c) for c in catalogues])]).astype(np.int64)
        columns = {c: (np.concatenate([getattr(k, c) for k in catalogues]) if catalogues
                       else np.zeros(0)).astype(EVENT_DTYPES[c]) for c in EVENT_COLUMNS}
        return cls(offsets, columns, {k: np.asarray(v) for k, v in parameters.items()},
                   np.asarray(alpha_c, dtype=np.float64), np.asarray(status, dtype=str),
                   None if ceiling_alpha is None else np.asarray(ceiling_alpha, dtype=np.float64),
                   None if ceiling_distance is None else np.asarray(ceiling_distance, dtype=np.float64),
                   dict(attrs or {}))
