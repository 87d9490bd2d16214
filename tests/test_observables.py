"""Observables on small runs whose values can be checked by hand (the single slider on the NumPy
reference, the chain of 10 on the kernel: the observables read a result, whichever backend made
it, and the reference takes seconds on the chain)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sliders
from sliders.analysis import observables as ob
from sliders.figures import single_slider_run

MU_S, MU_D = 0.6, 0.55
DMU = MU_S - MU_D


@pytest.fixture(scope="module")
def walls():
    """One slider between walls, sigma_mu = 0, F(0) = 0.45: a regular sawtooth."""
    return single_slider_run(0.45, backend="numpy", alpha_max=0.6)


@pytest.fixture(scope="module")
def chain():
    """A free chain of 10 sliders to the avalanche."""
    return sliders.tilt(sliders.Scene(n_sliders=10, seed=1), backend="fortran")


@pytest.fixture(scope="module")
def grids(chain):
    return ob.default_grids(chain.scene)


# -- single slider between walls: everything is known in closed form ---------------------

def test_walls_displacements_are_dmu_cos_alpha(walls):
    assert walls.status == "alpha_max"
    a = walls.alpha
    assert a.size >= 5
    d = ob.displacement_map(walls)
    assert d.shape == (a.size, 1)
    np.testing.assert_allclose(d[:, 0], DMU * np.cos(a), rtol=1e-6)
    np.testing.assert_allclose(ob.mean_event_displacement(walls), DMU * np.cos(a), rtol=1e-6)
    np.testing.assert_array_equal(ob.event_sizes(walls), np.ones(a.size, dtype=np.int64))
    np.testing.assert_array_equal(ob.event_size_counts(walls), [a.size])


def test_walls_forces_and_stopped_ratio(walls):
    a = walls.alpha
    after = ob.force_history(walls)[:, 0]
    before = ob.force_before_events(walls)[:, 0]
    np.testing.assert_allclose(before, MU_S * np.cos(a), atol=1e-9)  # at the threshold
    np.testing.assert_allclose(after, (2 * MU_D - MU_S) * np.cos(a), rtol=1e-6)
    ea, ratio = ob.stopped_force_ratios(walls)
    np.testing.assert_allclose(ea, a)
    np.testing.assert_allclose(ratio, 1.0, rtol=1e-6)
    alpha_edges = np.array([0.0, 0.2, 0.4, 0.6])
    ratio_edges = np.array([0.9, 0.995, 1.005, 1.1])
    h = ob.stopped_force_ratio_histogram(walls, alpha_edges, ratio_edges)
    expected = np.histogram(a, alpha_edges)[0]
    np.testing.assert_array_equal(h[:, 1], expected)
    assert h[:, [0, 2]].sum() == 0


def test_walls_cumulated_displacement(walls):
    a = walls.alpha
    grid = np.linspace(0.0, 0.6, 61)
    A = ob.cumulated_displacement(walls, grid)
    expected = np.array([np.sum(DMU * np.cos(a[a <= g])) for g in grid])
    np.testing.assert_allclose(A, expected, rtol=1e-6, atol=1e-12)
    assert A[0] == 0.0 and np.all(np.diff(A) >= 0)


def test_walls_histograms_and_model_bins(walls):
    grid = np.array([0.0, 0.1, 0.3, 0.6])
    counts, valid = ob.force_histogram(walls, grid, np.linspace(-0.7, 0.7, 141))
    assert valid.all()  # alpha_max run: at rest up to alpha_max inclusive
    np.testing.assert_array_equal(counts.sum(axis=1), 1)
    # F(0) = 0.45: bin floor((0.6 - 0.45) / 0.1) + 1 = 2; F(0.1) = 0.45 + sin 0.1 -> bin 1
    m = ob.model_bin_counts(walls, grid, MU_S, MU_D, 12)
    assert m[0, 1] == 1 and m[1, 0] == 1
    np.testing.assert_array_equal(m.sum(axis=1), 1)


# -- model bins ---------------------------------------------------------------------------

def test_model_bin_index():
    f = np.array([0.9, 0.6, 0.55, 0.45, 0.35, -0.45, -0.55, -0.59, -5.0])
    np.testing.assert_array_equal(ob.model_bin_index(f, MU_S, MU_D, 12),
                                  [1, 1, 1, 2, 3, 11, 12, 12, 12])


# -- free chain of 10 ---------------------------------------------------------------------

def test_chain_force_history_matches_dense(chain):
    """F after each event from the dense displacements, by hand (springs only, free ends)."""
    assert chain.status == "avalanche"
    du = chain.initial.displacement + np.cumsum(ob.displacement_map(chain), axis=0)
    lap = np.zeros_like(du)
    lap[:, :-1] += du[:, 1:] - du[:, :-1]
    lap[:, 1:] -= du[:, 1:] - du[:, :-1]
    expected = chain.initial.elastic_force0 + lap + np.sin(chain.alpha)[:, None]
    np.testing.assert_allclose(ob.force_history(chain), expected, atol=1e-12)
    f = ob.force_history(chain)
    # sum of forces of a free chain = N sin(alpha)
    np.testing.assert_allclose(f.sum(axis=1), 10 * np.sin(chain.alpha), atol=1e-9)


def test_chain_histograms_sum_to_n(chain, grids):
    counts, valid = ob.force_histogram(chain, grids.alpha, grids.force_edges)
    np.testing.assert_array_equal(valid, grids.alpha < chain.alpha_c)
    assert valid.any() and not valid.all()
    np.testing.assert_array_equal(counts[valid].sum(axis=1), 10)
    assert counts[~valid].sum() == 0
    m = ob.model_bin_counts(chain, grids.alpha, MU_S, MU_D, grids.n_model_bins)
    np.testing.assert_array_equal(m[valid].sum(axis=1), 10)
    assert m[~valid].sum() == 0
    # at alpha = 0 the forces are the prepared ones (xi = 0: no relaxation)
    h0 = np.histogram(chain.prepared_force(), grids.force_edges)[0]
    np.testing.assert_array_equal(counts[0], h0)


def test_chain_cumulated_displacement(chain, grids):
    d = ob.displacement_map(chain)
    totals = ob.event_total_displacement(chain)
    np.testing.assert_allclose(totals, d.sum(axis=1))
    # the same from the work of gravity (what a summary-only run has)
    np.testing.assert_allclose(chain.work_gravity / np.sin(chain.alpha), totals, rtol=1e-9)
    A = ob.cumulated_displacement(chain, grids.alpha)
    expected = [d[chain.alpha <= g].sum() for g in grids.alpha]
    np.testing.assert_allclose(A, expected, atol=1e-12)
    if d.min() >= 0.0:  # downhill-only run: A never decreases
        assert np.all(np.diff(A) >= 0.0)
    mdx = ob.mean_event_displacement(chain)
    moved = d != 0
    np.testing.assert_allclose(mdx, d.sum(axis=1) / moved.sum(axis=1))


def test_chain_event_sizes_and_sync(chain):
    s = ob.event_sizes(chain)
    d = ob.displacement_map(chain)
    np.testing.assert_array_equal(s, (d != 0).sum(axis=1))
    c = ob.event_size_counts(chain)
    assert c.shape == (10,) and c.sum() == chain.n_events
    np.testing.assert_array_equal(c, [np.sum(s == k) for k in range(1, 11)])
    sync = ob.synchronisation(chain)
    both = (d[:, :5] != 0).any(axis=1) & (d[:, 5:] != 0).any(axis=1)
    np.testing.assert_array_equal(sync["all_parts"], both)


def test_realisation_statistics_layout(chain, grids):
    row = ob.realisation_statistics(chain, grids)
    layout = ob.statistics_layout(grids, 10)
    assert set(row) == set(layout)
    for k, (shape, dtype) in layout.items():
        assert np.shape(row[k]) == shape, k
        assert np.asarray(row[k]).dtype == np.dtype(dtype), k
    assert row["alpha_c"] == chain.alpha_c and row["n_events"] == chain.n_events
    assert row["stopped_ratio_counts"].sum() == chain.n_moved.sum()
    assert row["event_counts"].sum() == chain.n_events


def test_combine_identical_rows_is_the_row(chain, grids):
    row = ob.realisation_statistics(chain, grids)
    s = ob.combine(ob.stack_rows([row, row, row]), grids, 10)
    valid = row["valid_alpha"]
    assert s.n_realisations == 3
    np.testing.assert_array_equal(s.n_valid, 3 * valid)
    p = row["model_bin_counts"] / (10 * 2 * DMU)
    np.testing.assert_allclose(s.p_mean[valid], p[valid])
    np.testing.assert_allclose(s.p_sem[valid], 0.0, atol=1e-12)
    assert np.all(np.isnan(s.p_mean[~valid]))
    dens = row["force_counts"] / (10 * np.diff(grids.force_edges))
    np.testing.assert_allclose(s.force_pdf[valid], dens[valid])
    # each valid PDF integrates to one
    np.testing.assert_allclose((s.force_pdf[valid] * np.diff(grids.force_edges)).sum(axis=1), 1.0)
    np.testing.assert_allclose(s.cumulated_mean[valid], row["cumulated_displacement"][valid])
    assert s.alpha_c_mean == pytest.approx(chain.alpha_c) and s.alpha_c_std == 0.0
    assert s.n_avalanche == 3
    np.testing.assert_array_equal(s.event_size_counts, 3 * row["event_size_counts"])
    # stopped-ratio PDF integrates to one in every populated bin
    populated = s.stopped_counts > 0
    np.testing.assert_allclose(
        (s.stopped_ratio_pdf[populated] * np.diff(grids.ratio_edges)).sum(axis=1), 1.0)


def test_combine_mean_and_sem_of_two_runs(chain, grids):
    """Two different rows: P_i mean and standard error by hand."""
    r1 = ob.realisation_statistics(chain, grids)
    r2 = dict(r1)
    r2["model_bin_counts"] = r1["model_bin_counts"][:, ::-1].copy()
    s = ob.combine(ob.stack_rows([r1, r2]), grids, 10)
    v = r1["valid_alpha"]
    p1 = r1["model_bin_counts"] / (10 * 2 * DMU)
    p2 = r2["model_bin_counts"] / (10 * 2 * DMU)
    np.testing.assert_allclose(s.p_mean[v], 0.5 * (p1 + p2)[v])
    np.testing.assert_allclose(s.p_sem[v], np.abs(p1 - p2)[v] / 2.0, atol=1e-12)


def test_summary_only_run_raises_clearly():
    r = sliders.tilt(sliders.Scene(n_sliders=3, seed=2, record="summary"), backend="numpy")
    for fn in (ob.displacement_map, ob.force_history, ob.mean_event_displacement,
               ob.stopped_force_ratios, ob.synchronisation):
        with pytest.raises(ValueError, match="summary"):
            fn(r)
    with pytest.raises(ValueError, match="summary"):
        ob.force_histogram(r, [0.0], [-1.0, 1.0])
    with pytest.raises(ValueError, match="summary"):
        ob.realisation_statistics(r, ob.default_grids(r.scene))
    # the cumulated displacement only needs the work of gravity
    A = ob.cumulated_displacement(r, [0.0, 0.6])
    assert A[0] == 0.0 and math.isfinite(A[1])


def test_default_grids():
    g = ob.default_grids(sliders.Scene(n_sliders=5))
    assert g.force_edges.size == 121
    assert g.force_edges[0] == pytest.approx(-0.7) and g.force_edges[-1] == pytest.approx(0.7)
    assert g.alpha[0] == 0.0 and g.alpha[-1] == pytest.approx(math.atan(0.6))
    assert g.n_model_bins == 12
    assert g.ratio_edges[0] <= -1.28 and g.ratio_edges[-1] >= 1.28
    assert g.stop_alpha_edges[-1] >= math.atan(0.6)
    back = ob.StatisticsGrids.from_arrays(g.to_arrays())
    for k, v in g.to_arrays().items():
        np.testing.assert_array_equal(np.asarray(getattr(back, k)), v)
    with pytest.raises(ValueError):
        ob.StatisticsGrids(np.array([0.0, 0.1]), np.array([1.0, 0.0]), g.ratio_edges,
                           g.stop_alpha_edges, 12, 0.6, 0.55)


def test_fits():
    x = np.linspace(0.0, 1.0, 20)
    f = ob.linear_fit(x, 2.0 + 3.0 * x)
    assert f["slope"] == pytest.approx(3.0) and f["intercept"] == pytest.approx(2.0)
    assert f["r2"] == pytest.approx(1.0)
    e = ob.exponential_fit(x, 0.5 * np.exp(7.0 * x), 0.1, 0.9)
    assert e["rate"] == pytest.approx(7.0) and e["prefactor"] == pytest.approx(0.5)


def test_moving_clusters(chain):
    """xi = 0: a slider starts only next to a moving one, so every event is one group."""
    c = ob.moving_clusters(chain)
    assert c.shape == (chain.n_events,)
    np.testing.assert_array_equal(c, 1)
    d = ob.displacement_map(chain) != 0
    first, last = d.argmax(axis=1), d.shape[1] - 1 - d[:, ::-1].argmax(axis=1)
    np.testing.assert_array_equal(last - first + 1, ob.event_sizes(chain))


def test_moving_clusters_synthetic():
    """Hand-made events: {0,1}, {0,3}, {2}, {0,5,6,9} in a chain of 10."""
    from types import SimpleNamespace

    from sliders.result import EventSparse

    idx = np.array([0, 1, 0, 3, 2, 0, 5, 6, 9])
    d = EventSparse(np.array([0, 2, 4, 5, 9]), idx, np.ones(idx.size), 10)
    fake = SimpleNamespace(displacement=d, alpha=np.array([0.1, 0.2, 0.3, 0.4]),
                           scene=SimpleNamespace(n_sliders=10, record="displacements"))
    np.testing.assert_array_equal(ob.moving_clusters(fake), [1, 2, 1, 3])
    np.testing.assert_array_equal(ob.synchronisation(fake)["all_parts"], [False, False, False, True])


def test_reproduction_helpers():
    """The analysis rules of the reproduction report on synthetic data."""
    from sliders.analysis.precursors import departure_angle
    from sliders.analysis.reproduction import verdict_close

    a = np.linspace(0.0, 0.5, 51)
    y = 1.0 + 8.0 * a
    y[a >= 0.38] -= 2.0 * (a[a >= 0.38] - 0.37)  # bends down from 0.38
    sem = np.full_like(a, 0.005)
    end, fit = departure_angle(a, y, sem, (0.0, 0.25), -1)
    assert fit["slope"] == pytest.approx(8.0)
    assert end == pytest.approx(0.38, abs=0.011)
    assert math.isnan(departure_angle(a, 1.0 + 8.0 * a, sem, (0.0, 0.25), -1)[0])
    assert verdict_close([0.50, 0.51, 0.52], 0.51, 0.005) == "agrees"
    assert verdict_close([0.500, 0.506, 0.5005, 0.5008, 0.5002, 0.5001], 0.51, 0.005) == "partly"
    assert verdict_close([0.40, 0.41], 0.51, 0.005) == "disagrees"
