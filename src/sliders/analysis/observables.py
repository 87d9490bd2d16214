"""Observables of tilt runs, per run and over an ensemble of realisations.

Every quantity of the paper's figures and statements is computed here from
what a run recorded (``Result``); the figures and the reproduction report
only draw or compare.  Two layers:

* **per run**: ``displacement_map``, ``force_history``, ``force_histogram``,
  ``model_bin_counts``, ``cumulated_displacement``, ``mean_event_displacement``,
  ``stopped_force_ratio_histogram``, ``event_sizes``, ``synchronisation`` ...
  Those that need the displacement of every slider raise ``ValueError`` when
  the run recorded only a summary (``scene.record="summary"``).
* **per realisation row / ensemble**: ``realisation_statistics(result, grids)``
  reduces one run to a dict of arrays whose shapes depend only on the grids
  (the MPI ensemble stores one such row per realisation), and
  ``combine(rows, grids, n_sliders)`` turns rows stacked over realisations
  into an ``EnsembleSummary`` of means and standard errors.

Conventions (decided here, the paper is silent):

* **Valid angles.**  The chain exists at rest at an angle ``alpha`` only
  before the avalanche: ``alpha < alpha_c``.  For a run that ended otherwise
  the limit is ``scene.alpha_max`` (inclusive) for status ``"alpha_max"``, the
  last completed event angle (inclusive) for ``"max_events"`` and the angle of
  the failed event (exclusive) for an error status.  Histograms are zero at
  invalid angles and come with a boolean ``valid`` mask; ensemble means use
  only the runs valid at each angle (``EnsembleSummary.n_valid``).
* **Histogram range.**  Values outside the outer edges are counted in the end
  bins (``np.clip``), so that every row of a force histogram sums to N.  The
  default edges contain every possible value (abs(F_t) <= mu_s cos(alpha)).
* **Displacement sums are signed** (the paper's A(alpha) sums
  x^(i+1) - x^(i)); a slider pushed uphill counts negatively.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..io.conventions import LENGTH
from .model import n_bins

__all__ = [
    "StatisticsGrids", "default_grids", "valid_limit", "valid_alphas",
    "displacement_map", "force_history", "force_before_events", "force_histogram",
    "model_bin_index", "model_bin_counts", "event_total_displacement",
    "cumulated_displacement", "mean_event_displacement", "stopped_force_ratios",
    "stopped_force_ratio_histogram", "event_sizes", "event_size_counts",
    "synchronisation", "moving_clusters", "extremity_activity", "realisation_statistics",
    "statistics_layout", "Statistic", "STATISTICS", "statistic_conventions",
    "EnsembleSummary", "combine", "summary_from_results", "exponential_fit",
    "linear_fit",
]

# -----------------------------------------------------------------------------
# grids
# -----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class StatisticsGrids:
    """The fixed grids on which per-realisation statistics are accumulated.

    ``alpha`` (G,): angles at which the force PDF, the model bins P_i and the
    cumulated displacement A(alpha) are sampled (increasing, from 0).
    ``force_edges`` (B+1,): edges of the F_t histogram.
    ``ratio_edges``: edges of the histogram of F_t / F_t* for stopped sliders,
    F_t* = (2 mu_d - mu_s_mean) cos(alpha_k).
    ``stop_alpha_edges``: angle bins in which those ratios are collected (by the
    angle alpha_k of the event the slider moved in).
    ``n_model_bins``: nu(0) of the model, the number of bins of width 2 dmu
    counted down from ``mu_s_mean``.
    ``mu_s_mean``, ``mu_d``: the friction coefficients the bins refer to.
    """

    alpha: np.ndarray
    force_edges: np.ndarray
    ratio_edges: np.ndarray
    stop_alpha_edges: np.ndarray
    n_model_bins: int
    mu_s_mean: float
    mu_d: float

    def __post_init__(self) -> None:
        for name in ("alpha", "force_edges", "ratio_edges", "stop_alpha_edges"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.ndim != 1 or a.size < (1 if name == "alpha" else 2):
                raise ValueError(f"grids.{name} must be a 1-d array "
                                 f"(at least {1 if name == 'alpha' else 2} values), got shape {a.shape}")
            if not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0):
                raise ValueError(f"grids.{name} must be finite and strictly increasing")
            object.__setattr__(self, name, a)
        if not (isinstance(self.n_model_bins, (int, np.integer)) and self.n_model_bins >= 1):
            raise ValueError(f"grids.n_model_bins must be a positive int, got {self.n_model_bins!r}")
        object.__setattr__(self, "n_model_bins", int(self.n_model_bins))
        if not self.mu_s_mean > self.mu_d:
            raise ValueError(f"grids need mu_s_mean > mu_d, got {self.mu_s_mean!r}, {self.mu_d!r}")
        object.__setattr__(self, "mu_s_mean", float(self.mu_s_mean))
        object.__setattr__(self, "mu_d", float(self.mu_d))

    @property
    def delta_mu(self) -> float:
        """Delta mu = mu_s_mean - mu_d, half the width of a model bin."""
        return self.mu_s_mean - self.mu_d

    @property
    def ratio_centers(self) -> np.ndarray:
        """Centres of the stopped-force ratio bins (dimensionless)."""
        return 0.5 * (self.ratio_edges[1:] + self.ratio_edges[:-1])

    @property
    def stop_alpha_centers(self) -> np.ndarray:
        """Centres of the angle bins of the stopped-force ratio, radians."""
        return 0.5 * (self.stop_alpha_edges[1:] + self.stop_alpha_edges[:-1])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays (for HDF5 datasets/attributes); inverse of ``from_arrays``."""
        return {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_arrays(cls, d: Mapping[str, object]) -> "StatisticsGrids":
        """The grids stored by ``to_arrays`` (as read from a file)."""
        return cls(
            alpha=np.asarray(d["alpha"], dtype=float),
            force_edges=np.asarray(d["force_edges"], dtype=float),
            ratio_edges=np.asarray(d["ratio_edges"], dtype=float),
            stop_alpha_edges=np.asarray(d["stop_alpha_edges"], dtype=float),
            n_model_bins=int(np.asarray(d["n_model_bins"])),
            mu_s_mean=float(np.asarray(d["mu_s_mean"])),
            mu_d=float(np.asarray(d["mu_d"])),
        )


def _model_n_bins(mu_s_mean: float, mu_d: float) -> int:
    """nu(0) = ceil(2 mu_s / (2 dmu)) (``model.n_bins`` at alpha = 0)."""
    return int(n_bins(0.0, mu_s_mean, mu_d))


def default_grids(scene, n_alpha: int = 55, n_force_bins: int = 120,
                  ratio_step: float = 0.005, stop_alpha_step: float = 0.05) -> StatisticsGrids:
    """Grids for a scene's statistics.

    * ``alpha``: ``n_alpha`` angles from 0 to atan(mu_s_mean) inclusive (the
      upper bound of alpha_c; 55 gives steps of 0.01 for mu_s_mean = 0.6).
    * ``force_edges``: ``n_force_bins`` equal bins on [-b, b], b = mu_s_mean +
      6 sigma_mu rounded up to 0.1 (121 edges on [-0.7, 0.7] by default).
    * ``ratio_edges``: steps of ``ratio_step`` covering every possible
      F_t/F_t*, i.e. +-(mu_s_mean + 6 sigma_mu)/abs(2 mu_d - mu_s_mean) rounded up
      to 0.1 (+-1.3 by default, 520 bins); figures show 0.5..1.3.
    * ``stop_alpha_edges``: steps of ``stop_alpha_step`` from 0 to beyond
      atan(mu_s_mean) (0, 0.05, ..., 0.55).
    """
    mu_s, mu_d, sigma = scene.mu_s_mean, scene.mu_d, scene.sigma_mu
    if not (isinstance(n_alpha, (int, np.integer)) and n_alpha >= 2):
        raise ValueError(f"n_alpha must be an int >= 2, got {n_alpha!r}")
    alpha = np.linspace(0.0, math.atan(mu_s), int(n_alpha))
    bound = math.ceil(round((mu_s + 6.0 * sigma) * 10.0, 9)) / 10.0
    force_edges = np.linspace(-bound, bound, int(n_force_bins) + 1)
    star = abs(2.0 * mu_d - mu_s)
    if star == 0.0:
        raise ValueError("F_t* = (2 mu_d - mu_s_mean) cos(alpha) vanishes for these "
                         f"coefficients (mu_d={mu_d}, mu_s_mean={mu_s}); the stopped-force "
                         "ratio is undefined")
    rbound = math.ceil(round((mu_s + 6.0 * sigma) / star * 10.0, 9)) / 10.0
    n_ratio = int(round(2.0 * rbound / ratio_step))
    ratio_edges = np.linspace(-rbound, rbound, n_ratio + 1)
    n_stop = int(math.ceil(math.atan(mu_s) / stop_alpha_step - 1e-9))
    stop_alpha_edges = stop_alpha_step * np.arange(n_stop + 1)
    return StatisticsGrids(alpha, force_edges, ratio_edges, stop_alpha_edges,
                           _model_n_bins(mu_s, mu_d), mu_s, mu_d)


# -----------------------------------------------------------------------------
# per run
# -----------------------------------------------------------------------------


def _tilt_only(result, what: str) -> None:
    """These observables read the drive as the tilt (sin and cos of it)."""
    if not result.scene.loading.drive_is_angle:
        raise ValueError(f"{what} is an observable of the tilt (it takes sin and cos of the "
                         f"drive); this run has loading={result.scene.loading.name!r}")


def valid_limit(result) -> tuple[float, bool]:
    """(angle, inclusive): the chain is at rest at alpha < angle (<= if inclusive).

    See the module notes: alpha_c for an avalanche, scene.alpha_max for
    "alpha_max", the last event for "max_events", the failed event otherwise.
    """
    _tilt_only(result, "valid_limit")
    if result.status == "avalanche" and math.isfinite(result.alpha_c):
        return float(result.alpha_c), False
    if result.status == "alpha_max":
        return float(result.scene.alpha_max), True
    if result.status == "max_events":
        return (float(result.alpha[-1]) if result.n_events else 0.0), True
    return float(result.final.drive), False


def valid_alphas(result, alphas) -> np.ndarray:
    """Boolean mask of the angles at which the chain is at rest (before the avalanche)."""
    a = np.asarray(alphas, dtype=float)
    limit, inclusive = valid_limit(result)
    return a <= limit if inclusive else a < limit


def _need(result, what: str):
    if result.displacement is None:
        raise ValueError(
            f"{what} needs the displacement of every slider, but this run recorded only a "
            f"summary (scene.record={result.scene.record!r}); rerun with "
            "record='displacements' or 'forces'")
    return result.displacement


def displacement_map(result) -> np.ndarray:
    """(K, N) displacement of every slider in every event (zero if it did not move)."""
    return _need(result, "displacement_map").dense()


def force_history(result) -> np.ndarray:
    """(K, N) tangential force F_t of every slider just after every event."""
    _need(result, "force_history")
    return np.asarray(result.tangential_force)


def force_before_events(result, after: np.ndarray | None = None) -> np.ndarray:
    """(K, N) tangential force just before every event (at the event angle).

    Nothing moves between events, so F_before[k] = F_after[k-1] - sin a_{k-1}
    + sin a_k (F_after[-1] the force when the tilt starts, at alpha = 0).
    """
    _tilt_only(result, "force_before_events")
    after = force_history(result) if after is None else after
    if result.n_events == 0:
        return np.zeros((0, result.scene.n_sliders))
    a = np.asarray(result.alpha, dtype=float)
    prev = np.vstack([result.start_force()[None, :], after[:-1]])
    a_prev = np.concatenate([[0.0], a[:-1]])
    return prev + (np.sin(a) - np.sin(a_prev))[:, None]


def _hist_rows(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Row-wise histogram of (G, M) values on edges; outside values go to the end bins."""
    b = edges.size - 1
    idx = np.searchsorted(edges, values, side="right") - 1
    idx = np.clip(idx, 0, b - 1)
    g = values.shape[0]
    flat = (np.arange(g)[:, None] * b + idx).ravel()
    return np.bincount(flat, minlength=g * b).reshape(g, b).astype(np.int64)


def force_histogram(result, alphas, edges) -> tuple[np.ndarray, np.ndarray]:
    """Counts of F_t of all sliders at each angle, and the validity mask.

    Returns ``(counts, valid)``: ``counts`` (G, B) int64, row g the histogram
    of the N forces of the chain at rest at ``alphas[g]``; rows at angles at
    or beyond the avalanche (``valid[g]`` False) are zero.  Each valid row
    sums to N (values outside the edges go to the end bins).
    """
    _need(result, "force_histogram")
    a = np.asarray(alphas, dtype=float)
    edges = np.asarray(edges, dtype=float)
    valid = valid_alphas(result, a)
    counts = np.zeros((a.size, edges.size - 1), dtype=np.int64)
    if valid.any():
        counts[valid] = _hist_rows(result.force_at(a[valid]), edges)
    return counts, valid


def model_bin_index(forces, mu_s_mean: float, mu_d: float, n_bins: int) -> np.ndarray:
    """Model bin number (1-based) of each force: bins of width 2 dmu down from mu_s_mean.

    Bin i holds ]mu_s - 2 i dmu, mu_s - 2 (i-1) dmu]; bin 1 also takes every
    force above mu_s_mean, bin ``n_bins`` everything below its upper edge.
    """
    dmu = mu_s_mean - mu_d
    i = np.floor((mu_s_mean - np.asarray(forces, dtype=float)) / (2.0 * dmu)).astype(np.int64) + 1
    return np.clip(i, 1, n_bins)


def model_bin_counts(result, alphas, mu_s_mean: float, mu_d: float, n_bins: int) -> np.ndarray:
    """(G, n_bins) number of sliders in each model bin at each angle (zero rows when invalid).

    The measured bin height is P_i = counts / (N 2 dmu) (probability per unit
    force, as in the paper, so that sum_i 2 dmu P_i = 1).
    """
    _need(result, "model_bin_counts")
    a = np.asarray(alphas, dtype=float)
    valid = valid_alphas(result, a)
    out = np.zeros((a.size, int(n_bins)), dtype=np.int64)
    if valid.any():
        idx = model_bin_index(result.force_at(a[valid]), mu_s_mean, mu_d, int(n_bins)) - 1
        g = int(valid.sum())
        flat = (np.arange(g)[:, None] * n_bins + idx).ravel()
        out[valid] = np.bincount(flat, minlength=g * n_bins).reshape(g, n_bins)
    return out


def event_total_displacement(result) -> np.ndarray:
    """(K,) sum over sliders of the (signed) displacement in each event.

    From the recorded displacements when present; for a summary-only run from
    the work of gravity, W_k / sin(alpha_k) (same value up to rounding).
    """
    if result.displacement is not None:
        d = result.displacement
        totals = np.zeros(d.n_events)
        np.add.at(totals, d.event_of_entry(), d.value)
        return totals
    _tilt_only(result, "event_total_displacement of a summary-only run")
    a = np.asarray(result.alpha, dtype=float)
    if np.any(a <= 0.0):
        raise ValueError("event_total_displacement: a summary-only run with an event at "
                         "alpha = 0 has no recorded displacement sum")
    return np.asarray(result.work_gravity, dtype=float) / np.sin(a)


def cumulated_displacement(result, alphas) -> np.ndarray:
    """A(alpha) = sum over events with alpha_k <= alpha of sum_n dx_n, at each angle.

    Constant after the last event (the avalanche itself is not counted).
    """
    totals = np.concatenate([[0.0], np.cumsum(event_total_displacement(result))])
    return totals[result.events_before(np.asarray(alphas, dtype=float))]


def mean_event_displacement(result) -> np.ndarray:
    """(K,) <dx> of every event: mean displacement over the sliders that moved in it."""
    d = _need(result, "mean_event_displacement")
    counts = np.diff(d.ptr)
    totals = np.zeros(d.n_events)
    np.add.at(totals, d.event_of_entry(), d.value)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, totals / np.maximum(counts, 1), np.nan)


def stopped_force_ratios(result) -> tuple[np.ndarray, np.ndarray]:
    """(alpha_k, ratio) for every (event, slider that moved in it).

    ratio = F_t / F_t*, F_t the slider's force just after event k and
    F_t* = (2 mu_d - mu_s_mean) cos(alpha_k).
    """
    d = _need(result, "stopped_force_ratios")
    _tilt_only(result, "stopped_force_ratios")
    sc = result.scene
    star_coef = 2.0 * sc.mu_d - sc.mu_s_mean
    if star_coef == 0.0:
        raise ValueError("F_t* = (2 mu_d - mu_s_mean) cos(alpha) vanishes; ratio undefined")
    after = force_history(result)
    ev = d.event_of_entry()
    a = np.asarray(result.alpha, dtype=float)[ev]
    forces = after[ev, d.index]
    return a, forces / (star_coef * np.cos(a))


def stopped_force_ratio_histogram(result, alpha_edges, ratio_edges) -> np.ndarray:
    """Counts of F_t/F_t* of stopped sliders, by event angle: (len(alpha_edges)-1, len(ratio_edges)-1).

    Event angles outside ``alpha_edges`` are dropped; ratios outside
    ``ratio_edges`` go to the end bins.
    """
    a, r = stopped_force_ratios(result)
    alpha_edges = np.asarray(alpha_edges, dtype=float)
    ratio_edges = np.asarray(ratio_edges, dtype=float)
    na, nr = alpha_edges.size - 1, ratio_edges.size - 1
    ia = np.searchsorted(alpha_edges, a, side="right") - 1
    keep = (ia >= 0) & (ia < na)
    ir = np.clip(np.searchsorted(ratio_edges, r[keep], side="right") - 1, 0, nr - 1)
    flat = ia[keep] * nr + ir
    return np.bincount(flat, minlength=na * nr).reshape(na, nr).astype(np.int64)


def event_sizes(result) -> np.ndarray:
    """(K,) number of distinct sliders that moved in each event."""
    return np.asarray(result.n_moved, dtype=np.int64)


def event_size_counts(result) -> np.ndarray:
    """(N,) number of events of size s at index s - 1."""
    n = result.scene.n_sliders
    s = event_sizes(result)
    return np.bincount(np.clip(s, 0, n), minlength=n + 1)[1:].astype(np.int64)


def synchronisation(result, n_parts: int = 2) -> dict[str, np.ndarray]:
    """Which parts of the chain move together, event by event.

    The chain is cut into ``n_parts`` equal parts (halves by default).  For
    each event: ``parts_moved`` (K,) how many parts contain a slider that
    moved, ``all_parts`` (K,) bool, every part moved in that event, and
    ``alpha`` (K,).  The paper's "two active regions synchronise" shows as
    events in which both halves move at once.
    """
    d = _need(result, "synchronisation")
    n = result.scene.n_sliders
    part = np.minimum(d.index * n_parts // n, n_parts - 1)
    hit = np.zeros((d.n_events, n_parts), dtype=bool)
    hit[d.event_of_entry(), part] = True
    moved = hit.sum(axis=1)
    return {"alpha": np.asarray(result.alpha, dtype=float), "parts_moved": moved,
            "all_parts": moved == n_parts}


def moving_clusters(result) -> np.ndarray:
    """(K,) number of separate groups of adjacent sliders that moved in each event.

    Without global coupling (xi = 0) a slider starts only when a neighbour
    moves, so the sliders of one event form a single group (unless two
    thresholds are crossed at the same angle).  Two or more groups in one
    event mean that distant regions rearranged together through the plate:
    the synchronisation indicator of the reproduction report.
    """
    d = _need(result, "moving_clusters")
    out = np.zeros(d.n_events, dtype=np.int64)
    for k in range(d.n_events):
        idx, _ = d.event(k)
        if idx.size:
            out[k] = 1 + int(np.count_nonzero(np.diff(np.sort(idx)) > 1))
    return out


def extremity_activity(result, edges, end_fraction: float = 0.25) -> dict[str, np.ndarray]:
    """Where along the chain the rearrangements of each angle bin happen: at the ends or not.

    For the events with ``edges[j] <= alpha_k < edges[j+1]`` (every recorded
    event; the avalanche itself is not one):

    * ``total[j]``: sum over events and sliders of abs(displacement);
    * ``up[j]``, ``down[j]``: the part of it carried by the first and the
      last ``end_fraction`` of the chain (sliders n <= f N, up the slope, and
      n > (1 - f) N, down the slope; x grows down the slope);
    * ``extent_up[j]``, ``extent_down[j]``: the length, as a fraction of N,
      of the run of adjacent sliders that all moved at least once in the bin,
      starting from slider 1 (resp. N) - the size of the active region
      attached to that end (0 when the end slider did not move);
    * ``events[j]``: number of events.

    With activity spread evenly along the chain the two ends would carry
    ``2 end_fraction`` of the displacement.
    """
    d = _need(result, "extremity_activity")
    edges = np.asarray(edges, dtype=float)
    nb = edges.size - 1
    n = result.scene.n_sliders
    a = np.asarray(result.alpha, dtype=float)
    event_bin = np.searchsorted(edges, a, side="right") - 1
    entry_bin = event_bin[d.event_of_entry()]
    keep = (entry_bin >= 0) & (entry_bin < nb)
    b, idx = entry_bin[keep], d.index[keep]
    mag = np.abs(d.value[keep])
    n_end = max(1, int(round(end_fraction * n)))
    out = {
        "total": np.bincount(b, weights=mag, minlength=nb),
        "up": np.bincount(b, weights=np.where(idx < n_end, mag, 0.0), minlength=nb),
        "down": np.bincount(b, weights=np.where(idx >= n - n_end, mag, 0.0), minlength=nb),
        "events": np.bincount(event_bin[(event_bin >= 0) & (event_bin < nb)], minlength=nb),
        "extent_up": np.zeros(nb), "extent_down": np.zeros(nb),
    }
    moved = np.zeros((nb, n), dtype=bool)
    moved[b, idx] = True
    for j in range(nb):
        still = np.flatnonzero(~moved[j])  # sliders that did not move in this bin
        out["extent_up"][j] = (still[0] if still.size else n) / n
        out["extent_down"][j] = ((n - 1 - still[-1]) if still.size else n) / n
    return out


# -----------------------------------------------------------------------------
# one realisation -> one row of fixed shapes
# -----------------------------------------------------------------------------


class _Run:
    """One run seen by the statistics: what several of them share, computed once."""

    def __init__(self, result, grids: StatisticsGrids):
        self.result, self.grids = result, grids
        self._histogram = None
        self._event_bins = None

    @property
    def force_histogram(self):
        """Counts of F_t / (m g) in the grid's force bins at each grid angle, computed once."""
        if self._histogram is None:
            self._histogram = force_histogram(self.result, self.grids.alpha, self.grids.force_edges)
        return self._histogram

    @property
    def event_bins(self):
        """(interval of each event among the grid's G-1, mask of those inside, <dx> per event)."""
        if self._event_bins is None:
            a = self.grids.alpha
            ig = np.searchsorted(a, np.asarray(self.result.alpha, dtype=float), side="right") - 1
            self._event_bins = (ig, (ig >= 0) & (ig < a.size - 1),
                                mean_event_displacement(self.result))
        return self._event_bins


