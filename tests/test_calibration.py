"""The calibration tests of a posterior (``analysis.forecast.calibration``) on a toy posterior
whose answer is known: a Gaussian parameter seen through Gaussian noise.

theta ~ N(0, 1) and x | theta ~ N(theta, s^2): the exact posterior is
N(x / (1 + s^2), s^2 / (1 + s^2)), so its PIT at the truth is uniform, its SBC ranks are
uniform on 0..L and each central interval holds its nominal share of the truths (within the
binomial spread).  A posterior half as wide is over-confident: the same tests fail.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sliders.analysis.forecast.calibration import (COVERAGES, calibration_of, coverage_of,
                                                   ks_count, ks_p_value, pit_is_off,
                                                   randomized_pit, sbc_ranks)

NOISE = 0.5
PAIRS = 2000


def normal_cdf(z):
    return 0.5 * np.vectorize(math.erfc)(-np.asarray(z) / math.sqrt(2.0))


def toy(rng, width: float = 1.0, pairs: int = PAIRS):
    """The truths, the posterior's means and sds (``width`` times the exact sd)."""
    theta = rng.standard_normal(pairs)
    x = theta + NOISE * rng.standard_normal(pairs)
    mean = x / (1 + NOISE**2)
    sd = width * NOISE / math.sqrt(1 + NOISE**2)
    return theta, mean, np.full(pairs, sd)


def binomial_band(p: float, n: int, z: float = 3.5) -> float:
    return z * math.sqrt(p * (1 - p) / n)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_exact_posterior_passes_every_test(seed):
    rng = np.random.default_rng(seed)
    theta, mean, sd = toy(rng)
    u = normal_cdf((theta - mean) / sd)  # no atom: lo = hi
    d = calibration_of(u, u, randomized_pit(u, u, rng))
    assert d["ks_p_value"] > 0.01 and d["ranks"] == u.tolist()
    for c in COVERAGES:
        assert abs(d["coverage"][f"{c:g}"] - c) < binomial_band(c, PAIRS)
    assert not pit_is_off(u, 0.01)
    draws = mean[:, None] + sd[:, None] * rng.standard_normal((PAIRS, 19))
    counts = np.bincount(sbc_ranks(theta, draws), minlength=20)  # uniform on 0..19
    expected = PAIRS / 20
    chi2 = float(np.sum((counts - expected) ** 2 / expected))
    assert chi2 < 43.8  # chi-squared, 19 degrees of freedom, 0.1 % level


def test_a_posterior_too_narrow_fails_them():
    rng = np.random.default_rng(2)
    theta, mean, sd = toy(rng, width=0.5)
    u = normal_cdf((theta - mean) / sd)
    d = calibration_of(u, u, u)
    assert d["ks_p_value"] < 1e-6 and pit_is_off(u, 0.01)
    for c in COVERAGES:  # the truths fall outside the intervals too often
        assert d["coverage"][f"{c:g}"] < c - binomial_band(c, PAIRS)
    draws = mean[:, None] + sd[:, None] * rng.standard_normal((PAIRS, 19))
    counts = np.bincount(sbc_ranks(theta, draws), minlength=20)
    assert counts[0] + counts[-1] > 3 * 2 * PAIRS / 20  # the ends over-full: a U-shaped histogram


def test_an_atom_counts_in_part_and_its_pit_is_drawn_within_it():
    lo, hi = np.array([0.0, 0.2, 0.5]), np.array([0.6, 0.2, 0.5])
    # the atom [0, 0.6] has 0.5 of its 0.6 inside [0.1, 0.9]; 0.2 and 0.5 are inside
    assert coverage_of(lo, hi, 0.8) == pytest.approx((0.5 / 0.6 + 1 + 1) / 3)
    u = randomized_pit(lo, hi, np.random.default_rng(0))
    assert 0.0 <= u[0] <= 0.6 and u[1] == 0.2 and u[2] == 0.5


def test_the_ks_count_over_draws_against_chance():
    rng = np.random.default_rng(3)
    exact = [ks_p_value(normal_cdf(((t - m) / s))) for t, m, s in
             (toy(rng, pairs=300) for _ in range(20))]
    narrow = [ks_p_value(normal_cdf(((t - m) / s))) for t, m, s in
              (toy(rng, 0.5, pairs=300) for _ in range(20))]
    calibrated = ks_count({"complete": {"mu_d": exact}}, 0.05)
    assert calibrated["tests"] == 20 and calibrated["expected_if_calibrated"] == pytest.approx(1.0)
    assert calibrated["failed"] <= 5  # P(more than 5 of 20 at 5 %) = 3e-4
    assert ks_count([narrow], 0.05)["failed"] == 20
