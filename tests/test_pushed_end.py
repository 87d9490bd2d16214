"""The second loading protocol, the chain pushed at one end (loading="pushed_end"):
the facts any correct run satisfies, on the NumPy reference (the Fortran kernel
has the tilt only and refuses this loading with a one-line error)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import sliders
from sliders import Scene, prepare, status
from sliders.chain import elastic_force
from sliders.driver import make_engine
from sliders.scene import SceneError

PUSHED = Scene(n_sliders=8, seed=5, loading="pushed_end", tilt=0.2, drive_stiffness=2.0,
               mode="explore", xi=0.001)


def pushed_events(scene, max_events=5_000, stop_at_sliding=True):
    """Advance one event at a time: (engine, state before, state after, chunk) per event."""
    engine = make_engine(scene, "numpy")
    state = prepare(scene)
    assert engine.advance(state, max_events=1, relax_only=True).status == status.RELAXED
    for _ in range(max_events):
        before = state.copy()
        chunk = engine.advance(state, max_events=1)
        yield engine, before, state, chunk
        if chunk.status != status.RUNNING and (stop_at_sliding or chunk.status != status.SLIDING):
            return


def test_forces_balance_stability_and_energy_after_every_event():
    """Sum of F_t = N sin(tilt) + driver force; every slider stable; the work
    of gravity and of the driver's spring = elastic change + dissipation."""
    sc = PUSHED
    n_events = 0
    for engine, before, after, chunk in pushed_events(sc):
        if chunk.n_events == 0:
            break
        n_events += 1
        load = engine.loading
        drive = after.alpha
        force = load.tangential(elastic_force(after, sc.xi, sc.walls), math.sin(sc.tilt), drive,
                                after.displacement)
        driver = sc.drive_stiffness * (drive - after.displacement[0])
        assert math.isclose(force.sum(), sc.n_sliders * math.sin(sc.tilt) + driver,
                            rel_tol=1e-12, abs_tol=1e-11)
        excess = np.abs(force) - after.mu_s * math.cos(sc.tilt)
        assert excess.max() <= sc.force_tol, f"unstable slider after event {n_events}"
        ev = {k: float(v[0]) for k, v in chunk.events.items()}
        assert ev["alpha"] == drive >= before.alpha  # the driver only advances
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
        gravity_only = math.sin(PUSHED.tilt) * step.sum()
        ev = chunk.events
        assert abs(gravity_only - ev["elastic_change"][0] - ev["dissipation"][0]) > 1e-6
        assert engine.loading.name == "pushed_end"


def test_single_slider_stick_slip_period():
    """N = 1 on the driver's spring K, sigma_mu = 0: released at F = mu_s cos,
    it swings about F = mu_d cos and stops at zero velocity after moving
    2 (mu_s - mu_d) cos / K; the driver then advances by the same amount."""
    sc = Scene(n_sliders=1, sigma_mu=0.0, loading="pushed_end", tilt=0.3, drive_stiffness=4.0,
               initial_forces="zero")
    expected = 2.0 * (sc.mu_s_mean - sc.mu_d) * math.cos(sc.tilt) / sc.drive_stiffness
    slips, drives = [], []
    for _, before, after, chunk in pushed_events(sc, max_events=6, stop_at_sliding=False):
        assert chunk.status == status.SLIDING  # one slider: every slip spans the system
        slips.append(after.displacement[0] - before.displacement[0])
        drives.append(after.alpha)
    assert len(slips) == 6
    np.testing.assert_allclose(slips, expected, rtol=1e-6)
    np.testing.assert_allclose(np.diff(drives), expected, rtol=1e-6)


def test_run_ends_at_the_onset_of_sliding_or_the_driver_limit():
    result = sliders.tilt(PUSHED, backend="numpy")
    assert result.status == "sliding"
    assert f"driver position D={result.events['alpha'][-1]:.4f}" in repr(result)
    assert result.events["n_moved"][-1] == PUSHED.n_sliders
    assert (result.events["n_moved"][:-1] < PUSHED.n_sliders).all()
    # the precursors' fronts start at slider 1 and are contiguous
    dense = result.displacement.dense()
    for row in dense[:-1]:
        moved = np.flatnonzero(row)
        assert moved[0] == 0 and moved.size == moved[-1] + 1
    limited = sliders.tilt(PUSHED.replace(drive_max=result.events["alpha"][5]), backend="numpy")
    assert limited.status == "alpha_max" and limited.n_events == 6
    np.testing.assert_array_equal(limited.events["alpha"], result.events["alpha"][:6])


def test_tilt_scenes_unchanged_by_the_new_keys():
    assert Scene(n_sliders=10) == Scene(n_sliders=10, loading="tilt", tilt=0.0)
    assert "loading" not in repr(Scene(n_sliders=10))


@pytest.mark.parametrize("values, message", [
    ({"loading": "pulled"}, "loading='pulled' must be one of"),
    ({"loading": "pushed_end", "tilt": 0.6}, "tilt=0.6 is out of range"),
    ({"loading": "pushed_end", "drive_stiffness": 0.0}, "drive_stiffness=0.0 is out of range"),
    ({"loading": "pushed_end", "drive_max": -1.0}, "drive_max=-1.0 is out of range"),
    ({"tilt": 0.1}, "tilt=0.1 is the fixed incline of loading='pushed_end'"),
    ({"loading": "pushed_end", "mu_d": 0.0}, "tilt=0.0 must be below atan(mu_d)=0"),
    ({"loading": "pushed_end", "record": "forces"}, "record='forces' rebuilds the forces of the tilt"),
])
def test_bad_pushed_end_values_give_one_line_errors(values, message):
    with pytest.raises(SceneError, match=re.escape(message)) as err:
        Scene(**values)
    assert "\n" not in str(err.value)


def test_fortran_backend_refuses_pushed_end_in_one_line():
    with pytest.raises(SceneError, match="runs on the NumPy reference only"):
        sliders.tilt(PUSHED, backend="fortran")


def test_command_line_refuses_the_fortran_backend_in_one_line(capsys):
    from sliders.__main__ import main

    with pytest.raises(SystemExit) as exit_:
        main(["tilt", "--loading", "pushed_end", "--n-sliders", "4", "--out", "unused.h5"])
    assert exit_.value.code != 0
    err = capsys.readouterr().err.strip()
    assert "runs on the NumPy reference only" in err and "\n" not in err
