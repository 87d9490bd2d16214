"""Ctrl-C inside ``engine.advance`` (issue 16, "No hang, ever"; kernel side).

A real SIGINT is sent to a child process while ``advance`` runs (for the
Fortran kernel: inside the kernel call, in the middle of an event).  The call
must return within 2 s a chunk with status INTERRUPTED holding the events
completed in the call, and leave the state of the uninterrupted run after the
same number of events: the event in progress undone entirely (displacements,
draws, stop counts, alpha).  Also here: the bisection's bound on both backends.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import sliders
from sliders import Scene, prepare, status
from sliders.driver import make_engine
from sliders.parts.checks import SceneError

pytestmark = pytest.mark.slow  # signals sent to running commands

# An event that never ends (no dynamic friction between walls: nothing
# dissipates; its sliders stop, redraw and restart) after two ordinary ones,
# run before the signal's call; and ordinary tilts, interrupted mid-run.
ENDLESS = dict(n_sliders=10, seed=1, mu_d=0.0, ends="walls", alpha_max=1.0,
               max_event_duration=1e12)
SCENES = {  # (scene, events run before the interrupted call, seconds before SIGINT)
    ("fortran", "endless"): (ENDLESS, 2, 1.0),
    ("numpy", "endless"): (ENDLESS, 2, 1.0),
    ("fortran", "tilt"): (dict(n_sliders=1000, seed=0, record="summary"), 0, 1.0),
    ("numpy", "tilt"): (dict(n_sliders=30, xi=0.001, seed=3, dt=0.01), 0, 1.5),
}

CHILD = r"""
import json, sys
from sliders import Scene, prepare
from sliders.driver import make_engine
backend, scene, before = sys.argv[1], Scene(**json.loads(sys.argv[2])), int(sys.argv[3])
engine = make_engine(scene, backend)
state = prepare(scene)
engine.advance(state, max_events=scene.max_events, relax_only=True)
assert engine.advance(state, max_events=before).n_events == before
print("ready", flush=True)
chunk = engine.advance(state, max_events=10**6)
print(json.dumps({"status": chunk.status, "message": chunk.message,
                  "n_events": chunk.n_events, "final_event": chunk.final_event,
                  "alpha": state.drive.hex(),
                  "state": [a.tobytes().hex() for a in (state.displacement, state.mu_s,
                                                         state.n_stops)]}), flush=True)
