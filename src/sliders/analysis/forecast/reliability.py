"""Do the intervals mean what they say?  Coverage over all cuts, per bin of what the forecaster
observes, per lead (a stress test), and the reliability of "the avalanche within delta".

The calibration target is the coverage over cuts drawn as the forecaster meets
them (tilts uniform over each run, ``features.training_cuts``), and in bins of
what it sees: the tilt reached and the events so far.  The lead is unknown to
the forecaster; the coverage at fixed leads is reported as a stress test.
"""

from __future__ import annotations

import json

import numpy as np

from .base import LOWER, MEDIAN, UPPER, probability_within
from .evaluation import cuts_at_leads
from .features import training_cuts
from ...io.safeio import publish_bytes

#: bins of the tilt reached and of the events so far (quantile edges of the test cuts)
OBSERVED_BINS = 4
#: bins of the forecast probability in the reliability diagram
RELIABILITY_BINS = 10


def _coverage(q, truth) -> dict:
    inside = (q[:, LOWER] <= truth) & (truth <= q[:, UPPER])
    return {"coverage": float(inside.mean()) if truth.size else float("nan"), "n": int(truth.size)}


def _binned(q, truth, value, n_bins) -> dict:
    """Coverage in quantile bins of ``value``: {"lo-hi": {coverage, n}}."""
    edges = np.unique(np.quantile(value, np.linspace(0, 1, n_bins + 1)))
    b = np.clip(np.searchsorted(edges, value, side="right") - 1, 0, edges.size - 2)
    return {f"{edges[k]:.4g}-{edges[k + 1]:.4g}": _coverage(q[b == k], truth[b == k])
            for k in range(edges.size - 1) if (b == k).any()}


def reliability_diagram(probability, happened, n_bins: int = RELIABILITY_BINS) -> dict:
    """Forecast probability against observed frequency, in equal bins of probability."""
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    b = np.clip(np.searchsorted(edges, probability, side="right") - 1, 0, n_bins - 1)
    rows = [{"p_mean": float(probability[b == k].mean()), "observed": float(happened[b == k].mean()),
             "n": int((b == k).sum())} for k in range(n_bins) if (b == k).any()]
    return {"bins": rows, "brier": float(np.mean((probability - happened) ** 2))}


def coverage_report(forecaster, cset, rows, leads, path: str | None = None,
                    delta: float = np.radians(1.0), draws_per_row: int = 10, seed: int = 0,
                    degrade=None) -> dict:
    """The coverage of ``forecaster``'s 80 % interval on rows ``rows`` of ``cset``.

    Parameters
    ----------
    forecaster : Forecaster
        Fitted.
    cset : CatalogueSet
        Held-out realisations.
    rows : array_like of int
        The rows measured.
    leads : array_like of float
        Leads before the avalanche of the stress test, radians.
    path : str, optional
        Where the report is written (JSON).
    delta : float
        The horizon of "the avalanche within delta" (reliability diagram).
    degrade : callable, optional
        ``degrade(cuts) -> cuts``: the test cuts as an experiment measures them.

    Returns
    -------
    dict
        ``all_cuts``, ``per_tilt_bin``, ``per_events_bin`` (coverage and n),
        ``per_lead`` (coverage, median absolute error in radians, n, keyed by the
        lead in degrees), ``reliability`` (the diagram of P(within delta)).
    """
    sub = cset.subset(np.asarray(rows))
    cuts = training_cuts(sub, draws_per_row, np.random.default_rng(seed))
    cuts = degrade(cuts) if degrade is not None else cuts
    q, _, levels = forecaster.quantiles(cuts, levels=True)
    truth = cuts.alpha_c
    events = np.array([len(c) for c in cuts.catalogues], dtype=float)
    p = probability_within(q, cuts.tilt_now, delta, levels)
    report = {"all_cuts": _coverage(q, truth),
              "per_tilt_bin": _binned(q, truth, cuts.tilt_now, OBSERVED_BINS),
              "per_events_bin": _binned(q, truth, events, OBSERVED_BINS),
              "reliability": reliability_diagram(p, (truth <= cuts.tilt_now + delta).astype(float)),
              "per_lead": {}}
    lead_cuts, group = cuts_at_leads(sub, np.arange(len(sub)), np.asarray(leads, dtype=float))
    lead_cuts = degrade(lead_cuts) if degrade is not None else lead_cuts
    ql, _ = forecaster.quantiles(lead_cuts)
    for j, lead in enumerate(np.asarray(leads, dtype=float)):
        m = group == j
        entry = _coverage(ql[m], lead_cuts.alpha_c[m])
        entry["median_abs"] = float(np.median(np.abs(ql[m, MEDIAN] - lead_cuts.alpha_c[m]))) \
            if m.any() else float("nan")
        report["per_lead"][f"{np.degrees(lead):g}"] = entry
    if path is not None:
        publish_bytes(path, (json.dumps(report, indent=1) + "\n").encode(), overwrite=True)
    return report
