"""The second loading protocol, the chain pushed at one end (loading="pushed_end"):
the facts any correct run satisfies, on both backends, and the Fortran kernel
against the NumPy reference event by event."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import sliders
from sliders import Scene, prepare, status
from sliders.chain import elastic_force
from sliders.driver import make_engine
from sliders.parts.checks import SceneError
from conftest import run
from helpers import assert_bit_for_bit, assert_same_run, libm_reference

PUSHED = Scene(n_sliders=8, seed=5, loading="pushed_end", incline=0.2, driver_stiffness=2.0,
               mode="explore", xi=0.001)
# The reference takes seconds on PUSHED (400 events) where the kernel takes milliseconds: the
# fast loop checks the facts below on the kernel and compares the kernel with the reference
# event by event (test_fortran_matches_numpy_*); the reference's own checks run in the full suite.
REFERENCE_SLOW = pytest.param("numpy", marks=pytest.mark.slow)
# PUSHED on the reference, tilted once for the tests that read it (one worker)
PUSHED_REFERENCE = pytest.mark.xdist_group("pushed-reference")


def pushed_events(scene, max_events=5_000, stop_at_sliding=True, backend="numpy"):
    """Advance one event at a time: (engine, state before, state after, chunk) per event."""
    engine = make_engine(scene, backend)
    state = prepare(scene)
    assert engine.advance(state, max_events=1, relax_only=True).status == status.RELAXED
    for _ in range(max_events):
        before = state.copy()
        chunk = engine.advance(state, max_events=1)
        yield engine, before, state, chunk
        if chunk.status != status.RUNNING and (stop_at_sliding or chunk.status != status.SLIDING):
            return


@pytest.mark.parametrize("backend", ["fortran", REFERENCE_SLOW])
def test_forces_balance_stability_and_energy_after_every_event(backend):
    """Sum of F_t = N sin(tilt) + driver force; every slider stable; the work
    of gravity and of the driver's spring = elastic change + dissipation."""
    sc = PUSHED
    load = sc.loading
    n_events = 0
    for _, before, after, chunk in pushed_events(sc, backend=backend):
        if chunk.n_events == 0:
            break
        n_events += 1
        drive = after.drive
        force = load.tangential(elastic_force(after, sc.xi, sc.walls), math.sin(sc.incline), drive,
                                after.displacement)
        driver = sc.driver_stiffness * (drive - after.displacement[0])
        assert math.isclose(force.sum(), sc.n_sliders * math.sin(sc.incline) + driver,
                            rel_tol=1e-12, abs_tol=1e-11)
        excess = np.abs(force) - after.mu_s * math.cos(sc.incline)
        assert excess.max() <= sc.force_tol, f"unstable slider after event {n_events}"
        ev = {k: float(v[0]) for k, v in chunk.events.items()}
        assert ev["drive"] == drive >= before.drive  # the driver only advances
        residual = ev["work_gravity"] - ev["elastic_change"] - ev["dissipation"]
        assert abs(residual) < 1e-7 * (ev["work_gravity"] + ev["dissipation"])
        if chunk.status == status.SLIDING:
            assert ev["n_moved"] == sc.n_sliders
            break
        assert chunk.status == status.RUNNING and ev["n_moved"] < sc.n_sliders
    assert chunk.status == status.SLIDING and n_events > 10


def test_driver_work_is_in_the_energy_balance():
    """Leaving the driver's spring out of the work breaks the balance of the
    events that moved slider 1 (all of them: every front starts there)."""
    engine = make_engine(PUSHED, "numpy")
    for _, before, after, chunk in pushed_events(PUSHED, max_events=20):
        step = after.displacement - before.displacement
        assert step[0] > 0.0  # every precursor starts at the pushed end
        gravity_only = math.sin(PUSHED.incline) * step.sum()
        ev = chunk.events
        assert abs(gravity_only - ev["elastic_change"][0] - ev["dissipation"][0]) > 1e-6
        assert engine.loading.name == "pushed_end"


def test_single_slider_stick_slip_period(backend):
    """N = 1 on the driver's spring K, sigma_mu = 0: released at F = mu_s cos,
    it swings about F = mu_d cos and stops at zero velocity after moving
    2 (mu_s - mu_d) cos / K; the driver then advances by the same amount."""
    sc = Scene(n_sliders=1, sigma_mu=0.0, loading="pushed_end", incline=0.3, driver_stiffness=4.0,
               initial_forces="zero")
    expected = 2.0 * (sc.mu_s_mean - sc.mu_d) * math.cos(sc.incline) / sc.driver_stiffness
    slips, drives = [], []
    for _, before, after, chunk in pushed_events(sc, max_events=6, stop_at_sliding=False,
                                                 backend=backend):
        assert chunk.status == status.SLIDING  # one slider: every slip spans the system
        slips.append(after.displacement[0] - before.displacement[0])
        drives.append(after.drive)
    assert len(slips) == 6
    np.testing.assert_allclose(slips, expected, rtol=1e-6)
    np.testing.assert_allclose(np.diff(drives), expected, rtol=1e-6)


