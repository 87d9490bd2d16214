"""The honest evaluation: a split by realisation, cuts at leads and at fixed tilts, metrics with
bootstrap confidence intervals, and the alarm "the avalanche within the next delta".

Every metric is computed per realisation and resampled over realisations
(``bootstrap``), so its interval says how much the number would move with
another test set of the same size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import LEVELS, LOWER, MEDIAN, UPPER, pinball_crps, probability_within
from .features import Cuts, training_cuts
from .integrity import Spec


@dataclass(frozen=True)
class Split:
    """Rows of one set for training, validation and test (disjoint, by realisation).

    Parameters
    ----------
    train, validation, test : numpy.ndarray
        Row indices, each sorted.
    """

    train: np.ndarray
    validation: np.ndarray
    test: np.ndarray

    def check(self) -> None:
        """Raise ``ValueError`` if a realisation is in two parts."""
        for a, b in ((self.train, self.validation), (self.train, self.test),
                     (self.validation, self.test)):
            if np.intersect1d(a, b).size:
                raise ValueError("a realisation is in two parts of the split")


def split_rows(n_rows: int, fractions=(0.6, 0.2, 0.2), seed: int = 0) -> Split:
    """Split rows ``0..n_rows-1`` at random into train, validation and test (fractions, seeded)."""
    f = np.asarray(fractions, dtype=float)
    if f.size != 3 or np.any(f < 0) or not np.isclose(f.sum(), 1.0):
        raise ValueError(f"fractions={tuple(fractions)} must be three shares summing to 1")
    perm = np.random.default_rng(seed).permutation(n_rows)
    a = int(round(f[0] * n_rows))
    b = a + int(round(f[1] * n_rows))
    s = Split(np.sort(perm[:a]), np.sort(perm[a:b]), np.sort(perm[b:]))
    s.check()
    return s


def cuts_at_leads(cset, rows, leads) -> tuple[Cuts, np.ndarray]:
    """Cut each row at ``alpha_c - lead`` for every lead (rows whose ``alpha_c`` exceeds it).

    Returns the cuts and, per cut, the index of its lead in ``leads``.
    """
    rows = np.asarray(rows, dtype=np.int64)
    ac = np.asarray(cset.alpha_c, dtype=float)[rows]
    r, g, a = [], [], []
    for j, lead in enumerate(np.asarray(leads, dtype=float)):
        ok = np.isfinite(ac) & (ac - lead > 0)
        r.append(rows[ok])
        g.append(np.full(int(ok.sum()), j))
        a.append(ac[ok] - lead)
    return Cuts.from_set(cset, np.concatenate(r), np.concatenate(a)), np.concatenate(g)


def cuts_at_tilts(cset, rows, tilts) -> tuple[Cuts, np.ndarray]:
    """Cut each row at every fixed tilt below its ``alpha_c``; returns the cuts and the tilt index."""
    rows = np.asarray(rows, dtype=np.int64)
    ac = np.asarray(cset.alpha_c, dtype=float)[rows]
    r, g, a = [], [], []
    for j, tilt in enumerate(np.asarray(tilts, dtype=float)):
        ok = np.isfinite(ac) & (ac > tilt)
        r.append(rows[ok])
        g.append(np.full(int(ok.sum()), j))
        a.append(np.full(int(ok.sum()), tilt))
    return Cuts.from_set(cset, np.concatenate(r), np.concatenate(a)), np.concatenate(g)


def _boot_stat(values: np.ndarray, stat, idx: np.ndarray):
    """The statistic, and its 5-95 % bootstrap interval over resampled cuts."""
    if values.size == 0:
        return np.nan, np.nan, np.nan
    reps = stat(values[idx], axis=1)
    return float(stat(values[None, :], axis=1)[0]), float(np.quantile(reps, 0.05)), \
        float(np.quantile(reps, 0.95))


def _mean(x, axis):
    return np.mean(x, axis=axis)


def _median(x, axis):
    return np.median(x, axis=axis)


def _p90(x, axis):
    return np.quantile(x, 0.9, axis=axis)


def score_group(q: np.ndarray, fallback: np.ndarray, truth: np.ndarray, tilt: np.ndarray,
                q_conditioned: np.ndarray, q_climatology: np.ndarray, n_boot: int,
                rng: np.random.Generator, levels: np.ndarray | None = None) -> dict:
    """The metrics of one forecaster on one group of cuts (one lead, or one tilt), with 90 % CIs.

    Each metric is a triple (value, 5 %, 95 %) over ``n_boot`` resamplings of
    the cuts (one cut per realisation in a group, so: of the realisations),
    paired across forecasters (the same resamples for the ratios).

    Returns
    -------
    dict
        ``median_abs``, ``p90_abs`` (radians), ``safe`` (share of point
        forecasts before the avalanche), ``coverage`` (80 % interval),
        ``crps`` (radians), ``skill`` (1 - CRPS / CRPS of climatology),
        ``vs_conditioned`` (median absolute error / that of the conditioned
        climatology), ``vs_remaining`` (median absolute error / median remaining
        angle), ``p90_vs_remaining`` (90th percentile absolute error / median
        remaining angle), ``fallback`` (share), ``n``.
    """
    n = truth.size
    idx = rng.integers(0, n, size=(n_boot, n)) if n else np.zeros((n_boot, 0), int)
    err = q[:, MEDIAN] - truth
    ab = np.abs(err)
    cov = (q[:, LOWER] <= truth) & (truth <= q[:, UPPER])
    crps = pinball_crps(q, truth, levels)
    crps_clim = pinball_crps(q_climatology, truth)
    ab_cond = np.abs(q_conditioned[:, MEDIAN] - truth)
    remaining = truth - tilt
    out = {"n": int(n), "median_abs": _boot_stat(ab, _median, idx),
           "p90_abs": _boot_stat(ab, _p90, idx),
           "safe": _boot_stat((err < 0).astype(float), _mean, idx),
           "coverage": _boot_stat(cov.astype(float), _mean, idx),
           "crps": _boot_stat(crps, _mean, idx),
           "fallback": float(np.mean(fallback)) if n else np.nan}
    if n:
        def ratio(num, den, f_num, f_den):
            val = float(f_num(num[None], 1)[0] / f_den(den[None], 1)[0])
            reps = f_num(num[idx], 1) / f_den(den[idx], 1)
            return val, float(np.quantile(reps, 0.05)), float(np.quantile(reps, 0.95))

        r = ratio(crps, crps_clim, _mean, _mean)
        out["skill"] = (1.0 - r[0], 1.0 - r[2], 1.0 - r[1])
        out["vs_conditioned"] = ratio(ab, ab_cond, _median, _median)
        out["vs_remaining"] = ratio(ab, remaining, _median, _median)
        out["p90_vs_remaining"] = ratio(ab, remaining, _p90, _median)
    else:
        for k in ("skill", "vs_conditioned", "vs_remaining", "p90_vs_remaining"):
            out[k] = (np.nan, np.nan, np.nan)
    return out


def score(predictions: dict, cuts: Cuts, group: np.ndarray, n_groups: int, n_boot: int = 400,
          seed: int = 0, reference: str = "conditioned", climatology: str = "climatology") -> dict:
    """``score_group`` for every forecaster and every group: ``{name: [metrics of group 0, ...]}``.

    ``predictions`` maps a forecaster's name to its ``(quantiles, fallback)``
    or ``(quantiles, fallback, levels)`` on ``cuts``
    (``Forecaster.quantiles``); it must hold ``reference`` and ``climatology``.
    """
    out = {}
    truth, tilt = cuts.alpha_c, cuts.tilt_now
    for name, (q, fb, *levels) in predictions.items():
        lv = levels[0] if levels else np.broadcast_to(LEVELS, q.shape)
        rows = []
        for g in range(n_groups):
            m = group == g
            rng = np.random.default_rng([seed, g])  # the same resamples for every forecaster
            rows.append(score_group(q[m], fb[m], truth[m], tilt[m], predictions[reference][0][m],
                                    predictions[climatology][0][m], n_boot, rng, lv[m]))
        out[name] = rows
    return out


def alarm_cuts(cset, rows, window: float, step: float) -> tuple[Cuts, np.ndarray]:
    """Cuts every ``step`` over the last ``window`` of tilt before each avalanche; returns the leads.

    The alarm is judged as an experimenter would run it: at each tilt the
    forecaster gives P(avalanche within delta), the alarm sounds the first
    time it exceeds a threshold.
    """
    leads = np.arange(window, 0.0, -step)
    cuts, g = cuts_at_leads(cset, rows, leads)
    return cuts, leads[g]


def alarm_roc(probability: np.ndarray, lead: np.ndarray, delta: float) -> dict:
    """ROC curve and AUC of "the avalanche within ``delta``" (positive: lead <= delta)."""
    from sklearn.metrics import roc_auc_score, roc_curve

    label = lead <= delta + 1e-12
    if label.all() or not label.any():
        return {"fpr": np.array([0.0, 1.0]), "tpr": np.array([0.0, 1.0]), "auc": np.nan}
    fpr, tpr, _ = roc_curve(label, probability)
    return {"fpr": fpr, "tpr": tpr, "auc": float(roc_auc_score(label, probability))}


def alarm_sequences(probability: np.ndarray, lead: np.ndarray, row: np.ndarray,
                    thresholds) -> dict:
    """The alarm run along each realisation: for each threshold, when it first sounds.

    Returns, per threshold, ``safe`` (share of realisations whose alarm
    sounded before the avalanche) and ``median_warning`` (median lead at
    which it sounded, radians, among those).
    """
    thresholds = np.asarray(thresholds, dtype=float)
    urows = np.unique(row)
    first = np.full((thresholds.size, urows.size), np.nan)
    for j, r in enumerate(urows):
        m = row == r
        order = np.argsort(-lead[m])  # along the tilt
        p, ld = probability[m][order], lead[m][order]
        on = p[None, :] >= thresholds[:, None]
        has = on.any(axis=1)
        first[has, j] = ld[np.argmax(on[has], axis=1)]
    safe = np.isfinite(first).mean(axis=1)
    warn = np.array([np.nanmedian(f) if np.isfinite(f).any() else np.nan for f in first])
    return {"thresholds": thresholds, "safe": safe, "median_warning": warn, "first": first}


def recommended_threshold(seq: dict, share: float = 0.9) -> float:
    """The highest threshold at which at least ``share`` of the alarms sound before the avalanche."""
    ok = seq["thresholds"][seq["safe"] >= share]
    return float(ok.max()) if ok.size else float(seq["thresholds"].min())


def alarm_probabilities(q: np.ndarray, cuts: Cuts, delta: float,
                        levels: np.ndarray | None = None) -> np.ndarray:
    """P(avalanche within ``delta``) of each cut, from its quantiles (at ``levels``, if not
    ``LEVELS``: ``Forecaster.quantiles(cuts, levels=True)``)."""
    return probability_within(q, cuts.tilt_now, delta, levels)


#: lower edges (degrees) of the bins of a forecast's own lead, ``point - tilt_now``, in which the
#: held-out accuracy is stored at training time (the last bin open above); the lead itself is
#: unknown at forecast time, the forecast's lead is what the forecaster sees
ACCURACY_LEAD_EDGES_DEG = (0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
#: fewest held-out cuts a bin of the stored accuracy needs to speak for itself (else: overall)
ACCURACY_MIN_CUTS = 30
#: bins of the 80 % interval's width within each lead bin of the stored accuracy
ACCURACY_WIDTH_BINS = 3
#: the columns of an expected-accuracy table, each with its largest value (None: unbounded)
ACCURACY_RANGES = {"median_abs_deg": 90.0, "coverage": 1.0, "n": None}


def _lead_bin(forecast_lead_deg) -> np.ndarray:
    """Each forecast lead's bin of ``ACCURACY_LEAD_EDGES_DEG`` (below 0: the first)."""
    edges = np.asarray(ACCURACY_LEAD_EDGES_DEG)
    return np.clip(np.searchsorted(edges, forecast_lead_deg, side="right") - 1, 0, edges.size - 1)


