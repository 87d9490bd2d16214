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
        self.loading = scene.loading  # the scene's parts, asked with the scene's values
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

        undo = None
        try:  # around the whole loop: a Ctrl-C between two events is answered too
            while True:
                # everything one iteration may change, to undo it on Ctrl-C
                undo = (state.drive, state.displacement.copy(), state.mu_s.copy(),
                        state.n_stops.copy(), len(records), len(ptr), len(index))
                done = self._one_event(state, max_events, relax_only, records, ptr, index,
                                       disp, chunk)
                if done is not None:
                    return done
                undo = None  # the event is complete and recorded: it is kept
        except KeyboardInterrupt:
            if undo is not None:  # else it came between events: nothing to undo
                drive, du, mu, stops, n_records, n_ptr, n_index = undo
                state.drive = drive
                state.displacement[:], state.mu_s[:], state.n_stops[:] = du, mu, stops
                del records[n_records:], ptr[n_ptr:], index[n_index:], disp[n_index:]
            return chunk(status.INTERRUPTED, message=INTERRUPTED_MESSAGE)

    def _one_event(self, state, max_events, relax_only, records, ptr, index, disp, chunk):
        """One iteration of advance: a Chunk if the call ends, else None."""
        sc = self.scene
        elastic = elastic_force(state, sc.xi, sc.walls)
        if not np.all(np.isfinite(elastic)):
            return chunk(status.NON_FINITE, message="non-finite force in the resting chain")
        load, law = self.loading, self.friction
        force = load.tangential(elastic, load.weight(state.drive), state.drive, state.displacement)
        unstable = np.abs(force) > law.static_threshold(state.mu_s, load.normal(state.drive),
                                                        sc.force_tol)
        if unstable.any():  # relaxation (preparation with coupling)
            triggers = np.flatnonzero(unstable)
            directions = np.sign(force[triggers])
        elif relax_only:
            return chunk(status.RELAXED)
        else:
            if len(records) >= max_events:
                return chunk(status.RUNNING)
            angle, triggers, directions = load.next_instability(elastic, state.mu_s, state.drive,
                                                                state.displacement, sc.force_tol)
            if load.beyond_limit(angle):
                return chunk(status.ALPHA_MAX)
            state.drive = angle
        outcome = self._event(state, triggers, directions)
        if outcome.status != status.RUNNING:
            work = {k: outcome.record[k] for k in ("duration", "n_steps", "slider_steps")}
            if outcome.status == status.AVALANCHE:
                return chunk(status.AVALANCHE, alpha_c=state.drive, final_event=work)
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
        """Integrate one rearrangement from its triggers until every slider rests
        (or the run ends inside it)."""
        sc = self.scene
        event = _Rearrangement(self, state, triggers, directions)
        while event.moving.any():
            trial = event.refined_step()
            if trial is None:  # refine_tol below the step's resolution
                return event.unfinished(status.REFINE_LIMIT, refine_limit_message(sc, state.drive))
            if not (np.isfinite(trial[0]).all() and np.isfinite(trial[1]).all()):
                event.count_step(trial)
                return event.unfinished(status.NON_FINITE, f"non-finite state at {sc.loading.drive_label}={state.drive}")
            event.accept(trial)
            try:
                event.stop_and_start()
            except RuntimeError as exc:
                return event.unfinished(status.RANDOM_FAILURE, str(exc))
            if event.t > sc.max_event_duration:
                return event.unfinished(
                    status.EVENT_DURATION_CAP,
                    f"rearrangement at {sc.loading.drive_label}={state.drive:.6f} still moving after "
                    f"{event.t:.1f} tau (max_event_duration={sc.max_event_duration} tau)",
                )
            if self.loading.runaway(event.moving, event.direction, event.weight, event.friction,
                                    sc.walls):
                state.displacement[:] = event.du
                return event.unfinished(status.AVALANCHE)
        return event.finished()


