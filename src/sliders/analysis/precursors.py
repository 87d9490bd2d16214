"""The paper's measures of a set of runs, each defined once: the avalanche bounds, the burst
periods of a slider, the synchronisation and extremity profiles of the events, the angle where
a curve departs from its fit, the modes of the stopped-force ratios.

``analysis.reproduction`` judges the paper's statements on them; a study
(``runs.study``) stores a run's burst periods and synchronisation share.
The analysis choices are fixed below, before any number is seen.
"""

from __future__ import annotations

import math

import numpy as np

from . import observables as ob

DEPARTURE_SIGMAS = 3.0  # a departure is > 3 standard errors on 2 consecutive angles
SYNC_BIN = 0.02  # angle bins of the synchronisation indicator
SYNC_FRACTION = 0.5  # synchronised: at least half the events of a bin have >= 2 groups
# Extremities of scene C (statement 14): decided before looking at the data.
EXTREMITY_BIN = 0.02  # angle bins of the extremity indicator (as SYNC_BIN)
END_FRACTION = 0.25  # "an extremity": the first / last quarter of the chain
HALF_CHAIN = 0.5  # "more than half the size of the system"


def avalanche_bounds(results) -> dict:
    """alpha_c against [atan mu_d, atan(mean mu_s)]: the scene's mean and each run's own."""
    sc = results[0].scene
    results = [r for r in results if r.status == "avalanche"]
    ac = np.array([r.alpha_c for r in results])
    lo, hi = math.atan(sc.mu_d), math.atan(sc.mu_s_mean)
    own_hi = np.array([math.atan(r.final.mu_s.mean()) for r in results])
    fin = np.isfinite(ac)
    return {
        "lo": lo, "hi": hi, "n": ac.size, "n_avalanche": int(fin.sum()),
        "in_nominal": int(np.sum((ac >= lo) & (ac <= hi))),
        "in_own": int(np.sum((ac >= lo) & (ac <= own_hi + 1e-12))),
        "min": float(np.nanmin(ac)) if fin.any() else math.nan,
        "max": float(np.nanmax(ac)) if fin.any() else math.nan,
    }


def burst_periods(results, dmu: float, mu_s: float) -> dict:
    """Angle between successive rearrangements of one slider, early (alone) and late (in groups).

    For every slider, the intervals between consecutive events it moved in.
    Early: both events of size 1 below alpha = 0.3, compared with the
    single-slider period 2 dmu / (1 + mu_s tan alpha).  Late: both events of
    size >= 3 above alpha = 0.35, compared with dmu.
    """
    early, late, early_pred = [], [], []
    for r in results:
        d = r.displacement
        sizes = ob.event_sizes(r)
        a = np.asarray(r.alpha)
        last: dict[int, int] = {}
        for k in range(d.n_events):
            idx, _ = d.event(k)
            for n in idx:
                j = last.get(int(n))
                if j is not None:
                    if sizes[j] == 1 and sizes[k] == 1 and a[k] < 0.3:
                        early.append(a[k] - a[j])
                        early_pred.append(2 * dmu / (1 + mu_s * math.tan(a[j])))
                    elif sizes[j] >= 3 and sizes[k] >= 3 and a[j] > 0.35:
                        late.append(a[k] - a[j])
                last[int(n)] = k
    e, lt = np.array(early), np.array(late)
    return {"early_median": float(np.median(e)) if e.size else math.nan, "early_n": e.size,
            "early_pred": float(np.median(early_pred)) if early_pred else math.nan,
            "early_iqr": (float(np.percentile(e, 25)), float(np.percentile(e, 75))) if e.size else None,
            "late_median": float(np.median(lt)) if lt.size else math.nan, "late_n": lt.size,
            "late_iqr": (float(np.percentile(lt, 25)), float(np.percentile(lt, 75))) if lt.size else None}