@dataclass(frozen=True)
class Statistic:
    """One per-realisation statistic: its row's shape (from the grids and N),
    dtype, how a run is reduced to it, how the rows of an ensemble combine
    (a function of (rows, ctx) giving ``EnsembleSummary`` fields; fields the
    dataclass does not know go to ``summary.extra``), and what its files say
    of it: the names of its row's axes (``dims``), its ``units`` ("1" for a
    count or a ratio) and its ``meaning`` (the ``long_name``).  Adding a
    statistic is adding one entry to ``STATISTICS``; one without units or
    meaning, or whose dims do not match its shape, is refused at import."""

    name: str
    shape: Callable[[StatisticsGrids, int], tuple[int, ...]]
    dtype: type
    compute: Callable[[_Run], np.ndarray]
    combine: Callable[[Mapping[str, np.ndarray], "_Ensemble"], dict] | None = None
    dims: tuple[str, ...] = ()
    units: str = ""
    meaning: str = ""

    def __post_init__(self):
        if not self.units or not self.meaning:
            raise ValueError(f"statistic {self.name!r}: give its units and its meaning (units "
                             "'1' for a count or a ratio)")
        grids = StatisticsGrids(np.zeros(1), np.arange(2.0), np.arange(2.0), np.arange(2.0), 1,
                                0.6, 0.5)  # the smallest grids: every axis of the row has one
        rank = len(self.shape(grids, 3))
        if len(self.dims) != rank:
            raise ValueError(f"statistic {self.name!r}: {len(self.dims)} dims {self.dims} for "
                             f"rows of {rank} axes")


