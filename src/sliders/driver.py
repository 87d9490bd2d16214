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
from typing import Callable

import numpy as np

from . import status
from .chain import ChainState
from .engine.contract import INTERRUPTED_MESSAGE, Chunk, join_chunks
from .keyed_random import realisation_seed
from .preparation import PreparationInterrupted, prepare, prepared_at_once
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
    PreparationInterrupted
        On Ctrl-C while a ``"history"`` preparation runs (no chain was made yet).
    SceneError
        If the run would need more memory than is available (``scene.memory_estimate``).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a sliders.Scene, not {type(scene).__name__}")
    loop = None
    try:
        loop = RunLoop(scene, backend, state, progress)
        loop.proceed()
        result = loop.result()
    except PreparationInterrupted:
        raise  # no chain to describe, and drawing it again would take as long
    except KeyboardInterrupt:
        # Ctrl-C in the Python around the engine (inside a call the engine answers
        # it): the run stops where it is and is described whole, its chain drawn
        # to the end if the interrupt came while it was drawn
        loop = loop or RunLoop(scene, backend, state, progress)
        loop.stop()
        result = loop.result()
    if loop.interrupted and not keep_partial:
        raise Interrupted(result)  # never swallowed: a loop over runs must stop too
    return result


_CONTINUING = (status.RUNNING, status.SPARSE_FULL)


class RunLoop:
    """One run's loop: build the engine, prepare and relax the chain, then drive
    the loading chunk by chunk until a chunk ends the run.  The loop owns its
    stop conditions (the run's end, ``max_events``, a Ctrl-C), and at any
    moment ``result`` describes the run so far, so that a Ctrl-C between two
    of its statements loses nothing.  Building one does no work.
    """

    def __init__(self, scene: Scene, backend: str, given: ChainState | None,
                 progress: Callable[[Progress], None] | None):
        self.scene, self.backend, self.given, self.progress = scene, backend, given, progress
        self.started = time.perf_counter()
        self.state: ChainState | None = None  # the chain as the engine leaves it
        self.initial: ChainState | None = None  # the relaxed chain the drive starts from
        self.relaxation = {"n_events": 0, "n_moved": 0, "slider_steps": 0}
        self.chunks: list[Chunk] = []  # the drive's engine calls, the last one ending the run
        self.end: tuple | None = None  # (status, message, alpha_c, final_event) once it ended
        self.interrupted = False  # a Ctrl-C reached the run (its result may still be whole)

    def proceed(self) -> None:
        """Run to the end: relax at alpha = 0, then drive in chunks of events."""
        scene = self.scene
        check_memory(scene)
        engine = make_engine(scene, self.backend)
        self.state = prepare(scene) if self.given is None else self.given.copy()
        # Relax at alpha = 0 first: with xi > 0 the coupling may destabilise sliders.
        relax = engine.advance(self.state, max_events=scene.max_events, relax_only=True)
        if relax.status != status.RELAXED:
            self.interrupted = relax.status == status.INTERRUPTED
            self.end = (relax.status, relax.message, math.nan, relax.final_event)
            return
        self.relaxation = {
            "n_events": relax.n_events,
            "n_moved": int(np.count_nonzero(self.state.displacement)),
            "slider_steps": int(relax.events["slider_steps"].sum()),
        }
        self.initial = self.state.copy()
        n_events = slider_steps = 0
        budget = chunk_events(scene, self.backend)
        while self.end is None:
            remaining = scene.max_events - n_events
            if remaining <= 0:
                self.end = (status.MAX_EVENTS, "", math.nan, {})
                break
            self.chunks.append(engine.advance(self.state, max_events=min(budget, remaining)))
            chunk = self.chunks[-1]
            n_events += chunk.n_events
            slider_steps += int(chunk.events["slider_steps"].sum())
            if self.progress is not None:
                self.progress(Progress(self.state.drive, n_events,
                                       time.perf_counter() - self.started, slider_steps))
            if chunk.status not in _CONTINUING:
                self.end = (chunk.status, chunk.message, chunk.alpha_c, chunk.final_event)
        # the engine's Ctrl-C that came as the run ended: the whole run, still interrupted
        self.interrupted = (self.end[0] == status.INTERRUPTED
                            or getattr(engine, "interrupted_late", False))

    def stop(self) -> None:
        """End the run here, on a Ctrl-C: the chain is drawn if it was not (unless
        drawing it is itself a run, ``PreparationInterrupted``), and a run whose
        last chunk had ended it keeps that end."""
        self.interrupted = True
        if self.state is None:
            if self.given is None and not prepared_at_once(self.scene):
                raise PreparationInterrupted(self.scene)
            check_memory(self.scene)
            self.state = prepare(self.scene) if self.given is None else self.given.copy()
        last = self.chunks[-1] if self.chunks else None
        if self.end is None and last is not None and last.status not in _CONTINUING:
            self.end = (last.status, last.message, last.alpha_c, last.final_event)
        if self.end is None:
            self.end = (status.INTERRUPTED, INTERRUPTED_MESSAGE, math.nan, {})

    def result(self) -> Result:
        """The run so far (it has ended: ``proceed`` returned or ``stop`` was called)."""
        code, message, alpha_c, final_event = self.end
        if code == status.INTERRUPTED and not message:
            message = INTERRUPTED_MESSAGE
        initial = self.initial if self.initial is not None else self.state
        return _finish(self.scene, self.backend, code, message, alpha_c, self.chunks, initial,
                       self.state, self.relaxation, self.started, final_event)


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

