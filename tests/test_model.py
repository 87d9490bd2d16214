"""Tests of the analytical model (paper Sec. IV), ``sliders.analysis.model``."""

import math

import numpy as np
import pytest

from sliders.analysis import model

CASES = [(0.6, 0.55), (0.6, 0.595)]  # nu(0) = 12 and 120
ALPHAS = np.array([0.0, 0.01, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0])


# ---------------------------------------------------------------- bins
def test_n_bins_integer_ratio_and_edges():
    assert model.n_bins(0.0, 0.6, 0.55) == 12
    assert model.n_bins(0.0, 0.6, 0.595) == 120
    edge = math.asin(1.2 - 0.1 * 11)  # lower bound reaches the edge of bin 12
    assert model.n_bins(edge - 1e-6, 0.6, 0.55) == 12
    assert model.n_bins(edge, 0.6, 0.55) == 11
    assert model.n_bins(0.0, 0.6, 0.53) == 9  # 8.57 -> 9
    np.testing.assert_array_equal(model.n_bins([0.0, 0.5], 0.6, 0.55), [12, 8])


# ---------------------------------------------------------------- closed form vs RK4
@pytest.mark.parametrize("mu_s, mu_d", CASES)
def test_closed_form_matches_rk4(mu_s, mu_d):
    closed = model.bin_heights(ALPHAS, mu_s, mu_d)
    rk4 = model.integrate_master_equations(ALPHAS, mu_s, mu_d)
    assert closed.shape == rk4.shape == (ALPHAS.size, model.n_bins(0.0, mu_s, mu_d))
    assert np.all(np.isfinite(closed)) and np.all(np.isfinite(rk4))
    assert np.all(closed >= 0.0)
    assert np.max(np.abs(closed - rk4)) < 1e-10
    # initial condition and the exponential decay of the lowest bin
    np.testing.assert_allclose(closed[0], 1.0 / (2 * mu_s), rtol=0, atol=1e-15)
    np.testing.assert_allclose(closed[:, -1],
                               np.exp(-ALPHAS / (2 * (mu_s - mu_d))) / (2 * mu_s),
                               rtol=1e-12, atol=1e-300)


def test_rk4_is_not_exact_with_few_steps():
    """The comparison above is meaningful: a coarse RK4 run is visibly off."""
    closed = model.bin_heights(ALPHAS, 0.6, 0.55)
    coarse = model.integrate_master_equations(ALPHAS, 0.6, 0.55, steps_per_unit=2)
    assert np.max(np.abs(closed - coarse)) > 1e-6


def test_scalar_alpha_shape():
    p = model.bin_heights(0.3, 0.6, 0.55)
    assert p.shape == (12,)
    assert model.bin_heights(0.3, 0.6, 0.55, nu="alpha").shape == (model.n_bins(0.3, 0.6, 0.55),)


# ---------------------------------------------------------------- conservation
@pytest.mark.parametrize("mu_s, mu_d", CASES)
def test_probability_conservation(mu_s, mu_d):
    for p in (model.bin_heights(ALPHAS, mu_s, mu_d),
              model.integrate_master_equations(ALPHAS, mu_s, mu_d),
              model.integrate_master_equations(ALPHAS, mu_s, mu_d, variable_nu=True)):
        np.testing.assert_allclose(model.probability_total(p, mu_s, mu_d), 1.0,
                                   rtol=0, atol=1e-12)


def test_conservation_non_integer_ratio():
    p = model.bin_heights(ALPHAS, 0.6, 0.53)
    np.testing.assert_allclose(model.probability_total(p, 0.6, 0.53), 9 * 0.07 / 0.6,
                               rtol=1e-12)


def test_variable_nu_removes_bins():
    mu_s, mu_d = 0.6, 0.55
    first_edge = math.asin(0.1)
    alphas = np.array([0.05, first_edge - 1e-4, first_edge, 0.3, 0.5])
    var = model.integrate_master_equations(alphas, mu_s, mu_d, variable_nu=True)
    fixed = model.bin_heights(alphas, mu_s, mu_d)
    # before the first edge nothing differs
    assert np.max(np.abs(var[:2] - fixed[:2])) < 1e-10
    # active bins follow nu(alpha); removed bins are zero
    for row, a in zip(var, alphas):
        nu = model.n_bins(a, mu_s, mu_d)
        assert np.all(row[:nu] > 0) and np.all(row[nu:] == 0)
    # at the edge, bin 12's mass went into bin 11
    np.testing.assert_allclose(var[2, 10], fixed[2, 10] + fixed[2, 11], rtol=1e-9)