@dataclass
class _Ensemble:
    """What the combine functions share: R, N, the grids and the valid mask."""

    r: int
    n: int
    grids: StatisticsGrids
    valid: np.ndarray  # (R, G)
    n_valid: np.ndarray  # (G,)


def _combine_force_pdf(rows, ens: _Ensemble) -> dict:
    fc = np.asarray(rows["force_counts"], dtype=float)
    width = np.diff(ens.grids.force_edges)
    with np.errstate(invalid="ignore", divide="ignore"):
        force_pdf = np.where(ens.n_valid[:, None] > 0,
                             fc.sum(axis=0) / (np.maximum(ens.n_valid, 1)[:, None] * ens.n
                                               * width[None, :]),
                             np.nan)
    return {"force_pdf": force_pdf}


def _combine_model_bins(rows, ens: _Ensemble) -> dict:
    p = np.asarray(rows["model_bin_counts"], dtype=float) / (ens.n * 2.0 * ens.grids.delta_mu)
    p_mean, p_sem = _mean_sem(p, ens.valid)
    return {"p_mean": p_mean, "p_sem": p_sem}


def _combine_cumulated(rows, ens: _Ensemble) -> dict:
    a_mean, a_sem = _mean_sem(np.asarray(rows["cumulated_displacement"], dtype=float), ens.valid)
    return {"cumulated_mean": a_mean, "cumulated_sem": a_sem}


