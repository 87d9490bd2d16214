"""The scene is composed of parts: a friction law and a loading that own their parameters,
checks, packing and physics.  The flat keys of files and of the command line build the
same parts, files written with the flat layout still load, and a new loading is a class
(this file defines one and runs it on the NumPy reference)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import sliders
from sliders import Coulomb, PushedEnd, Scene, SceneError, Tilt, keyed_random
from sliders.chain import elastic_force
from sliders.engine import contract
from sliders.parts.checks import check_real
from sliders.parts.friction import Friction
from sliders.parts.loading import TIE_TOL, Loading

DATA = Path(__file__).resolve().parent / "data"


# ------------------------------------------------ parts and flat keys
def test_flat_keywords_build_the_parts():
    assert Scene(mu_d=0.5, sigma_mu=0.0) == Scene(friction=Coulomb(mu_d=0.5, sigma_mu=0.0))
    pushed = Scene(loading="pushed_end", incline=0.2, driver_stiffness=2.0, drive_max=9.0)
    assert pushed == Scene(loading=PushedEnd(incline=0.2, stiffness=2.0, drive_max=9.0))
    assert Scene(alpha_max=1.0) == Scene(loading=Tilt(alpha_max=1.0))
    assert (pushed.incline, pushed.driver_stiffness, pushed.mu_d) == (0.2, 2.0, 0.55)
    assert not hasattr(pushed, "tilt")  # tilt names the loading, not the incline
    # a part holds no scene: the same part object serves every scene it is given to
    assert not hasattr(pushed.loading, "scene") and not hasattr(pushed.friction, "scene")
    assert pushed.loading is Scene(loading=pushed.loading).loading


def test_the_parts_check_their_own_values():
    with pytest.raises(SceneError, match=r"mu_s_mean=0.5 must exceed mu_d=0.5"):
        Coulomb(mu_d=0.5, mu_s_mean=0.5)
    with pytest.raises(SceneError, match=r"driver_stiffness=0.0 is out of range"):
        PushedEnd(stiffness=0.0)
    with pytest.raises(SceneError, match=r"alpha_max=2.0 is out of range"):
        Tilt(alpha_max=2.0)
    with pytest.raises(SceneError, match=r"tilt=0.1 is not a scene key: .* incline is incline="):
        Scene(loading="pushed_end", tilt=0.1)
    with pytest.raises(SceneError, match=r"tilt=0.1 is not a scene key"):
        Scene(n_sliders=8).replace(tilt=0.1)
    with pytest.raises(SceneError, match=r"drive_stiffness=2.0 is not a scene key: .* is "
                                         r"driver_stiffness= \(drive names the loading's variable\)"):
        Scene(loading="pushed_end", drive_stiffness=2.0)
    # a rule between parts: the incline below the friction's max_stable_incline(), atan(mu_d)
    with pytest.raises(SceneError, match=r"incline=0.5 is out of range: allowed \[0, 0.463647609\]"):
        Scene(friction=Coulomb(mu_d=0.5), loading=PushedEnd(incline=0.5))


def test_replace_changes_a_part_by_its_flat_keys_or_whole():
    pushed = Scene(n_sliders=8, loading=PushedEnd(incline=0.2, stiffness=2.0))
    assert pushed.replace(incline=0.3).loading == PushedEnd(incline=0.3, stiffness=2.0)
    assert pushed.replace(loading="tilt") == Scene(n_sliders=8)
    assert pushed.replace(loading=Tilt(alpha_max=1.0)).alpha_max == 1.0
    assert pushed.replace(mu_d=0.5).friction == Coulomb(mu_d=0.5)
    with pytest.raises(SceneError, match="drive_max=3.0 is a parameter of loading='pushed_end'"):
        Scene().replace(drive_max=3.0)


def test_repr_shows_the_parts_that_differ_and_evaluates_back():
    scene = Scene(n_sliders=8, mu_d=0.5, loading="pushed_end", incline=0.2)
    assert repr(scene) == ("Scene(n_sliders=8, friction=Coulomb(mu_d=0.5), "
                           "loading=PushedEnd(incline=0.2))")
    assert eval(repr(scene), vars(sliders)) == scene
    assert repr(Scene(n_sliders=400, xi=0.001, seed=1)) == "Scene(n_sliders=400, xi=0.001, seed=1)"


def test_the_kernel_parameters_come_from_the_parts():
    real, ints = contract.pack_parameters(Scene(mu_d=0.3, loading=PushedEnd(incline=0.1,
                                                                             drive_max=4.0)),
                                          0.0, False, False, 1)
    by_name = dict(zip(contract.REAL_PARAMETERS, real))
    assert (by_name["mu_d"], by_name["incline"], by_name["drive_max"]) == (0.3, 0.1, 4.0)
    assert dict(zip(contract.INT_PARAMETERS, ints))["loading"] == PushedEnd.code


# ------------------------------------------------ files of the flat layout
# The scene attribute of a tilt file and of a pushed-end file (the flat keys, in file order),
# as files wrote it while the incline's key was "tilt" and the driver's stiffness "drive_stiffness".
FLAT_FILES = [
    '{"n_sliders": 400, "xi": 0.001, "spring_length": 10.0, "mu_d": 0.55, "mu_s_mean": 0.6, '
    '"sigma_mu": 0.01, "seed": 1, "ends": "free", "initial_forces": "uniform", "mode": '
    '"explore", "dt": 0.01, "refine_tol": 1e-10, "max_event_duration": 10000000.0, '
    '"max_events": 10000000, "alpha_max": 1.5707953267948966, "force_tol": 1e-12, "avalanche": '
    '"sliding", "loading": "tilt", "tilt": 0.0, "drive_stiffness": 1.0, "drive_max": '
    '1000000000.0, "record": "summary"}',
    '{"n_sliders": 6, "xi": 0.0, "spring_length": 10.0, "mu_d": 0.55, "mu_s_mean": 0.6, '
    '"sigma_mu": 0.01, "seed": 5, "ends": "free", "initial_forces": "uniform", "mode": '
    '"trajectory", "dt": 0.001, "refine_tol": 1e-10, "max_event_duration": 10000000.0, '
    '"max_events": 10000000, "alpha_max": 1.5707953267948966, "force_tol": 1e-12, "avalanche": '
    '"sliding", "loading": "pushed_end", "tilt": 0.2, "drive_stiffness": 2.0, "drive_max": 50.0, '
    '"record": "displacements"}',
]


@pytest.mark.parametrize("text", FLAT_FILES, ids=["tilt", "pushed_end"])
def test_flat_scene_attributes_round_trip_byte_for_byte(text):
    """A stored scene with the old keys loads; written again it holds ``incline`` and
    ``driver_stiffness`` in their places, and that text round-trips byte for byte."""
    scene = Scene.from_stored(json.loads(text))
    now = text.replace('"tilt": ', '"incline": ').replace('"drive_stiffness"', '"driver_stiffness"')
    assert json.dumps(scene.to_dict()) == now
    assert json.dumps(Scene.from_dict(json.loads(now)).to_dict()) == now
    with pytest.raises(SceneError, match="tilt=.* is not a scene key"):
        Scene.from_dict(json.loads(text))  # given (not stored), the old key is refused


def test_files_written_with_the_flat_layout_load():
    """Two files written by the package with the flat Scene (tests/data): their scenes
    come back as parts, their events as written, and a rerun gives the same events."""
    tilt = sliders.Result.load(DATA / "tilt_walls_n6.h5")
    assert tilt.scene == Scene(n_sliders=6, seed=3, friction=Coulomb(mu_d=0.5), ends="walls",
                               mode="explore", loading=Tilt(alpha_max=1.0), record="summary")
    pushed = sliders.Result.load(DATA / "pushed_end_n6.h5")
    assert pushed.scene.loading == PushedEnd(incline=0.2, stiffness=2.0, drive_max=50.0)
    assert pushed.status == "sliding" and pushed.n_events == 181
    assert np.all(pushed.alpha == 0.2) and np.all(np.diff(pushed.drive) >= 0)  # the incline
    rerun = sliders.run(pushed.scene)
    np.testing.assert_array_equal(rerun.drive, pushed.drive)
    np.testing.assert_array_equal(sliders.tilt(tilt.scene).events["drive"], tilt.events["drive"])


def test_a_run_file_holds_the_drive_and_the_incline_each_in_its_column(tmp_path):
    """Format 2: ``events/drive`` the loading's variable (rad, or D in g tau^2), a coordinate of
    the events; ``events/alpha`` the incline's angle (the drive under the tilt, the fixed
    incline under the pushed end).  Read back, the drive is the run's."""
    h5py = pytest.importorskip("h5py")
    for scene, unit in ((Scene(n_sliders=8, seed=2, mode="explore"), "rad"),
                        (Scene(n_sliders=8, seed=2, loading=PushedEnd(incline=0.15)), "g tau^2")):
        run = sliders.run(scene)
        path = tmp_path / f"{scene.loading.name}.h5"
        run.save(path)
        with h5py.File(path, "r") as f:
            assert f.attrs["format_version"] == 2
            drive, alpha = f["events/drive"][()], f["events/alpha"][()]
            assert f["events/drive"].attrs["units"] == unit
            assert f["events/alpha"].attrs["units"] == "rad"
            assert f["events/n_moved"].attrs["coordinates"] == "drive"
        np.testing.assert_array_equal(drive, run.drive)
        expected = run.drive if scene.loading.name == "tilt" else np.full(run.n_events, 0.15)
        np.testing.assert_array_equal(alpha, expected)
        back = sliders.Result.load(path)
        np.testing.assert_array_equal(back.drive, run.drive)
        assert sorted(back.events) == sorted(run.events)


