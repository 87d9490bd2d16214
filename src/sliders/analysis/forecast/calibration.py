"""Is a posterior calibrated?  The tests of simulation-based calibration, for any posterior.

Given pairs (true parameter, catalogue) drawn from the joint law the posterior
conditions on, a calibrated posterior's CDF at the truth, the probability
integral transform (PIT), is uniform on [0, 1] (Talts et al. 2018's rank, in
the limit of many draws).  A parameter with atoms (xi = 0, a number of sliders)
gives an interval [``lo``, ``hi``] of PITs, the CDF just below the truth and at
it; the PIT is then drawn uniformly in it (``randomized_pit``) and an interval's
coverage counts the share of each atom inside it (``coverage_of``, the
non-randomized PIT of Czado, Gneiting and Held 2009).

* ``pit_is_off``: the uniformity tests of the posterior's recalibration
  (Kolmogorov-Smirnov, and the binomial share in central intervals);
* ``calibration_of``: one parameter's KS p-value, coverages and PITs;
* ``sbc_ranks``: the ranks of the truths among posterior draws (uniform on
  ``0..L`` when calibrated);
* ``ks_count``: how many KS tests over several independent draws fail at a
  level, against the number a calibrated posterior fails by chance.

This module imports SciPy's statistics (a second and more): the posterior imports it when it
fits, not when it is read.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import binomtest, kstest

#: the central intervals whose coverage is reported
COVERAGES = (0.5, 0.8, 0.95)


def ks_p_value(u) -> float:
    """The Kolmogorov-Smirnov p-value of ``u`` against the uniform law on [0, 1]."""
    return float(kstest(np.asarray(u, dtype=float), "uniform").pvalue)


def pit_is_off(u, alpha: float, intervals=COVERAGES) -> bool:
    """Independent probability integral transforms ``u`` are not uniform: the
    Kolmogorov-Smirnov test, or the share inside a central interval of ``intervals``
    (binomial), fails at ``alpha``."""
    if ks_p_value(u) < alpha:
        return True
    inside = [int(np.sum(np.abs(np.asarray(u) - 0.5) <= c / 2)) for c in intervals]
    return any(binomtest(k, len(u), c).pvalue < alpha for k, c in zip(inside, intervals))


def randomized_pit(lo, hi, rng) -> np.ndarray:
    """PITs drawn uniformly in [``lo``, ``hi``] (an atom's probability spread; ``lo`` itself
    where the two meet)."""
    return rng.uniform(lo, hi)


def coverage_of(lo, hi, c: float) -> float:
    """The share of the truths inside the central ``c`` interval, each PIT uniform on
    [``lo``, ``hi``] (an atom's share inside counted in part; a point where they meet)."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    a, b = 0.5 - c / 2, 0.5 + c / 2
    width = hi - lo
    part = np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0.0, None) / np.where(width > 0, width, 1)
    return float(np.mean(np.where(width > 0, part, (lo >= a) & (lo <= b))))


def calibration_of(lo, hi, u, coverages=COVERAGES) -> dict:
    """One parameter's calibration from its PIT bounds over independent pairs and its PITs
    ``u`` drawn in them (``randomized_pit``): their KS p-value, each central interval's
    coverage (``coverage_of``, keyed ``f"{c:g}"``) and the PITs (``ranks``)."""
    return {"ks_p_value": ks_p_value(u),
            "coverage": {f"{c:g}": coverage_of(lo, hi, c) for c in coverages},
            "ranks": np.asarray(u).tolist()}


def sbc_ranks(truth, draws) -> np.ndarray:
    """(n,) the rank of each truth among its ``L`` posterior draws (``draws``: (n, L)): how many
    fall below it, uniform on ``0..L`` when the posterior is calibrated."""
    return np.sum(np.asarray(draws) < np.asarray(truth)[:, None], axis=1)


def ks_count(p_values, level: float = 0.05) -> dict:
    """How many of the KS tests ``p_values`` (any nesting of lists and dicts of numbers) fail at
    ``level``, and how many a calibrated posterior fails by chance: one draw's few tests say
    less than several independent draws' count."""
    def flat(x):
        if isinstance(x, dict):
            return [v for item in x.values() for v in flat(item)]
        if isinstance(x, (list, tuple, np.ndarray)):
            return [v for item in x for v in flat(item)]
        return [float(x)]

    every = flat(p_values)
    return {"tests": len(every), "failed": int(sum(v <= level for v in every)),
            "expected_if_calibrated": level * len(every)}
