"""Forecasters of the avalanche angle (sliders.analysis.forecast): the issue's checks.

Small synthetic catalogues (exact rate laws) and a few tiny simulated runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from sliders.analysis.forecast import (LEVELS, Climatology, ConditionedClimatology, Cuts,
                                       LastEventPlusLead, LinearInverseRate, Now,
                                       PointProcessInverseRate, training_cuts)
from sliders.analysis.forecast.base import pinball_crps, probability_within
from sliders.analysis.forecast.baselines import conditioned_quantiles
from sliders.analysis.forecast.evaluation import split_rows
from sliders.analysis.forecast.learned import Learned
from sliders.analysis.forecast.physics import ModelBased, PaperRule, transition_angle
from sliders.io.catalogue import Catalogue, CatalogueSet
from helpers import rate_law_catalogue, synthetic_set


@pytest.mark.parametrize("forecaster", [LinearInverseRate("events"), PointProcessInverseRate("events"),
                                        LinearInverseRate("displacement"),
                                        LinearInverseRate("events", exponent=None)])
@pytest.mark.parametrize("tilt", [0.42, 0.47])
def test_inverse_rate_recovers_alpha_c_of_an_exact_rate_law(forecaster, tilt):
    alpha_c = 0.5
    cat = rate_law_catalogue(alpha_c, 100.0, tilt)
    forecaster.fit(synthetic_set(3))
    f = forecaster.predict(cat)
    assert not f.fallback
    assert abs(f.point - alpha_c) < 0.15 * (alpha_c - tilt)
    lo, hi = f.interval
    assert lo <= alpha_c <= hi


def test_inverse_rate_without_acceleration_falls_back():
    alpha = np.linspace(0.01, 0.3, 200)  # a steady rate: no finite failure angle
    n = alpha.size
    cat = Catalogue(alpha, np.ones(n), np.full(n, 0.01), -np.ones(n), -np.ones(n), tilt_now=0.3)
    f = PointProcessInverseRate("events").fit(synthetic_set(20)).predict(cat)
    assert f.fallback and f.point > 0.3


def test_point_mass_prior_gives_the_point():
    rows = 12
    cats = [rate_law_catalogue(0.5, 40.0, 0.499) for _ in range(rows)]
    cset = CatalogueSet.from_catalogues(cats, {"mu_d": np.full(rows, 0.54)}, np.full(rows, 0.5),
                                        ["avalanche"] * rows)
    clim = Climatology().fit(cset)
    q, fb = clim.quantiles(Cuts.from_set(cset, [0, 1], [0.1, 0.4]))
    assert np.all(q == 0.5) and not fb.any()
    assert clim.predict(cats[0]).interval == (0.5, 0.5)
    q, _ = ConditionedClimatology().fit(cset).quantiles(Cuts.from_set(cset, [0], [0.3]))
    assert np.all(q == 0.5)


def test_now_and_conditioned_climatology_respect_the_tilt():
    cset = synthetic_set(40)
    cuts = Cuts.from_set(cset, np.arange(40), cset.alpha_c - 0.02)
    qn, _ = Now().quantiles(cuts)
    assert np.allclose(qn, cuts.tilt_now[:, None])
    qc, _ = ConditionedClimatology().fit(cset).quantiles(cuts)
    assert np.all(qc >= cuts.tilt_now[:, None])
    ql, _ = LastEventPlusLead(draws_per_row=5).fit(cset).quantiles(cuts)
    assert np.all(ql >= cuts.tilt_now[:, None])


@pytest.mark.slow  # fits the learned forecaster (tens of seconds)
def test_learned_forecaster_is_deterministic_with_a_fixed_seed():
    train = synthetic_set(30, seed=1)
    test = synthetic_set(5, seed=2)
    cuts = Cuts.from_set(test, np.arange(5), test.alpha_c - 0.03)
    a = Learned(draws_per_row=8, max_iter=15, random_state=3).fit(train).quantiles(cuts)[0]
    b = Learned(draws_per_row=8, max_iter=15, random_state=3).fit(train).quantiles(cuts)[0]
    c = Learned(draws_per_row=8, max_iter=15, random_state=4).fit(train).quantiles(cuts)[0]
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.all(np.diff(a, axis=1) >= 0) and np.all(a > cuts.tilt_now[:, None])


def test_split_has_no_leakage():
    s = split_rows(103, seed=5)
    parts = [set(s.train), set(s.validation), set(s.test)]
    assert sum(map(len, parts)) == 103 and set().union(*parts) == set(range(103))
    assert not (parts[0] & parts[1] or parts[0] & parts[2] or parts[1] & parts[2])
    cset = synthetic_set(103)
    train = cset.subset(s.train)
    cuts = training_cuts(train, 6, np.random.default_rng(0))
    # every training cut is a prefix of a training realisation, none of a test one
    test_alpha_c = set(cset.alpha_c[s.test])
    assert not test_alpha_c & set(cuts.alpha_c)
    for cat, r in zip(cuts.catalogues[:50], cuts.row[:50]):
        whole = train.catalogue(int(r))
        assert np.array_equal(cat.alpha, whole.alpha[:len(cat)])


def test_training_cuts_do_not_know_the_lead():
    """Cut tilts are drawn without alpha_c: the lead spreads over the whole run, not a few values."""
    cset = synthetic_set(200)
    cuts = training_cuts(cset, 10, np.random.default_rng(1))
    lead = cuts.alpha_c - cuts.tilt_now
    assert np.all(lead > 0)
    assert np.unique(np.round(lead, 3)).size > 100
    assert np.corrcoef(cuts.tilt_now, cuts.alpha_c)[0, 1] < 0.5


def test_probability_within_and_crps():
    q = np.tile(np.linspace(0.4, 0.6, LEVELS.size), (2, 1))
    p = probability_within(q, np.array([0.3, 0.5]), 0.0)
    assert p[0] == 0.0 and 0.4 < p[1] < 0.6
    assert probability_within(np.full((1, LEVELS.size), 0.5), np.array([0.5]), 0.01)[0] == 1.0
    crps = pinball_crps(q, np.array([0.5, 0.9]))
    assert crps[0] < crps[1]


def test_paper_rule_and_model_based_on_simulated_runs():
    from sliders.runs.forecast.dev import dev_catalogue_set

    prior = {"mu_d": ("uniform", (0.4, 0.6)), "mu_s_minus_mu_d": ("loguniform", (0.03, 0.08)),
             "sigma_mu": ("uniform", (0.005, 0.02)), "xi": ("point", 0.0),
             "n_sliders": ("choice", (40,))}
    cset = dev_catalogue_set(16, seed=3, prior=prior)
    assert np.isfinite(cset.alpha_c).all()
    # the single-slider displacement measures mu_s - mu_d
    from sliders.analysis.forecast.features import size_one_delta_mu

    est = np.array([size_one_delta_mu(cset.catalogue(i)) for i in range(16)])
    true = cset.parameters["mu_s_mean"] - cset.parameters["mu_d"]
    assert np.corrcoef(est, true)[0, 1] > 0.8
    # two lone slips of one slider (neighbours at rest) give mu_d exactly when xi = 0
    from sliders.analysis.forecast.features import densest_value, single_slider_mu_d

    mu_d = np.array([densest_value(single_slider_mu_d(cset.catalogue(i)))[0] for i in range(16)])
    ok = np.isfinite(mu_d)
    assert ok.mean() > 0.7
    assert np.median(np.abs(mu_d[ok] - cset.parameters["mu_d"][ok])) < 1e-6
    at = np.array([transition_angle(cset.catalogue(i)) for i in range(16)])
    assert np.isfinite(at).mean() > 0.5 and np.all(at[np.isfinite(at)] < cset.alpha_c[np.isfinite(at)])
    train, test = cset.subset(np.arange(12)), cset.subset(np.arange(12, 16))
    cuts = Cuts.from_set(test, np.arange(4), test.alpha_c - 0.02)
    for f in (PaperRule(), ModelBased(draws_per_row=3)):
        q, fb = f.fit(train).quantiles(cuts)
        assert q.shape == (4, LEVELS.size) and np.all(q >= cuts.tilt_now[:, None])


@pytest.mark.slow  # fits the learned forecaster (tens of seconds)
def test_learned_forecaster_widens_its_interval_outside_its_training_domain():
    """A tilt above every training avalanche angle is out of the domain: the interval is widened
    to hold the conditioned climatology's, marked, with the reason; a training-like cut is not."""
    train = synthetic_set(60, seed=1)
    f = Learned(inputs="angles_sizes", draws_per_row=8, max_iter=10, random_state=0).fit(train)
    late = rate_law_catalogue(0.9, 60.0, 0.8)
    cuts = Cuts.from_catalogues([late])
    inside, why = f.domain(cuts)
    assert not inside[0] and "above" in why[0]
    q, fb = f.quantiles(cuts)
    assert fb[0] and np.all(q >= 0.8)
    qc, _ = conditioned_quantiles(f.climatology_.alpha_c_, cuts.tilt_now)
    assert q[0, 1] <= qc[0, 1] and q[0, -2] >= qc[0, -2]
    busy = train.catalogue(0).cut(0.2)
    assert f.domain(Cuts.from_catalogues([busy]))[0][0]