def accuracy_table(q: np.ndarray, tilt_now: np.ndarray, truth: np.ndarray, rows: int) -> dict:
    """The held-out accuracy of a forecaster per bin of its forecast lead (plain floats).

    ``q``: its quantiles at ``LEVELS`` on held-out cuts at ``tilt_now``, whose
    avalanche came at ``truth`` (radians); ``rows``: the realisations they cut.
    Returns ``lead_edges_deg`` (lower edges, the last bin open), and per bin
    ``median_abs_deg`` (the median of ``abs(point - truth)``), ``coverage`` (of the 80 %
    interval) and ``n`` (cuts); a bin of fewer than ``ACCURACY_MIN_CUTS``
    cuts holds the overall numbers (its ``n`` still its own).  ``overall``:
    the same over every cut.  A model file's table is checked in this form when the file is
    loaded (``ACCURACY_FIELDS``).
    """
    q, truth = np.asarray(q, dtype=float), np.asarray(truth, dtype=float)
    if not truth.size:
        raise ValueError("no held-out cut to measure the accuracy on")
    err = np.degrees(np.abs(q[:, MEDIAN] - truth))
    inside = (q[:, LOWER] <= truth) & (truth <= q[:, UPPER])
    b = _lead_bin(np.degrees(q[:, MEDIAN] - np.asarray(tilt_now, dtype=float)))
    overall = {"median_abs_deg": float(np.median(err)), "coverage": float(inside.mean()),
               "n": float(truth.size), "rows": float(rows)}
    table = {"lead_edges_deg": [float(e) for e in ACCURACY_LEAD_EDGES_DEG],
             "median_abs_deg": [], "coverage": [], "n": [], "overall": overall}
    width = np.degrees(q[:, UPPER] - q[:, LOWER])
    cells = {"width_edges_deg": [], "median_abs_deg": [], "coverage": [], "n": []}
    for k in range(len(ACCURACY_LEAD_EDGES_DEG)):
        m = b == k
        own = m.sum() >= ACCURACY_MIN_CUTS
        table["median_abs_deg"].append(float(np.median(err[m])) if own else overall["median_abs_deg"])
        table["coverage"].append(float(inside[m].mean()) if own else overall["coverage"])
        table["n"].append(float(m.sum()))
        # within the lead bin, bins of the interval's width (the forecaster's own uncertainty,
        # which tells a small pile's forecast from a large one's): terciles of its cuts
        edges = (np.quantile(width[m], [1 / 3, 2 / 3]) if m.sum() >= ACCURACY_WIDTH_BINS *
                 ACCURACY_MIN_CUTS else np.array([np.inf, np.inf]))
        w = np.searchsorted(edges, width[m], side="right")
        cells["width_edges_deg"].append([float(e) if np.isfinite(e) else 90.0 for e in edges])
        for c, values in (("median_abs_deg", err[m]), ("coverage", inside[m])):
            cells[c].append([float(np.median(values[w == j]) if c == "median_abs_deg" else
                                   values[w == j].mean()) if (w == j).sum() >= ACCURACY_MIN_CUTS
                             else table[c][-1] for j in range(ACCURACY_WIDTH_BINS)])
        cells["n"].append([float((w == j).sum()) for j in range(ACCURACY_WIDTH_BINS)])
    table["by_width"] = cells
    return table