# ------------------------------------------------ a new loading costs one class
@dataclass(frozen=True, repr=False)
class UniformPull(Loading):
    """A flat, horizontal track (normal load m g) on which every slider is pulled by the
    same force lambda (units of m g), the drive, up to ``pull_max``."""

    pull_max: float = 10.0

    name = "uniform_pull"
    flat_keys = {"pull_max": "pull_max"}
    drive_label = "pull"
    drive_unit = "m g"

    def check_own(self) -> None:
        check_real("pull_max", self.pull_max, 0.0, None, open_low=True)

    def weight(self, drive: float) -> float:
        return drive

    def normal(self, drive: float) -> float:
        return 1.0

    def forces(self, state, xi, walls, drives, displacement=None) -> np.ndarray:
        du = state.displacement if displacement is None else np.asarray(displacement, dtype=float)
        elastic = elastic_force(state, xi, walls, du)
        return elastic + np.asarray(drives, dtype=float)[..., None]

    def next_instability(self, elastic, mu, drive, du, force_tol):
        """Slider n starts forwards at E_n + lambda = mu_n (the pull only grows)."""
        root = np.maximum(mu - elastic, drive)
        pull = float(root.min())
        triggers = np.flatnonzero(root <= pull + TIE_TOL)
        return pull, triggers, np.ones(triggers.size)

    def beyond_limit(self, drive: float) -> bool:
        return drive > self.pull_max

    def runaway(self, moving, direction, weight, kinetic, walls) -> bool:
        """Every slider of a free chain moving forwards with the pull beating kinetic friction."""
        return (not walls and moving.all() and np.all(direction > 0.0)
                and weight > kinetic)