def test_recent_gaps_of_a_hand_made_catalogue():
    """gap_k: the tilt reached minus the k-th last event's angle; gap_share_k = gap_k / gap_2k."""
    from sliders.analysis.forecast.features import catalogue_features

    alpha = np.array([0.1, 0.2, 0.3, 0.36, 0.38, 0.3985])
    cat = Catalogue(alpha, np.ones(6), np.zeros(6), -np.ones(6), -np.ones(6), tilt_now=0.4)
    f = catalogue_features(cat)
    assert f["gap_1"] == pytest.approx(0.0015) and f["gap_2"] == pytest.approx(0.02)
    assert f["gap_4"] == pytest.approx(0.1) and np.isnan(f["gap_8"])
    assert f["gap_share_1"] == pytest.approx(0.075) and f["gap_share_2"] == pytest.approx(0.2)
    assert np.isnan(f["gap_share_4"])
    # the shortest window (0.002 rad) holds the last event only; 0.05 rad the last three
    assert f["events_0.002"] == pytest.approx(1 / 0.002) and f["events_0.05"] == pytest.approx(3 / 0.05)


@pytest.mark.parametrize("rate_a", [20.0, 60.0])
def test_gap_shares_of_a_rate_law_measure_the_rate_not_the_remaining_angle(rate_a):
    """Under the rate A / (alpha_c - alpha) the k-th last event lies (alpha_c - tilt)(e^(k/A) - 1)
    back: cut just before an event, gap_k / gap_2k = 1 / (1 + e^(k/A)) at any remaining angle."""
    from sliders.analysis.forecast.features import recent_gaps

    whole = rate_law_catalogue(0.5, rate_a, 0.499)
    for m in (40, 100):  # the cut lies a hair before event m: the remaining angle differs
        cat = whole.cut(float(whole.alpha[m]) - 1e-12)
        f = recent_gaps(cat.alpha, cat.tilt_now)
        for k in (2, 4, 8, 16):
            assert f[f"gap_share_{k}"] == pytest.approx(1.0 / (1.0 + np.exp(k / rate_a)), rel=1e-6)


