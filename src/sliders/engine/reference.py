"""NumPy reference implementation of the quasi-static tilt, written for clarity.

This is the executable specification that the Fortran kernel
(``fortran/sliders_events.f90``) must reproduce event by event.  It favours
obviousness over speed: every step recomputes the force on every slider.

Algorithm (docs/model.md: the quasi-static tilt, keyed randomness, the avalanche):

* Between events nothing moves, so E_n = F_n - sin(alpha) is fixed and slider n
  destabilises at the smallest alpha' >= alpha with abs(E_n + sin a') = mu_n cos a'
  (closed form, ``next_instability``).  Tilt jumps there; every slider whose
  angle ties within ``TIE_TOL`` starts with it.
* An event integrates the moving sliders at fixed alpha with velocity Verlet.
  A moving slider has a fixed direction d = sign(F) while it runs, so its
  friction is -mu_d cos(alpha) d.  Crossings inside a step are a resting slider
  exceeding its threshold, abs(F) > mu cos(alpha) + force_tol, or a moving slider
  whose velocity changes sign, d v < 0.  When a step of size h crosses, the
  crossing is bracketed in [0, h] and the bracket is closed by bisection on
  the step size (each trial restarts from the start of the step) until its
  width is below ``refine_tol``; the step taken is the bracket's upper end.
  The bisection tests only the sliders that crossed in the full step (a
  slider that crosses and uncrosses within one step is not a crossing), so
  that the kernel's refinement costs O(crossers), not O(moving sliders).
* A stopping slider comes to rest (v = 0), increments its stop count k and
  draws mu_s(seed, n, k); if abs(F) still exceeds the new threshold it restarts
  at once in the direction of F.
* The bracket is halved at most ``MAX_HALVINGS`` times: a ``refine_tol``
  below what the step can resolve ends the run with ``REFINE_LIMIT`` (the
  event undone, as for the cap) instead of looping for ever.
* Ctrl-C (KeyboardInterrupt) inside ``advance`` undoes the event in progress
  entirely (displacements, draws, stop counts, alpha) and returns the events
  completed so far with status ``INTERRUPTED``.
* The event ends when every slider is at rest.  The avalanche is the paper's
  criterion: every slider is moving, all downwards, with tan(alpha) > mu_d so
  that the centre of mass accelerates.  An event longer than
  ``max_event_duration`` (tau) stops the run with its own status.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import status
from ..chain import ChainState, elastic_energy, elastic_force
from ..scene import Scene
from .contract import (INTERRUPTED_MESSAGE, MAX_HALVINGS, Chunk, events_from_records,
                       refine_limit_message)
# next_instability, TIE_TOL and TRANSCENDENTALS live with the tilt loading;
# re-exported here for the callers and tests that import them from the reference.
from .loading import TIE_TOL, TRANSCENDENTALS, next_instability  # noqa: F401


@dataclass
class _EventOutcome:
    status: int
    record: dict = field(default_factory=dict)
    moved_index: np.ndarray | None = None
    moved_displacement: np.ndarray | None = None


class NumpyEngine:
    """The reference backend: same interface as the Fortran one."""

    name = "numpy"

    def __init__(self, scene: Scene):
        self.scene = scene
        self.loading = scene.loading  # the scene's parts, bound to it
        self.friction = scene.friction

    # -- public -----------------------------------------------------------
    def advance(self, state: ChainState, max_events: int, relax_only: bool = False) -> Chunk:
        """Run rearrangements until ``max_events`` are recorded or the run ends."""
        sc = self.scene
        records: list[dict] = []
        ptr, index, disp = [0], [], []

        def chunk(code, alpha_c=math.nan, message="", final_event=None):
            events = events_from_records(records)
            return Chunk(
                code, events, np.array(ptr, dtype=np.int64),
                np.array(np.concatenate(index) if index else [], dtype=np.int64),
                np.array(np.concatenate(disp) if disp else [], dtype=float),
                alpha_c, message, dict(final_event or {}),
            )

        while True:
            # everything one iteration may change, to undo it on Ctrl-C
            undo = (state.alpha, state.displacement.copy(), state.mu_s.copy(),
                    state.n_stops.copy(), len(records), len(ptr), len(index))
            try:
                done = self._one_event(state, max_events, relax_only, records, ptr, index,
                                       disp, chunk)
            except KeyboardInterrupt:
                alpha, du, mu, stops, n_records, n_ptr, n_index = undo
                state.alpha = alpha
                state.displacement[:], state.mu_s[:], state.n_stops[:] = du, mu, stops
                del records[n_records:], ptr[n_ptr:], index[n_index:], disp[n_index:]
                return chunk(status.INTERRUPTED, message=INTERRUPTED_MESSAGE)
            if done is not None:
                return done

    def _one_event(self, state, max_events, relax_only, records, ptr, index, disp, chunk):
        """One iteration of advance: a Chunk if the call ends, else None."""
        sc = self.scene
        elastic = elastic_force(state, sc.xi, sc.walls)
        if not np.all(np.isfinite(elastic)):
            return chunk(status.NON_FINITE, message="non-finite force in the resting chain")
        load, law = self.loading, self.friction
        force = load.tangential(elastic, load.weight(state.alpha), state.alpha, state.displacement)
        unstable = np.abs(force) > law.static_threshold(state.mu_s, load.normal(state.alpha))
        if unstable.any():  # relaxation (preparation with coupling)
            triggers = np.flatnonzero(unstable)
            directions = np.sign(force[triggers])
        elif relax_only:
            return chunk(status.RELAXED)
        else:
            if len(records) >= max_events:
                return chunk(status.RUNNING)
            angle, triggers, directions = load.next_instability(elastic, state.mu_s, state.alpha,
                                                                state.displacement)
            if load.beyond_limit(angle):
                return chunk(status.ALPHA_MAX)
            state.alpha = angle
        outcome = self._event(state, triggers, directions)
        if outcome.status != status.RUNNING:
            work = {k: outcome.record[k] for k in ("duration", "n_steps", "slider_steps")}
            if outcome.status == status.AVALANCHE:
                return chunk(status.AVALANCHE, alpha_c=state.alpha, final_event=work)
            return chunk(outcome.status, message=outcome.record.get("message", ""),
                         final_event=work)
        records.append(outcome.record)
        if sc.record != "summary":
            index.append(outcome.moved_index)
            disp.append(outcome.moved_displacement)
            ptr.append(ptr[-1] + outcome.moved_index.size)
        else:
            ptr.append(0)
        if load.spanning_ends_run() and not relax_only and outcome.record["n_moved"] == sc.n_sliders:
            return chunk(status.SLIDING)  # the onset drive is the last event's
        return None

    # -- one rearrangement ------------------------------------------------
    def _event(self, state: ChainState, triggers, directions) -> _EventOutcome:
        sc = self.scene
        n = state.n_sliders
        load, law = self.loading, self.friction
        # the drive is fixed during an event: its terms are numbers here
        weight, normal = load.weight(state.alpha), load.normal(state.alpha)
        friction = law.kinetic_force(normal)
        threshold = law.static_threshold(state.mu_s, normal)

        du_start = state.displacement.copy()
        du = du_start.copy()
        v = np.zeros(n)
        direction = np.zeros(n)
        moving = np.zeros(n, dtype=bool)
        moving[triggers] = True
        direction[triggers] = directions
        moved = moving.copy()
        drive = state.alpha
        force = load.tangential(elastic_force(state, sc.xi, sc.walls, du), weight, drive, du)
        acc = np.where(moving, force - friction * direction, 0.0)

        def substep(h):
            """Velocity-Verlet step of size h from (du, v, acc); only movers move."""
            du1 = du + np.where(moving, v * h + 0.5 * acc * h * h, 0.0)
            force1 = load.tangential(elastic_force(state, sc.xi, sc.walls, du1), weight, drive, du1)
            acc1 = np.where(moving, force1 - friction * direction, 0.0)
            v1 = np.where(moving, v + 0.5 * (acc + acc1) * h, 0.0)
            return du1, v1, force1

        def crossings(trial):
            """Mask of the sliders that cross in this trial (stop or start)."""
            _, v1, force1 = trial
            stops = moving & (direction * v1 < 0.0)
            starts = ~moving & (np.abs(force1) > threshold)
            return stops | starts

        t = 0.0
        n_steps = slider_steps = n_stops = 0
        path = 0.0

        mu_start, stops_start = state.mu_s.copy(), state.n_stops.copy()

        def unfinished(code, message=""):
            """The event ends the run: its status and the work it did.  On an
            error the state is the one before the event (draws undone too)."""
            if code != status.AVALANCHE:
                state.mu_s[:], state.n_stops[:] = mu_start, stops_start
            record = {"duration": t, "n_steps": n_steps, "slider_steps": slider_steps}
            if message:
                record["message"] = message
            return _EventOutcome(code, record)

        while moving.any():
            h = sc.dt
            trial = substep(h)
            candidates = crossings(trial)
            if candidates.any():
                lo, hi = 0.0, h
                halvings = 0
                while hi - lo > sc.refine_tol:
                    if halvings == MAX_HALVINGS:  # refine_tol below the step's resolution
                        return unfinished(status.REFINE_LIMIT,
                                          refine_limit_message(sc, state.alpha))
                    halvings += 1
                    mid = 0.5 * (lo + hi)
                    trial_mid = substep(mid)
                    if crossings(trial_mid)[candidates].any():
                        hi, trial = mid, trial_mid
                    else:
                        lo = mid
                h = hi
            du1, v1, force1 = trial
            n_steps += 1
            slider_steps += int(moving.sum())
            t += h
            if not (np.all(np.isfinite(du1)) and np.all(np.isfinite(v1))):
                return unfinished(status.NON_FINITE, f"non-finite state at alpha={state.alpha}")
            path += float(np.sum(np.where(moving, direction * (du1 - du), 0.0)))
            du, v, force = du1, v1, force1

            stops = np.flatnonzero(moving & (direction * v < 0.0))
            if stops.size:
                n_stops += stops.size
                v[stops] = 0.0
                moving[stops] = False
                direction[stops] = 0.0
                state.n_stops[stops] += 1
                try:
                    state.mu_s[stops] = law.draw_at_stop(stops, state.n_stops[stops])
                except RuntimeError as exc:
                    return unfinished(status.RANDOM_FAILURE, str(exc))
                threshold[stops] = law.static_threshold(state.mu_s[stops], normal)
            starts = np.flatnonzero(~moving & (np.abs(force) > threshold))
            moving[starts] = True
            direction[starts] = np.sign(force[starts])
            moved[starts] = True
            acc = np.where(moving, force - friction * direction, 0.0)

            if t > sc.max_event_duration:
                return unfinished(
                    status.EVENT_DURATION_CAP,
                    f"rearrangement at alpha={state.alpha:.6f} still moving after "
                    f"{t:.1f} tau (max_event_duration={sc.max_event_duration} tau)",
                )
            if load.runaway(moving, direction, weight, friction):
                state.displacement[:] = du
                return unfinished(status.AVALANCHE)

        step = du - du_start
        record = {
            "alpha": state.alpha,
            "n_moved": int(moved.sum()),
            "n_stops": n_stops,
            "n_steps": n_steps,
            "slider_steps": slider_steps,
            "duration": t,
            "work_gravity": load.work(weight, step, drive, du_start),
            "elastic_change": elastic_energy(state, sc.xi, sc.walls, du)
            - elastic_energy(state, sc.xi, sc.walls, du_start),
            "dissipation": friction * path,
        }
        state.displacement[:] = du
        moved_index = np.flatnonzero(moved)
        return _EventOutcome(status.RUNNING, record, moved_index, step[moved_index])
