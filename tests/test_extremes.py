"""Numerical extremes: every scene either runs correctly or is refused clearly.

Issue "Speed against accuracy, numerical extremes and scaling, measured".
Each extreme scene must either give physically correct results (the facts of
docs/model.md, "Facts the tests check": every slider stable after every event, sum of forces
N sin(alpha) for a free chain, energy balance per event, the closed forms
where they exist) and end with a clear status, or be refused by ``Scene``
with a message naming the parameter before anything runs.  No hang, no
silent NaN: every run happens in a forked child process with a time limit
(pytest-timeout is not installed, and a signal cannot interrupt a call into
the Fortran kernel), and every recorded number is checked to be finite.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import time

import numpy as np
import pytest

import sliders
from sliders import Scene, SceneError, prepare, status
from sliders.analysis import model
from sliders.chain import elastic_force
from sliders.driver import make_engine
from sliders.engine.contract import EVENT_FIELDS
from sliders.parts.loading import ALPHA_MAX_LIMIT, next_instability
from sliders.scene import max_time_step

_FORK = multiprocessing.get_context("fork")


def _child(conn, fn, args) -> None:
    """Run fn(*args) and send back ("ok", value) or ("raised", exception)."""
    for s in (signal.SIGINT, signal.SIGTERM):  # whatever the test process installed
        signal.signal(s, signal.SIG_DFL)
    try:
        conn.send(("ok", fn(*args)))
    except BaseException as exc:  # noqa: BLE001 - handed to the parent, raised there
        conn.send(("raised", exc))


def isolated(fn, *args, timeout: float = 60.0):
    """fn(*args) in a forked child; fail (and SIGKILL it) if it runs past ``timeout`` seconds.

    SIGKILL, not SIGTERM: a child stuck in the kernel cannot run a Python handler, and a
    handler inherited from the test process must not keep it alive."""
    receive, send = _FORK.Pipe(duplex=False)
    child = _FORK.Process(target=_child, args=(send, fn, args), daemon=True)
    child.start()
    send.close()
    try:
        if not receive.poll(timeout):
            pytest.fail(f"{getattr(fn, '__name__', fn)}{args!r} still running after {timeout} s (hang)")
        try:
            kind, value = receive.recv()
        except EOFError:
            child.join(5)
            pytest.fail(f"{getattr(fn, '__name__', fn)}{args!r}: the child died "
                        f"(exit status {child.exitcode})")
    finally:
        receive.close()
        if child.is_alive():
            child.kill()
        child.join()
    if kind == "raised":
        raise value
    return value


def tilt(scene: Scene, backend: str = "fortran"):
    return sliders.tilt(scene, backend=backend)


def stepped(scene: Scene, backend: str = "fortran", max_events: int = 100_000) -> dict:
    """Event by event: the facts of docs/model.md ("Facts the tests check") after every completed event."""
    engine = make_engine(scene, backend)
    state = prepare(scene)
    relax = engine.advance(state, max_events=scene.max_events, relax_only=True)
    out = {"relax_status": status.NAMES[relax.status], "alpha": [], "n_moved": [],
           "max_excess": -math.inf, "max_force_sum_error": 0.0, "max_energy_rel": 0.0,
           "dissipation": [], "finite": True}
    chunk = relax
    for _ in range(max_events):
        before = state.copy()
        chunk = engine.advance(state, max_events=1)
        if chunk.n_events:
            ev = chunk.events
            out["finite"] &= all(bool(np.all(np.isfinite(ev[f]))) for f in EVENT_FIELDS)
            out["finite"] &= bool(np.all(np.isfinite(state.displacement)) and np.all(np.isfinite(state.mu_s)))
            e = elastic_force(state, scene.xi, scene.walls)
            force = e + math.sin(state.drive)
            excess = np.abs(force) - state.mu_s * math.cos(state.drive)
            out["max_excess"] = max(out["max_excess"], float(excess.max()))
            if not scene.walls:
                out["max_force_sum_error"] = max(out["max_force_sum_error"],
                                                 abs(float(force.sum()) - scene.n_sliders * math.sin(state.drive)))
            residual = ev["work_gravity"][0] - ev["elastic_change"][0] - ev["dissipation"][0]
            # relative to the energies moved, plus rounding (with mu_d = 0 an event can end
            # where it started: work and elastic change both ~1e-15)
            scale = ev["work_gravity"][0] + ev["dissipation"][0] + abs(ev["elastic_change"][0])
            out["max_energy_rel"] = max(out["max_energy_rel"], abs(residual) / (scale + 1e-5))
            out["alpha"].append(float(ev["drive"][0]))
            out["n_moved"].append(int(ev["n_moved"][0]))
            out["dissipation"].append(float(ev["dissipation"][0]))
        if chunk.status != status.RUNNING:
            break
    out.update(status=status.NAMES[chunk.status], message=chunk.message, alpha_c=chunk.alpha_c,
               n_events=len(out["alpha"]), last_rest_mu_mean=float(before.mu_s.mean()),
               final_alpha=state.drive)
    return out


def assert_facts(run: dict, scene: Scene, expect=("avalanche",)) -> None:
    """The facts of docs/model.md on a stepped run, and a clear end."""
    assert run["finite"], "a recorded number is not finite"
    assert run["status"] in expect, f"status {run['status']!r} ({run['message']})"
    if run["n_events"]:
        assert run["max_excess"] <= scene.force_tol, f"unstable slider after an event: {run['max_excess']}"
        assert run["max_force_sum_error"] <= 1e-10 * max(1, scene.n_sliders)
        assert run["max_energy_rel"] <= 1e-6, f"energy balance violated: {run['max_energy_rel']}"
        assert np.all(np.diff(run["alpha"]) >= 0.0)
    if run["status"] == "avalanche":
        lo = math.atan(scene.mu_d)
        assert lo < run["alpha_c"] <= math.atan(run["last_rest_mu_mean"]) + 1e-12
    if run["status"] in ("event_duration_cap", "non_finite", "random_failure"):
        assert run["message"], "an error status must come with a message"


def assert_finite_result(result) -> None:
    for f in EVENT_FIELDS:
        assert np.all(np.isfinite(result.events[f])), f"non-finite {f}"
    assert np.all(np.isfinite(result.final.displacement))
    assert result.status != "non_finite", result.message


def first_instability(scene: Scene) -> float:
    state = prepare(scene)
    return next_instability(state.elastic_force0, state.mu_s, 0.0)[0]


# --------------------------------------------------------------------------- N = 1, 2

@pytest.mark.parametrize("backend", ["fortran", "numpy"])
@pytest.mark.parametrize("forces", ["zero", "uniform"])
def test_single_free_slider_avalanches_at_atan_mu_s(backend, forces):
    scene = Scene(n_sliders=1, seed=4, initial_forces=forces)
    result = isolated(tilt, scene, backend)
    mu_s = prepare(scene).mu_s[0]
    assert result.status == "avalanche" and result.n_events == 0
    assert result.alpha_c == pytest.approx(math.atan(mu_s), abs=1e-12)


def test_single_slider_between_walls_up_to_the_alpha_limit():
    """Closed form all the way to pi/2 - 1e-6 (events pile up, each one exact)."""
    scene = Scene(n_sliders=1, ends="walls", sigma_mu=0.0, seed=3, alpha_max=ALPHA_MAX_LIMIT,
                  record="forces")
    result = isolated(tilt, scene)
    assert_finite_result(result)
    assert result.status == "alpha_max"
    exact = model.single_slider_angles(float(result.prepared_force()[0]), scene.mu_s_mean,
                                                scene.mu_d, scene.alpha_max)
    assert result.n_events == exact.size
    np.testing.assert_allclose(result.alpha, exact, atol=1e-11)
    dx = result.displacement.dense()[:, 0]
    np.testing.assert_allclose(dx, model.single_slider_displacement(result.alpha, scene.mu_s_mean, scene.mu_d),
                               rtol=1e-8, atol=1e-14)


@pytest.mark.parametrize("ends", ["free", "walls"])
def test_two_sliders_obey_the_facts_on_both_backends(ends):
    scene = Scene(n_sliders=2, seed=1, ends=ends, alpha_max=1.0 if ends == "walls" else ALPHA_MAX_LIMIT)
    expect = ("alpha_max",) if ends == "walls" else ("avalanche",)
    runs = {b: isolated(stepped, scene, b) for b in ("fortran", "numpy")}
    for run in runs.values():
        assert_facts(run, scene, expect)
        assert run["n_events"] >= 5
    assert runs["fortran"]["n_moved"] == runs["numpy"]["n_moved"]
    np.testing.assert_allclose(runs["fortran"]["alpha"], runs["numpy"]["alpha"], atol=1e-9)


# --------------------------------------------------------------------------- large N

@pytest.mark.slow  # 10^5 sliders, seconds of kernel time
def test_hundred_thousand_sliders_early_regime():
    """N = 1e5 (summary) up to alpha = 0.2: clean state, every number finite, sane timing.

    The full run to the avalanche is out of reach of a test (see
    docs/accuracy.md: hours at dt = 1e-3, and the largest events near the
    avalanche outlast the default 5000 tau cap); benchmarks/scaling.py measures
    the large-N runs.
    """
    scene = Scene(n_sliders=100_000, seed=0, record="summary", alpha_max=0.2)
    started = time.perf_counter()
    result = isolated(tilt, scene, timeout=120)
    elapsed = time.perf_counter() - started
    print(f"N=1e5 to alpha=0.2: {result.n_events} events, {elapsed:.1f} s")
    assert_finite_result(result)
    assert result.status == "alpha_max"
    assert 10_000 < result.n_events < 100_000
    final = result.final
    force = elastic_force(final, 0.0, False) + math.sin(final.drive)
    assert np.all(np.abs(force) - final.mu_s * math.cos(final.drive) <= scene.force_tol)
    assert abs(force.sum() - scene.n_sliders * math.sin(final.drive)) < 1e-7


def test_slow_avalanche_hits_the_duration_cap_with_a_clear_status():
    """Found by benchmarks/accuracy.py: N = 100, seed 22, dt = 1e-2.

    The last event starts at tan(alpha) - mu_d = 1.7e-4: the centre of mass
    accelerates at only ~1.5e-4, and 5000 tau (the default cap before the
    speed modes) pass before every slider slides downwards at once.  The run
    must say so, not call it an avalanche; with a larger cap the same event is
    the avalanche.
    """
    scene = Scene(n_sliders=100, seed=22, dt=1e-2, record="summary", max_event_duration=5000.0)
    capped = isolated(tilt, scene)
    assert capped.status == "event_duration_cap" and math.isnan(capped.alpha_c)
    assert "still moving after 5000.0 tau" in capped.message
    assert 0 < math.tan(capped.final.drive) - scene.mu_d < 1e-3
    longer = isolated(tilt, scene.replace(max_event_duration=2e4))
    assert longer.status == "avalanche" and longer.alpha_c == capped.final.drive


# --------------------------------------------------------------------------- stiffness

@pytest.mark.parametrize("xi", [0.0, 1e-6, 1.0, 100.0])
def test_cantilever_stiffness_extremes(xi):
    scene = Scene(n_sliders=10, seed=1, xi=xi)
    run = isolated(stepped, scene)
    assert run["relax_status"] == "relaxed"
    assert_facts(run, scene)
    assert run["n_events"] >= 5


@pytest.mark.slow  # seconds of work: the full suite
def test_stiff_cantilever_agrees_between_backends():
    scene = Scene(n_sliders=10, seed=1, xi=100.0)
    fortran, numpy_ = isolated(tilt, scene, "fortran"), isolated(tilt, scene, "numpy")
    assert fortran.status == numpy_.status == "avalanche"
    np.testing.assert_array_equal(fortran.n_moved, numpy_.n_moved)
    np.testing.assert_allclose(fortran.alpha, numpy_.alpha, atol=1e-9)


def test_stiff_cantilever_refuses_a_too_large_time_step():
    limit = max_time_step(100.0)
    assert limit == pytest.approx(2 * math.pi / math.sqrt(104) / 30)
    with pytest.raises(SceneError, match=r"dt=0\.03 is out of range.*fastest spring period"):
        Scene(xi=100.0, dt=0.03)
    Scene(xi=100.0, dt=limit)  # the limit itself is accepted


# --------------------------------------------------------------------------- friction

@pytest.mark.slow  # the NumPy reference on every tie (the kernel's ties: the walls' test below)
def test_no_static_disorder_exact_ties_on_both_backends():
    scene = Scene(n_sliders=10, seed=1, sigma_mu=0.0)
    runs = {b: isolated(stepped, scene, b) for b in ("fortran", "numpy")}
    for run in runs.values():
        assert_facts(run, scene)
    assert runs["fortran"]["n_moved"] == runs["numpy"]["n_moved"]
    np.testing.assert_allclose(runs["fortran"]["alpha"], runs["numpy"]["alpha"], atol=1e-9)


def test_static_barely_above_dynamic():
    """mu_s_mean - mu_d = 1e-4 (sigma_mu = 0.01 >> delta mu: draws redrawn above mu_d)."""
    scene = Scene(n_sliders=10, seed=1, mu_d=0.6 - 1e-4)
    run = isolated(stepped, scene)
    assert_facts(run, scene)
    assert run["n_events"] > 50
    assert run["alpha_c"] > math.atan(0.6 - 1e-4)


def test_large_friction_gap_avalanches_at_the_first_instability():
    """mu_s_mean - mu_d = 0.5: the first slider to go sets the whole chain sliding."""
    scene = Scene(n_sliders=10, seed=1, mu_d=0.1)
    run = isolated(stepped, scene)
    assert_facts(run, scene)
    assert run["n_events"] == 0
    assert run["alpha_c"] == pytest.approx(first_instability(scene), abs=1e-12)


def test_zero_dynamic_friction_free_chain():
    """mu_d = 0: tan(alpha) > mu_d at any tilt, so the chain avalanches as soon as it all slides."""
    for n in (10, 100):
        scene = Scene(n_sliders=n, seed=1, mu_d=0.0)
        run = isolated(stepped, scene)
        assert_facts(run, scene)
        assert all(d == 0.0 for d in run["dissipation"])
        if n == 10:
            assert run["n_events"] == 0
            assert run["alpha_c"] == pytest.approx(first_instability(scene), abs=1e-12)


def test_zero_dynamic_friction_between_walls_ends_clearly():
    """mu_d = 0 between walls: nothing dissipates, an event can go on for ever.

    The run must end with the duration cap and its message (never taken for
    an avalanche); the events completed before obey the facts, with work of
    gravity = elastic energy change exactly.
    """
    scene = Scene(n_sliders=10, seed=1, mu_d=0.0, ends="walls", alpha_max=1.0, max_event_duration=500.0)
    run = isolated(stepped, scene)
    assert_facts(run, scene, expect=("event_duration_cap", "alpha_max"))
    assert run["status"] == "event_duration_cap"
    assert "still moving after" in run["message"] and "max_event_duration=500.0" in run["message"]
    assert all(d == 0.0 for d in run["dissipation"])


def test_single_slider_without_dynamic_friction_between_walls():
    scene = Scene(n_sliders=1, ends="walls", sigma_mu=0.0, mu_d=0.0, seed=3, alpha_max=1.4, record="forces")
    result = isolated(tilt, scene)
    assert_finite_result(result)
    exact = model.single_slider_angles(float(result.prepared_force()[0]), scene.mu_s_mean,
                                                0.0, scene.alpha_max)
    assert result.status == "alpha_max" and result.n_events == exact.size >= 1
    np.testing.assert_allclose(result.alpha, exact, atol=1e-11)
    np.testing.assert_allclose(result.displacement.dense()[:, 0], scene.mu_s_mean * np.cos(exact), rtol=1e-8)


# --------------------------------------------------------------------------- geometry

@pytest.mark.parametrize("length", [0.0, 1e6])
def test_spring_length_never_enters_the_dynamics(length):
    base = isolated(tilt, Scene(n_sliders=10, seed=1, record="forces"))
    other = isolated(tilt, Scene(n_sliders=10, seed=1, record="forces", spring_length=length))
    np.testing.assert_array_equal(other.alpha, base.alpha)
    np.testing.assert_array_equal(other.n_moved, base.n_moved)
    np.testing.assert_array_equal(other.displacement.dense(), base.displacement.dense())
    assert other.alpha_c == base.alpha_c
    offset = np.arange(10) * (length - 10.0)
    np.testing.assert_allclose(other.final.positions() - offset, base.final.positions(),
                               rtol=0, atol=1e-15 * max(length, 10.0) * 10)


# --------------------------------------------------------------------------- near pi/2

def test_steep_friction_avalanches_near_pi_over_two():
    scene = Scene(n_sliders=10, seed=1, mu_s_mean=30.0, mu_d=29.0, sigma_mu=0.1)
    run = isolated(stepped, scene)
    assert_facts(run, scene)
    assert math.atan(29.0) < run["alpha_c"] < math.atan(30.5)
    assert run["n_events"] > 50


def test_walls_tilted_to_the_alpha_limit():
    scene = Scene(n_sliders=10, seed=1, ends="walls", alpha_max=ALPHA_MAX_LIMIT)
    run = isolated(stepped, scene)
    assert_facts(run, scene, expect=("alpha_max",))
    assert run["alpha"][-1] <= ALPHA_MAX_LIMIT
    assert run["n_events"] > 100


def test_alpha_max_at_pi_over_two_is_refused():
    with pytest.raises(SceneError, match=r"alpha_max=.* is out of range.*pi/2 - 1e-6"):
        Scene(alpha_max=math.pi / 2)
    with pytest.raises(SceneError, match="alpha_max"):
        Scene(alpha_max=ALPHA_MAX_LIMIT + 1e-9)


# --------------------------------------------------------------------------- no disorder at all

@pytest.mark.parametrize("backend", ["fortran", "numpy"])
def test_no_disorder_free_chain_avalanches_at_atan_mu_s_without_precursor(backend):
    """Every slider ties at atan(mu_s): all start together and the avalanche is
    seen on the first step, up to N = 1e5 (the one N = 1e5 scene that reaches
    its avalanche within a test: with disorder the last events are slip fronts
    crossing the chain at the sound speed, >= N^2 / (4 dt) slider-steps, see
    docs/performance.md, "Scaling with N")."""
    for n in ((10, 1000, 100_000) if backend == "fortran" else (10,)):
        scene = Scene(n_sliders=n, seed=1, initial_forces="zero", sigma_mu=0.0, record="summary")
        result = isolated(tilt, scene, backend)
        assert result.status == "avalanche" and result.n_events == 0
        assert result.alpha_c == pytest.approx(math.atan(scene.mu_s_mean), abs=1e-12)
        assert result.final_event["n_steps"] == 1 and result.final_event["slider_steps"] == n
        force = elastic_force(result.final, 0.0, False) + math.sin(result.alpha_c)
        assert abs(force.sum() - n * math.sin(result.alpha_c)) < 1e-9 * n


@pytest.mark.parametrize("backend", ["fortran", pytest.param("numpy", marks=pytest.mark.slow)])
def test_no_disorder_between_walls_stays_symmetric(backend):
    scene = Scene(n_sliders=10, seed=1, initial_forces="zero", sigma_mu=0.0, ends="walls",
                  alpha_max=1.0 if backend == "fortran" else 0.75)
    result = isolated(tilt, scene, backend)
    assert_finite_result(result)
    assert result.status == "alpha_max" and result.n_events >= 3
    assert result.alpha[0] == pytest.approx(math.atan(scene.mu_s_mean), abs=1e-12)
    d = result.displacement.dense()
    np.testing.assert_allclose(d, d[:, ::-1], rtol=0, atol=1e-12)
    run = isolated(stepped, scene, backend)
    assert_facts(run, scene, expect=("alpha_max",))