def test_nu_alpha_closed_form_not_conserved():
    """nu(alpha) substituted in the fixed-nu solution loses probability."""
    p = model.bin_heights(0.5, 0.6, 0.55, nu="alpha")
    assert model.probability_total(p, 0.6, 0.55) < 0.9


# ---------------------------------------------------------------- crude limit
def test_crude_limit_small_alpha():
    mu_s, mu_d = 0.6, 0.595  # nu = 120, far from the lower bound

    def error(alpha):
        p = model.bin_heights(alpha, mu_s, mu_d)
        p1, _ = model.crude_bin_heights(alpha, mu_s, mu_d)
        return abs(p[0] - p1)

    assert error(0.01) < error(0.1) / 50
    # plateau: P_i = 1/(2 mu_s) for 1 < i << nu
    p = model.bin_heights(0.1, mu_s, mu_d)
    _, plateau = model.crude_bin_heights(0.1, mu_s, mu_d)
    np.testing.assert_allclose(p[1:60], plateau, rtol=1e-12)
    assert abs(p[-1] - plateau) > 0.1 * plateau  # ... but not near the lower bound


def test_crude_slope_dp1():
    """P_1 grows like alpha / (4 mu_s dmu) initially (Eq. crude)."""
    mu_s, mu_d = 0.6, 0.55
    p1 = model.bin_heights([0.0, 1e-4], mu_s, mu_d)[:, 0]
    slope = (p1[1] - p1[0]) / 1e-4
    assert slope == pytest.approx(1 / (4 * mu_s * (mu_s - mu_d)), rel=1e-3)


# ---------------------------------------------------------------- paper's P_1
@pytest.mark.parametrize("nu", [3, 5, 12, 30])
def test_paper_p1_matches_conservation(nu):
    al = np.linspace(0.0, 1.0, 21)
    stable = model.bin_heights(al, 0.6, 0.55, nu=nu)[:, 0]
    corrected = model.paper_p1(al, 0.6, 0.55, nu=nu)
    assert np.max(np.abs(stable - corrected)) < 1e-12
    # as printed, the paper's P_1 is short by 1/(2 mu_s): P_1(0) = 0
    printed = model.paper_p1(al, 0.6, 0.55, nu=nu, as_printed=True)
    np.testing.assert_allclose(corrected - printed, 1 / 1.2, rtol=1e-12)
    assert printed[0] == 0.0


# ---------------------------------------------------------------- transition angle
def test_transition_angles():
    stirling = model.transition_angle_stirling(0.6)
    assert stirling == pytest.approx(1.2 / (1 + math.e), rel=1e-14)
    assert stirling == pytest.approx(0.32273, abs=1e-5)
    exact = model.transition_angle_exact(0.6, 0.55)
    from_p3 = model.transition_angle_from_p3(0.6, 0.55)
    print(f"alpha_t: Stirling {stirling:.4f}, Eq. not_neg {exact:.4f}, P_3 {from_p3:.4f}")
    assert math.isfinite(exact) and 0.2 < exact < 0.5
    assert abs(exact - stirling) < 0.1
    assert math.isfinite(from_p3) and exact < from_p3 < 0.5


def test_transition_angle_exact_satisfies_condition():
    mu_s, mu_d = 0.6, 0.55
    a_t = model.transition_angle_exact(mu_s, mu_d)
    dmu = mu_s - mu_d

    def lhs(a):
        m = model.n_bins(a, mu_s, mu_d) - 2
        return math.exp(m * math.log(a / (2 * dmu)) - math.lgamma(m + 1))

    assert lhs(a_t) >= 0.1 * (1 - 1e-9)
    grid = np.linspace(1e-3, a_t, 2000)[:-1]
    assert max(lhs(a) for a in grid) < 0.1


def test_transition_angle_from_p3_satisfies_condition():
    mu_s, mu_d = 0.6, 0.55
    a_t = model.transition_angle_from_p3(mu_s, mu_d)

    def deficit(a):
        nu = model.n_bins(a, mu_s, mu_d)
        return 1 - 2 * mu_s * model.bin_heights(a, mu_s, mu_d, nu=nu)[2]

    assert deficit(a_t) >= 0.1 - 1e-12
    assert deficit(a_t - 1e-6) < 0.1
    assert max(deficit(a) for a in np.linspace(0, a_t, 400)[:-1]) < 0.1