def sync_profile(results, alpha_max: float = 0.56) -> dict:
    """Synchronisation indicator per angle bin, pooled over runs.

    An event is *multi-region* when the sliders that moved in it form two or
    more separate groups (``observables.moving_clusters``).  Per bin of
    ``SYNC_BIN``: ``weighted`` = share of the total displacement that occurs
    in multi-region events (the indicator), ``fraction`` = share of the
    events that are multi-region, ``fraction_halves`` = share of the events
    in which both halves of the chain move.  ``onset``: first bin from which
    the weighted share is at least ``SYNC_FRACTION`` in every bin holding
    events, except the bin of the avalanche (cut short by it); NaN if never.
    Meant for one run (``run_onsets`` gives one onset per run).
    """
    edges = np.arange(0.0, alpha_max + SYNC_BIN, SYNC_BIN)
    nb = edges.size - 1
    multi, total, halves = np.zeros(nb), np.zeros(nb), np.zeros(nb)
    disp_multi, disp_total = np.zeros(nb), np.zeros(nb)
    for r in results:
        a = np.asarray(r.alpha)
        c = ob.moving_clusters(r)
        both = ob.synchronisation(r)["all_parts"]
        dx = np.abs(ob.event_total_displacement(r))
        i = np.clip(np.searchsorted(edges, a, side="right") - 1, 0, nb - 1)
        np.add.at(total, i, 1)
        np.add.at(multi, i, c >= 2)
        np.add.at(halves, i, both)
        np.add.at(disp_total, i, dx)
        np.add.at(disp_multi, i, np.where(c >= 2, dx, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = multi / total
        frac_halves = halves / total
        weighted = disp_multi / disp_total
    onset = math.nan
    populated = np.flatnonzero(disp_total > 0)
    ac = [r.alpha_c for r in results if math.isfinite(r.alpha_c)]
    last = (np.searchsorted(edges, max(ac), side="right") - 1) if ac else nb
    judged = populated[populated < last] if populated.size and populated[-1] == last else populated
    for pos, j in enumerate(judged):
        if np.all(weighted[judged[pos:]] >= SYNC_FRACTION):
            onset = float(edges[j])
            break
    return {"edges": edges, "fraction": frac, "fraction_halves": frac_halves, "total": total,
            "weighted": weighted, "onset": onset,
            "overall": float(multi.sum() / max(total.sum(), 1)),
            "overall_weighted": float(disp_multi.sum() / max(disp_total.sum(), 1e-300))}


def extremity_profile(results, alpha_max: float = 0.56) -> dict:
    """The extremity indicator (``observables.extremity_activity``) pooled and per run.

    Pooled over the runs, per bin of ``EXTREMITY_BIN``: displacement shares
    of the up-slope and down-slope quarters; per run, the extent of the
    active region attached to each end.  ``onset_up`` / ``onset_down`` (one
    per run): first bin from which the region attached to that end spans at
    least ``HALF_CHAIN`` of the chain in every bin holding events, up to the
    avalanche (its own bin, cut short, excluded as in ``sync_profile``); NaN
    if never.
    """
    edges = np.arange(0.0, alpha_max + EXTREMITY_BIN, EXTREMITY_BIN)
    nb = edges.size - 1
    tot, up, down = np.zeros(nb), np.zeros(nb), np.zeros(nb)
    onsets = {"up": [], "down": []}
    extents = {"up": [], "down": []}
    for r in results:
        e = ob.extremity_activity(r, edges, END_FRACTION)
        tot += e["total"]
        up += e["up"]
        down += e["down"]
        populated = np.flatnonzero(e["events"] > 0)
        if math.isfinite(r.alpha_c) and populated.size:
            last = np.searchsorted(edges, r.alpha_c, side="right") - 1
            populated = populated[populated < last] if populated[-1] == last else populated
        for end in ("up", "down"):
            ext = e[f"extent_{end}"]
            extents[end].append(np.where(e["events"] > 0, ext, np.nan))
            onset = math.nan
            for pos, j in enumerate(populated):
                if np.all(ext[populated[pos:]] >= HALF_CHAIN):
                    onset = float(edges[j])
                    break
            onsets[end].append(onset)
    with np.errstate(invalid="ignore", divide="ignore"):
        share_up, share_down = up / tot, down / tot
    return {"edges": edges, "share_up": share_up, "share_down": share_down, "total": tot,
            "overall_up": float(up.sum() / tot.sum()), "overall_down": float(down.sum() / tot.sum()),
            "onset_up": np.array(onsets["up"]), "onset_down": np.array(onsets["down"]),
            "extent_up": np.array(extents["up"]), "extent_down": np.array(extents["down"])}


def median_onset(onsets) -> float:
    """Median over the runs, a run without an onset counting as "never" (later than any)."""
    o = np.where(np.isfinite(onsets), onsets, np.inf)
    m = float(np.median(o)) if o.size else math.nan
    return m if math.isfinite(m) else math.nan


def departure_angle(alpha, y, sem, fit_range, direction: int) -> tuple[float, dict]:
    """First angle beyond the fit range where y leaves the fitted line by > 3 sigma (2 in a row).

    direction -1: y falls below the line; +1: above.  sigma combines the
    standard error of the point and that of the extrapolated line.
    """
    alpha = np.asarray(alpha)
    sel = (alpha >= fit_range[0]) & (alpha <= fit_range[1]) & np.isfinite(y)
    f = ob.linear_fit(alpha[sel], y[sel], sem[sel] if np.all(np.isfinite(sem[sel]) & (sem[sel] > 0))
                      else None)
    # covariance of intercept/slope ignored: conservative (larger) line error via both errors
    line = f["intercept"] + f["slope"] * alpha
    line_err = np.hypot(f["intercept_err"], f["slope_err"] * alpha)
    sig = np.hypot(np.nan_to_num(sem, nan=0.0), line_err)
    dev = direction * (y - line) / np.where(sig > 0, sig, np.inf)
    out = np.isfinite(y) & (alpha > fit_range[1]) & (dev > DEPARTURE_SIGMAS)
    idx = np.flatnonzero(out[:-1] & out[1:])
    return (float(alpha[idx[0]]) if idx.size else math.nan), f


def stopped_modes(summary, rebin: int = 2) -> list[dict]:
    """Per angle bin: count, mode (bins of 0.01) and median of F_t/F_t*."""
    g = summary.grids
    nr = g.ratio_edges.size - 1
    redges = g.ratio_edges[::rebin]
    rmid = 0.5 * (redges[1:] + redges[:-1])
    out = []
    for j, c in enumerate(g.stop_alpha_centers):
        n = int(summary.stopped_counts[j])
        if n == 0:
            continue
        p = summary.stopped_ratio_pdf[j] * np.diff(g.ratio_edges)
        pr = p.reshape(nr // rebin, rebin).sum(axis=1)
        cdf = np.cumsum(p)
        median = float(g.ratio_edges[1:][np.searchsorted(cdf, 0.5)])
        out.append({"lo": float(g.stop_alpha_edges[j]), "hi": float(g.stop_alpha_edges[j + 1]),
                    "n": n, "mode": float(rmid[np.argmax(pr)]), "median": median,
                    "mean": float(np.sum(p * g.ratio_centers))})
    return out