def _leads(f) -> tuple:
    return (len(f.expected_accuracy_["lead_edges_deg"]),)


#: a forecaster's expected-accuracy table as ``accuracy_table`` writes it, checked when a model
#: file is read (``integrity.check_fields``) so that ``typical_accuracy`` reads only finite
#: errors in degrees, coverages in [0, 1] and counts from 0, one per lead bin (and width cell)
ACCURACY_FIELDS = {"expected_accuracy_": Spec("dict", when=lambda f: bool(
    getattr(f, "expected_accuracy_", None)), of={
        "lead_edges_deg": Spec("f", lo=0.0, min_size=1, increasing="strictly"),
        **{c: Spec("f", shape=_leads, lo=0.0, hi=hi) for c, hi in ACCURACY_RANGES.items()},
        "overall": Spec("dict", of={c: Spec("number", lo=0.0, hi=hi) for c, hi in
                                    {**ACCURACY_RANGES, "rows": None}.items()}),
        "by_width": Spec("dict", optional=True, of={
            "width_edges_deg": Spec("f", ndim=2, lo=0.0, increasing=True,
                                    shape=lambda f: (*_leads(f), ACCURACY_WIDTH_BINS - 1)),
            **{c: Spec("f", ndim=2, lo=0.0, hi=hi,
                       shape=lambda f: (*_leads(f), ACCURACY_WIDTH_BINS))
               for c, hi in ACCURACY_RANGES.items()}})})}