"""


def relaxed(scene: Scene, backend: str):
    engine = make_engine(scene, backend)
    state = prepare(scene)
    engine.advance(state, max_events=scene.max_events, relax_only=True)
    return engine, state


@pytest.mark.parametrize("backend, kind", sorted(SCENES))
def test_sigint_returns_the_completed_events_and_undoes_the_current_one(backend, kind):
    params, before, delay = SCENES[backend, kind]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    child = subprocess.Popen([sys.executable, "-c", CHILD, backend, json.dumps(params), str(before)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert child.stdout.readline().strip() == "ready", child.stderr.read()
        time.sleep(delay)
        assert child.poll() is None, "the run ended before the signal"
        sent = time.perf_counter()
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=30)
        took = time.perf_counter() - sent
    finally:
        child.kill()
    assert child.returncode == 0, err
    assert took < 2.0, f"stopped {took:.2f} s after SIGINT"
    report = json.loads(out)
    assert report["status"] == status.INTERRUPTED
    assert report["message"] == "interrupted by the user"
    assert report["final_event"] == {}
    k = report["n_events"]  # completed in the interrupted call
    assert k == 0 if kind == "endless" else k >= 1

    scene = Scene(**params)
    engine, state = relaxed(scene, backend)
    chunk = engine.advance(state, max_events=before + k)
    assert chunk.n_events == before + k and chunk.status == status.RUNNING
    assert float.fromhex(report["alpha"]) == state.drive
    expected = [a.tobytes().hex() for a in (state.displacement, state.mu_s, state.n_stops)]
    for name, got, want in zip(("displacement", "mu_s", "n_stops"), report["state"], expected):
        assert got == want, name


@pytest.mark.parametrize("backend", ["fortran", "numpy"])
def test_an_unreachable_refine_tol_ends_with_its_status(backend):
    """1e-20 tau cannot be resolved within a step of 1e-3: bounded halvings,
    a clear status and message, the event undone (as for the duration cap).
    Scene refuses such a value up front; the kernel's own bound is the second
    line of defence, tested here by setting the value past the validation."""
    with pytest.raises(SceneError, match="refine_tol=1e-20 is out of range"):
        Scene(n_sliders=10, seed=0, refine_tol=1e-20)
    scene = Scene(n_sliders=10, seed=0)
    object.__setattr__(scene, "refine_tol", 1e-20)
    run = sliders.tilt(scene, backend=backend)
    assert run.status == "refine_limit"
    assert "refine_tol=1e-20" in run.message and "128 halvings" in run.message
    assert run.final_event["n_steps"] >= 1
    untouched = prepare(scene)
    np.testing.assert_array_equal(run.final.displacement, untouched.displacement)
    np.testing.assert_array_equal(run.final.n_stops, untouched.n_stops)
    np.testing.assert_array_equal(run.final.mu_s, untouched.mu_s)


def test_a_resolvable_refine_tol_is_unaffected_by_the_bound():
    """The bound never cuts a refinement that converges: 1e-15 at dt = 1e-2
    needs 44 halvings and runs to the avalanche."""
    run = sliders.tilt(Scene(n_sliders=10, seed=0, dt=1e-2, refine_tol=1e-15))
    assert run.status == "avalanche"


def ctrl_c_as_the_kernel_returns(monkeypatch, code: int) -> None:
    """Every kernel call that ends with status ``code`` sends this process a SIGINT
    before it returns, and waits while the main thread handles it."""
    from sliders import _kernel

    real = _kernel.tilt_advance

    def returns_then_ctrl_c(*args):
        out = real(*args)
        if out[3] == code:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the main thread handles it while it waits for us
        return out

    monkeypatch.setattr(_kernel, "tilt_advance", returns_then_ctrl_c)


def test_ctrl_c_as_the_run_ends_is_not_swallowed(monkeypatch):
    """Ctrl-C that lands while the kernel returns its avalanche: the finished run
    is kept (attached to the exception), and the interrupt still reaches the caller."""
    whole = sliders.tilt(Scene(n_sliders=10, seed=0, mode="explore"))
    ctrl_c_as_the_kernel_returns(monkeypatch, status.AVALANCHE)
    with pytest.raises(sliders.Interrupted) as caught:
        sliders.tilt(Scene(n_sliders=10, seed=0, mode="explore"))
    partial = caught.value.partial
    # On a loaded machine the main thread may handle the signal only after the
    # kernel call returned: then the last chunk is dropped (status interrupted).
    # Either way the interrupt reaches the caller with every kept event intact.
    assert partial.status in ("avalanche", "interrupted")
    if partial.status == "avalanche":
        assert partial.alpha_c == whole.alpha_c and partial.n_events == whole.n_events
    else:
        assert partial.n_events <= whole.n_events
        np.testing.assert_array_equal(partial.alpha, whole.alpha[:partial.n_events])


def test_ctrl_c_as_the_relaxation_ends_stops_the_run(monkeypatch):
    """Ctrl-C that lands while the kernel returns the relaxation at alpha = 0: the run
    stops there (as the reference does), rather than tilting on to its end with the
    interrupt forgotten (a loop of short runs once carried on past a SIGTERM)."""
    ctrl_c_as_the_kernel_returns(monkeypatch, status.RELAXED)
    with pytest.raises(sliders.Interrupted) as caught:
        sliders.tilt(Scene(n_sliders=10, seed=0, mode="explore"))
    assert caught.value.partial.status == "interrupted"
    assert caught.value.partial.n_events == 0


def test_ctrl_c_as_a_historys_avalanche_comes_ends_the_history_as_interrupted(monkeypatch):
    """The history preparation's tilt, Ctrl-C landing as its avalanche is returned: the
    preparation stops as interrupted instead of tilting back a full history."""
    from sliders.preparation import last_stable_state

    ctrl_c_as_the_kernel_returns(monkeypatch, status.AVALANCHE)
    with pytest.raises(sliders.PreparationInterrupted, match="no chain was made"):
        last_stable_state(Scene(n_sliders=10, seed=0, mode="explore"))


def test_ctrl_c_in_a_history_preparation_stops_the_run_with_no_chain(monkeypatch):
    """A tilt whose chain is prepared by its history, Ctrl-C answered by the history's
    engine: the run stops at once with PreparationInterrupted (a KeyboardInterrupt), and
    draws no chain again to describe a run that never started."""
    ctrl_c_as_the_kernel_returns(monkeypatch, status.RELAXED)
    started = time.monotonic()
    with pytest.raises(sliders.PreparationInterrupted) as caught:
        sliders.tilt(Scene(n_sliders=10, seed=0, mode="explore", initial_forces="history"))
    assert isinstance(caught.value, KeyboardInterrupt)
    assert time.monotonic() - started < 3.0  # one relaxation and the signal's second


def test_ctrl_c_after_the_kernel_returned_keeps_its_events(monkeypatch):
    """A Ctrl-C handled in the Python that turns the kernel's outputs into a chunk:
    the kernel's events are in the state already, so the chunk is built to the end
    and answers INTERRUPTED with them, and the state is the uninterrupted run's
    after as many events (a chunk lost there left a state ahead of its events)."""
    from sliders.engine import fortran_engine

    scene = Scene(n_sliders=50, seed=2, record="displacements")
    real, calls = fortran_engine._message, []

    def ctrl_c_once(*args):
        calls.append(args)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(*args)

    engine, state = relaxed(scene, "fortran")
    monkeypatch.setattr(fortran_engine, "_message", ctrl_c_once)
    try:
        chunk = engine.advance(state, max_events=7)
    except KeyboardInterrupt:
        pytest.fail("the Ctrl-C left the engine: the kernel's chunk was lost")
    monkeypatch.undo()
    assert chunk.status == status.INTERRUPTED and chunk.n_events == 7
    again, expected = relaxed(scene, "fortran")
    whole = again.advance(expected, max_events=7)
    assert state.drive == expected.drive
    for name in ("displacement", "mu_s", "n_stops"):
        np.testing.assert_array_equal(getattr(state, name), getattr(expected, name), name)
    for field in chunk.events:
        np.testing.assert_array_equal(chunk.events[field], whole.events[field], field)
    np.testing.assert_array_equal(chunk.sparse_displacement, whole.sparse_displacement)


def test_ctrl_c_inside_the_kernel_threads_start_waits_for_the_kernel(monkeypatch):
    """A Ctrl-C raised in Thread.start after the kernel thread launched: the
    engine stops that kernel and waits for it before returning, so that no
    caller saves a state the kernel is still writing (a saved file once
    failed its own checksum this way)."""
    import threading

    scene = Scene(n_sliders=400, seed=1, record="summary")
    engine = make_engine(scene, "fortran")
    state = prepare(scene)
    assert engine.advance(state, max_events=1, relax_only=True).status == status.RELAXED
    real_start = threading.Thread.start
    workers = []

    def start_then_ctrl_c(thread):
        real_start(thread)
        workers.append(thread)
        raise KeyboardInterrupt

    monkeypatch.setattr(threading.Thread, "start", start_then_ctrl_c)
    chunk = engine.advance(state, max_events=10_000)
    monkeypatch.undo()
    assert workers and not workers[0].is_alive()  # the kernel had ended before the return
    assert chunk.status == status.INTERRUPTED
    kept = state.copy()
    time.sleep(0.2)  # nothing writes into the state any more
    np.testing.assert_array_equal(state.mu_s, kept.mu_s)
    np.testing.assert_array_equal(state.displacement, kept.displacement)
