!> Run status codes of the sliders kernel.
!>
!> Exactly the codes of src/sliders/status.py (the Python side is the
!> reference; tests/test_backends.py checks that both agree).
module sliders_status
  use sliders_kinds, only: ip
  implicit none
  private

  public :: status_running, status_avalanche, status_alpha_max, status_max_events
  public :: status_event_duration_cap, status_non_finite, status_random_failure
  public :: status_relaxed, status_sparse_full, status_interrupted, status_refine_limit
  public :: status_sliding

  !> The chunk's event budget is used up; call again.
  integer(ip), parameter :: status_running = 0
  !> Every slider slides downwards with tan(alpha) > mu_d.
  integer(ip), parameter :: status_avalanche = 1
  !> The next rearrangement would be beyond alpha_max.
  integer(ip), parameter :: status_alpha_max = 2
  !> max_events rearrangements recorded (set by the driver, not the kernel).
  integer(ip), parameter :: status_max_events = 3
  !> One rearrangement lasted longer than max_event_duration.
  integer(ip), parameter :: status_event_duration_cap = 4
  !> A NaN or infinity appeared in the state.
  integer(ip), parameter :: status_non_finite = 5
  !> No static coefficient above mu_d could be drawn.
  integer(ip), parameter :: status_random_failure = 6
  !> Relax-only call: the chain is at rest at the current angle.
  integer(ip), parameter :: status_relaxed = 7
  !> The event or displacement buffer is full (call again).
  integer(ip), parameter :: status_sparse_full = 8
  !> The caller raised the interrupt flag (Ctrl-C): the event in progress is
  !> undone, the completed events are kept.
  integer(ip), parameter :: status_interrupted = 9
  !> A crossing's bracket was still wider than refine_tol after the bounded
  !> number of halvings (refine_tol below what the step can resolve).
  integer(ip), parameter :: status_refine_limit = 10
  !> Pushed end: every slider moved in the last event, the onset of sliding.
  integer(ip), parameter :: status_sliding = 11

end module sliders_status
