"""The Fortran backend: ``sliders._kernel.tilt_advance`` behind the engine API.

``FortranEngine.advance`` has the contract of ``reference.NumpyEngine.advance``
(the specification): it mutates ``state.displacement``, ``state.mu_s``,
``state.n_stops`` and ``state.drive`` in place and returns a ``Chunk`` with the
same event fields and dtypes and the same sparse (CSR) layout.  The kernel is
``fortran/sliders_events.f90``; it reproduces the reference event by event.

Buffers.  The kernel writes into buffers owned by the engine (reused across
calls).  It stops before starting an event when the event buffer is full or,
when displacements are recorded, fewer than N sparse entries are free, and
returns ``SPARSE_FULL``; the driver calls again.  A relax-only call must end
``RELAXED``, so there the engine calls again itself and joins the pieces.

Interruption.  The kernel call releases the GIL and runs in a worker thread;
the calling thread waits in short waits, so Ctrl-C reaches it at once.  On
``KeyboardInterrupt`` the engine raises the kernel's interrupt flag, waits for
the kernel (it reads the flag every 1e5 slider-steps, well under a
millisecond) and returns a ``Chunk`` with status ``INTERRUPTED``: the events
completed in the call, the event in progress undone entirely (displacements,
draws, stop counts, drive), exactly as ``reference.NumpyEngine`` does.  Any
other exception arriving while it waits also stops the kernel first (the
state is then consistent) and is raised again.  A Ctrl-C handled in the Python
after the kernel returned is answered the same way: the kernel's events are in
the state already, so the chunk is built to the end, never lost.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from .. import keyed_random, status
from ..chain import ChainState
from ..scene import Scene
from .contract import (EVENT_FIELDS, INT_FIELDS, INTERRUPTED_MESSAGE, REAL_FIELDS, Chunk,
                       join_chunks, pack_parameters, refine_limit_message)

EVENT_CAPACITY = 4096  # event buffer of a relax-only call
MAX_EVENT_CAPACITY = 1 << 16  # events per kernel call, at most (4.7 MB of buffers)
_CONTRACT_MISMATCH = -1  # sliders_wrapper_tilt: the packed widths are not sliders_contract's
_DETAIL_RESTING, _DETAIL_STATE = 1, 2  # sliders_events: detail_resting, detail_state
_LAUNCH_GRACE = 1.0  # s: a started kernel thread announces itself well within this
_WAIT_SECONDS = 0.05  # the waiting thread wakes this often (signals reach it at once anyway)


def sparse_capacity(n_sliders: int) -> int:
    """Entries of the displacement buffer: room for at least 8 full events."""
    return max(8 * n_sliders, 4096) + n_sliders


class FortranEngine:
    """The compiled backend: same interface as ``reference.NumpyEngine``."""

    name = "fortran"

    def __init__(self, scene: Scene):
        from .. import _kernel  # the compiled extension (meson build)

        self.scene = scene
        self._tilt_advance = _kernel.tilt_advance
        self._record_sparse = scene.record != "summary"
        n = scene.n_sliders
        self._sparse_index = np.zeros(sparse_capacity(n) if self._record_sparse else 1, dtype=np.int64)
        self._sparse_value = np.zeros(self._sparse_index.size)
        self._capacity = 0
        self._event_real = self._event_int = self._sparse_ptr = None
        self._interrupt = np.zeros(1, dtype=np.int32)  # read by the kernel (VOLATILE)

    def _buffers(self, capacity: int) -> None:
        if capacity > self._capacity:
            self._capacity = capacity
            self._event_real = np.zeros((capacity, len(REAL_FIELDS)), order="F")
            self._event_int = np.zeros((capacity, len(INT_FIELDS)), dtype=np.int64, order="F")
            self._sparse_ptr = np.zeros(capacity + 1, dtype=np.int64)

    # -- public -----------------------------------------------------------
    def advance(self, state: ChainState, max_events: int, relax_only: bool = False) -> Chunk:
        """Run rearrangements until ``max_events`` are recorded or the run ends."""
        if not relax_only:
            return self._call(state, max_events, relax_only=False)
        pieces = []
        while True:  # a relaxation must end RELAXED (or in error): join the pieces
            try:
                piece = self._call(state, max_events, relax_only=True)
            except KeyboardInterrupt:
                if not pieces:
                    raise
                # between two calls: the pieces' events are in the state, so they are kept
                piece = join_chunks([], status.INTERRUPTED, message=INTERRUPTED_MESSAGE)
            pieces.append(piece)
            if piece.status != status.SPARSE_FULL:
                if len(pieces) == 1:
                    return piece
                return join_chunks(pieces, piece.status, piece.alpha_c, piece.message,
                                   piece.final_event)

    # -- one kernel call --------------------------------------------------
    def _call(self, state: ChainState, max_events: int, relax_only: bool) -> Chunk:
        sc = self.scene
        n = state.n_sliders
        if n != sc.n_sliders:
            raise ValueError(f"state has {n} sliders, scene.n_sliders={sc.n_sliders}")
        max_events = int(max(0, min(max_events, np.iinfo(np.int32).max)))
        self._buffers(EVENT_CAPACITY if relax_only else max(1, min(max_events, MAX_EVENT_CAPACITY)))

        e0, t0, w0 = state.elastic_force0, state.spring_extension0, state.cantilever_stretch0
        mu = np.ascontiguousarray(state.mu_s, dtype=np.float64)
        stops = np.ascontiguousarray(state.n_stops, dtype=np.int64)
        du = np.ascontiguousarray(state.displacement, dtype=np.float64)
        if t0.size != n + 1 or e0.size != n or w0.size != n or stops.size != n or du.size != n:
            raise ValueError("inconsistent ChainState array sizes")

        real_params, int_params = pack_parameters(sc, float(state.drive), self._record_sparse,
                                                  relax_only, max_events)
        chain0 = np.concatenate([e0, w0, t0]).astype(np.float64)  # the kernel's packed layout
        outcome: dict = {}
        args = (real_params, int_params, chain0, mu, stops, du, self._event_real, self._event_int,
                self._sparse_ptr, self._sparse_index, self._sparse_value, self._interrupt)
        try:
            self._interruptible(outcome, args)
            return self._chunk(state, outcome, mu, stops, du)
        except KeyboardInterrupt:
            if "value" not in outcome:
                raise  # the kernel never ran: nothing changed
            # Ctrl-C in the Python after the kernel: its events are in the state's
            # arrays already, so the chunk is built to the end (building it has no
            # other effect) and answers the interrupt like one inside the call
            outcome["pending"] = True
            return self._chunk(state, outcome, mu, stops, du)

    def _chunk(self, state: ChainState, outcome: dict, mu, stops, du) -> Chunk:
        """The kernel's outputs written back into ``state`` and returned as a Chunk."""
        sc = self.scene
        (drive, n_events, n_sparse, code, alpha_c, event_time, final_steps, final_slider_steps,
         detail) = outcome["value"]
        if code == _CONTRACT_MISMATCH:
            raise RuntimeError("Fortran kernel: its packed layout (sliders_contract.f90) is not "
                               "contract.py's; rebuild the extension")
        if outcome.get("pending"):
            code = self._answer_ctrl_c(int(code))
        # write back (no-ops when the state arrays were passed themselves)
        state.mu_s[:] = mu
        state.n_stops[:] = stops
        state.displacement[:] = du
        state.drive = float(drive)

        k = int(n_events)
        if code == status.SPARSE_FULL and k == 0:
            raise RuntimeError(
                f"Fortran kernel: the displacement buffer ({self._sparse_index.size} entries) "
                f"cannot hold one event of {state.n_sliders} sliders")
        events = {f: self._event_real[:k, j].copy() for j, f in enumerate(REAL_FIELDS)}
        events.update({f: self._event_int[:k, j].copy() for j, f in enumerate(INT_FIELDS)})
        events = {f: events[f] for f in EVENT_FIELDS}
        ptr = self._sparse_ptr[: k + 1].copy()
        m = int(n_sparse)
        return Chunk(
            int(code), events, ptr,
            self._sparse_index[:m].copy(), self._sparse_value[:m].copy(),
            float(alpha_c) if code == status.AVALANCHE else math.nan,
            _message(sc, int(code), int(detail), state.drive, float(event_time)),
            _final_event(float(event_time), int(final_steps), int(final_slider_steps)),
        )

    def _answer_ctrl_c(self, code: int) -> int:
        """The status of a call a Ctrl-C reached after the kernel stopped reading the flag.

        A call that stopped between events (its chunk is full, or the relaxation
        is done: no run's end) is INTERRUPTED, as the reference answers.  A run
        that had ended (avalanche, alpha_max, an error) keeps its status, and
        ``interrupted_late`` tells the driver to raise the interrupt still.
        """
        if code in (status.RUNNING, status.SPARSE_FULL, status.RELAXED):
            return status.INTERRUPTED
        if code != status.INTERRUPTED:
            self.interrupted_late = True
        return code

    def _interruptible(self, outcome: dict, args: tuple) -> None:
        """The kernel call in a worker thread; Ctrl-C raises the interrupt flag.

        Fills ``outcome``: "value" (the kernel's outputs) and "pending" (a
        Ctrl-C came while it ran), or raises the kernel's error.  A Ctrl-C is
        raised on only if the kernel never launched.
        """
        self._interrupt[0] = 0
        self.interrupted_late = False
        finished = threading.Event()
        launched = threading.Event()

        def kernel():
            launched.set()
            try:
                outcome["value"] = tuple(self._tilt_advance(*args))
            except BaseException as exc:  # handed to the calling thread
                outcome["error"] = exc
            finally:
                finished.set()

        worker = threading.Thread(target=kernel, name="sliders-kernel", daemon=True)
        pending = None
        try:
            worker.start()
        except BaseException as exc:
            # Ctrl-C inside start(): the thread may already run the kernel,
            # which writes into the state, so it must be stopped and waited
            # for (else the caller would save a state still changing); if it
            # never launched, nothing runs and the interrupt goes on up.
            self._interrupt[0] = 1
            pending = exc
            if not launched.wait(_LAUNCH_GRACE):
                raise
        # An Event, not Thread.join alone: a join interrupted by KeyboardInterrupt
        # can leave is_alive() False while the thread still runs.
        while True:
            try:
                if finished.wait(_WAIT_SECONDS):
                    worker.join()
                    break
            except BaseException as exc:  # Ctrl-C (or a signal handler's exception)
                self._interrupt[0] = 1
                pending = pending or exc
        if "error" in outcome:
            raise outcome["error"]
        if pending is not None and not isinstance(pending, KeyboardInterrupt):
            raise pending
        outcome["pending"] = pending is not None


