"""Catalogues cut at a tilt, and what a learned forecaster sees of them.

A *cut* is one realisation's catalogue as an experimenter holds it at the tilt
``alpha_obs``: the events up to that tilt, nothing after.  ``Cuts`` holds many
of them together with the realisation they come from (for the split and the
truth) and, when they come from a simulation, what only a simulation knows:
every slider's distance to its threshold at the last stored angle before the
cut (``ceiling``) and the true ``mu_d``.  Forecasters of the catalogue never
read those.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...io.catalogue import Catalogue, CatalogueSet
from .measurement import MEASUREMENT_FEATURES, PERFECT

#: the shortest recent window (radians): about a tenth of a degree
SHORTEST_WINDOW = 0.002
#: the recent windows (radians of tilt before the cut) over which rates are counted
WINDOWS = (SHORTEST_WINDOW, 0.005, 0.01, 0.02, 0.05, 0.1)
#: the k-th last events whose distance to the tilt reached is a feature (``recent_gaps``)
GAP_ORDERS = (1, 2, 4, 8, 16, 32)
#: the tilt up to which the early events measure mu_s (below the transition for mu_d >= 0.3)
EARLY_ANGLE = 0.2
#: lone-slider estimates of mu_d within this of each other agree
AGREE_TOL = 1e-3
#: the number of smallest threshold distances the ceiling forecaster sees
CEILING_K = 16


@dataclass
class Cuts:
    """Many catalogues as seen at their tilts.

    Parameters
    ----------
    catalogues : list of Catalogue
        Each cut (``tilt_now`` is the tilt reached).
    row : numpy.ndarray
        (n,) the realisation each cut comes from (-1: not from a set).
    alpha_c : numpy.ndarray, optional
        (n,) the truth, when known.
    ceiling : numpy.ndarray, optional
        (n, K) the K smallest distances of a slider to its threshold at the
        last stored angle at or below the cut, m g (simulation only).
    mu_d : numpy.ndarray, optional
        (n,) the true dynamic friction coefficient (simulation only).
    measurement : list of Measurement, optional
        How each cut was measured (default: a perfect record in sliders).
    n_sliders : numpy.ndarray, optional
        (n,) each cut's pile's number of sliders (simulation only: a camera's
        positions are fractions of the pile's length).
    cache : dict
        Features computed once for several forecasters, filled by whoever
        builds the cuts (``learned.with_design``); forecasters read it and
        never write into it.
    """

    catalogues: list
    row: np.ndarray
    alpha_c: np.ndarray | None = None
    ceiling: np.ndarray | None = None
    mu_d: np.ndarray | None = None
    measurement: list | None = None
    n_sliders: np.ndarray | None = None
    cache: dict = field(default_factory=dict, repr=False)

    def measurements(self) -> list:
        """Each cut's ``Measurement`` (a perfect record where none was given)."""
        return [PERFECT] * len(self) if self.measurement is None else list(self.measurement)

    def __len__(self) -> int:
        """Number of cuts."""
        return len(self.catalogues)

    @property
    def tilt_now(self) -> np.ndarray:
        """(n,) the tilt reached at each cut, radians."""
        return np.array([c.tilt_now for c in self.catalogues], dtype=float)

    @property
    def last_event(self) -> np.ndarray:
        """(n,) the angle of the last event seen (0 if none), radians."""
        return np.array([c.alpha[-1] if len(c) else 0.0 for c in self.catalogues], dtype=float)

    @classmethod
    def from_catalogues(cls, catalogues, measurement=None) -> "Cuts":
        """Cuts of catalogues from any source (no truth, no simulation extras), all measured alike."""
        catalogues = list(catalogues)
        return cls(catalogues, np.full(len(catalogues), -1, dtype=np.int64),
                   measurement=None if measurement is None else [measurement] * len(catalogues))

    @classmethod
    def from_set(cls, cset: CatalogueSet, rows, alpha_obs) -> "Cuts":
        """Cut row ``rows[j]`` of ``cset`` at ``alpha_obs[j]``, with the truth and the extras.

        Parameters
        ----------
        cset : CatalogueSet
            The realisations.
        rows : array_like of int
            The row of each cut (repeats allowed).
        alpha_obs : array_like of float
            The tilt of each cut, radians, below that row's ``alpha_c``.
        """
        rows = np.asarray(rows, dtype=np.int64)
        alpha_obs = np.asarray(alpha_obs, dtype=float)
        whole = {}
        cats = []
        for r, a in zip(rows, alpha_obs):
            if r not in whole:
                whole[r] = cset.catalogue(int(r))
            cats.append(whole[r].cut(float(a)))
        ceiling = None
        if cset.ceiling_distance is not None and cset.ceiling_alpha is not None and rows.size:
            g = np.searchsorted(cset.ceiling_alpha, alpha_obs, side="right") - 1
            d = cset.ceiling_distance[rows, np.clip(g, 0, None), :CEILING_K]
            ceiling = np.where((g >= 0)[:, None], d, np.nan)
        par = cset.parameters
        mu_d = np.asarray(par["mu_d"], dtype=float)[rows] if "mu_d" in par else None
        n = np.asarray(par["n_sliders"], dtype=np.int64)[rows] if "n_sliders" in par else None
        return cls(cats, rows, np.asarray(cset.alpha_c, dtype=float)[rows], ceiling, mu_d,
                   n_sliders=n)


def training_cuts(cset: CatalogueSet, draws_per_row: int, rng: np.random.Generator,
                  alpha_max: float | None = None) -> Cuts:
    """Cuts at tilts drawn over the whole run, independently of where the avalanche is.

    Each row gets ``draws_per_row`` tilts uniform on [0, ``alpha_max``] (the
    largest ``alpha_c`` of the set unless given); those below the row's
    ``alpha_c`` are kept.  The tilt is drawn without looking at ``alpha_c``
    (the rejection only says that the avalanche has not come yet, which an
    experimenter knows too), so a model cannot learn "the catalogue ends a
    fixed lead before the avalanche": conditioned on the tilt, the cuts hold
    the prior's ``alpha_c`` above it.
    """
    ok = np.flatnonzero(np.isfinite(cset.alpha_c))
    if ok.size == 0:
        raise ValueError("no realisation of the set reached the avalanche")
    top = float(np.max(cset.alpha_c[ok])) if alpha_max is None else float(alpha_max)
    a = rng.uniform(0.0, top, size=(ok.size, draws_per_row))
    keep = a < cset.alpha_c[ok, None]
    rows = np.repeat(ok, draws_per_row).reshape(ok.size, draws_per_row)[keep]
    return Cuts.from_set(cset, rows, a[keep])


def _window_sums(alpha, values, tilt, windows):
    lo = np.searchsorted(alpha, tilt - np.asarray(windows), side="left")
    c = np.concatenate([[0.0], np.cumsum(values)])
    return c[-1] - c[lo]


def size_one_delta_mu(cat: Catalogue) -> float:
    """Delta mu from the events in which one slider moved alone (the paper's single slider).

    A slider slipping alone between resting neighbours starts at
    ``mu_s,n cos(alpha)`` and stops at ``(2 mu_d - mu_s,n) cos(alpha)``: it moves
    by ``(mu_s,n - mu_d) cos(alpha)``.  The median of displacement / cos(alpha)
    over such events estimates Delta mu (NaN without any).
    """
    one = cat.size == 1
    if not one.any():
        return np.nan
    return float(np.median(cat.displacement[one] / np.cos(cat.alpha[one])))


def _indices(cat: Catalogue) -> bool:
    """The movers are given as slider indices (whole numbers), not as a camera's fractions of
    the pile's length."""
    return cat.first.dtype.kind in "iu" and cat.last.dtype.kind in "iu"


def lone_slip_pairs(cat: Catalogue) -> list[tuple[int, int]]:
    """Every pair (j, i) of events in which one slider slipped alone, at j and again at i,
    while its neighbours stayed at rest in between; in the order of the second slip (empty
    without the moved sliders, ``first``/``last``)."""
    n = len(cat)
    if n < 2 or cat.first[0] < 0 and cat.first.max() < 0 or not _indices(cat):
        return []
    first, last, size = cat.first.tolist(), cat.last.tolist(), cat.size.tolist()
    width = max(last) + 3
    previous = [-1] * width  # per slider: its last lone slip, if its neighbourhood kept still since
    out = []
    for i in range(n):
        lo, hi = first[i], last[i]
        if lo < 0:
            continue
        if size[i] == 1 and lo == hi and previous[lo + 1] >= 0:
            out.append((previous[lo + 1], i))
        for k in range(lo, hi + 3):  # sliders lo-1 .. hi+1, shifted by one
            previous[k] = -1
        if size[i] == 1 and lo == hi:
            previous[lo + 1] = i
    return out


def single_slider_mu_d(cat: Catalogue) -> np.ndarray:
    """mu_d from every slider that slipped alone twice while its neighbours stayed at rest.

    A slider slipping alone at ``alpha_i`` with threshold ``mu_1`` moves by
    ``d_i = (mu_1 - mu_d) cos(alpha_i)`` and stops with the force
    ``(2 mu_d - mu_1) cos(alpha_i)``; while nothing near it moves, only the tilt
    changes that force, so it slips again at ``alpha_j`` where it reaches the
    new threshold ``mu_2 = mu_d + d_j / cos(alpha_j)``.  Together:

        mu_d = (d_i + d_j - (sin(alpha_j) - sin(alpha_i))) / (cos(alpha_i) - cos(alpha_j)),

    the exact form of the paper's single-slider period
    ``Delta alpha = 2 Delta mu / (1 + mu_s tan(alpha))``.  It needs the moved
    sliders (``first``/``last``) and the displacement in the model's units
    (g tau^2, i.e. the spring stiffness known).  One estimate per such pair
    of slips (``lone_slip_pairs``), in the order of the second slip (empty without any);
    neglects the cantilever springs (xi), whose plate moves with the chain
    (``coupled_lone_slips`` does not).
    """
    alpha, disp = cat.alpha.tolist(), cat.displacement.tolist()
    out = []
    for j, i in lone_slip_pairs(cat):
        den = math.cos(alpha[j]) - math.cos(alpha[i])
        if den > 0:
            out.append((disp[j] + disp[i] - (math.sin(alpha[i]) - math.sin(alpha[j]))) / den)
    return np.array(out)


#: lone-slip pairs whose equation ``coupled_lone_slips``' solution satisfies within this
#: (in units of mu_d) agree with it
COUPLED_TOL = 1e-4
#: the unknowns ``coupled_lone_slips`` solves for: mu_d, xi and xi / N
COUPLED_UNKNOWNS = 3


def coupled_lone_slips(cat: Catalogue) -> tuple[float, float, int]:
    """mu_d and xi from the lone-slip pairs (``lone_slip_pairs``), the cantilever springs
    counted, and how many pairs agree with them: (NaN, NaN, 0) with fewer than four.

    A slider alone in its slip at ``alpha_j`` meets the stiffness K = 2 + xi (1 - 1/N) (its
    two springs, its cantilever less the plate's share of its own move: the plate follows
    the barycentre), so it moves by ``d_j = 2 (mu_1 - mu_d) cos(alpha_j) / K`` and stops with
    the force ``(2 mu_d - mu_1) cos(alpha_j)``, as without the plate.  Until it slips again
    at ``alpha_i``, the tilt adds ``sin(alpha_i) - sin(alpha_j)`` to that force and the plate
    ``xi S / N``, S the displacements of the events in between (their sliders' sum).  At
    ``alpha_i`` the force is ``mu_d cos(alpha_i) + K d_i / 2``.  Each pair is thus an
    equation linear in mu_d, xi and xi / N (D = d_j + d_i):

        mu_d (cos a_j - cos a_i) - xi D / 2 + (xi / N) (S + D / 2) = D - (sin a_i - sin a_j),

    solved by least squares over the pairs, those off by more than ``COUPLED_TOL`` dropped
    and the rest solved again (twice at most).  Exact when the angles are, whatever xi
    (N is not needed: an estimate from the slider indices would spoil it).
    """
    terms = _pair_terms(cat)
    if terms is None:
        return math.nan, math.nan, 0
    a, d, between, rise = terms
    m = np.column_stack([np.ones_like(a), -d / 2 / a, (between + d / 2) / a])
    sol, off = _pruned_least_squares(m, (d - rise) / a)
    return float(sol[0]), float(sol[1]), int(np.sum(off <= COUPLED_TOL))


def _pair_terms(cat: Catalogue):
    """The terms of the lone-slip pairs' equations (``lone_slip_pairs``, the second slip at a
    larger angle): cos a_j - cos a_i, D = d_j + d_i, S (the displacement of the events in
    between) and sin a_i - sin a_j; None with fewer than four pairs."""
    pairs = lone_slip_pairs(cat)
    if len(pairs) < COUPLED_UNKNOWNS + 1:
        return None
    j, i = np.array(pairs).T
    alpha, disp = cat.alpha, cat.displacement
    a = np.cos(alpha[j]) - np.cos(alpha[i])
    j, i, a = j[a > 0], i[a > 0], a[a > 0]
    if a.size < COUPLED_UNKNOWNS + 1:
        return None
    before = np.concatenate([[0.0], np.cumsum(disp)])
    return (a, disp[i] + disp[j], before[i] - before[j + 1],
            np.sin(alpha[i]) - np.sin(alpha[j]))


def _pruned_least_squares(m: np.ndarray, y: np.ndarray):
    """``m x = y`` by least squares, the rows off by more than ``COUPLED_TOL`` (and three
    times the median) dropped and the rest solved again (twice at most): the solution and
    every row's misfit."""
    keep = np.ones(y.size, dtype=bool)
    for _ in range(3):
        sol = np.linalg.lstsq(m[keep], y[keep], rcond=None)[0]
        off = np.abs(y - m @ sol)
        near = off <= max(COUPLED_TOL, 3.0 * float(np.median(off[keep])))
        if near.sum() <= m.shape[1] or (near == keep).all():
            break
        keep = near
    return sol, off


def slider_indices(cat: Catalogue, measurement) -> Catalogue:
    """``cat`` with its movers as slider indices: as given, or from a camera's fractions of the
    pile's length, the sliders' spacing read as the least gap between two positions seen (the
    pile's number of sliders if told).  Unknown positions stay -1."""
    if measurement.position_unit == "sliders" or not len(cat):
        return cat
    known = (cat.first >= 0) & (cat.last >= 0)
    first, last = measurement.position_fractions(cat.first), measurement.position_fractions(cat.last)
    seen = np.unique(np.concatenate([first[known], last[known]]))
    gaps = np.diff(seen)
    gaps = gaps[gaps > 1e-9]
    n = measurement.n_sliders if measurement.n_sliders and not measurement.n_sliders_high else (
        round(1.0 / float(gaps.min())) if gaps.size else 0)
    if n < 1:
        return Catalogue(cat.alpha, cat.size, cat.displacement, np.full(len(cat), -1),
                         np.full(len(cat), -1), cat.tilt_now)
    first, last = (np.where(known, np.round(p * n - 0.5), -1).astype(np.int64)
                   for p in (first, last))
    return Catalogue(cat.alpha, cat.size, cat.displacement, first, last, cat.tilt_now)


def scale_free_lone_slips(cat: Catalogue, measurement) -> tuple[float, float, int, float]:
    """mu_d from the lone-slip pairs of a catalogue whose displacements are in an unknown unit,
    solved with that unit: (mu_d, ``u`` below, pairs that agree, the pairs' median misfit),
    NaN with fewer than four pairs.

    ``coupled_lone_slips``' equation with every displacement ``d = s d'`` (``d'`` as recorded,
    ``s`` unknown) is linear in mu_d, ``u = s (1 + xi / 2)`` and ``v = s xi / N``:

        mu_d (cos a_j - cos a_i) - u D' + v (S' + D' / 2) = -(sin a_i - sin a_j),

    so the tilt's own sine fixes the unit and mu_d is exact when the angles are, in pixels or
    millimetres as in g tau^2 (``in_model_units`` takes s from u and v).
    """
    solved = _scale_free_solution(slider_indices(cat, measurement))
    if solved is None:
        return math.nan, math.nan, 0, math.nan
    sol, off = solved
    return float(sol[0]), float(sol[1]), int(np.sum(off <= COUPLED_TOL)), float(np.median(off))


def _scale_free_solution(indexed: Catalogue):
    """(mu_d, u, v) of ``scale_free_lone_slips`` and every pair's misfit (None: too few pairs)."""
    terms = _pair_terms(indexed)
    if terms is None:
        return None
    a, d, between, rise = terms
    m = np.column_stack([np.ones_like(a), -d / a, (between + d / 2) / a])
    return _pruned_least_squares(m, -rise / a)


#: lone-slip pairs that must agree, to ``COUPLED_TOL``, for a camera's unit to be read from them
#: (``in_model_units``): their equations then hold exactly, as only an exact record's do
UNIT_PAIRS = 8


def in_model_units(cat: Catalogue, measurement) -> tuple[Catalogue | None, float, int]:
    """A camera's catalogue in the model's units, when its lone slips fix its unit exactly:
    (the catalogue with displacements in g tau^2 and the movers as slider indices, model
    units per camera unit, the pairs that agree); (None, NaN, pairs) when fewer than
    ``UNIT_PAIRS`` pairs agree (a noisy record, or too few lone slips)."""
    indexed = slider_indices(cat, measurement)
    solved = _scale_free_solution(indexed)
    if solved is None:
        return None, math.nan, 0
    (_, u, v), off = solved
    agree = int(np.sum(off <= COUPLED_TOL))
    # u = s (1 + xi / 2), v = s xi / N: xi = N r / (1 - N r / 2) with r = v / u
    n = n_sliders_estimate(indexed)
    r = float(v / u) * n if u > 0 and np.isfinite(n) else math.nan
    unit = float(u) / (1.0 + max(r / (1.0 - r / 2.0), 0.0) / 2.0) if r < 2.0 else math.nan
    if agree < UNIT_PAIRS or not (np.isfinite(unit) and unit > 0) or (indexed.first < 0).any():
        return None, math.nan, agree
    return (Catalogue(indexed.alpha, indexed.size, indexed.displacement * unit, indexed.first,
                      indexed.last, indexed.tilt_now), unit, agree)


def cuts_in_model_units(cuts: Cuts) -> tuple[Cuts, np.ndarray]:
    """The cuts whose camera's unit their lone slips fix (``in_model_units``), in the model's
    units and measured so, and which of ``cuts`` they are (a boolean mask)."""
    out, which = [], np.zeros(len(cuts), dtype=bool)
    for k, (cat, m) in enumerate(zip(cuts.catalogues, cuts.measurements())):
        if m.camera and (back := in_model_units(cat, m)[0]) is not None:
            out.append((back, m.in_model_units()))
            which[k] = True
    sub = Cuts([c for c, _ in out], cuts.row[which],
               None if cuts.alpha_c is None else cuts.alpha_c[which],
               measurement=[m for _, m in out])
    return sub, which


def n_sliders_estimate(cat: Catalogue) -> float:
    """Number of sliders from the slider indices seen (largest index + 1; NaN if unknown).

    The sliders are numbered 0..N-1 and the first and last mover of each event
    are recorded; the largest index seen, corrected for the finite sample like
    the German-tank estimate, estimates N.
    """
    known = cat.last >= 0
    if not known.any() or not _indices(cat):
        return np.nan
    m = float(cat.last[known].max() + 1)
    k = int(np.unique(np.concatenate([cat.first[known], cat.last[known]])).size)
    return m + m / max(k, 1) - 1.0 if k > 1 else m


#: features that count sliders (unknown when sizes are in an arbitrary unit)
SIZE_IN_SLIDERS = ("moves", "max_size", "max_size_recent", "mean_size_recent", "max_size_frac")


def catalogue_features(cat: Catalogue, arbitrary_size: bool = False) -> dict:
    """What a learned forecaster sees of one cut: plain numbers from the events and the tilt.

    Angles in radians.  Rates are counted over the recent windows
    ``WINDOWS``; NaN where a feature cannot be computed (the regressor
    handles missing values).  ``arbitrary_size``: the sizes are in an
    unknown unit, so every feature counting sliders is NaN and only the
    ratios of sizes (``size_ratio_*``, invariant under a change of unit)
    remain.
    """
    t = float(cat.tilt_now)
    n = len(cat)
    alpha, size, disp = cat.alpha, cat.size.astype(float), cat.displacement
    f = {"tilt": t, "n_events": float(n)}
    f["last_event"] = float(alpha[-1]) if n else 0.0
    f["quiet"] = t - f["last_event"]
    f["first_event"] = float(alpha[0]) if n else np.nan
    f["moves"] = float(size.sum())
    f["displacement"] = float(disp.sum())
    n_est = n_sliders_estimate(cat)
    f["n_sliders"] = n_est
    scale = n_est if np.isfinite(n_est) and n_est > 0 else np.nan
    ev = _window_sums(alpha, np.ones(n), t, WINDOWS)
    mv = _window_sums(alpha, size, t, WINDOWS)
    ds = _window_sums(alpha, disp, t, WINDOWS)
    for w, e, m, d in zip(WINDOWS, ev, mv, ds):
        f[f"events_{w:g}"] = e / w
        f[f"moves_{w:g}"] = m / w
        f[f"disp_{w:g}"] = d / w
        f[f"moves_per_slider_{w:g}"] = m / w / scale
    f["max_size"] = float(size.max()) if n else 0.0
    f["max_size_frac"] = f["max_size"] / scale
    recent = alpha >= t - 0.05
    f["max_size_recent"] = float(size[recent].max()) if recent.any() else 0.0
    f["mean_size_recent"] = float(size[recent].mean()) if recent.any() else 0.0
    f["since_largest"] = t - float(alpha[np.argmax(size)]) if n else np.nan
    dmu = size_one_delta_mu(cat)
    f["delta_mu_single"] = dmu
    # the crude model's P_1 = (1 + alpha / (2 Delta mu)) / (2 mu_s) integrated: the events
    # up to EARLY_ANGLE number N (a + a^2 / (4 Delta mu)) / (2 mu_s)
    a_e = min(t, EARLY_ANGLE)
    early = int(np.sum(alpha <= a_e))
    mu_s = scale * (a_e + a_e ** 2 / (4 * dmu)) / (2.0 * early) if early >= 3 and dmu > 0 else np.nan
    f["mu_s_early"] = mu_s
    f["atan_mu_d_model"] = float(np.arctan(mu_s - dmu)) if np.isfinite(mu_s - dmu) else np.nan
    f["atan_mu_s_model"] = float(np.arctan(mu_s)) if np.isfinite(mu_s) else np.nan
    pairs = single_slider_mu_d(cat)
    mu_d, agree = densest_value(pairs)
    f["single_slider_pairs"] = float(pairs.size)
    f["single_slider_agree"] = float(agree)
    f["atan_mu_d_single"] = float(np.arctan(mu_d)) if np.isfinite(mu_d) else np.nan
    f.update(size_ratios(cat))
    f.update(recent_gaps(alpha, t))
    if arbitrary_size:
        for k in f:
            if k in SIZE_IN_SLIDERS or k.startswith(("moves_", "delta_mu", "mu_s_early", "atan_mu")):
                f[k] = np.nan
    return f


#: the windows (radians of tilt before the cut) of a camera's displacement rates: from a fifth
#: of a degree (a camera's angles carry errors of a tenth) to six degrees
CAMERA_WINDOWS = (0.0035, 0.01, 0.02, 0.05, 0.1)


def displacement_scale(cat: Catalogue) -> float:
    """The catalogue's own unit of displacement: the median displacement per mover over its
    events (NaN without a displaced event).  In the model's units a lone slip moves
    ``(mu_s - mu_d) cos(alpha)``: a camera's catalogue divided by this reads the same in
    pixels, millimetres or g tau^2."""
    moved = (cat.displacement > 0) & (cat.size > 0)
    if not moved.any():
        return np.nan
    return float(np.median(cat.displacement[moved] / cat.size[moved]))


def positions_as_fractions(cat: Catalogue, measurement) -> tuple[np.ndarray, np.ndarray]:
    """The movers' positions as fractions of the pile's length from its up-slope end (NaN:
    unknown): as given (``position_unit`` "fraction"), or slider indices over the pile's
    number of sliders (told, else estimated from the indices)."""
    first, last = cat.first.astype(float), cat.last.astype(float)
    unknown = (first < 0) | (last < 0)
    if measurement.position_unit == "sliders":
        n = measurement.n_sliders or n_sliders_estimate(cat)
        first, last = (first + 0.5) / n, (last + 0.5) / n
    else:
        first, last = measurement.position_fractions(first), measurement.position_fractions(last)
    return np.where(unknown, np.nan, first), np.where(unknown, np.nan, last)


def camera_features(cat: Catalogue, measurement) -> dict:
    """What a camera's displacements and positions say, free of their units.

    Displacements are read in the catalogue's own unit (``displacement_scale``): their
    rates over ``CAMERA_WINDOWS`` in that unit and over the catalogue's mean rate (the
    rate grows by tens towards the avalanche), the recent displacement per mover over the
    catalogue's, the displacement-weighted tilt since the events; positions as fractions
    of the pile's length (``positions_as_fractions``): the extent of the recent events,
    where they lie, and the number of sliders that sizes over extents give.  Unchanged,
    to rounding, when every displacement is multiplied by one factor, or when positions
    are given in another unit converted to the same fractions.
    """
    t = float(cat.tilt_now)
    n = len(cat)
    scale = displacement_scale(cat)
    d = cat.displacement / scale if np.isfinite(scale) and scale > 0 else np.full(n, np.nan)
    size = cat.size.astype(float)
    onset = float(cat.alpha[0]) if n else t
    mean_rate = float(np.sum(d)) / max(t - onset, SHORTEST_WINDOW)
    f = {"disp_total_rel": float(np.sum(d)) / max(n, 1)}
    sums = _window_sums(cat.alpha, d, t, CAMERA_WINDOWS)
    moves = _window_sums(cat.alpha, size, t, CAMERA_WINDOWS)
    for w, ds, m in zip(CAMERA_WINDOWS, sums, moves):
        f[f"disp_rel_{w:g}"] = ds / w
        f[f"disp_growth_{w:g}"] = ds / w / mean_rate if mean_rate > 0 else np.nan
        f[f"disp_per_move_{w:g}"] = ds / m if m > 0 else np.nan
    last = cat.alpha >= t - CAMERA_WINDOWS[-1]
    weight = float(np.sum(d[last])) if n else 0.0
    f["disp_weighted_since"] = (float(np.sum(d[last] * (t - cat.alpha[last]))) / weight
                                if weight > 0 else np.nan)
    first, end = positions_as_fractions(cat, measurement)
    extent = end - first
    recent = (cat.alpha >= t - 0.05) & np.isfinite(extent)
    f["extent_max_recent"] = float(extent[recent].max()) if recent.any() else np.nan
    f["extent_max"] = float(np.nanmax(extent)) if np.isfinite(extent).any() else np.nan
    f["centre_recent"] = float(np.mean(0.5 * (first + end)[recent])) if recent.any() else np.nan
    wide = (size >= 3) & (extent > 0)
    f["log_n_from_extent"] = (float(np.log(np.median((size[wide] - 1.0) / extent[wide])))
                              if wide.any() and measurement.size_unit == "sliders" else np.nan)
    # solved over every pair (a noisy record's pairs agree only to its noise: the misfit says
    # how well, the agreeing pairs how exactly)
    mu_d, unit, agree, misfit = scale_free_lone_slips(cat, measurement)
    ok = np.isfinite(mu_d) and abs(mu_d) < 10.0
    f["atan_mu_d_lone"] = float(np.arctan(mu_d)) if ok else np.nan
    f["atan_mu_d_lone_minus_tilt"] = f["atan_mu_d_lone"] - t
    f["lone_pairs_agree"] = float(agree)
    f["log_lone_misfit"] = float(np.log10(max(misfit, 1e-12))) if ok else np.nan
    # the displacement's own scale in the model's units (mu_s - mu_d over the median slip)
    f["log_delta_mu_lone"] = (float(np.log(unit * scale)) if ok and unit > 0
                              and np.isfinite(scale) else np.nan)
    return f


def camera_feature_names() -> list[str]:
    """The names of ``camera_features``, in order."""
    return list(camera_features(Catalogue([], [], [], [], []), PERFECT))


def camera_feature_matrix(cuts: Cuts) -> tuple[np.ndarray, list[str]]:
    """(n, F) ``camera_features`` of every cut, and their names."""
    rows = [camera_features(c, m) for c, m in zip(cuts.catalogues, cuts.measurements())]
    names = camera_feature_names()
    x = np.array([[r[k] for k in names] for r in rows], dtype=float).reshape(len(rows), len(names))
    return x, names


def size_ratios(cat: Catalogue) -> dict:
    """Sizes relative to the catalogue's mean size: unchanged by any unit of size."""
    size = cat.size.astype(float)
    mean = float(size.mean()) if size.size else np.nan
    t = float(cat.tilt_now)
    f = {"size_ratio_max": float(size.max()) / mean if size.size else np.nan}
    for w in (0.01, 0.05):
        recent = cat.alpha >= t - w
        f[f"size_ratio_recent_{w:g}"] = float(size[recent].mean()) / mean if recent.any() else np.nan
    big = size > 2.0 * mean
    f["share_large"] = float(big.mean()) if size.size else np.nan
    return f


def recent_gaps(alpha: np.ndarray, tilt_now: float) -> dict:
    """How far back the k-th last events lie, and how that distance grows with k.

    ``gap_k`` = tilt reached - angle of the k-th last event (``GAP_ORDERS``;
    NaN with fewer events).  Under a rate ``A / (alpha_c - alpha)`` the k-th
    last event lies ``(alpha_c - tilt)(exp(k / A) - 1)`` back: the ratios
    ``gap_share_k = gap_k / gap_2k`` (in [0, 1], free of any angle scale)
    measure ``A``, the gaps then the remaining angle; under a steady rate the
    share is about one half.  The last fraction of a degree, which windows
    of fixed width blur, is read from the events themselves.
    """
    n = alpha.size
    gap = {k: tilt_now - float(alpha[n - k]) if n >= k else np.nan for k in GAP_ORDERS}
    f = {f"gap_{k}": g for k, g in gap.items()}
    for k in GAP_ORDERS[:-1]:
        wide = gap[2 * k]
        f[f"gap_share_{k}"] = gap[k] / wide if wide > 0 else np.nan
    return f


def densest_value(estimates, tol: float = AGREE_TOL) -> tuple[float, int]:
    """The value most estimates agree on (within ``tol``), and how many do: (NaN, 0) if none.

    The lone-slider pairs give mu_d exactly when nothing but the tilt changed
    the slider's force between its slips (xi = 0); the others scatter.  The
    median of the densest cluster keeps the exact ones.
    """
    e = np.sort(np.asarray(estimates, dtype=float))
    e = e[np.isfinite(e)]
    if e.size == 0:
        return np.nan, 0
    count = np.searchsorted(e, e + tol, side="right") - np.searchsorted(e, e - tol, side="left")
    k = int(np.argmax(count))
    return float(np.median(e[np.abs(e - e[k]) <= tol])), int(count[k])


def feature_matrix(cuts: Cuts) -> tuple[np.ndarray, list[str]]:
    """(n, F) features of every cut (``catalogue_features`` and the measurement's) and their names."""
    meas = cuts.measurements()
    rows = [catalogue_features(c, m.size_unit == "arbitrary") for c, m in zip(cuts.catalogues, meas)]
    names = list(rows[0]) if rows else list(catalogue_features(Catalogue([], [], [], [], [])))
    x = np.array([[r[k] for k in names] for r in rows], dtype=float).reshape(len(rows), len(names))
    mx = np.array([m.as_features(c) for c, m in zip(cuts.catalogues, meas)]).reshape(len(rows), -1)
    return np.hstack([x, mx]), names + list(MEASUREMENT_FEATURES)


def ceiling_features(cuts: Cuts) -> tuple[np.ndarray, list[str]]:
    """(n, K) log10 of the K smallest threshold distances at the last stored angle (simulation only)."""
    d = np.asarray(cuts.ceiling, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.log10(np.maximum(d, 1e-12))
    return x, [f"log_distance_{k}" for k in range(x.shape[1])]
