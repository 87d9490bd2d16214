"""Run status codes, shared with the Fortran kernel (fortran/sliders_status.f90)."""

from __future__ import annotations

RUNNING = 0  # the chunk's event budget is used up; call again
AVALANCHE = 1  # every slider slides downwards with tan(alpha) > mu_d
ALPHA_MAX = 2  # the next rearrangement would be beyond scene.alpha_max
MAX_EVENTS = 3  # scene.max_events rearrangements recorded
EVENT_DURATION_CAP = 4  # one rearrangement lasted longer than scene.max_event_duration
NON_FINITE = 5  # a NaN or infinity appeared in the state
RANDOM_FAILURE = 6  # no static coefficient above mu_d could be drawn
RELAXED = 7  # relax-only call: the chain is at rest at the current angle
SPARSE_FULL = 8  # the displacement buffer filled mid-chunk (call again)
INTERRUPTED = 9  # Ctrl-C/SIGTERM; the event in progress is undone, the completed ones kept
REFINE_LIMIT = 10  # a crossing bracket stayed wider than refine_tol after MAX_HALVINGS halvings
SLIDING = 11  # pushed_end: every slider moved in the last event, the onset of sliding

NAMES = {
    RUNNING: "running",
    AVALANCHE: "avalanche",
    ALPHA_MAX: "alpha_max",
    MAX_EVENTS: "max_events",
    EVENT_DURATION_CAP: "event_duration_cap",
    NON_FINITE: "non_finite",
    RANDOM_FAILURE: "random_failure",
    RELAXED: "relaxed",
    SPARSE_FULL: "sparse_full",
    INTERRUPTED: "interrupted",
    REFINE_LIMIT: "refine_limit",
    SLIDING: "sliding",
}

FINAL_OK = {AVALANCHE, ALPHA_MAX, MAX_EVENTS, SLIDING}
ERRORS = {EVENT_DURATION_CAP, NON_FINITE, RANDOM_FAILURE, REFINE_LIMIT}
