"""The honest evaluation: a split by realisation, cuts at leads and at fixed tilts, metrics with
bootstrap confidence intervals, and the alarm "the avalanche within the next delta".

Every metric is computed per realisation and resampled over realisations
(``bootstrap``), so its interval says how much the number would move with
another test set of the same size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LEVELS, LOWER, MEDIAN, UPPER, pinball_crps, probability_within
from .features import Cuts


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