def test_stirling_limit_small_dmu():
    """As dmu -> 0, Eq. not_neg tends to the root of e alpha + sin(alpha) = 2 mu_s."""
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if math.e * mid + math.sin(mid) < 1.2 else (lo, mid)
    assert abs(model.transition_angle_exact(0.6, 0.5995) - lo) < 1e-3
    assert abs(model.transition_angle_exact(0.6, 0.55) - lo) > 1e-2


# ---------------------------------------------------------------- single slider
def test_single_slider_event():
    assert model.single_slider_displacement(0.0, 0.6, 0.55) == pytest.approx(0.05)
    assert model.single_slider_force_drop(0.3, 0.6, 0.55) == pytest.approx(0.1 * math.cos(0.3))
    assert model.single_slider_next_increment(0.0, 0.6, 0.55) == pytest.approx(0.1)


@pytest.mark.parametrize("mu_s, mu_d, f0", [(0.6, 0.55, 0.59), (0.6, 0.55, -0.3),
                                            (0.6, 0.59, 0.0)])
def test_single_slider_angles(mu_s, mu_d, f0):
    dmu = mu_s - mu_d
    angles = model.single_slider_angles(f0, mu_s, mu_d, 1.2)
    assert angles.size > 5 and np.all(np.diff(angles) > 0) and angles[-1] <= 1.2
    # each angle is exactly on the threshold; first from the initial force
    assert f0 + math.sin(angles[0]) == pytest.approx(mu_s * math.cos(angles[0]), abs=1e-14)
    force_after = (2 * mu_d - mu_s) * np.cos(angles[:-1])
    elastic = force_after - np.sin(angles[:-1])
    np.testing.assert_allclose(elastic + np.sin(angles[1:]), mu_s * np.cos(angles[1:]),
                               rtol=0, atol=1e-14)
    increments = np.diff(angles)
    recurrence = model.single_slider_next_increment(angles[:-1], mu_s, mu_d)
    assert np.max(np.abs(increments - recurrence)) < 10 * dmu**2
    small = angles[:-1] < 0.1
    if small.any():
        np.testing.assert_allclose(increments[small], 2 * dmu, rtol=0.1)


def test_single_slider_small_angle_increments():
    """Delta alpha ~ 2 dmu up to O(mu_s alpha) and O(dmu) relative corrections."""
    angles = model.single_slider_angles(0.5999, 0.6, 0.595, 0.3)
    assert angles[0] < 0.001
    increments = np.diff(angles)[angles[1:] < 0.05]
    assert increments.size >= 4
    np.testing.assert_allclose(increments, 0.01, rtol=0.05)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, name", [
    (lambda: model.bin_heights(0.1, 0.5, 0.55), "mu_s_mean"),
    (lambda: model.bin_heights(0.1, 0.55, 0.55), "mu_s_mean"),
    (lambda: model.bin_heights(-0.1, 0.6, 0.55), "alpha"),
    (lambda: model.bin_heights(float("nan"), 0.6, 0.55), "alpha"),
    (lambda: model.bin_heights(0.1, float("nan"), 0.55), "mu_s_mean"),
    (lambda: model.bin_heights(0.1, 0.6, 0.55, nu="bogus"), "nu"),
    (lambda: model.n_bins([0.1, -1.0], 0.6, 0.55), "alpha"),
    (lambda: model.crude_bin_heights(0.1, 0.6, 0.7), "mu_s_mean"),
    (lambda: model.integrate_master_equations([0.1, float("nan")], 0.6, 0.55), "alphas"),
    (lambda: model.integrate_master_equations([0.1], 0.6, 0.55, method="euler"), "method"),
    (lambda: model.single_slider_angles(0.7, 0.6, 0.55, 1.0), "initial_force"),
    (lambda: model.single_slider_angles(0.0, 0.5, 0.55, 1.0), "mu_s"),
    (lambda: model.single_slider_angles(0.0, 0.6, 0.55, float("nan")), "alpha_max"),
    (lambda: model.single_slider_next_increment(-0.2, 0.6, 0.55), "alpha_i"),
    (lambda: model.single_slider_displacement(0.1, 0.6, -0.1), "mu_d"),
    (lambda: model.transition_angle_exact(0.6, 0.55, level=1.5), "level"),
    (lambda: model.transition_angle_from_p3(0.5, 0.55), "mu_s_mean"),
    (lambda: model.transition_angle_stirling(-0.6), "mu_s_mean"),
])
def test_bad_input(call, name):
    with pytest.raises(ValueError, match=name):
        call()
