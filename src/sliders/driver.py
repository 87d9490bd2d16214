"""The quasi-static driver: prepare, relax, then drive the loading to the run's end.

``run`` drives the scene's loading (the tilt to the avalanche, the pushed end
to the onset of sliding); ``sliders.tilt`` is its alias at the package's top.

Both backends implement the same ``advance(state, max_events, relax_only)``
method (see ``reference.NumpyEngine``); the driver calls it in chunks so that
it can report progress, and assembles the result.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from . import status
from .chain import ChainState
from .engine.contract import INTERRUPTED_MESSAGE, Chunk, join_chunks
from .keyed_random import realisation_seed
from .preparation import prepare
from .engine.reference import NumpyEngine
from .result import EventSparse, Result
from .parts.checks import SceneError
from .scene import BACKENDS, Scene, check_memory
from .engine.fortran_engine import FortranEngine

CHUNK_EVENTS = {"numpy": 16, "fortran": 512}
# A kernel call starts with O(N) set-up (forces, angles, min-tree): for long
# chains the chunks grow with N so that it stays a few per cent of the run.
CHUNK_EVENTS_PER_SLIDER = {"numpy": 0.0, "fortran": 0.02}


def chunk_events(scene: Scene, backend: str) -> int:
    """Events per engine call (one progress report each)."""
    return max(CHUNK_EVENTS[backend], int(CHUNK_EVENTS_PER_SLIDER[backend] * scene.n_sliders))


@dataclass
class Progress:
    """What a progress callback receives after every chunk: ``drive``, the drive
    reached (the tilt alpha in rad, or the pushed end's driver position D in
    g tau^2, ``scene.loading.drive_label``), the events, seconds and slider-steps so far."""

    drive: float
    n_events: int
    elapsed: float
    slider_steps: int


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (or a SIGTERM the caller turned into KeyboardInterrupt) stopped ``run``.

    A KeyboardInterrupt, so that a script looping over runs stops too, with a
    non-zero exit, unless it catches this on purpose.  ``partial`` is the
    ``Result`` of the events completed before the interrupt (status
    "interrupted"; its state is the one after the last completed event).
    """

    def __init__(self, partial: Result):
        super().__init__(f"run interrupted after {partial.n_events} completed events "
                         "(their Result is the exception's .partial)")
        self.partial = partial


def make_engine(scene: Scene, backend: str):
    """The engine of a backend name ("fortran" or "numpy")."""
    if backend == "numpy":
        return NumpyEngine(scene)
    if backend == "fortran":
        return FortranEngine(scene)
    raise SceneError(f"backend={backend!r} must be one of {BACKENDS}")