def _final_event(duration: float, n_steps: int, slider_steps: int) -> dict:
    """The work of the event that ended the run unfinished (empty between
    events: the kernel reports zero steps then)."""
    if n_steps == 0:
        return {}
    return {"duration": duration, "n_steps": n_steps, "slider_steps": slider_steps}


def _message(sc: Scene, code: int, detail: int, drive: float, event_time: float) -> str:
    """The reference's messages for the error statuses."""
    if code == status.NON_FINITE:
        if detail == _DETAIL_RESTING:
            return "non-finite force in the resting chain"
        return f"non-finite state at {sc.loading.drive_label}={drive}"
    if code == status.EVENT_DURATION_CAP:
        return (f"rearrangement at {sc.loading.drive_label}={drive:.6f} still moving after "
                f"{event_time:.1f} tau (max_event_duration={sc.max_event_duration} tau)")
    if code == status.INTERRUPTED:
        return INTERRUPTED_MESSAGE
    if code == status.REFINE_LIMIT:
        return refine_limit_message(sc, drive)
    if code == status.RANDOM_FAILURE:
        return (f"static coefficient: no draw above mu_d={sc.mu_d} in "
                f"{keyed_random.MAX_ATTEMPTS} attempts "
                f"(mu_s_mean={sc.mu_s_mean}, sigma_mu={sc.sigma_mu})")
    return ""
