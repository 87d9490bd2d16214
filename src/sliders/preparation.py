"""Preparation of the chain at alpha = 0 (paper Sec. II-C-1; docs/model.md, "Preparation").

Steps, and the choices made where the paper is silent:

1. Static coefficients mu_{s,n}: the friction law's draw at stop count 0
   (``draw_at_stop``; Coulomb: keyed Gaussian draws, redrawn until above mu_d).
2. Tangential forces f_n uniform in ]-mu_s_mean, mu_s_mean[.  *Own threshold*:
   a force with abs(f_n) >= mu_{s,n} would be unstable for its own slider, so it is
   redrawn (keyed rejection); the forces stay uniform on
   ]-a_n, a_n[ with a_n = min(mu_s_mean, mu_{s,n}).
3. *Zero sum* (free chain only): the internal forces of a free chain sum to
   zero, so the drawn forces must too.  Wanted: the uniform law on the box
   prod ]-a_n, a_n[ conditioned on sum f = 0 (whose one-slider marginals are
   flat up to O(1/N)).  A feasible start is made by removing the residual
   S = sum f in proportion to each force's room to its bound (for S > 0,
   f_n -> f_n - S (f_n + a_n) / sum_m (f_m + a_m), which keeps every force
   inside its range), then ``ZERO_SUM_SWEEPS`` sweeps of a pairwise Gibbs
   sampler mix it: the sliders are paired at random (keyed permutation) and
   each pair's forces are redrawn uniformly on the segment that keeps their
   sum and both bounds.  That move leaves the conditioned uniform law
   invariant, so the start's bias (the projection alone thins the end bins by
   ~40 % at N = 100) is washed out.  For N = 1 the force is 0.
   Between walls no constraint applies: the walls take the net force.
4. Positions from forces: spring tensions are running sums of the forces
   (T_0 = 0 at the left end), positions running sums of the tensions.
5. With xi > 0: l* = (x_N - x_1)/(N - 1), the plate anchors are
   c_n = mean(x) + (n - (N+1)/2) l*, the coupling is switched on and the chain
   is relaxed at alpha = 0 with the dynamics (done by the driver, through the
   same event code as the tilt).

``initial_forces="history"`` (``prepare_with_history``): a pile that was once
brought near its avalanche angle and returned.  The same scene with another
seed (``history_seed``) is prepared as above and tilted to its last stable
state before the avalanche; it is then tilted back to alpha = 0 in steps of
``UNLOAD_STEP``, the chain relaxed at every step by the event code (sliders
that slip backwards, F_n < -mu_s,n cos alpha, move as in any event); the
state reached at alpha = 0, its coefficients and stop counts included, is the
prepared chain (rebased: its displacement folded into the reference state).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from . import keyed_random, status
from .chain import ChainState, elastic_force
from .engine.fortran_engine import FortranEngine
from .engine.reference import NumpyEngine
from .parts.loading import ALPHA_MAX_LIMIT
from .scene import Scene

class PreparationInterrupted(KeyboardInterrupt):
    """Ctrl-C (or a SIGTERM the caller turned into KeyboardInterrupt) stopped a
    preparation that is itself a run (``"history"``, seconds to minutes): no chain
    was made, so nothing is drawn again to describe it."""

    def __init__(self, scene: Scene):
        super().__init__(f"interrupted while the history of a chain of {scene.n_sliders} "
                         "sliders was prepared (initial_forces='history'); no chain was made")


def prepared_at_once(scene: Scene) -> bool:
    """Whether ``prepare(scene)`` is a few array operations (every preparation but
    ``"history"``, which tilts a chain to its avalanche and back)."""
    return scene.initial_forces != "history"


#: ``progress(phase, alpha, n_events)`` of a history: ``phase`` "to the avalanche" (after each
#: chunk of events; ``n_events`` so far) or "back to 0" (after each step back; the events of
#: the relaxations so far), ``alpha`` the tilt reached in rad
HistoryProgress = Callable[[str, float, int], None]

MAX_FORCE_ATTEMPTS = 1000
ZERO_SUM_SWEEPS = 20
PAIRING_STREAM = 0xFFFFFFFD  # keyed stream of the random pairings
PAIR_DRAW_STREAM = 0xFFFFFFFC  # keyed stream of the pair redraws


def draw_initial_forces(scene: Scene, mu_s: np.ndarray) -> np.ndarray:
    """Uniform forces in ]-mu_s_mean, mu_s_mean[, each stable for its own mu_s."""
    n = scene.n_sliders
    if scene.initial_forces == "zero":
        return np.zeros(n)
    sliders = np.arange(n)
    bound = np.minimum(mu_s, scene.mu_s_mean)
    forces = np.full(n, np.nan)
    pending = np.ones(n, dtype=bool)
    for attempt in range(MAX_FORCE_ATTEMPTS):
        idx = sliders[pending]
        u = keyed_random.uniform(scene.seed, idx, keyed_random.PREPARATION_STREAM, attempt)
        f = (2.0 * u - 1.0) * scene.mu_s_mean
        ok = np.abs(f) < bound[idx]
        forces[idx[ok]] = f[ok]
        pending[idx[ok]] = False
        if not pending.any():
            break
    else:  # pragma: no cover - needs mu_s far below mu_s_mean for 1000 draws
        raise RuntimeError("preparation: could not draw stable initial forces")
    if not scene.walls:
        forces = mix_at_zero_sum(scene.seed, remove_net_force(forces, bound), bound)
    return forces


def mix_at_zero_sum(seed: int, forces: np.ndarray, bound: np.ndarray,
                    sweeps: int = ZERO_SUM_SWEEPS) -> np.ndarray:
    """Pairwise Gibbs sweeps at fixed sum, inside ]-bound, bound[ (see module doc)."""
    forces = forces.copy()
    n = forces.size
    sliders = np.arange(n)
    for sweep in range(sweeps):
        order = np.argsort(keyed_random.uniform(seed, sliders, PAIRING_STREAM, sweep), kind="stable")
        first, second = order[0 : n - 1 : 2], order[1:n:2]
        total = forces[first] + forces[second]
        low = np.maximum(-bound[first], total - bound[second])
        high = np.minimum(bound[first], total + bound[second])
        u = keyed_random.uniform(seed, first, PAIR_DRAW_STREAM, sweep)
        forces[first] = low + u * (high - low)
        forces[second] = total - forces[first]
    return forces


def remove_net_force(forces: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """Make the forces sum to zero, staying inside ]-bound, bound[ (see module doc)."""
    total = forces.sum()
    if total > 0.0:
        room = forces + bound
        return forces - total * room / room.sum()
    if total < 0.0:
        room = bound - forces
        return forces - total * room / room.sum()
    return forces.copy()


def prepare(scene: Scene, history_progress: HistoryProgress | None = None) -> ChainState:
    """The prepared chain at alpha = 0, before any coupling relaxation.

    Parameters
    ----------
    scene : Scene
        Its ``n_sliders``, friction coefficients, ``seed``, ``ends`` and
        ``initial_forces`` are used.
    history_progress : callable, optional
        For ``initial_forces="history"`` (a tilt of its own, minutes for large
        chains): called as the history advances (``prepare_with_history``).

    Returns
    -------
    ChainState
        Static coefficients drawn with key (seed, n, 0); elastic forces (m g)
        uniform in ]-mu_s_mean, mu_s_mean[, each stable for its own slider and,
        for a free chain, summing to zero (docs/model.md, "Preparation").
    """
    if scene.initial_forces == "history":
        return prepare_with_history(scene, history_progress)
    n = scene.n_sliders
    sliders = np.arange(n)
    mu_s = scene.friction.draw_at_stop(scene.seed, sliders, np.zeros(n, dtype=np.int64))
    forces = draw_initial_forces(scene, mu_s)

    # Spring k joins slider k-1 and k; F_n = T_{n+1} - T_n with T_0 = 0 (left
    # wall spring at rest; absent for a free chain) so T_{n+1} = sum_{j<=n} f_j.
    extension = np.zeros(n + 1)
    extension[1:] = np.cumsum(forces)
    if not scene.walls:
        extension[-1] = 0.0  # free end: no spring (the forces sum to zero)
    u0 = np.zeros(n)
    u0[1:] = np.cumsum(extension[1:n])

    stretch = np.zeros(n)
    e0 = forces.copy()
    if scene.xi > 0.0 and n > 1:
        spacing_excess = (u0[-1] - u0[0]) / (n - 1)  # l* - l
        anchors = (sliders - (n - 1) / 2.0) * spacing_excess
        stretch = u0 - u0.mean() - anchors
        e0 = forces - scene.xi * stretch
    lattice = sliders * scene.spring_length + u0
    return ChainState(
        elastic_force0=e0,
        spring_extension0=extension,
        cantilever_stretch0=stretch,
        lattice_position0=lattice,
        mu_s=mu_s,
    )


HISTORY_REALISATION = 0x7FFFFFFF  # the history's seed: realisation_seed(seed, this)
UNLOAD_STEP = 0.01  # rad: the steps of the tilt back to alpha = 0
HISTORY_CHUNK = 512  # events per engine call of the history's tilt


def history_seed(seed: int) -> int:
    """The seed of the run that makes a ``"history"`` preparation (another disorder, keyed by ``seed``)."""
    return keyed_random.realisation_seed(seed, HISTORY_REALISATION)


def _history_engine(scene: Scene):
    try:
        return FortranEngine(scene)
    except (ImportError, AttributeError):  # the kernel is not built: the reference, same events
        return NumpyEngine(scene)


def _relaxed(engine, state: ChainState, scene: Scene, where: str) -> int:
    """Relax ``state`` in place; the number of its events."""
    relax = engine.advance(state, max_events=scene.max_events, relax_only=True)
    if relax.status == status.INTERRUPTED:  # the engine answered a signal
        raise PreparationInterrupted(scene)
    if relax.status != status.RELAXED:
        raise RuntimeError(f"history preparation: the relaxation {where} ended with status "
                           f"{status.NAMES.get(relax.status, relax.status)!r}")
    return relax.n_events


def last_stable_state(scene: Scene, engine=None,
                      progress: HistoryProgress | None = None) -> ChainState:
    """The chain of ``scene`` (prepared as "uniform") just after its last event before the avalanche.

    Tilted in chunks of events; the chunk in which the avalanche starts is run
    again from its start up to the event before it.  A run that ends
    otherwise (``alpha_max``, ``max_events``) gives its final state.
    """
    engine = engine or _history_engine(scene)
    state = prepare(scene)
    _relaxed(engine, state, scene, "at alpha = 0")
    n_events = 0
    while True:
        before = state.copy()
        chunk = engine.advance(state, max_events=HISTORY_CHUNK)
        # a Ctrl-C as the avalanche came stops the history too
        code = status.INTERRUPTED if getattr(engine, "interrupted_late", False) else chunk.status
        n_events += chunk.n_events
        if progress is not None and code != status.INTERRUPTED:
            progress("to the avalanche", state.drive, n_events)
        if code in (status.RUNNING, status.SPARSE_FULL):
            continue
        if code == status.AVALANCHE:
            state = before
            if chunk.n_events:
                engine.advance(state, max_events=chunk.n_events)
            return state
        if code in (status.ALPHA_MAX, status.MAX_EVENTS):
            return state
        if code == status.INTERRUPTED:
            raise PreparationInterrupted(scene)
        raise RuntimeError(f"history preparation: the tilt ended with status "
                           f"{status.NAMES.get(code, code)!r}")


def tilt_back(state: ChainState, scene: Scene, engine=None, step: float = UNLOAD_STEP,
              progress: HistoryProgress | None = None) -> ChainState:
    """``state`` tilted back to alpha = 0 in steps of ``step`` rad, relaxed at every step
    (in place)."""
    engine = engine or _history_engine(scene)
    n_events = 0
    for alpha in np.arange(state.drive, 0.0, -step)[1:].tolist() + [0.0]:
        state.drive = float(alpha)
        n_events += _relaxed(engine, state, scene, f"at alpha = {alpha:.4f} on the way back")
        if progress is not None:
            progress("back to 0", state.drive, n_events)
    return state


def rebased(state: ChainState, scene: Scene) -> ChainState:
    """The same chain with its displacement folded into the reference (displacement 0, alpha 0)."""
    du = state.displacement
    extension = state.spring_extension0.copy()
    extension[1:-1] += np.diff(du)
    if scene.walls:
        extension[0] += du[0]
        extension[-1] -= du[-1]
    return ChainState(
        elastic_force0=elastic_force(state, scene.xi, scene.walls),
        spring_extension0=extension,
        cantilever_stretch0=state.cantilever_stretch0 + (du - du.mean() if scene.xi > 0 else 0.0),
        lattice_position0=state.lattice_position0 + du,
        mu_s=state.mu_s.copy(),
        n_stops=state.n_stops.copy(),
    )


def prepare_with_history(scene: Scene, progress: HistoryProgress | None = None) -> ChainState:
    """The ``"history"`` preparation (module docstring): a chain brought to its last stable
    state before an avalanche (the same scene, seed ``history_seed(scene.seed)``), then
    tilted back to alpha = 0.

    Parameters
    ----------
    scene : Scene
        The scene to prepare; its ``seed`` keys the history's seed, and every
        other field but ``alpha_max`` is the history's too (the history is
        tilted to its avalanche).
    progress : callable, optional
        ``progress(phase, alpha, n_events)`` as the history advances (``HistoryProgress``).

    Returns
    -------
    ChainState
        At rest at alpha = 0, displacement zero, with the history's static
        coefficients and stop counts.
    """
    # to its avalanche whatever the scene's alpha_max (a run cut at angles keeps its history)
    past = scene.replace(seed=history_seed(scene.seed), initial_forces="uniform",
                         alpha_max=ALPHA_MAX_LIMIT)
    engine = _history_engine(past)
    state = tilt_back(last_stable_state(past, engine, progress), past, engine,
                      progress=progress)
    return rebased(state, past)