# the reference's 10 s run: the full suite's (the fast loop compares the backends bit for bit)
@pytest.mark.parametrize("backend", ["fortran", pytest.param("numpy", marks=[PUSHED_REFERENCE,
                                                                             pytest.mark.slow])])
def test_run_ends_at_the_onset_of_sliding_or_the_driver_limit(backend):
    result = run(PUSHED, backend)
    assert result.status == "sliding"
    assert f"driver position D={result.events['drive'][-1]:.4f}" in repr(result)
    assert result.events["n_moved"][-1] == PUSHED.n_sliders
    assert (result.events["n_moved"][:-1] < PUSHED.n_sliders).all()
    # the precursors' fronts start at slider 1 and are contiguous
    dense = result.displacement.dense()
    for row in dense[:-1]:
        moved = np.flatnonzero(row)
        assert moved[0] == 0 and moved.size == moved[-1] + 1
    limited = sliders.tilt(PUSHED.replace(drive_max=result.events["drive"][5]), backend=backend)
    assert limited.status == "alpha_max" and limited.n_events == 6
    np.testing.assert_array_equal(limited.events["drive"], result.events["drive"][:6])


def test_tilt_scenes_unchanged_by_the_new_keys():
    assert Scene(n_sliders=10) == Scene(n_sliders=10, loading="tilt", incline=0.0)
    assert "loading" not in repr(Scene(n_sliders=10))


@pytest.mark.parametrize("values, message", [
    ({"loading": "pulled"}, "loading='pulled' must be one of"),
    ({"loading": "pushed_end", "incline": 0.6}, "incline=0.6 is out of range"),
    ({"loading": "pushed_end", "driver_stiffness": 0.0}, "driver_stiffness=0.0 is out of range"),
    ({"loading": "pushed_end", "drive_max": -1.0}, "drive_max=-1.0 is out of range"),
    ({"incline": 0.1}, "incline=0.1 is a parameter of loading='pushed_end'; with loading='tilt' leave "
                       "it out"),
    # tilt names the loading: the incline's old key is refused, naming its key now
    ({"loading": "pushed_end", "tilt": 0.2}, "tilt=0.2 is not a scene key: the pushed end's fixed "
                                             "incline is incline="),
    ({"driver_stiffness": 2.0}, "driver_stiffness=2.0 is a parameter of loading='pushed_end'"),
    ({"loading": "pushed_end", "alpha_max": 1.0}, "alpha_max=1.0 is a parameter of loading='tilt'"),
    ({"loading": sliders.PushedEnd(incline=0.1), "incline": 0.2},
     "incline=0.2 is a parameter of loading=PushedEnd(incline=0.1): give it there"),
    ({"loading": "pushed_end", "mu_d": 0.0}, "incline=0.0 must be below atan(mu_d)=0"),
    ({"loading": "pushed_end", "record": "forces"}, "record='forces' rebuilds the forces of the tilt"),
])
def test_bad_pushed_end_values_give_one_line_errors(values, message):
    with pytest.raises(SceneError, match=re.escape(message)) as err:
        Scene(**values)
    assert "\n" not in str(err.value)


# ------------------------------------------------ Fortran against NumPy
# free and walls (seconds each with glibc's functions in the reference): the full suite; the fast
# loop keeps a free chain bit for bit (steep_soft_driver), the first 80 events of PUSHED
# compared with cantilevers below, and walls compared on the tilt (test_backends)
@pytest.mark.parametrize("scene", [
    pytest.param(PUSHED.replace(xi=0.0), marks=pytest.mark.slow),
    pytest.param(Scene(n_sliders=12, seed=2, loading="pushed_end", incline=0.0,
                       driver_stiffness=0.5, ends="walls", dt=0.004, max_events=150),
                 marks=pytest.mark.slow),
    Scene(n_sliders=10, seed=7, loading="pushed_end", incline=0.4, driver_stiffness=0.2,
          dt=0.004),
], ids=["free", "walls", "steep_soft_driver"])
def test_fortran_matches_numpy_bit_for_bit(scene, monkeypatch):
    """xi = 0: the kernel reproduces the reference (with glibc's
    transcendentals, those the kernel calls) event by event, to the last bit:
    drives, moved sliders, their displacements, draws and final states."""
    libm_reference(monkeypatch)
    f, n = sliders.tilt(scene, "fortran"), sliders.tilt(scene, "numpy")
    assert n.status in ("sliding", "max_events") and n.n_events > 10
    assert_bit_for_bit(f, n)