def _combine_stopped_ratio(rows, ens: _Ensemble) -> dict:
    sc = np.asarray(rows["stopped_ratio_counts"], dtype=float).sum(axis=0)
    stopped = sc.sum(axis=1)
    rwidth = np.diff(ens.grids.ratio_edges)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio_pdf = np.where(stopped[:, None] > 0, sc / (np.maximum(stopped, 1)[:, None] * rwidth), np.nan)
    return {"stopped_ratio_pdf": ratio_pdf, "stopped_counts": stopped.astype(np.int64)}


def _combine_event_sizes(rows, ens: _Ensemble) -> dict:
    esc = np.asarray(rows["event_size_counts"], dtype=np.int64).sum(axis=0)
    total = esc.sum()
    esp = esc / total if total else np.full(esc.shape, np.nan)
    return {"event_size_counts": esc, "event_size_pdf": esp}


def _combine_alpha_c(rows, ens: _Ensemble) -> dict:
    ac = np.asarray(rows["alpha_c"], dtype=float).reshape(ens.r)
    fin = ac[np.isfinite(ac)]
    ac_mean = float(fin.mean()) if fin.size else math.nan
    ac_std = float(fin.std(ddof=1)) if fin.size > 1 else math.nan
    ac_sem = ac_std / math.sqrt(fin.size) if fin.size > 1 else math.nan
    return {"alpha_c_values": ac, "alpha_c_mean": ac_mean, "alpha_c_std": ac_std,
            "alpha_c_sem": ac_sem, "n_avalanche": int(fin.size)}