@pytest.mark.slow  # seconds of work: the full suite
def test_a_loading_defined_here_runs_on_the_reference():
    """The toy loading is a class of this file alone: the scene, the reference engine, the
    result and its forces take it as they take the tilt; the physics is the model's."""
    scene = Scene(n_sliders=30, seed=4, mode="explore", loading=UniformPull())
    assert repr(scene) == "Scene(n_sliders=30, seed=4, mode='explore', loading=UniformPull())"
    assert scene.to_dict()["loading"] == "uniform_pull" and scene.to_dict()["pull_max"] == 10.0
    result = sliders.run(scene, backend="numpy")
    assert result.status == "avalanche" and result.n_events > 10
    assert np.all(np.diff(result.drive) >= 0.0)
    # the first event: the weakest slider of the prepared chain, at mu_n - F_n
    assert math.isclose(result.drive[0], float(np.min(result.initial.mu_s - result.start_force())),
                        abs_tol=1e-12)
    # energy: the pull's work = elastic change + dissipation, event by event
    scale = np.abs(result.work_gravity).max()
    assert np.abs(result.energy_residual).max() < 1e-6 * scale
    # the avalanche: the pull beats kinetic friction, and a free chain (mean force = pull)
    # at rest cannot hold a pull beyond its static coefficients
    assert scene.mu_d < result.alpha_c <= scene.mu_s_mean + 5 * scene.sigma_mu
    assert repr(result).startswith("<Result Scene(n_sliders=30") and "avalanche" in repr(result)