@pytest.mark.parametrize("scene", [
    pytest.param(PUSHED, marks=[PUSHED_REFERENCE, pytest.mark.slow]),
    PUSHED.replace(max_events=80),  # the fast loop's: the first 80 of its 400 events
], ids=["to_sliding", "first_80"])
def test_fortran_matches_numpy_with_cantilevers(scene):
    """xi > 0: the mean of du is summed in another order, so the drives agree
    to rounding (the run's tolerances), the events exactly."""
    f, n = run(scene, "fortran"), run(scene, "numpy")
    assert n.status == ("sliding" if scene == PUSHED else "max_events")
    assert_same_run(f, n)


def test_command_line_runs_the_pushed_end_on_the_kernel(tmp_path, capsys):
    """The onset of sliding is a normal end (exit 0), reported as a drive."""
    from sliders.__main__ import main

    out = tmp_path / "pushed.h5"
    assert main(["tilt", "--loading", "pushed_end", "--incline", "0.2", "--n-sliders", "6",
                 "--out", str(out), "--quiet"]) == 0
    result = sliders.Result.load(out)
    assert result.status == "sliding" and result.scene.loading == sliders.PushedEnd(incline=0.2)
    assert result.events["n_moved"][-1] == 6
    assert capsys.readouterr().out.startswith(
        f"sliding: last drive D={result.events['drive'][-1]:.5f}")


def test_ensembles_refuse_the_pushed_end_in_one_line(tmp_path):
    """The ensemble's statistics are the tilt's (alpha_c, precursors by angle):
    a pushed-end ensemble would bin driver positions as angles, so it is refused."""
    import subprocess
    import sys

    out = tmp_path / "pushed.h5"
    res = subprocess.run([sys.executable, "-m", "sliders.ensemble", "--loading", "pushed_end",
                          "--n-sliders", "6", "--realisations", "2", "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode != 0 and not out.exists()
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "ensembles and studies gather the tilt's statistics" in lines[0]


def test_result_forces_include_the_driver():
    """Result's force analysis is the loading's: after every event the
    rebuilt forces balance N sin(tilt) + K (D - u_1) and are stable; up to the
    next event's drive only slider 1's force grows, to a static threshold.  The
    analysis reads the run, not the backend that made it (the two agree bit for
    bit on this scene: test_fortran_matches_numpy_bit_for_bit[free])."""
    sc = PUSHED.replace(xi=0.0)
    result = sliders.tilt(sc)
    force = result.tangential_force
    du = result.displacement_after()
    drive = result.events["drive"]
    driver = sc.driver_stiffness * (drive - du[:, 0])
    np.testing.assert_allclose(force.sum(axis=1), sc.n_sliders * math.sin(sc.incline) + driver,
                               rtol=1e-12, atol=1e-10)
    assert np.abs(force).max() <= sc.mu_s_mean + 5 * sc.sigma_mu  # stable: no force beyond any mu_s
    # just below the next event's drive only slider 1's force has changed, by
    # K dD, and it is up at a static threshold (every mu_s lies above mu_d)
    at_next = result.force_at(drive[1:] - 1e-9)
    np.testing.assert_array_equal(at_next[:, 1:], force[:-1, 1:])
    np.testing.assert_allclose(at_next[:, 0], force[:-1, 0] + sc.driver_stiffness
                               * (drive[1:] - 1e-9 - drive[:-1]), rtol=0, atol=1e-10)
    assert np.all(at_next[:, 0] > sc.mu_d * math.cos(sc.incline))


def test_tilt_animation_refuses_a_pushed_scene_in_one_line(tmp_path, capsys):
    from sliders.figures import main

    scene_file = tmp_path / "pushed.toml"
    scene_file.write_text('n_sliders = 6\nloading = "pushed_end"\n')
    assert main(["--animate", "--scene", str(scene_file), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "the pushed chain has its own figure" in err
    assert not list(tmp_path.glob("*.gif"))


@pytest.mark.parametrize("observable", ["valid_limit", "force_before_events",
                                        "stopped_force_ratios"])
def test_tilt_observables_refuse_a_pushed_run(observable):
    """They take sin and cos of the drive: on driver positions they would be wrong."""
    from sliders.analysis import observables

    result = sliders.tilt(PUSHED.replace(xi=0.0, max_events=20))
    with pytest.raises(ValueError, match="is an observable of the tilt"):
        getattr(observables, observable)(result)
    assert observables.event_sizes(result).size == 20  # loading-free ones still work
