"""The preparation with a history (``initial_forces="history"``) and a prior that draws it."""

from __future__ import annotations

import numpy as np
import pytest

import sliders
from sliders.chain import elastic_energy, elastic_force
from sliders.io.prior_file import read_prior_ensemble
from sliders.preparation import (history_seed, last_stable_state, prepare, rebased, tilt_back,
                                 _history_engine)
from sliders.parts.checks import SceneError

SCENE = sliders.Scene(n_sliders=30, seed=4, mode="explore", xi=1e-3, initial_forces="history")


def test_last_stable_state_is_the_last_event_before_the_avalanche():
    past = SCENE.replace(seed=history_seed(SCENE.seed), initial_forces="uniform")
    run = sliders.tilt(past)
    assert run.status == "avalanche"
    state = last_stable_state(past)
    assert state.drive == run.alpha[-1]
    stopped = sliders.tilt(past.replace(max_events=run.n_events))  # the same run, stopped there
    assert stopped.status == "max_events"
    assert np.array_equal(state.displacement, stopped.final.displacement)
    assert np.array_equal(state.mu_s, stopped.final.mu_s)
    assert np.array_equal(state.n_stops, stopped.final.n_stops)


def test_history_state_is_at_rest_at_zero_and_rebased():
    past = SCENE.replace(seed=history_seed(SCENE.seed), initial_forces="uniform")
    engine = _history_engine(past)
    back = tilt_back(last_stable_state(past, engine), past, engine)
    assert back.drive == 0.0
    state = rebased(back, past)
    assert np.all(state.displacement == 0) and state.drive == 0.0
    assert np.allclose(elastic_force(state, past.xi, False), elastic_force(back, past.xi, False),
                       rtol=0, atol=1e-12)
    assert elastic_energy(state, past.xi, False) == pytest.approx(
        elastic_energy(back, past.xi, False), rel=1e-12)
    assert np.all(np.abs(elastic_force(state, past.xi, False)) <= state.mu_s)
    assert np.array_equal(prepare(SCENE).mu_s, state.mu_s)  # prepare dispatches to it


def test_a_pile_brought_near_its_avalanche_starts_from_it():
    """Tilted again, the chain meets its history's avalanche at the same angle, without the
    history's precursors (nothing slipped on the way back); both backends agree."""
    past = SCENE.replace(seed=history_seed(SCENE.seed), initial_forces="uniform")
    before = sliders.tilt(past)
    again = sliders.tilt(SCENE)
    assert again.status == "avalanche"
    assert again.n_events < before.n_events // 4
    assert abs(again.alpha_c - before.alpha_c) < 1e-3
    ref = sliders.tilt(SCENE, backend="numpy")
    assert np.array_equal(ref.alpha, again.alpha) and ref.alpha_c == again.alpha_c


def test_a_historys_progress_follows_its_tilt_and_changes_nothing():
    """``history_progress`` is told the tilt up to the avalanche (angles and events growing)
    then the steps back to 0; the chain is bit for bit the one prepared without it, and a
    run given it is the run that prepares it itself (as ``tilt`` on the command line does)."""
    scene = SCENE.replace(n_sliders=300)  # three chunks of events up to its avalanche
    told = []
    state = prepare(scene, history_progress=lambda *a: told.append(a))
    phases = [phase for phase, _, _ in told]
    assert phases[0] == "to the avalanche" and phases[-1] == "back to 0"
    k = phases.index("back to 0")
    assert set(phases[k:]) == {"back to 0"} and k >= 3
    up, back = np.array(told[:k])[:, 1:].astype(float), np.array(told[k:])[:, 1:].astype(float)
    assert np.all(np.diff(up, axis=0) > 0)  # alpha and the events grow
    assert np.all(np.diff(back[:, 0]) < 0) and back[-1, 0] == 0.0
    plain = prepare(scene)
    for name in ("elastic_force0", "spring_extension0", "cantilever_stretch0", "mu_s", "n_stops"):
        np.testing.assert_array_equal(getattr(state, name), getattr(plain, name), name)
    given, itself = sliders.tilt(scene, state=state), sliders.tilt(scene)
    assert given.alpha_c == itself.alpha_c
    np.testing.assert_array_equal(given.alpha, itself.alpha)


def test_history_needs_a_free_tilted_chain():
    with pytest.raises(SceneError, match="initial_forces='history'"):
        SCENE.replace(ends="walls", alpha_max=1.0)


def test_a_prior_draws_the_preparation(tmp_path):
    from sliders.runs import prior as prior_run

    path = tmp_path / "p.toml"
    path.write_text('[prior]\nrealisations = 6\ndesign = "latin"\n[scene]\nn_sliders = 20\n'
                    '[parameters]\nmu_d = { uniform = [0.4, 0.6] }\n'
                    'mu_s_minus_mu_d = { uniform = [0.03, 0.06] }\n'
                    'initial_forces = { choice = ["uniform", "history"] }\n')
    assert prior_run.main([str(path), "--out", str(tmp_path / "p.h5"), "--quiet"]) == 0
    got = read_prior_ensemble(tmp_path / "p.h5")
    prep = got.parameters["initial_forces"]
    assert set(prep) == {"uniform", "history"}
    events = np.diff(got.offsets)
    assert events[prep == "history"].mean() < events[prep == "uniform"].mean()