def _combine_event_displacement(rows, ens: _Ensemble) -> dict:
    """<dx> per angle interval from the per-run sums and counts (files without
    these optional rows leave both fields None)."""
    if "event_counts" not in rows or "event_mean_displacement_sum" not in rows:
        return {}
    ev_counts = np.asarray(rows["event_counts"], dtype=np.int64).sum(axis=0)
    s = np.asarray(rows["event_mean_displacement_sum"], dtype=float).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ev_mdx = np.where(ev_counts > 0, s / np.maximum(ev_counts, 1), np.nan)
    return {"event_counts": ev_counts, "event_mean_displacement": ev_mdx}


def _event_interval_sums(run: _Run, weights: bool) -> np.ndarray:
    ig, keep, mdx = run.event_bins
    g = run.grids.alpha.size
    if weights:
        return np.bincount(ig[keep], weights=np.nan_to_num(mdx[keep]),
                           minlength=g - 1).astype(np.float64)
    return np.bincount(ig[keep], minlength=g - 1).astype(np.int64)


# The rows of one realisation (in this order in ensemble files).
STATISTICS = (
    Statistic("force_counts", lambda g, n: (g.alpha.size, g.force_edges.size - 1), np.int64,
              lambda run: run.force_histogram[0], _combine_force_pdf,
              ("alpha", "force_bin"), "1", "histogram of the N forces F_t at each angle"),
    Statistic("valid_alpha", lambda g, n: (g.alpha.size,), np.bool_,
              lambda run: run.force_histogram[1],  # combined through _Ensemble.valid
              dims=("alpha",), units="1", meaning="1 where the chain is at rest at that angle"),
    Statistic("model_bin_counts", lambda g, n: (g.alpha.size, g.n_model_bins), np.int64,
              lambda run: model_bin_counts(run.result, run.grids.alpha, run.grids.mu_s_mean,
                                           run.grids.mu_d, run.grids.n_model_bins),
              _combine_model_bins,
              ("alpha", "model_bin"), "1", "sliders in each model bin of width 2 dmu"),
    Statistic("cumulated_displacement", lambda g, n: (g.alpha.size,), np.float64,
              lambda run: cumulated_displacement(run.result, run.grids.alpha).astype(np.float64),
              _combine_cumulated,
              ("alpha",), LENGTH, "A(alpha): sum of all displacements up to alpha"),
    Statistic("stopped_ratio_counts",
              lambda g, n: (g.stop_alpha_edges.size - 1, g.ratio_edges.size - 1), np.int64,
              lambda run: stopped_force_ratio_histogram(run.result, run.grids.stop_alpha_edges,
                                                        run.grids.ratio_edges),
              _combine_stopped_ratio,
              ("stop_alpha_bin", "ratio_bin"), "1",
              "histogram of F_t/F_t* of the sliders that moved, by event angle"),
    Statistic("event_size_counts", lambda g, n: (int(n),), np.int64,
              lambda run: event_size_counts(run.result), _combine_event_sizes,
              ("event_size",), "1", "events in which s distinct sliders moved"),
    Statistic("alpha_c", lambda g, n: (), np.float64,
              lambda run: np.float64(run.result.alpha_c), _combine_alpha_c,
              (), "rad", "avalanche angle (NaN if the run ended otherwise)"),
    Statistic("n_events", lambda g, n: (), np.int64,
              lambda run: np.int64(run.result.n_events),
              lambda rows, ens: {"n_events": np.asarray(rows["n_events"],
                                                        dtype=np.int64).reshape(ens.r)},
              (), "1", "number of completed rearrangements"),
    Statistic("event_counts", lambda g, n: (g.alpha.size - 1,), np.int64,
              lambda run: _event_interval_sums(run, weights=False),  # with the next one
              dims=("alpha_interval",), units="1",
              meaning="events with angle in [alpha_g, alpha_g+1)"),
    Statistic("event_mean_displacement_sum", lambda g, n: (g.alpha.size - 1,), np.float64,
              lambda run: _event_interval_sums(run, weights=True), _combine_event_displacement,
              ("alpha_interval",), LENGTH,
              "sum over those events of the mean displacement of the movers"),
)


