"""The alarm's skill as a lab measures it: piles followed to their avalanche, the alarm judged
at each threshold, and the threshold a forecaster's alarm sounds at by default.

A pile followed from well before its avalanche gives at each step P(avalanche within
``within``); a single forecast's alarm is ``P >= threshold`` (no hysteresis).  Per
threshold: the share of piles whose alarm rose before their avalanche (``hit_share``), the
warning (degrees before the avalanche at which it first rose: median and 10th percentile of
the piles it rose for), and the false alarms: the share of piles whose alarm first rose more
than ``FALSE_ALARM_DEG`` before their avalanche.  ``choose_threshold`` picks the default: the
most hits with at most ``MAX_FALSE_ALARMS`` false alarms.  Plain NumPy.
"""

from __future__ import annotations

import math

import numpy as np

#: an alarm first raised more than this many degrees before the avalanche is a false alarm
FALSE_ALARM_DEG = 3.0
#: the share of false alarms the default threshold may give
MAX_FALSE_ALARMS = 0.10
#: the thresholds judged
THRESHOLDS = np.round(np.arange(0.3, 0.91, 0.05), 2)


def first_alarms(probability, lead, row, thresholds=THRESHOLDS) -> tuple[np.ndarray, np.ndarray]:
    """(thresholds, piles) the lead (radians before the avalanche) at which each pile's alarm
    first rose along its follow (NaN: never), and the piles (``row`` values) in order.

    ``probability``, ``lead``, ``row``: one entry per step of every pile's follow (any order).
    """
    probability, lead, row = (np.asarray(a) for a in (probability, lead, row))
    thresholds = np.asarray(thresholds, dtype=float)
    piles = np.unique(row)
    first = np.full((thresholds.size, piles.size), np.nan)
    for j, r in enumerate(piles):
        m = row == r
        order = np.argsort(-lead[m], kind="stable")  # along the tilt
        p, ld = probability[m][order], lead[m][order]
        on = p[None, :] >= thresholds[:, None]
        has = on.any(axis=1)
        first[has, j] = ld[np.argmax(on[has], axis=1)]
    return first, piles


def alarm_table(first: np.ndarray, thresholds=THRESHOLDS) -> list[dict]:
    """Per threshold, from ``first_alarms``: ``hit_share``, ``warning_median_deg``,
    ``warning_p10_deg`` (of the piles whose alarm rose), ``false_alarm_share``, ``piles``."""
    out = []
    for t, f in zip(np.asarray(thresholds, dtype=float), first):
        rose = np.isfinite(f)
        deg = np.degrees(f[rose])
        out.append({"threshold": float(t), "hit_share": float(rose.mean()),
                    "warning_median_deg": float(np.median(deg)) if deg.size else math.nan,
                    "warning_p10_deg": float(np.percentile(deg, 10)) if deg.size else math.nan,
                    "false_alarm_share": float(np.mean(rose & (np.degrees(np.nan_to_num(f))
                                                              > FALSE_ALARM_DEG))),
                    "piles": int(f.size)})
    return out


def choose_threshold(table: list[dict], max_false: float = MAX_FALSE_ALARMS) -> dict | None:
    """The row of ``table`` with the most hits among those of at most ``max_false`` false
    alarms (a tie: the larger median warning, then the lower threshold); None if none is."""
    ok = [r for r in table if r["false_alarm_share"] <= max_false]
    if not ok:
        return None
    return max(ok, key=lambda r: (r["hit_share"], np.nan_to_num(r["warning_median_deg"]),
                                  -r["threshold"]))