def measure_expected_accuracy(forecasters: dict, held, seed: int = 0, draws_per_row: int = 5) -> dict:
    """Store in every learned forecaster (``expected_accuracy_``) its accuracy on ``held``.

    ``held``: realisations kept out of its training (a ``CatalogueSet`` whose
    avalanches are known).  Each forecaster is measured on random cuts of them
    drawn as its own training cuts are (``Learned.training_cuts``: degraded
    as its training catalogues were), binned by its forecast lead
    (``accuracy_table``).  Returns ``{method: table}`` of those measured.
    """
    out = {}
    ok = np.flatnonzero(np.isfinite(np.asarray(held.alpha_c, dtype=float)))
    if not ok.size:
        return out
    held = held.subset(ok)
    for method, f in forecasters.items():
        if not hasattr(f, "training_cuts"):
            continue
        cuts = f.training_cuts(held, np.random.default_rng([seed, 11]))
        q, _ = f.quantiles(cuts)
        f.expected_accuracy_ = accuracy_table(q, cuts.tilt_now, cuts.alpha_c, len(held))
        out[method] = f.expected_accuracy_
    return out


def typical_accuracy(forecaster, forecast) -> dict | None:
    """What the forecaster's held-out piles say of a forecast like ``forecast`` (``Forecast``).

    Reads the table stored at training time (``measure_expected_accuracy``) in
    the bin of the forecast's own lead (``forecast.point - forecast.tilt_now``):
    ``median_abs_deg`` (typical error at this stage, degrees), ``coverage`` (the
    share of held-out cuts its 80 % intervals covered), ``n`` (those cuts),
    ``lead_bin_deg`` (the bin, degrees; its upper end None: open).  None if the
    forecaster holds no such table (one trained without held-out rows), or if the
    forecast fell back (out of the training domain, where the held-out piles say nothing).
    """
    table = getattr(forecaster, "expected_accuracy_", None)
    if not table or forecast.fallback:
        return None
    edges = table["lead_edges_deg"]
    k = int(_lead_bin(np.degrees(forecast.point - forecast.tilt_now)))
    cells = table.get("by_width")
    if cells:  # the cell of the forecast's own interval width within its lead bin
        width = math.degrees(float(forecast.quantiles[UPPER] - forecast.quantiles[LOWER]))
        j = int(np.searchsorted(cells["width_edges_deg"][k], width, side="right"))
        return {"median_abs_deg": float(cells["median_abs_deg"][k][j]),
                "coverage": float(cells["coverage"][k][j]), "n": int(cells["n"][k][j]),
                "lead_bin_deg": (float(edges[k]),
                                 float(edges[k + 1]) if k + 1 < len(edges) else None)}
    return {"median_abs_deg": float(table["median_abs_deg"][k]),
            "coverage": float(table["coverage"][k]), "n": int(table["n"][k]),
            "lead_bin_deg": (float(edges[k]), float(edges[k + 1]) if k + 1 < len(edges) else None)}