def statistic_conventions() -> dict[str, tuple[tuple[str, ...], str, str]]:
    """What an ensemble file says of each statistic of ``STATISTICS``: name -> (dims of a row,
    units, long name); ``io.conventions.ensemble_variables`` is given it."""
    return {st.name: (st.dims, st.units, st.meaning) for st in STATISTICS}


def statistics_layout(grids: StatisticsGrids, n_sliders: int) -> dict[str, tuple[tuple[int, ...], type]]:
    """{key: (shape, dtype)} of ``realisation_statistics`` for these grids.

    For pre-creating one dataset per key with a leading realisation axis.
    """
    return {st.name: (st.shape(grids, n_sliders), st.dtype) for st in STATISTICS}


def realisation_statistics(result, grids: StatisticsGrids) -> dict[str, np.ndarray]:
    """Reduce one run to arrays whose shapes depend only on ``grids`` and N.

    Keys (G = len(grids.alpha)):

    ``force_counts`` (G, B) int64
        Histogram of the N forces F_t at each grid angle (zero rows where not
        valid), on ``grids.force_edges``.
    ``valid_alpha`` (G,) bool
        The chain is at rest at that angle (alpha < alpha_c for an avalanche).
    ``model_bin_counts`` (G, n_model_bins) int64
        Sliders in each model bin (width 2 dmu down from mu_s_mean; bin 1 also
        takes forces above mu_s_mean, the last bin everything below);
        P_i = counts / (N 2 dmu).
    ``cumulated_displacement`` (G,) float64
        A(alpha): sum of all displacements in events at alpha_k <= alpha
        (defined at every angle; constant after the last event).
    ``stopped_ratio_counts`` (S, R) int64
        Histogram of F_t/F_t* of the sliders that moved in each event, rows
        by event angle on ``grids.stop_alpha_edges``, columns on
        ``grids.ratio_edges``.
    ``event_size_counts`` (N,) int64
        Number of events in which s distinct sliders moved, at index s - 1.
    ``alpha_c`` () float64
        Avalanche angle (NaN if the run ended otherwise).
    ``n_events`` () int64
        Number of completed rearrangements.
    ``event_counts`` (G-1,) int64
        Events with angle in [alpha_g, alpha_{g+1}) (extra key, for <dx>(alpha)).
    ``event_mean_displacement_sum`` (G-1,) float64
        Sum over those events of their <dx> (mean over the sliders that moved).
    """
    _need(result, "realisation_statistics")
    run = _Run(result, grids)
    return {st.name: st.compute(run) for st in STATISTICS}


