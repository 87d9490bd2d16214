"""The facts of docs/model.md ("Facts the tests check") that any correct run satisfies, on both backends."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import BACKENDS, run, session_cached
from sliders import Scene, prepare, status
from sliders.analysis import model
from sliders.chain import elastic_force
from sliders.driver import make_engine

# seed 1 at a coarser step (as in tests/test_backends.py): its reference runs in the fast loop,
# 3 s of CPU instead of 11; the invariants hold at any step
CHAINS = [Scene(n_sliders=10, seed=s, xi=xi, dt=4e-3 if s == 1 else 1e-3)
          for s in (1, 2) for xi in (0.0, 0.001)]
# The kernel is checked on every chain; the NumPy reference, run event by event (seconds where
# the kernel takes milliseconds), on one chain of each xi: FAST_REFERENCE in the fast loop, the
# other in the full suite.  A reference that broke an invariant on another chain would also part
# from the kernel, which tests/test_backends.py compares with it event by event, energies
# included.
FAST_REFERENCE = CHAINS[1]
REFERENCE_CHAINS = (FAST_REFERENCE, CHAINS[2])


def cases(fast_reference: bool):
    """(scene, backend) of every chain on the kernel and of REFERENCE_CHAINS on the reference,
    slow but for FAST_REFERENCE if ``fast_reference``.  The tests of one reference chain go to
    one xdist worker, which runs it once for them all."""
    return [pytest.param(scene, backend, id=f"{backend}-N10-seed{scene.seed}-xi{scene.xi}",
                         marks=() if backend == "fortran" else
                         [pytest.mark.xdist_group(f"reference-N10-seed{scene.seed}-xi{scene.xi}")]
                         + ([] if fast_reference and scene == FAST_REFERENCE
                            else [pytest.mark.slow]))
            for backend in BACKENDS for scene in CHAINS
            if backend == "fortran" or scene in REFERENCE_CHAINS]


def step_events(scene, backend, max_events=10_000):
    """Advance one event at a time, yielding (state before, state after, status)."""
    engine = make_engine(scene, backend)
    state = prepare(scene)
    engine.advance(state, max_events=1, relax_only=True)
    for _ in range(max_events):
        before = state.copy()
        chunk = engine.advance(state, max_events=1)
        yield before, state, chunk
        if chunk.status != status.RUNNING:
            return


def stepped_run(scene, backend):
    """Run one event at a time, keeping what the tests below check: the status of every call,
    the largest excess of a tangential force over its static threshold after every event,
    the last resting state's mean static coefficient and the alpha_c of the last call."""
    statuses, excess = [], []
    for before, after, chunk in step_events(scene, backend):
        statuses.append(chunk.status)
        force = elastic_force(after, scene.xi, scene.walls) + math.sin(after.drive)
        excess.append(float((np.abs(force) - after.mu_s * math.cos(after.drive)).max()))
    return {"status": statuses, "excess": excess, "mean_mu_s": float(before.mu_s.mean()),
            "alpha_c": chunk.alpha_c}


def stepped(scene, backend):
    """``stepped_run`` once per test session (shared by the two tests that read it)."""
    return session_cached("stepped", stepped_run, scene, backend)


@pytest.mark.parametrize("scene, backend", cases(fast_reference=True))
def test_every_slider_is_stable_after_every_event(scene, backend):
    steps = stepped(scene, backend)
    *running, last = steps["status"]
    assert all(s == status.RUNNING for s in running) and last == status.AVALANCHE
    for n_events, excess in enumerate(steps["excess"][:-1], start=1):
        assert excess <= scene.force_tol, f"unstable slider after event {n_events}"
    assert len(running) > 5


@pytest.mark.parametrize("scene, backend", cases(fast_reference=True))
def test_alpha_c_within_the_bounds_of_the_resting_state(scene, backend):
    """tan(alpha_c) <= mean mu_s of the last resting state, and tan(alpha_c) > mu_d."""
    steps = stepped(scene, backend)
    assert steps["status"][-1] == status.AVALANCHE
    assert math.atan(scene.mu_d) < steps["alpha_c"] <= math.atan(steps["mean_mu_s"]) + 1e-12


@pytest.mark.parametrize("scene, backend", cases(fast_reference=False))
def test_forces_sum_to_n_sin_alpha(scene, backend):
    result = run(scene.replace(record="forces"), backend)
    force = result.tangential_force
    np.testing.assert_allclose(force.sum(axis=1), scene.n_sliders * np.sin(result.alpha), atol=1e-12)
    np.testing.assert_allclose(result.start_force().sum(), 0.0, atol=1e-12)


@pytest.mark.parametrize("scene, backend", cases(fast_reference=False))
def test_energy_balance_per_event(scene, backend):
    """Work of gravity = elastic energy change + mu_d cos(alpha) x path length."""
    result = run(scene.replace(record="forces"), backend)
    scale = result.work_gravity + result.dissipation
    assert (result.work_gravity > 0).all() and (result.dissipation > 0).all()
    assert np.all(np.abs(result.energy_residual) <= 1e-6 * scale + 1e-12)