def run(
    scene: Scene,
    backend: str = "fortran",
    *,
    state: ChainState | None = None,
    progress: Callable[[Progress], None] | None = None,
    keep_partial: bool = False,
) -> Result:
    """Drive a prepared chain quasi-statically to the end of its run: the
    tilt to the avalanche, the pushed end to the onset of sliding (or to the
    loading's limit, ``max_events``, ...).  ``sliders.tilt`` is its alias.

    Parameters
    ----------
    scene : Scene
        The configured run.
    backend : {"fortran", "numpy"}
        The Fortran kernel or the NumPy reference; both give the same events.
    state : ChainState, optional
        Start from this state instead of preparing one (it is copied).
    progress : callable, optional
        Called with a ``Progress`` after every chunk of events.
    keep_partial : bool
        On Ctrl-C (KeyboardInterrupt, in the kernel or in ``progress``),
        return the completed events as a result of status "interrupted"
        instead of raising ``Interrupted`` (which carries them as
        ``.partial``).  The default raises: a loop over runs must stop.

    Returns
    -------
    Result
        Every completed rearrangement (drives: angles in radians or driver
        positions in g tau^2, ``Result.drive``; displacements in
        g tau^2, durations in tau), how the run ended (``status``) and the
        avalanche angle ``alpha_c`` (NaN unless it ended in the avalanche).

    Raises
    ------
    Interrupted
        On Ctrl-C, unless ``keep_partial``.
    SceneError
        If the run would need more memory than is available (``scene.memory_estimate``).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a sliders.Scene, not {type(scene).__name__}")
    check_memory(scene)
    started = time.perf_counter()
    engine, stopped = _to_the_end(lambda: make_engine(scene, backend))
    given = state
    state, stopped_preparing = _to_the_end(lambda: prepare(scene) if given is None else given.copy())

    relaxation = {"n_events": 0, "n_moved": 0, "slider_steps": 0}
    # Relax at alpha = 0 first: with xi > 0 the coupling may destabilise sliders.
    interrupted = Chunk(status.INTERRUPTED, {}, np.zeros(1, np.int64), np.zeros(0, np.int64),
                        np.zeros(0), message=INTERRUPTED_MESSAGE)
    if stopped or stopped_preparing:
        relax = interrupted
    else:
        try:
            relax = engine.advance(state, max_events=scene.max_events, relax_only=True)
        except KeyboardInterrupt:
            relax = interrupted
    if relax.status != status.RELAXED:
        result = _finish(scene, backend, relax.status, relax.message, math.nan, [], state, state,
                         relaxation, started, relax.final_event)
        return _interrupt_or_return(result, keep_partial)
    relaxation = {
        "n_events": relax.n_events,
        "n_moved": int(np.count_nonzero(state.displacement)),
        "slider_steps": int(relax.events["slider_steps"].sum()),
    }
    initial = state.copy()

    chunks: list[Chunk] = []
    final_event: dict = {}
    n_events = 0
    slider_steps = 0
    budget = chunk_events(scene, backend)
    while True:
        remaining = scene.max_events - n_events
        if remaining <= 0:
            code, message, alpha_c = status.MAX_EVENTS, "", math.nan
            break
        try:
            chunk = engine.advance(state, max_events=min(budget, remaining))
        except KeyboardInterrupt:
            # An engine that lets Ctrl-C through loses the chunk in flight (its
            # events were not returned); the completed events are what counts.
            code, message, alpha_c = status.INTERRUPTED, INTERRUPTED_MESSAGE, math.nan
            break
        chunks.append(chunk)
        n_events += chunk.n_events
        slider_steps += int(chunk.events["slider_steps"].sum())
        if progress is not None:
            try:
                progress(Progress(state.drive, n_events, time.perf_counter() - started,
                                  slider_steps))
            except KeyboardInterrupt:
                code, message, alpha_c = status.INTERRUPTED, INTERRUPTED_MESSAGE, math.nan
                break
        if chunk.status not in (status.RUNNING, status.SPARSE_FULL):
            code, message, alpha_c = chunk.status, chunk.message, chunk.alpha_c
            final_event = chunk.final_event
            break
    result, stopped = _to_the_end(lambda: _finish(scene, backend, code, message, alpha_c, chunks,
                                                  initial, state, relaxation, started,
                                                  final_event))
    if (stopped or getattr(engine, "interrupted_late", False)) and not keep_partial:
        raise Interrupted(result)  # Ctrl-C as the run ended: the whole run, never swallowed
    return _interrupt_or_return(result, keep_partial)


def _to_the_end(work: Callable[[], Any]) -> tuple[Any, bool]:
    """(work(), whether Ctrl-C landed in it).  For the milliseconds of Python
    around the engine (building it, drawing the chain, assembling the result):
    a Ctrl-C there lets ``work`` run again to the end (it has no side
    effects), and the caller then stops as if the engine had been
    interrupted, so that run always answers Ctrl-C with ``Interrupted``."""
    try:
        return work(), False
    except KeyboardInterrupt:
        return work(), True


def _interrupt_or_return(result: Result, keep_partial: bool) -> Result:
    if result.status == status.NAMES[status.INTERRUPTED]:
        if not result.message:
            result.message = INTERRUPTED_MESSAGE
        if not keep_partial:
            raise Interrupted(result)
    return result


def _finish(scene, backend, code, message, alpha_c, chunks, initial, final, relaxation, started,
            final_event):
    run = join_chunks(chunks, code)
    displacement = None
    if scene.record != "summary":
        displacement = EventSparse(run.sparse_ptr, run.sparse_index, run.sparse_displacement,
                                   scene.n_sliders)
    if not message and code in status.ERRORS:
        message = status.NAMES[code]
    return Result(
        scene=scene, backend=backend, status=status.NAMES[code], message=message,
        alpha_c=float(alpha_c), events=run.events, displacement=displacement,
        initial=initial, final=final, relaxation=relaxation,
        wall_time=time.perf_counter() - started, final_event=dict(final_event),
    )


def realisation_scene(scene: Scene, r: int) -> Scene:
    """Realisation ``r`` of an ensemble of ``scene``: its seed keyed by (scene.seed, r)."""
    return scene.replace(seed=realisation_seed(scene.seed, r))


def tilt_realisations(scene: Scene, runs: int, backend: str = "fortran", first: int = 0):
    """The serial ensemble loop: yields ``(r, Result)`` for realisations
    ``first`` .. ``first + runs - 1`` of ``scene`` (``realisation_scene``), the
    same runs as the rows of ``python -m sliders.ensemble``."""
    for r in range(first, first + runs):
        yield r, run(realisation_scene(scene, r), backend=backend)