def test_calibration_bin_edges_keep_their_least_count_between_tied_values():
    from sliders.analysis.forecast.learned import MIN_PER_BIN, _quantile_edges

    values = np.r_[np.zeros(2 * MIN_PER_BIN), np.arange(4 * MIN_PER_BIN) % 7]
    edges = _quantile_edges(values, 4)
    counts = np.bincount(np.searchsorted(edges, values), minlength=4)
    assert edges.size == 3 and np.isinf(edges[-1])  # three bins only: the ties leave no fourth
    assert counts[:3].min() >= MIN_PER_BIN and counts[3] == 0 and counts.sum() == values.size


@pytest.mark.slow  # fits the learned forecaster (tens of seconds)
def test_shortest_interval_is_no_longer_than_the_central_one_and_keeps_the_median():
    train, test = synthetic_set(60, seed=1), synthetic_set(20, seed=2)
    cuts = training_cuts(test, 5, np.random.default_rng(3))
    shortest = Learned(draws_per_row=10, max_iter=20, random_state=0).fit(train)
    central = Learned(draws_per_row=10, max_iter=20, interval="central", random_state=0).fit(train)
    qs, qc = shortest.quantiles(cuts)[0], central.quantiles(cuts)[0]
    lo, mid, hi = (int(np.flatnonzero(np.isclose(LEVELS, v))[0]) for v in (0.1, 0.5, 0.9))
    assert np.allclose(qs[:, mid], qc[:, mid])
    assert np.all(qs[:, hi] - qs[:, lo] <= qc[:, hi] - qc[:, lo] + 1e-12)
    assert np.all(qs[:, lo] <= qc[:, lo] + 1e-12) and np.any(qs[:, lo] < qc[:, lo])
    assert np.all(np.diff(qs, axis=1) >= 0)
    with pytest.raises(ValueError, match="interval"):
        Learned(interval="lead").fit(train)


