"""Slow slip pulses near atan(mu_d) end at their true end (docs/slip_pulses.md).

The two realisations of the main job (mpi_runs/scenes/paper_n100.toml) that
the former 1e5 tau event cap stopped, run with the scene's own cap:

* realisation 150: a pulse at tan(alpha) - mu_d = -7.6e-6 lasts 1.8e5 tau.
  Below atan(mu_d) the energy balance bounds its path by U0 / eps
  (eps = mu_d cos(alpha) - sin(alpha) > 0, U0 the elastic energy at its
  start): docs/slip_pulses.md proves it, and the run shows the pulse ends
  only when that elastic energy is spent.
* realisation 107: at tan(alpha) - mu_d = +6.2e-5 the avalanche event takes
  2.2e5 tau to set every slider sliding downwards.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import run
from sliders import Scene
from sliders.chain import elastic_energy
from sliders.keyed_random import realisation_seed

pytestmark = pytest.mark.slow  # slip pulses measured on long runs

PAPER_N100 = Path(__file__).resolve().parents[1] / "mpi_runs" / "scenes" / "paper_n100.toml"
OLD_CAP = 1e5  # tau: the cap every speed mode had when these runs were capped


def paper_realisation(r: int) -> Scene:
    """Realisation r of the main job's ensemble, exactly as sliders.ensemble runs it."""
    base = Scene.from_toml(PAPER_N100)
    return base.replace(seed=realisation_seed(base.seed, r))


def energy_before_and_after(result, k: int) -> tuple[float, float]:
    """Elastic energy of the chain at rest before and after event k."""
    after = result.displacement_after()
    before = after[k - 1] if k else result.initial.displacement
    sc = result.scene
    return (elastic_energy(result.initial, sc.xi, sc.walls, before),
            elastic_energy(result.initial, sc.xi, sc.walls, after[k]))


def path_bound_margin(result, k: int) -> tuple[float, float]:
    """(path of event k, U0 / eps): the proven bound, for an event below atan(mu_d)."""
    sc = result.scene
    a = result.alpha[k]
    eps = sc.mu_d * math.cos(a) - math.sin(a)
    path = result.events["dissipation"][k] / (sc.mu_d * math.cos(a))
    u0, _ = energy_before_and_after(result, k)
    return path, u0 / eps


def test_the_scene_cap_outlasts_the_longest_event_measured():
    """Every scene of mpi_runs caps one event beyond the longest event measured in
    the paper's ensembles: 3.55e6 tau, the avalanche event of the N = 400,
    xi = 0 study's realisation 66 (docs/slip_pulses.md)."""
    from sliders.analysis.study_spec import load_study

    for path in sorted(PAPER_N100.parent.glob("*.toml")):
        if "[study]" in path.read_text():  # a study file: every point's scene
            scenes = load_study(path).scenes
        else:
            scenes = [Scene.from_toml(path)]
        for scene in scenes:
            assert scene.max_event_duration > 2 * 3.55e6, path.name


def test_a_pulse_below_atan_mu_d_ends_when_its_elastic_energy_is_spent():
    result = run(paper_realisation(150), "fortran")
    assert result.status == "avalanche"
    k = int(np.argmax(result.events["duration"]))
    sc = result.scene
    assert result.events["duration"][k] > OLD_CAP          # the event the old cap stopped
    assert math.tan(result.alpha[k]) < sc.mu_d              # ... just below atan(mu_d)
    assert result.alpha_c > result.alpha[k]
    path, bound = path_bound_margin(result, k)
    assert path <= bound                                    # proven: docs/slip_pulses.md
    # measured: the pulse runs until (almost) all its elastic energy is spent
    assert path >= 0.99 * bound
    u0, u_end = energy_before_and_after(result, k)
    assert u_end < 0.01 * u0
    # and the chain's whole motion was downhill (path = net displacement)
    step = result.displacement.event(k)[1]
    assert np.all(step >= 0.0) and step.sum() == pytest.approx(path, rel=1e-9)
    assert abs(result.energy_residual[k]) < 1e-8 * result.events["work_gravity"][k]


def test_a_slow_avalanche_just_above_atan_mu_d_is_reached():
    result = run(paper_realisation(107), "fortran")
    assert result.status == "avalanche"
    assert result.final_event["duration"] > OLD_CAP
    assert 0 < math.tan(result.alpha_c) - result.scene.mu_d < 1e-4


@pytest.mark.parametrize("xi", [0.0, 0.001])
@pytest.mark.parametrize("ends", ["free", "walls"])
def test_every_event_below_atan_mu_d_respects_the_path_bound(xi, ends):
    """The bound holds for any event with tan(alpha) < mu_d (not only pulses):
    every event of ordinary runs, both couplings, both kinds of ends."""
    mu_d = 0.55
    limit = math.atan(mu_d)
    checked = 0
    for seed in (1, 2, 3):
        scene = Scene(n_sliders=40, xi=xi, seed=seed, ends=ends, mode="explore",
                      alpha_max=limit if ends == "walls" else Scene().alpha_max)
        result = run(scene, "fortran")
        for k in np.flatnonzero(result.alpha < limit):
            path, bound = path_bound_margin(result, int(k))
            assert path <= bound * (1 + 1e-9) + 1e-12
            checked += 1
    assert checked > 100
