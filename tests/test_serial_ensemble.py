"""The one serial ensemble loop (driver.tilt_realisations): realisation r is
the scene with the keyed seed of (scene seed, r), as in python -m sliders.ensemble."""

from __future__ import annotations

import numpy as np

import sliders
from sliders import Scene, keyed_random
from sliders.driver import realisation_scene, tilt_realisations
from sliders.figures import run_ensemble


def test_realisation_r_is_the_keyed_seed():
    scene = Scene(n_sliders=12, seed=7)
    assert realisation_scene(scene, 3).seed == keyed_random.realisation_seed(7, 3)
    assert realisation_scene(scene, 3).replace(seed=7) == scene


def test_the_loop_runs_the_realisations_in_order():
    scene = Scene(n_sliders=10, seed=5, mode="explore")
    runs = list(tilt_realisations(scene, 2, first=1))
    assert [r for r, _ in runs] == [1, 2]
    alone = sliders.tilt(realisation_scene(scene, 2))
    assert runs[1][1].alpha_c == alone.alpha_c
    assert np.array_equal(runs[1][1].events["drive"], alone.events["drive"])


def test_figures_ensemble_uses_the_loop():
    summary, results = run_ensemble(n_sliders=10, runs=2, base_seed=5, keep_results=True)
    expected = [res.alpha_c for _, res in
                tilt_realisations(Scene(n_sliders=10, seed=5, record="displacements"), 2)]
    assert [res.alpha_c for res in results] == expected
    assert summary.n_realisations == 2