def test_the_toy_loading_stops_at_its_limit_with_the_chain_at_rest():
    """Below mu_d no slip runs away: the run ends at pull_max, every slider within its
    static threshold there."""
    scene = Scene(n_sliders=30, seed=4, mode="explore", loading=UniformPull(pull_max=0.5))
    result = sliders.run(scene, backend="numpy")
    assert result.status == "alpha_max" and result.n_events > 3
    assert result.drive[-1] <= 0.5
    at_limit = result.force_at([0.5])[0]
    assert np.all(np.abs(at_limit) <= result.final.mu_s + scene.force_tol)
    assert np.allclose(at_limit.mean(), 0.5)  # a free chain's springs cancel: mean force = pull


def test_a_loading_without_a_fortran_twin_is_refused_by_the_kernel():
    with pytest.raises(SceneError, match="loading='uniform_pull' has no Fortran twin"):
        sliders.run(Scene(n_sliders=5, loading=UniformPull(pull_max=1.0)), backend="fortran")


# ------------------------------------------------ a new friction law costs one class
@dataclass(frozen=True, repr=False)
class UniformStatic(Friction):
    """Coulomb friction whose static coefficient, at every stop, is drawn uniformly in
    [mu_s_mean - static_width, mu_s_mean + static_width] (keyed by seed, slider, stop)."""

    mu_d: float = 0.55
    mu_s_mean: float = 0.6
    static_width: float = 0.02

    name = "uniform_static"
    flat_keys = {"mu_d": "mu_d", "mu_s_mean": "mu_s_mean", "static_width": "static_width"}

    def check_own(self) -> None:
        check_real("static_width", self.static_width, 0.0, self.mu_s_mean - self.mu_d)

    def static_threshold(self, mu_s, normal, force_tol):
        return mu_s * normal + force_tol

    def kinetic_force(self, normal):
        return self.mu_d * normal

    def draw_at_stop(self, seed, sliders, n_stops):
        u = keyed_random.uniform(seed, sliders, n_stops, 0)
        return self.mu_s_mean + self.static_width * (2.0 * u - 1.0)

    def max_stable_incline(self):
        return math.atan(self.mu_d)


@pytest.mark.slow  # seconds of work: the full suite
def test_a_friction_law_defined_here_runs_on_the_reference():
    """The toy law is a class of this file alone: the preparation draws its coefficients,
    the reference engine asks it for thresholds, kinetic force and draws at every stop,
    and the run ends in the model's avalanche between atan(mu_d) and atan(max mu_s)."""
    law = UniformStatic(mu_d=0.5, mu_s_mean=0.6, static_width=0.05)
    scene = Scene(n_sliders=30, seed=7, mode="explore", friction=law)
    assert scene.friction is law and scene.mu_s_mean == 0.6
    assert scene.to_dict()["static_width"] == 0.05 and scene.to_dict()["friction"] == "uniform_static"
    result = sliders.run(scene, backend="numpy")
    assert result.status == "avalanche" and result.n_events > 10
    low, high = 0.55, 0.65
    # the coefficients are the law's: uniform draws, never the Gaussian's tails
    for mu in (result.initial.mu_s, result.final.mu_s):
        assert np.all((mu >= low) & (mu <= high))
    np.testing.assert_array_equal(result.initial.mu_s,
                                  law.draw_at_stop(7, np.arange(30), np.zeros(30, np.int64)))
    stopped = np.flatnonzero(result.final.n_stops > 0)
    assert stopped.size > 0  # sliders redrew at their stops, with the law's key
    np.testing.assert_array_equal(result.final.mu_s[stopped],
                                  law.draw_at_stop(7, stopped, result.final.n_stops[stopped]))
    assert math.atan(0.5) < result.alpha_c <= math.atan(high)
    # energy: the dissipation is the law's kinetic force times the path
    scale = np.abs(result.work_gravity).max()
    assert np.abs(result.energy_residual).max() < 1e-6 * scale


def test_a_friction_law_without_a_fortran_twin_is_refused_by_the_kernel():
    with pytest.raises(SceneError, match="friction='uniform_static' has no Fortran twin"):
        sliders.run(Scene(n_sliders=5, friction=UniformStatic()), backend="fortran")