# -----------------------------------------------------------------------------
# ensemble
# -----------------------------------------------------------------------------


@dataclass
class EnsembleSummary:
    """Ensemble means over R realisations (see ``combine``).

    Arrays on the grids' angles (G,) unless stated.  Where no realisation is
    valid, means are NaN.
    """

    grids: StatisticsGrids
    n_sliders: int
    n_realisations: int
    n_valid: np.ndarray  # (G,) realisations at rest at each angle
    force_pdf: np.ndarray  # (G, B) density of F_t (integrates to 1 over the edges)
    p_mean: np.ndarray  # (G, n_model_bins) measured P_i, mean over valid runs
    p_sem: np.ndarray  # (G, n_model_bins) its standard error
    cumulated_mean: np.ndarray  # (G,) A(alpha), mean over valid runs
    cumulated_sem: np.ndarray  # (G,)
    stopped_ratio_pdf: np.ndarray  # (S, R) density of F_t/F_t* per angle bin
    stopped_counts: np.ndarray  # (S,) stopped sliders per angle bin (all runs)
    alpha_c_values: np.ndarray  # (R,) as stored (NaN: no avalanche)
    alpha_c_mean: float
    alpha_c_std: float
    alpha_c_sem: float
    n_avalanche: int
    event_size_counts: np.ndarray  # (N,) total over runs
    event_size_pdf: np.ndarray  # (N,) fraction of events of size s (index s-1)
    n_events: np.ndarray  # (R,)
    event_counts: np.ndarray | None = None  # (G-1,) total events per angle interval
    event_mean_displacement: np.ndarray | None = None  # (G-1,) mean <dx> of those events
    extra: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line: N, the realisations, the avalanches and alpha_c; not the arrays."""
        return (f"<EnsembleSummary N={self.n_sliders}: {self.n_realisations} realisations, "
                f"{self.n_avalanche} avalanches, alpha_c = {self.alpha_c_mean:.4f} +- "
                f"{self.alpha_c_sem:.4f} rad (spread {self.alpha_c_std:.4f}), "
                f"{self.grids.alpha.size} angles in [{self.grids.alpha[0]:g}, {self.grids.alpha[-1]:g}]>")

    @property
    def alpha(self) -> np.ndarray:
        """(G,) angles of the statistics grid, radians."""
        return self.grids.alpha

    @property
    def alpha_mid(self) -> np.ndarray:
        """(G-1,) midpoints of the angle intervals of ``event_mean_displacement``."""
        a = self.grids.alpha
        return 0.5 * (a[1:] + a[:-1])


def _mean_sem(values: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over axis 0 of values where mask (broadcast) is True."""
    m = np.broadcast_to(mask.reshape(mask.shape + (1,) * (values.ndim - mask.ndim)), values.shape)
    n = m.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(m, values, 0.0).sum(axis=0)
        mean = np.where(n > 0, s / np.maximum(n, 1), np.nan)
        dev = np.where(m, values - mean, 0.0)
        var = (dev ** 2).sum(axis=0) / np.maximum(n - 1, 1)
        sem = np.where(n > 1, np.sqrt(var / np.maximum(n, 1)), np.nan)
    return mean, sem