@pytest.mark.slow
def test_the_shortest_interval_leaves_the_probability_within_to_the_distribution():
    """The shortest interval's quantiles sit at other levels than ``LEVELS``; read at those
    levels, P(avalanche within delta) is the calibrated distribution's, as the central reading
    of the same fitted forecaster gives it; read at ``LEVELS`` it would not be."""
    from sklearn.base import clone

    train, test = synthetic_set(60, seed=1), synthetic_set(20, seed=2)
    cuts = training_cuts(test, 5, np.random.default_rng(3))
    shortest = Learned(draws_per_row=10, max_iter=20, random_state=0).fit(train)
    central = clone(shortest).set_params(interval="central")
    central.__dict__.update({k: v for k, v in vars(shortest).items() if k.endswith("_")})
    qs, _, ls = shortest.quantiles(cuts, levels=True)
    qc, _, lc = central.quantiles(cuts, levels=True)
    lo = int(np.flatnonzero(np.isclose(LEVELS, 0.1))[0])
    assert np.allclose(lc, LEVELS) and np.all(ls[:, lo] <= 0.1) and np.any(ls[:, lo] < 0.1)
    delta = np.radians(1.0)
    p_central = probability_within(qc, cuts.tilt_now, delta)
    p_shortest = probability_within(qs, cuts.tilt_now, delta, ls)
    assert np.max(np.abs(p_shortest - p_central)) < 0.03
    p_misread = probability_within(qs, cuts.tilt_now, delta)
    assert np.max(np.abs(p_misread - p_central)) > np.max(np.abs(p_shortest - p_central))
    i = int(np.argmin(ls[:, lo]))  # one forecast alone carries its levels
    one = shortest.predict(cuts.catalogues[i])
    assert one.levels is not None and np.allclose(one.levels, ls[i])
    assert one.probability_within(delta) == pytest.approx(p_shortest[i])


def test_only_the_angles_and_sizes_forecaster_reads_the_short_range_features():
    cuts = training_cuts(synthetic_set(10, seed=1), 3, np.random.default_rng(0))
    short = ("gap_1", "gap_share_16", "events_0.002", "ffm_event_ml_p_log_remaining")
    _, every = Learned(inputs="all").design(cuts)
    _, blind = Learned(inputs="angles_sizes").design(cuts)
    assert not set(short) & set(every) and "ffm_ml_disp_p_log_remaining" in every
    assert set(short) <= set(blind) and "ffm_ml_disp_p_log_remaining" not in blind


def test_stored_accuracy_is_read_in_the_bin_of_the_forecasts_own_lead():
    """``accuracy_table`` bins held-out cuts by the forecast lead (point - tilt), and
    ``typical_accuracy`` reads a new forecast's bin; a bin of too few cuts holds the overall."""
    from sliders.analysis.forecast import Forecast
    from sliders.analysis.forecast.base import LOWER, MEDIAN, UPPER
    from sliders.analysis.forecast.evaluation import (ACCURACY_MIN_CUTS, accuracy_table,
                                                      typical_accuracy, typical_accuracy_line)

    n = 2 * ACCURACY_MIN_CUTS
    tilt = np.full(n, 0.3)
    q = np.tile(np.linspace(0.0, 1.0, LEVELS.size), (n, 1)) * 1e-3 + 0.3
    # half the cuts forecast 0.3° ahead and miss by 0.1° inside the interval, half 3° ahead and
    # miss by 2° outside it
    near, far = np.arange(n) < n // 2, np.arange(n) >= n // 2
    q[near] += np.radians(0.3) - q[near, MEDIAN][:, None] + 0.3
    q[far] += np.radians(3.0) - q[far, MEDIAN][:, None] + 0.3
    truth = np.where(near, q[:, MEDIAN] + np.radians(0.1), q[:, MEDIAN] + np.radians(2.0))
    q[near, LOWER], q[near, UPPER] = truth[near] - 0.01, truth[near] + 0.01
    table = accuracy_table(q, tilt, truth, rows=n)
    assert table["n"][0] == n // 2 and table["n"][3] == n // 2 and sum(table["n"]) == n
    assert table["coverage"][0] == 1.0 and table["coverage"][3] == 0.0
    assert np.isclose(table["median_abs_deg"][0], 0.1) and np.isclose(table["median_abs_deg"][3], 2.0)
    assert table["coverage"][1] == table["overall"]["coverage"] == 0.5  # empty: the overall
    f = Learned()
    assert typical_accuracy(f, Forecast(np.full(LEVELS.size, 0.31), 0.3, "learned")) is None
    f.expected_accuracy_ = table
    far_forecast = Forecast(np.full(LEVELS.size, 0.3 + np.radians(4.0)), 0.3, "learned_blind")
    got = typical_accuracy(f, far_forecast)
    assert got["lead_bin_deg"] == (2.0, 5.0) and got["coverage"] == 0.0 and got["n"] == n // 2
    assert np.isclose(got["median_abs_deg"], 2.0)
    assert typical_accuracy_line(f, far_forecast).startswith("typical error at this stage: 2.0°")
    late = Forecast(np.full(LEVELS.size, 0.3 + np.radians(50.0)), 0.3, "learned_blind")
    assert typical_accuracy(f, late)["lead_bin_deg"] == (20.0, None)
    out = Forecast(far_forecast.quantiles, 0.3, "learned_blind", fallback=True)
    assert typical_accuracy(f, out) is None