class _Rearrangement:
    """One rearrangement in progress at a fixed drive: the moving sliders' state.

    The drive's terms (weight, normal, kinetic friction) are numbers here; a
    moving slider keeps its direction d while it runs, so its friction is
    -friction * d.  ``du``, ``v``, ``force`` and ``acc`` are the state at the
    end of the last accepted step.
    """

    def __init__(self, engine: NumpyEngine, state: ChainState, triggers, directions):
        sc, load, law = engine.scene, engine.loading, engine.friction
        self.scene, self.state, self.loading, self.law = sc, state, load, law
        n = state.n_sliders
        self.weight, self.normal = load.weight(state.drive), load.normal(state.drive)
        self.friction = law.kinetic_force(self.normal)
        self.threshold = law.static_threshold(state.mu_s, self.normal, sc.force_tol)
        self.drive = state.drive
        self.du_start = state.displacement.copy()
        self.du = self.du_start.copy()
        self.v = np.zeros(n)
        self.direction = np.zeros(n)
        self.moving = np.zeros(n, dtype=bool)
        self.moving[triggers] = True
        self.direction[triggers] = directions
        self.moved = self.moving.copy()
        self.force = self.tangential(self.du)
        self.acc = np.where(self.moving, self.force - self.friction * self.direction, 0.0)
        self.t = 0.0
        self.n_steps = self.slider_steps = self.n_stops = 0
        self.path = 0.0
        self.mu_start, self.stops_start = state.mu_s.copy(), state.n_stops.copy()

    def tangential(self, du):
        """Tangential force on every slider at displacements du."""
        sc = self.scene
        return self.loading.tangential(elastic_force(self.state, sc.xi, sc.walls, du),
                                       self.weight, self.drive, du)

    def substep(self, h):
        """Velocity-Verlet step of size h from (du, v, acc); only movers move.
        The trial is (du, v, force, h, acc) at its end."""
        moving, v, acc = self.moving, self.v, self.acc
        du1 = self.du + np.where(moving, v * h + 0.5 * acc * h * h, 0.0)
        force1 = self.tangential(du1)
        acc1 = np.where(moving, force1 - self.friction * self.direction, 0.0)
        v1 = np.where(moving, v + 0.5 * (acc + acc1) * h, 0.0)
        return du1, v1, force1, h, acc1

    def crossings(self, trial):
        """Mask of the sliders that cross in this trial (stop or start)."""
        v1, force1 = trial[1], trial[2]
        stops = self.moving & (self.direction * v1 < 0.0)
        starts = ~self.moving & (np.abs(force1) > self.threshold)
        return stops | starts

    def refined_step(self):
        """The next step: a full dt, or, when a slider crosses within it, the upper
        end of the crossing's bracket closed by bisection to refine_tol (only the
        sliders that crossed in the full step are tested).  None when the bracket
        cannot close within MAX_HALVINGS halvings."""
        sc = self.scene
        trial = self.substep(sc.dt)
        candidates = self.crossings(trial)
        if not candidates.any():
            return trial
        lo, hi = 0.0, sc.dt
        halvings = 0
        while hi - lo > sc.refine_tol:
            if halvings == MAX_HALVINGS:
                return None
            halvings += 1
            mid = 0.5 * (lo + hi)
            trial_mid = self.substep(mid)
            if self.crossings(trial_mid)[candidates].any():
                hi, trial = mid, trial_mid
            else:
                lo = mid
        return trial

    def count_step(self, trial) -> None:
        """Count an integration step (steps, slider-steps, the event clock)."""
        self.n_steps += 1
        self.slider_steps += int(np.count_nonzero(self.moving))
        self.t += trial[3]

    def accept(self, trial) -> None:
        """Take the step: counters, the path of the movers, the new state (its
        acceleration stands until a slider stops or starts)."""
        self.count_step(trial)
        du1, v1, force1, _, acc1 = trial
        self.path += float(np.add.reduce(np.where(self.moving, self.direction * (du1 - self.du),
                                                  0.0)))
        self.du, self.v, self.force, self.acc = du1, v1, force1, acc1

    def stop_and_start(self) -> None:
        """Stop the movers whose velocity changed sign (each draws its new static
        coefficient, RuntimeError if the draw fails), then start every resting
        slider beyond its threshold in the direction of its force."""
        state, moving, direction = self.state, self.moving, self.direction
        stops = (moving & (direction * self.v < 0.0)).nonzero()[0]
        if stops.size:
            self.n_stops += stops.size
            self.v[stops] = 0.0
            moving[stops] = False
            direction[stops] = 0.0
            state.n_stops[stops] += 1
            state.mu_s[stops] = self.law.draw_at_stop(self.scene.seed, stops, state.n_stops[stops])
            self.threshold[stops] = self.law.static_threshold(state.mu_s[stops], self.normal,
                                                              self.scene.force_tol)
        starts = (~moving & (np.abs(self.force) > self.threshold)).nonzero()[0]
        if starts.size:
            moving[starts] = True
            direction[starts] = np.sign(self.force[starts])
            self.moved[starts] = True
        if stops.size or starts.size:  # else the step's own acceleration stands
            self.acc = np.where(moving, self.force - self.friction * direction, 0.0)

    def unfinished(self, code, message="") -> _EventOutcome:
        """The event ends the run: its status and the work it did.  On an error
        the state is the one before the event (draws undone too)."""
        if code != status.AVALANCHE:
            self.state.mu_s[:], self.state.n_stops[:] = self.mu_start, self.stops_start
        record = {"duration": self.t, "n_steps": self.n_steps, "slider_steps": self.slider_steps}
        if message:
            record["message"] = message
        return _EventOutcome(code, record)

    def finished(self) -> _EventOutcome:
        """Every slider rests: the event's record, the state moved to its end."""
        sc, state, du = self.scene, self.state, self.du
        step = du - self.du_start
        record = {
            "drive": state.drive,
            "n_moved": int(self.moved.sum()),
            "n_stops": self.n_stops,
            "n_steps": self.n_steps,
            "slider_steps": self.slider_steps,
            "duration": self.t,
            "work_gravity": self.loading.work(self.weight, step, self.drive, self.du_start),
            "elastic_change": elastic_energy(state, sc.xi, sc.walls, du)
            - elastic_energy(state, sc.xi, sc.walls, self.du_start),
            "dissipation": self.friction * self.path,
        }
        state.displacement[:] = du
        moved_index = np.flatnonzero(self.moved)
        return _EventOutcome(status.RUNNING, record, moved_index, step[moved_index])