def combine(rows: Mapping[str, np.ndarray], grids: StatisticsGrids, n_sliders: int) -> EnsembleSummary:
    """Ensemble means from rows of ``realisation_statistics`` stacked over R realisations.

    Every row given is used (filter unfinished realisations before).  Force
    PDF: counts pooled over the runs valid at each angle, divided by
    (n_valid N bin width) - the mean of the per-run densities.  P_i and A:
    mean and standard error of the per-run values over the valid runs.
    Stopped-ratio PDF: counts pooled over all runs, normalised per angle bin
    to unit integral over ``ratio_edges``.  alpha_c statistics over the runs
    that avalanched (finite alpha_c).
    """
    valid = np.asarray(rows["valid_alpha"], dtype=bool)
    if valid.ndim != 2 or valid.shape[1] != grids.alpha.size:
        raise ValueError(f"rows['valid_alpha'] must have shape (R, {grids.alpha.size}), "
                         f"got {valid.shape}")
    n_valid = valid.sum(axis=0)
    ens = _Ensemble(r=valid.shape[0], n=int(n_sliders), grids=grids, valid=valid, n_valid=n_valid)
    combined: dict = {}
    for st in STATISTICS:
        if st.combine is not None:
            combined.update(st.combine(rows, ens))
    known = {f.name for f in fields(EnsembleSummary)}
    return EnsembleSummary(
        grids=grids, n_sliders=ens.n, n_realisations=ens.r, n_valid=n_valid,
        **{k: v for k, v in combined.items() if k in known},
        extra={k: v for k, v in combined.items() if k not in known},
    )


def stack_rows(rows: Iterable[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Stack per-realisation dicts into {key: array with leading axis R}."""
    rows = list(rows)
    if not rows:
        raise ValueError("stack_rows: no realisations")
    return {k: np.stack([np.asarray(row[k]) for row in rows]) for k in rows[0]}


def summary_from_results(results: Sequence, grids: StatisticsGrids | None = None) -> EnsembleSummary:
    """``combine`` of the ``realisation_statistics`` of runs of one scene (default grids)."""
    results = list(results)
    if not results:
        raise ValueError("summary_from_results: no results")
    if grids is None:
        grids = default_grids(results[0].scene)
    n = results[0].scene.n_sliders
    if any(r.scene.n_sliders != n for r in results):
        raise ValueError("summary_from_results: all runs must have the same number of sliders")
    return combine(stack_rows(realisation_statistics(r, grids) for r in results), grids, n)


# -----------------------------------------------------------------------------
# fits used by the figures and the reproduction report
# -----------------------------------------------------------------------------


def linear_fit(x, y, sigma=None) -> dict[str, float]:
    """Least-squares y = a + b x; returns slope, intercept, their standard errors, r2, rms.

    With ``sigma`` the fit is weighted (1/sigma^2) and the errors are scaled
    by the reduced chi^2 when it exceeds 1; without, errors from the residuals.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    w = np.ones_like(x)
    if sigma is not None:
        s = np.asarray(sigma, dtype=float)
        ok &= np.isfinite(s) & (s > 0)
        w = np.where(ok, 1.0 / np.where(ok, s, 1.0) ** 2, 0.0)
    x, y, w = x[ok], y[ok], w[ok]
    if x.size < 3:
        return {k: math.nan for k in ("slope", "intercept", "slope_err", "intercept_err", "r2",
                                      "rms", "n")} | {"n": float(x.size)}
    design = np.vstack([np.ones_like(x), x]).T
    wd = design * np.sqrt(w)[:, None]
    coef, *_ = np.linalg.lstsq(wd, y * np.sqrt(w), rcond=None)
    resid = y - design @ coef
    dof = x.size - 2
    chi2 = float(np.sum(w * resid ** 2))
    cov = np.linalg.inv(wd.T @ wd)
    scale = chi2 / dof if sigma is None else max(1.0, chi2 / dof)
    cov = cov * scale
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return {"slope": float(coef[1]), "intercept": float(coef[0]),
            "slope_err": float(math.sqrt(cov[1, 1])), "intercept_err": float(math.sqrt(cov[0, 0])),
            "r2": 1.0 - float(np.sum(resid ** 2)) / ss_tot if ss_tot > 0 else math.nan,
            "rms": float(math.sqrt(np.mean(resid ** 2))), "n": float(x.size),
            "chi2_red": chi2 / dof}


def exponential_fit(x, y, lo: float, hi: float) -> dict[str, float]:
    """Fit y = C exp(k x) on lo <= x <= hi (y > 0) by a line through log y.

    Returns rate k, its error, prefactor C and r2 of the log fit.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    sel = (x >= lo) & (x <= hi) & np.isfinite(y) & (y > 0)
    f = linear_fit(x[sel], np.log(y[sel]))
    return {"rate": f["slope"], "rate_err": f["slope_err"],
            "prefactor": math.exp(f["intercept"]) if math.isfinite(f["intercept"]) else math.nan,
            "r2": f["r2"], "n": f["n"], "lo": lo, "hi": hi}