def test_single_slider_between_walls_follows_the_closed_form(backend):
    scene = Scene(n_sliders=1, ends="walls", sigma_mu=0.0, seed=3, alpha_max=1.2, record="forces")
    result = run(scene, backend)
    mu_s, mu_d = scene.mu_s_mean, scene.mu_d
    assert result.status == "alpha_max" and result.n_events >= 8
    cos = np.cos(result.alpha)
    # each event moves it by exactly (mu_s - mu_d) cos(alpha) ...
    np.testing.assert_allclose(result.displacement.dense()[:, 0], model.single_slider_displacement(result.alpha, mu_s, mu_d), rtol=1e-9)
    # ... the force drops from the threshold mu_s cos(alpha) by 2 (mu_s - mu_d) cos(alpha) ...
    after = result.tangential_force[:, 0]
    np.testing.assert_allclose(mu_s * cos - after, model.single_slider_force_drop(result.alpha, mu_s, mu_d), rtol=1e-9)
    # ... and the angles follow the exact sequence, close to the first-order recurrence.
    exact = model.single_slider_angles(result.prepared_force()[0], mu_s, mu_d, scene.alpha_max)
    np.testing.assert_allclose(result.alpha, exact[: result.n_events], atol=1e-12)
    increments = np.diff(result.alpha)
    recurrence = model.single_slider_next_increment(result.alpha[:-1], mu_s, mu_d)
    assert np.all(np.abs(increments - recurrence) < 10 * (mu_s - mu_d) ** 2)


def test_initial_forces_are_flat_zero_sum_and_stable():
    scene = Scene(n_sliders=20_000, seed=5)
    state = prepare(scene)
    force = state.elastic_force0
    assert abs(force.sum()) < 1e-9
    assert np.all(np.abs(force) < state.mu_s) and np.all(np.abs(force) < scene.mu_s_mean)
    # Kolmogorov-Smirnov distance to the uniform law on ]-mu_s, mu_s[ (1% critical value)
    x = np.sort(force)
    cdf = (x + scene.mu_s_mean) / (2 * scene.mu_s_mean)
    n = x.size
    distance = max(np.max(np.arange(1, n + 1) / n - cdf), np.max(cdf - np.arange(n) / n))
    assert distance < 1.63 / math.sqrt(n)
    # and a coarse histogram has no bin far from flat (5 sigma)
    counts, _ = np.histogram(force, bins=24, range=(-scene.mu_s_mean, scene.mu_s_mean))
    expected = n / 24
    assert np.all(np.abs(counts - expected) < 5 * math.sqrt(expected))


def test_small_chains_keep_a_flat_initial_distribution():
    """Zero net force must not thin the edges (a plain projection loses ~40 % there at N = 100).

    The remaining edge deficit is physical: each force must also lie below its
    own mu_s ~ N(0.6, 0.01), which removes ~4 % of the outermost bin, and the
    zero-sum condition ~1.5 %.
    """
    forces = np.concatenate([prepare(Scene(n_sliders=100, seed=s)).elastic_force0 for s in range(200)])
    density, _ = np.histogram(forces, bins=12, range=(-0.6, 0.6), density=True)
    flat = 1 / 1.2
    assert np.all(np.abs(density[1:-1] / flat - 1) < 0.08)
    assert np.all(np.abs(density[[0, -1]] / flat - 0.945) < 0.08)


def test_coupling_relaxation_leaves_a_stable_chain(backend):
    scene = Scene(n_sliders=50, xi=1.0, seed=2, dt=1e-3)
    state = prepare(scene)
    force0 = elastic_force(state, scene.xi, scene.walls)
    assert np.any(np.abs(force0) > state.mu_s)  # the stiff plate does destabilise sliders
    chunk = make_engine(scene, backend).advance(state, max_events=1, relax_only=True)
    assert chunk.status == status.RELAXED
    force = elastic_force(state, scene.xi, scene.walls)
    assert np.all(np.abs(force) <= state.mu_s + scene.force_tol)
    assert abs(force.sum()) < 1e-9


def test_non_finite_state_is_reported_not_returned(backend):
    scene = Scene(n_sliders=5, seed=1)
    state = prepare(scene)
    state.elastic_force0[2] = np.nan
    chunk = make_engine(scene, backend).advance(state, max_events=10)
    assert chunk.status == status.NON_FINITE
    assert chunk.n_events == 0


def test_event_duration_cap_is_reported_in_tau(backend):
    scene = Scene(n_sliders=10, seed=1, max_event_duration=0.2, dt=1e-3)
    result = run(scene, backend)
    assert result.status == "event_duration_cap"
    assert "0.2 tau" in result.message
    assert math.isnan(result.alpha_c)


def test_nearby_time_steps_give_the_same_first_events():
    """Draws keyed by (seed, slider, stop count): the order of stops inside a step cannot matter."""
    a = run(Scene(n_sliders=10, seed=7, dt=1e-3), "fortran")
    b = run(Scene(n_sliders=10, seed=7, dt=0.9e-3), "fortran")
    k = 12
    assert a.n_events >= k and b.n_events >= k
    np.testing.assert_array_equal(a.n_moved[:k], b.n_moved[:k])
    np.testing.assert_allclose(a.alpha[:k], b.alpha[:k], atol=1e-5)
