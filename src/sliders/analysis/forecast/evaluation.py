"""The honest evaluation: a split by realisation, cuts at leads and at fixed tilts, metrics with
bootstrap confidence intervals, and the alarm "the avalanche within the next delta".

Every metric is computed per realisation and resampled over realisations
(``bootstrap``), so its interval says how much the number would move with
another test set of the same size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import LOWER, MEDIAN, UPPER, pinball_crps, probability_within
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