def typical_accuracy_line(forecaster, forecast) -> str | None:
    """``typical_accuracy`` as one line of text, e.g. "typical error at this stage: 1.6°; its
    80 % intervals covered 0.82 of held-out piles" (None without a stored table)."""
    t = typical_accuracy(forecaster, forecast)
    if t is None:
        return None
    return (f"typical error at this stage: {t['median_abs_deg']:.1f}°; its 80 % intervals "
            f"covered {t['coverage']:.2f} of held-out piles")


def coverage_by_kind(forecaster, cset, kinds: dict, leads, draws_per_row: int = 10,
                     seed: int = 0, degrade=None) -> dict:
    """The 80 % coverage and median absolute error of ``forecaster`` per kind of pile of ``cset``.

    ``kinds``: ``{label: boolean mask over cset's rows}`` (e.g. bins of the number
    of sliders, of the coupling); ``leads``: radians before the avalanche.  For each
    kind: over random cuts (``features.training_cuts``, as the forecaster meets
    them) and at each lead (key ``"<degrees>deg"``), ``coverage``,
    ``median_abs_deg`` and ``n`` (cuts).  ``degrade(cuts) -> cuts``: the cuts as
    an experiment measures them.
    """
    rows = np.flatnonzero(np.isfinite(np.asarray(cset.alpha_c, dtype=float)))
    sub = cset.subset(rows)
    leads = np.asarray(leads, dtype=float)
    groups = {"random_cuts": training_cuts(sub, draws_per_row, np.random.default_rng(seed))}
    at_leads, which = cuts_at_leads(sub, np.arange(len(sub)), leads)
    predicted = {}
    for key, cuts in groups.items():
        cuts = degrade(cuts) if degrade is not None else cuts
        predicted[key] = (forecaster.quantiles(cuts)[0], cuts.alpha_c, cuts.row, None)
    at_leads = degrade(at_leads) if degrade is not None else at_leads
    q_leads = forecaster.quantiles(at_leads)[0]
    for j, lead in enumerate(leads):
        predicted[f"{np.degrees(lead):g}deg"] = (q_leads, at_leads.alpha_c, at_leads.row, which == j)
    out = {}
    for label, mask in kinds.items():
        of_kind = np.asarray(mask, dtype=bool)[rows]
        out[label] = {}
        for key, (q, truth, row, keep) in predicted.items():
            m = of_kind[row] if keep is None else of_kind[row] & keep
            inside = (q[m, LOWER] <= truth[m]) & (truth[m] <= q[m, UPPER])
            out[label][key] = {
                "coverage": float(inside.mean()) if m.any() else float("nan"),
                "median_abs_deg": float(np.degrees(np.median(np.abs(q[m, MEDIAN] - truth[m]))))
                if m.any() else float("nan"), "n": int(m.sum())}
    return out
