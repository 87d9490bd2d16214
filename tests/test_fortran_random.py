"""The Fortran keyed generator (sliders._kernel) against keyed_random.py."""

import numpy as np
import pytest

from sliders import _kernel, keyed_random

U32_MAX = 2**32 - 1
SEEDS = [0, 1, 20240601, 2**31, U32_MAX]


def keys(n, seed=0):
    """n keys (slider, count, draw) with the edge values put in front."""
    rng = np.random.default_rng(seed)
    slider = rng.integers(0, 10**6, n, endpoint=True)
    count = rng.integers(0, 10**5, n, endpoint=True)
    draw = rng.integers(0, U32_MAX, n, endpoint=True)
    edges = [0, 1, 2, 2**31 - 1, 2**31, U32_MAX - 1, U32_MAX]
    m = len(edges)
    slider[:m], count[:m], draw[:m] = edges, edges[::-1], edges
    slider[m : 2 * m] = U32_MAX - np.arange(m)
    count[m : 2 * m] = keyed_random.PREPARATION_STREAM
    draw[m : 2 * m] = U32_MAX - np.arange(m)
    return slider, count, draw


@pytest.mark.parametrize("seed", SEEDS)
def test_uniform_bit_exact(seed):
    slider, count, draw = keys(4000, seed)
    got = _kernel.random_uniform(seed, slider, count, draw)
    want = keyed_random.uniform(seed, slider, count, draw)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))
    assert np.all((got > 0.0) & (got < 1.0))


@pytest.mark.parametrize("seed", SEEDS)
def test_static_coefficient_matches(seed):
    slider, count, _ = keys(3000, seed)
    # mu_d one sigma below the mean: about one draw in six is rejected at least once
    args = (0.6, 0.1, 0.5)
    got, status = _kernel.random_static_coefficient(seed, slider, count, *args)
    want = keyed_random.static_coefficient(seed, slider, count, *args)
    assert status == 0
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0.0)
    assert np.all(got > 0.5)


def test_doubles_are_not_truncated():
    slider = np.arange(2000)
    count = np.zeros_like(slider)
    got, status = _kernel.random_static_coefficient(7, slider, count, 0.6, 1e-12, 0.5)
    assert status == 0
    dev = got - 0.6
    assert np.all(np.abs(dev) < 1e-10)
    assert 0.5e-12 < dev.std() < 2e-12  # float32 would give 0.6 +- 1e-8 or exactly 0.6
    np.testing.assert_allclose(
        got, keyed_random.static_coefficient(7, slider, count, 0.6, 1e-12, 0.5), rtol=1e-15
    )


def test_exhausted_attempts_report_status():
    got, status = _kernel.random_static_coefficient(3, [0, 1], [0, 0], 0.6, 0.01, 10.0)
    assert status != 0
    assert np.all(np.isnan(got))
    with pytest.raises(RuntimeError):
        keyed_random.static_coefficient(3, [0, 1], [0, 0], 0.6, 0.01, 10.0)


def test_uniform_statistics():
    n = 10**5
    slider = np.arange(n)
    u = _kernel.random_uniform(11, slider, slider % 97, np.zeros(n, dtype=np.int64))
    sigma = np.sqrt(1.0 / 12.0)
    assert abs(u.mean() - 0.5) < 5 * sigma / np.sqrt(n)
    # standard error of the sample std: sqrt(mu4 - sigma^4) / (2 sigma sqrt(n)), mu4 = 1/80
    se_std = np.sqrt(1.0 / 80.0 - 1.0 / 144.0) / (2 * sigma * np.sqrt(n))
    assert abs(u.std() - sigma) < 5 * se_std


def test_gaussian_statistics():
    n = 10**5
    slider = np.arange(n)
    mu, status = _kernel.random_static_coefficient(5, slider, slider % 13, 0.6, 0.01, 0.5)
    assert status == 0
    assert np.all(mu > 0.5)
    assert abs(mu.mean() - 0.6) < 5 * 0.01 / np.sqrt(n)
    assert abs(mu.std() - 0.01) < 5 * 0.01 / np.sqrt(2 * n)
