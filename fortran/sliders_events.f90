!> The quasi-static loading: next-instability drives, one rearrangement, the
!> loading loop.
!>
!> The loading (sliders_loading) gives the drive's terms: the tilt's sin/cos
!> alpha, or for the pushed end sin/cos of the fixed tilt plus the driver's
!> spring on slider 1 (sliders_chain's tangential_force, used wherever a
!> slider's tangential force is formed: between events, at an event's start,
!> for the pool, and for slider 1 in end_sliders).  "alpha" below is the drive
!> lambda: the tilt, or the driver's position.
!>
!> This is src/sliders/engine/reference.py (the specification) reorganised so that
!> the cost follows what moves ("integrate only what moves"):
!>
!> * Per integration step only the *active* sliders (the moving ones and
!>   their neighbours) have their force computed and their threshold checked;
!>   they are kept as runs of consecutive sliders, merged into spans across
!>   short gaps of pool sliders (which ride along with threshold +inf), so
!>   that the step is, per span, two branch-free loops over contiguous
!>   memory (vectorised): predict (and, per run, the mean's sums when xi >
!>   0), then force + velocity + crossing test (step_spans, one call for all
!>   spans).  A resting slider has v = acc = 0, so the Verlet update leaves
!>   it in place.  The steps between two crossings are taken in one call
!>   (quiet_steps), the trial and state arrays (ws%du, v, acc and their
!>   trial twins; both agree outside the spans) swapping roles from step to
!>   step; the caller's du is written at the end of the event.  The
!>   *involved* sliders (every slider active at some point of the event) are
!>   remembered for the bookkeeping at the end of the event.  The sum of du is
!>   kept incrementally during an event (recomputed exactly between events).
!> * Every other slider (resting, not active: the "pool") has a fixed force
!>   when xi = 0; when xi > 0 they all feel the same shift
!>   s = xi (mean(du) - mean at event start).  The pool is tested through two
!>   scalars, the minima over it of  gap+ = thr - (F - s)  and
!>   gap- = thr + (F - s)  (thr = mu cos(a) + force_tol, F and s taken when
!>   the slider joined the pool): a pool slider crosses when s > gap+ or
!>   -s > gap-.  A minimum is rescanned (O(N), rare: at most twice per start)
!>   only when its slider leaves the pool.  A pool slider crossing is a start
!>   like any other (it enters the bisection predicate).  A slider already
!>   beyond its threshold at the start of an event is caught the same way.
!> * The instability angle of every slider is cached.  With xi = 0 only the
!>   involved sliders of the last event have their elastic force and angle
!>   recomputed, and the next angle comes from a min-tree (tree_next,
!>   O(log N) per changed slider); the stability check after an event covers
!>   the involved sliders only, and the pool needs no thresholds (its forces
!>   never change), so an event costs O(involved log N), not O(N).  With
!>   xi > 0 every elastic force shifts in every event, so every angle
!>   changes: coupled_next bounds them all without asin and computes the
!>   exact angles of the few that can be the next (hypot(1, mu) and atan(mu)
!>   are cached, renewed only for the involved sliders, whose mu may change).
!> * A step that crosses is cut back by bisection, whose trials test only the
!>   sliders that crossed in the full step (and their neighbours' positions;
!>   with xi > 0 the mean through a rigorous enclosure, exactly only when
!>   the enclosure leaves the test open): a crossing costs two full trials
!>   plus O(crossers) per bisection trial, not O(active) per trial, which was
!>   quadratic in the number of moving sliders for the large late events.
!>   The runs are then updated from the old runs and the starts
!>   (update_runs), not rescanned over the event's whole range.
!> * Every loop is bounded: the bisection by max_halvings
!>   (status_refine_limit), an event by max_event_duration in tau
!>   (every step advances by at least refine_tol/2), the call by max_events
!>   and its buffers; and another thread can stop the call at once through
!>   the VOLATILE interrupt flag (status_interrupted, the event undone).
!> * The elastic energy change of an event is computed locally
!>   (sliders_chain), exactly; the path length (dissipation) telescopes to
!>   the sum over sliding phases of |du at stop - du at start|.
!>
!> With xi > 0 some O(N) work between events (stability check, angle
!> bounds, gaps, exact sum) stays: 4 % of N = 1e4 to the avalanche; per
!> integration step no O(N) work is done.  Same operations in
!> the same order as the reference wherever it matters for rounding (forces,
!> Verlet update, crossing tests); the remaining differences (libm, order of
!> sums) are at the last-bit level.
module sliders_events
  use, intrinsic :: ieee_arithmetic, only: ieee_value, &
                                           ieee_positive_inf, ieee_quiet_nan
  use sliders_kinds, only: dp, ip, i8
  use sliders_status, only: status_running, status_avalanche, status_alpha_max, &
                            status_event_duration_cap, status_non_finite, &
                            status_random_failure, status_relaxed, status_sparse_full, &
                            status_interrupted, status_refine_limit, status_sliding
  use sliders_chain, only: chain_params, elastic_force, tangential_force, total_displacement, &
                           spring_energy_change, cantilever_energy_change
  use sliders_contract, only: ev_alpha, ev_duration, ev_work_gravity, ev_elastic_change, &
                              ev_dissipation, ev_n_moved, ev_n_stops, ev_n_steps, ev_slider_steps
  use sliders_friction, only: static_threshold, kinetic_force, draw_at_stop
  use sliders_loading, only: loading_params, drive_terms, loading_work, loading_runaway, &
                             beyond_limit, spanning_ends_run, pushed_next, tilt_root_cache, &
                             roots_from, root_lower_bounds, tie_tol
  use sliders_contract, only: loading_pushed_end
  implicit none
  private

  public :: tilt_params, tilt_run
  public :: max_halvings, interrupt_check_steps
  public :: detail_none, detail_resting, detail_state

  !> A crossing's bracket is halved at most this often (reference.MAX_HALVINGS):
  !> a step of 1 tau closes to 3e-39 within it, so only a refine_tol below
  !> what the step can resolve reaches it (status_refine_limit, never a hang).
  integer(ip), parameter :: max_halvings = 128
  !> The interrupt flag is read after this many slider-steps (~0.3 ms) and
  !> before every event.
  integer(i8), parameter :: interrupt_check_steps = 100000_i8
  !> Runs separated by at most this many pool sliders are integrated as one
  !> span (one loop): a pool slider inside a loop costs less than a loop's
  !> start and end (measured: benchmarks/kernel_speed.py).
  integer(ip), parameter :: span_gap = 16
  !> quiet_steps stores the forces (which only a crossing reads) in its first
  !> this many steps: a crossing that comes later pays one trial again, less
  !> than the stores it saved (about 5 % of a trial each).
  integer(ip), parameter :: keep_forces_steps = 32

  !> What a non-finite status refers to (for the message).
  integer(ip), parameter :: detail_none = 0, detail_resting = 1, detail_state = 2

  !> Everything of the scene the kernel uses.  No defaults: every field is
  !> set from the packed parameters (contract.py, from the scene's defaults).
  type :: tilt_params
    type(chain_params) :: chain
    type(loading_params) :: loading   !< the drive lambda ("alpha" here) and its end
    real(dp) :: mu_d
    real(dp) :: mu_s_mean
    real(dp) :: sigma_mu
    integer(i8) :: seed
    real(dp) :: dt
    real(dp) :: refine_tol
    real(dp) :: max_event_duration
    real(dp) :: force_tol
    logical :: record_sparse    !< store the moved sliders' displacements
    logical :: relax_only       !< only relax at the current angle
    integer(ip) :: max_events   !< events to record in this call
  end type tilt_params

  !> Work arrays of one tilt_run call (allocated once per call, sized n).
  !> Between events: du_start = du_t = du, v = acc = dir = 0, nmov = 0,
  !> nothing active, involved or moved; `elastic` and the roots up to date.
  !> A slider moves iff dir /= 0 (+1 down, -1 up).
  type :: workspace
    real(dp), allocatable :: elastic(:)      !< E_i at rest (cache)
    real(dp), allocatable :: root_down(:)    !< instability angle downwards
    real(dp), allocatable :: root_up(:)      !< instability angle upwards
    real(dp), allocatable :: radius(:)       !< hypot(1, mu) (cache)
    real(dp), allocatable :: phi(:)          !< atan(mu) (cache)
    real(dp), allocatable :: du_start(:)     !< du at the start of the event
    real(dp), allocatable :: du(:)           !< du during an event (the caller's du is
                                             !< written at its end): accepted state
    real(dp), allocatable :: du_t(:)         !< trial du (== du unless active)
    real(dp), allocatable :: du_phase(:)     !< du when the slider last started
    real(dp), allocatable :: v(:), acc(:), dir(:)
    real(dp), allocatable :: v_t(:), acc_t(:)
    real(dp), allocatable :: f_t(:)          !< force F of the active sliders, trial
    real(dp), allocatable :: thr(:)          !< mu cos(a) + force_tol (+inf in the pool)
    real(dp), allocatable :: gap_plus(:)     !< pool: thr - (F - s) on joining it
    real(dp), allocatable :: gap_minus(:)    !< pool: thr + (F - s) on joining it
    real(dp), allocatable :: mu_new(:)
    logical, allocatable :: active(:), involved(:), moved(:)
    logical, allocatable :: redrawn(:)       !< stopped (mu redrawn) in this event
    real(dp), allocatable :: mu_start(:)     !< mu at the event start, if redrawn
    integer(i8), allocatable :: stops_start(:)  !< stop count at the event start, if redrawn
    integer(ip), allocatable :: nmov(:)      !< moving sliders among i-1, i, i+1
    integer(ip), allocatable :: ilist(:)     !< involved sliders (unordered)
    integer(ip), allocatable :: slist(:)     !< triggers / starts of one step
    integer(ip), allocatable :: cand(:)      !< sliders that crossed in a full step
    real(dp), allocatable :: sdir(:)         !< their directions
    integer(ip), allocatable :: stops(:)     !< stops of one step
    integer(ip), allocatable :: sorted(:)    !< moved sliders, increasing
    integer(ip), allocatable :: run_lo(:), run_hi(:)  !< runs of active sliders
    integer(ip), allocatable :: span_lo(:), span_hi(:)  !< the runs merged across short gaps
    integer(ip), allocatable :: seg_lo(:), seg_hi(:)  !< where update_runs looks
    integer(ip), allocatable :: changed(:)   !< sliders the tilt loop checks (increasing): all, or the last event's (xi = 0)
    real(dp), allocatable :: tree(:)         !< min-tree of min(root_down, root_up) (xi = 0)
    real(dp), allocatable :: bound(:)        !< lower bounds of the angles (xi > 0)
    integer(ip) :: leaves = 0                !< its number of leaves (a power of 2 >= n)
    integer(ip) :: n_changed = 0
    real(dp) :: cos_a = 1.0_dp               !< cos(alpha) of the current event
    real(dp) :: force_tol = 0.0_dp
    integer(ip) :: n_runs = 0
    integer(ip) :: n_spans = 0
    integer(ip) :: m = 0                     !< number of moving sliders
    integer(ip) :: ni = 0                    !< number of involved sliders
    integer(ip) :: n_down = 0                !< moving sliders with dir > 0
    integer(ip) :: i_lo = 0, i_hi = 0        !< range of the involved sliders
    real(dp) :: sum_du = 0.0_dp              !< sum of du at rest (exact loop)
    real(dp) :: dsum = 0.0_dp                !< sum of du - du_start, in the event
    real(dp) :: path = 0.0_dp                !< path length of the event so far
    real(dp) :: min_plus = 0.0_dp, min_minus = 0.0_dp  !< pool gap minima
    integer(ip) :: arg_plus = 0, arg_minus = 0         !< where (0: empty pool)
    logical :: stale = .false.               !< a minimum's slider left the pool
    !> Sums over the active sliders at the start of a crossing step (xi > 0:
    !> candidate_trial's enclosure of the trial mean): v, acc, |du|, |v|,
    !> |acc|, and how many sliders.
    real(dp) :: sum_v = 0.0_dp, sum_acc = 0.0_dp
    real(dp) :: abs_du = 0.0_dp, abs_v = 0.0_dp, abs_acc = 0.0_dp
    integer(ip) :: n_active = 0
  end type workspace

  !> What one event produced.
  type :: event_record
    integer(ip) :: status = status_running
    integer(ip) :: detail = detail_none
    integer(i8) :: n_moved = 0, n_stops = 0, n_steps = 0, slider_steps = 0
    real(dp) :: duration = 0.0_dp, work_gravity = 0.0_dp
    real(dp) :: elastic_change = 0.0_dp, dissipation = 0.0_dp
  end type event_record

contains

  ! ------------------------------------------------------------------ angles

  !> Smallest angle >= alpha at which a resting slider destabilises, and the
  !> sliders within tie_tol of it (increasing order, into ws%slist, their
  !> directions into ws%sdir), when every elastic force changed (xi > 0):
  !> exactly min over i of max(min(root_down, root_up), alpha), with asin
  !> evaluated only where it can matter.  A lower bound of every slider's
  !> angle (root_lower_bound, a polynomial: vectorised) and one exact angle,
  !> at the smallest bound, give a limit; only the sliders whose bound is
  !> below it can be the minimum or tie with it, and only they get their
  !> exact roots (roots_from).  Same angle, same triggers, as the full scan.
  subroutine coupled_next(ws, n, alpha, angle, n_trig)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: alpha
    real(dp), intent(out) :: angle
    integer(ip), intent(out) :: n_trig
    integer(ip) :: i, k, n_cand
    real(dp) :: limit

    angle = ieee_value(angle, ieee_positive_inf)
    n_trig = 0
    call root_lower_bounds(n, ws%elastic, ws%radius, ws%phi, alpha, ws%bound)
    i = minloc(ws%bound(1:n), 1)
    if (.not. ws%bound(i) <= huge(1.0_dp)) return     ! no root in [0, pi/2]
    call roots_from(ws%elastic(i), ws%radius(i), ws%phi(i), ws%root_down(i), ws%root_up(i))
    limit = max(min(ws%root_down(i), ws%root_up(i)), alpha) + tie_tol
    n_cand = 0
    do i = 1, n
      if (ws%bound(i) <= limit) then
        n_cand = n_cand + 1
        ws%cand(n_cand) = i
      end if
    end do
    !GCC$ novector
    do k = 1, n_cand     ! scalar asin: glibc's, as the reference's libm substitute
      i = ws%cand(k)
      call roots_from(ws%elastic(i), ws%radius(i), ws%phi(i), ws%root_down(i), ws%root_up(i))
      angle = min(angle, max(min(ws%root_down(i), ws%root_up(i)), alpha))
    end do
    do k = 1, n_cand
      i = ws%cand(k)
      if (max(min(ws%root_down(i), ws%root_up(i)), alpha) <= angle + tie_tol) then
        n_trig = n_trig + 1
        ws%slist(n_trig) = i
        if (ws%root_down(i) <= ws%root_up(i)) then
          ws%sdir(n_trig) = 1.0_dp
        else
          ws%sdir(n_trig) = -1.0_dp
        end if
      end if
    end do
  end subroutine coupled_next

  ! -------------------------------------------------------------- tilt loop

  !> Rearrangements from the state (mutated in place) until `max_events` are
  !> recorded or the run ends: reference.NumpyEngine.advance.
  !>
  !> Per event k (1-based): ev_real(k, ev_*) and ev_int(k, ev_*); with
  !> record_sparse the moved sliders (0-based, increasing) and their
  !> displacements are sp_index/sp_value(sp_ptr(k)+1 : sp_ptr(k+1)), else
  !> sp_ptr stays 0.  Before starting an event the call returns
  !> status_sparse_full if the event buffer is full or, with record_sparse,
  !> fewer than n sparse entries are free.  `event_time` is the duration of
  !> the event that ended the run unfinished (the avalanche, the duration
  !> cap, a non-finite state), `final_work` its integration steps and
  !> slider-steps (zero otherwise); `detail` says what a non-finite status
  !> refers to.  A nonzero interrupt(1) (set by another thread: VOLATILE)
  !> ends the call with status_interrupted within interrupt_check_steps
  !> slider-steps: the event in progress is undone entirely (du, mu, stop
  !> counts, and alpha back to the last completed event), the completed
  !> events are kept.
  subroutine tilt_run(params, e0, t0, w0, mu, n_stops, du, alpha, ev_real, ev_int, &
                      sp_ptr, sp_index, sp_value, n_events, n_sparse, status, &
                      alpha_c, event_time, final_work, detail, interrupt)
    type(tilt_params), intent(in) :: params
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), intent(inout) :: alpha
    real(dp), intent(inout) :: ev_real(:, :)
    integer(i8), intent(inout) :: ev_int(:, :)
    integer(i8), contiguous, intent(inout) :: sp_ptr(:)
    integer(i8), contiguous, intent(inout) :: sp_index(:)
    real(dp), contiguous, intent(inout) :: sp_value(:)
    integer(ip), intent(out) :: n_events, n_sparse, status
    real(dp), intent(out) :: alpha_c, event_time
    integer(i8), intent(out) :: final_work(2)
    integer(ip), intent(out) :: detail
    integer(ip), volatile, intent(inout) :: interrupt(:)   ! only read
    type(tilt_params) :: p       ! params, with the pushed end's driver at the drive
    type(workspace) :: ws
    type(event_record) :: rec
    integer(ip) :: n, i, n_trig, j, n_bad, k
    real(dp) :: sin_a, cos_a, f, angle, alpha_done
    logical :: coupled, pushed

    p = params
    n = p%chain%n
    pushed = p%loading%protocol == loading_pushed_end
    coupled = p%chain%xi /= 0.0_dp
    call allocate_workspace(ws, n)
    ws%du_start = du
    ws%du = du
    ws%du_t = du
    ws%sum_du = total_displacement(du)
    do i = 1, n
      ws%elastic(i) = elastic_force(p%chain, e0, du, i, ws%sum_du/real(n, dp))
    end do
    !GCC$ novector
    do i = 1, n
      call cache_trig(ws, mu, i)
    end do
    if (.not. coupled) then     ! xi > 0: coupled_next computes the angles it needs
      call roots_from(ws%elastic, ws%radius, ws%phi, ws%root_down, ws%root_up)
      call tree_build(ws, n)
    end if
    ! the first check covers every slider; with xi = 0 the later ones only
    ! the sliders of the last event (end_event: no other force changed)
    ws%n_changed = n
    do i = 1, n
      ws%changed(i) = i
    end do

    n_events = 0
    n_sparse = 0
    sp_ptr(1) = 0
    alpha_c = ieee_value(alpha_c, ieee_quiet_nan)
    event_time = 0.0_dp
    final_work = 0_i8
    detail = detail_none
    do
      if (interrupt(1) /= 0) then
        status = status_interrupted
        exit
      end if
      ! A non-finite force stops the run; unstable sliders at the current
      ! angle start at once (relaxation).
      call drive_terms(p%loading, alpha, sin_a, cos_a)
      p%chain%driver_position = alpha
      n_trig = 0
      n_bad = 0
      do k = 1, ws%n_changed
        i = ws%changed(k)
        f = tangential_force(p%chain, i, ws%elastic(i), sin_a, du(i))
        n_bad = n_bad + merge(0_ip, 1_ip, abs(ws%elastic(i)) <= huge(1.0_dp))
        if (abs(f) > static_threshold(mu(i), cos_a, p%force_tol)) then
          n_trig = n_trig + 1
          ws%slist(n_trig) = i
          ws%sdir(n_trig) = sign(1.0_dp, f)
        end if
      end do
      if (n_bad > 0) then
        status = status_non_finite
        detail = detail_resting
        exit
      end if
      angle = alpha
      if (n_trig == 0) then
        if (p%relax_only) then
          status = status_relaxed
          exit
        end if
        if (n_events >= p%max_events) then
          status = status_running
          exit
        end if
        if (pushed) then    ! only slider 1 feels the driver
          angle = pushed_next(p%loading, ws%elastic(1), mu(1), du(1), alpha, p%force_tol)
          n_trig = 1
          ws%slist(1) = 1
          ws%sdir(1) = 1.0_dp
        else if (coupled) then
          call coupled_next(ws, n, alpha, angle, n_trig)
        else
          call tree_next(ws, alpha, angle, n_trig)
        end if
        if (beyond_limit(p%loading, angle)) then
          status = status_alpha_max
          exit
        end if
      end if
      if (n_events >= size(ev_real, 1) .or. &
          (p%record_sparse .and. size(sp_index) - n_sparse < n)) then
        status = status_sparse_full
        exit
      end if
      alpha_done = alpha
      alpha = angle
      p%chain%driver_position = alpha

      call run_event(p, ws, e0, t0, w0, mu, n_stops, du, alpha, n_trig, interrupt, rec)
      if (rec%status == status_interrupted) then
        ! undone entirely: the state after the last completed event
        status = status_interrupted
        alpha = alpha_done
        exit
      end if
      if (rec%status /= status_running) then
        status = rec%status
        detail = rec%detail
        event_time = rec%duration
        final_work = [rec%n_steps, rec%slider_steps]
        if (status == status_avalanche) alpha_c = alpha
        exit
      end if

      n_events = n_events + 1
      ev_real(n_events, ev_alpha) = alpha
      ev_real(n_events, ev_duration) = rec%duration
      ev_real(n_events, ev_work_gravity) = rec%work_gravity
      ev_real(n_events, ev_elastic_change) = rec%elastic_change
      ev_real(n_events, ev_dissipation) = rec%dissipation
      ev_int(n_events, ev_n_moved) = rec%n_moved
      ev_int(n_events, ev_n_stops) = rec%n_stops
      ev_int(n_events, ev_n_steps) = rec%n_steps
      ev_int(n_events, ev_slider_steps) = rec%slider_steps
      if (p%record_sparse) then
        do j = 1, int(rec%n_moved, ip)
          i = ws%sorted(j)
          sp_index(n_sparse + j) = int(i - 1, i8)
          sp_value(n_sparse + j) = du(i) - ws%du_start(i)
        end do
        n_sparse = n_sparse + int(rec%n_moved, ip)
        sp_ptr(n_events + 1) = int(n_sparse, i8)
      else
        sp_ptr(n_events + 1) = 0
      end if
      call end_event(p, ws, e0, mu, du)
      if (spanning_ends_run(p%loading) .and. .not. p%relax_only .and. rec%n_moved == n) then
        status = status_sliding       ! the onset drive is the last event's
        exit
      end if
    end do
  end subroutine tilt_run

  !> Allocates every work array of size n (once per tilt_run) and clears them.
  subroutine allocate_workspace(ws, n)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n

    allocate (ws%elastic(n), ws%root_down(n), ws%root_up(n), ws%du_start(n), ws%du_t(n))
    allocate (ws%du(n), ws%bound(n))
    allocate (ws%radius(n), ws%phi(n))
    allocate (ws%du_phase(n))
    allocate (ws%v(n), ws%acc(n), ws%dir(n), ws%v_t(n), ws%acc_t(n), ws%f_t(n))
    allocate (ws%thr(n), ws%gap_plus(n), ws%gap_minus(n), ws%mu_new(n))
    allocate (ws%active(n), ws%involved(n), ws%moved(n), ws%nmov(n), ws%ilist(n))
    allocate (ws%redrawn(n), ws%mu_start(n), ws%stops_start(n), ws%changed(n))
    ws%leaves = 1
    do while (ws%leaves < n)
      ws%leaves = 2*ws%leaves
    end do
    allocate (ws%tree(2*ws%leaves - 1))
    allocate (ws%cand(n), ws%slist(n), ws%sdir(n), ws%stops(n), ws%sorted(n), ws%run_lo(n), ws%run_hi(n))
    allocate (ws%seg_lo(n + 2), ws%seg_hi(n + 2), ws%span_lo(n), ws%span_hi(n))
    ws%v = 0.0_dp
    ws%acc = 0.0_dp
    ws%dir = 0.0_dp
    ws%v_t = 0.0_dp
    ws%acc_t = 0.0_dp
    ws%f_t = 0.0_dp
    ws%thr = ieee_value(1.0_dp, ieee_positive_inf)     ! the pool's (see merge_spans)
    ws%active = .false.
    ws%involved = .false.
    ws%moved = .false.
    ws%redrawn = .false.
    ws%nmov = 0
  end subroutine allocate_workspace

  ! ------------------------------------------------------------ one event

  !> One rearrangement at fixed alpha, started by the n_trig sliders in
  !> ws%slist with directions ws%sdir (reference.NumpyEngine._event).
  !> On a normal end du holds the new displacements and ws%sorted the moved
  !> sliders; on an error du, mu and n_stops are restored to the event start
  !> (as in the reference); on an avalanche du is the state at detection.
  subroutine run_event(p, ws, e0, t0, w0, mu, n_stops, du, alpha, n_trig, interrupt, rec)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), intent(in) :: alpha
    integer(ip), intent(in) :: n_trig
    integer(ip), volatile, intent(inout) :: interrupt(:)   ! only read
    type(event_record), intent(out) :: rec
    integer(ip) :: n, i, j, k, r, n_moved, n_start, n_stop, draw_status, halvings
    integer(i8) :: unchecked_steps
    real(dp) :: sin_a, cos_a, friction, sum0, mean0, mean, t, h, lo, hi, mid
    real(dp) :: dsum_t, step, xi, shift, f, thr
    integer(ip) :: n_cand
    logical :: crossed, pool_crossed, draws_ok, changed

    n = p%chain%n
    xi = p%chain%xi
    call drive_terms(p%loading, alpha, sin_a, cos_a)
    friction = kinetic_force(p%mu_d, cos_a)
    sum0 = ws%sum_du
    mean0 = sum0/real(n, dp)

    ! With xi > 0, thresholds and every slider's gaps to them at event start
    ! (O(n)): all resting sliders start in the pool, so one already beyond
    ! its threshold is found by the first step's check, as in the reference.
    ! With xi = 0 no pool force ever changes and none is beyond its threshold
    ! (the tilt loop started every such slider), so only the active sliders
    ! need a threshold, set when they become active.
    ws%cos_a = cos_a
    ws%force_tol = p%force_tol
    if (xi /= 0.0_dp) then
      do i = 1, n       ! ws%thr stays +inf in the pool (merge_spans)
        thr = static_threshold(mu(i), cos_a, p%force_tol)
        f = tangential_force(p%chain, i, ws%elastic(i), sin_a, ws%du(i))
        ws%gap_plus(i) = thr - f
        ws%gap_minus(i) = thr + f
      end do
    end if
    ws%m = 0
    ws%ni = 0
    ws%n_down = 0
    ws%i_lo = n + 1
    ws%i_hi = 0
    do k = 1, n_trig
      call start_slider(ws, ws%slist(k), ws%sdir(k), n, ws%du, mu)
    end do
    call find_runs(ws)
    do r = 1, ws%n_runs
      do i = ws%run_lo(r), ws%run_hi(r)
        ws%f_t(i) = tangential_force(p%chain, i, ws%elastic(i), sin_a, ws%du(i))
        if (ws%dir(i) /= 0.0_dp) ws%acc(i) = ws%f_t(i) - friction*ws%dir(i)
      end do
    end do
    call far_minima(ws, n, xi /= 0.0_dp)

    t = 0.0_dp
    ws%path = 0.0_dp
    ws%dsum = 0.0_dp
    rec = event_record()
    unchecked_steps = 0
    do while (ws%m > 0)
      ! ---- steps of dt, accepted in quiet_steps until one crosses (its
      ! trial is left unaccepted) or one of the checks below is due; a
      ! crossing step is cut back to the first crossing by bisection (which
      ! tests only the sliders that crossed in the full step, and the pool
      ! if it did: O(crossers) per trial, not O(active)), then accepted
      call quiet_steps(p, ws, e0, sum0, mean0, sin_a, friction, t, rec, unchecked_steps, &
                       dsum_t, crossed)
      if (crossed) then
        h = p%dt
        call crossing_candidates(ws, sum0 + dsum_t, mean0, xi, n, n_cand, pool_crossed)
        if (xi /= 0.0_dp) call mean_sums(ws)
        lo = 0.0_dp
        hi = h
        halvings = 0
        do while (hi - lo > p%refine_tol)
          if (halvings == max_halvings) then   ! refine_tol below the step's resolution
            rec%status = status_refine_limit
            rec%duration = t
            call abort_event(ws, du, mu, n_stops)
            return
          end if
          halvings = halvings + 1
          mid = 0.5_dp*(lo + hi)
          call candidate_trial(p, ws, e0, ws%du, mid, sum0, mean0, sin_a, friction, n_cand, &
                               pool_crossed, crossed)
          if (crossed) then
            hi = mid
          else
            lo = mid
          end if
        end do
        h = hi
        call trial_step(p, ws, e0, ws%du, h, sum0, mean0, sin_a, friction, dsum_t, crossed)
        call swap_state(ws)
        call count_step(ws, rec, h, dsum_t, t, unchecked_steps)
      end if
      if (unchecked_steps >= interrupt_check_steps) then
        unchecked_steps = 0
        if (interrupt(1) /= 0) then
          rec%status = status_interrupted
          call abort_event(ws, du, mu, n_stops)
          return
        end if
      end if

      ! ---- NaN or infinity: checked before anything else can happen (a
      ! crossing, the duration cap), and every 1024 steps; in between
      ! nothing but du and v (restored on abort) changes, so this is the
      ! reference's check at every step.
      if (crossed .or. t > p%max_event_duration .or. iand(rec%n_steps, 1023_i8) == 0) then
        if (.not. all_finite(ws, ws%du)) then
          rec%status = status_non_finite
          rec%detail = detail_state
          rec%duration = t
          call abort_event(ws, du, mu, n_stops)
          return
        end if
      end if

      ! ---- a crossing step: stops, then starts (nothing else changes state)
      if (crossed) then
        mean = (sum0 + ws%dsum)/real(n, dp)
        shift = 0.0_dp
        if (xi /= 0.0_dp) shift = xi*(mean - mean0)

        ! stops: rest, count, redraw (keyed by the 0-based slider number)
        call find_changes(ws, .true., ws%stops, n_stop)
        if (n_stop > 0) then
          rec%n_stops = rec%n_stops + n_stop
          draws_ok = .true.
          do k = 1, n_stop
            i = ws%stops(k)
            call stop_slider(ws, i, n, ws%du)
            if (.not. ws%redrawn(i)) then    ! keep the event-start draw for an abort
              ws%redrawn(i) = .true.
              ws%mu_start(i) = mu(i)
              ws%stops_start(i) = n_stops(i)
            end if
            n_stops(i) = n_stops(i) + 1
            ws%mu_new(k) = draw_at_stop(p%seed, int(i - 1, i8), n_stops(i), &
                                              p%mu_s_mean, p%sigma_mu, p%mu_d, draw_status)
            if (draw_status /= 0) draws_ok = .false.
          end do
          if (.not. draws_ok) then
            rec%status = status_random_failure
            rec%duration = t
            call abort_event(ws, du, mu, n_stops)
            return
          end if
          do k = 1, n_stop
            i = ws%stops(k)
            mu(i) = ws%mu_new(k)
            ws%thr(i) = static_threshold(mu(i), cos_a, p%force_tol)
          end do
        end if

        ! starts: every resting slider beyond its threshold now
        call find_changes(ws, .false., ws%slist, n_start)
        do k = 1, n_start
          ws%sdir(k) = sign(1.0_dp, ws%f_t(ws%slist(k)))
        end do
        if (pool_crosses(ws, shift)) then
          do i = 1, n        ! rare: a pool slider crossed, find it (O(n))
            if (ws%active(i)) cycle
            if (shift > ws%gap_plus(i) .or. -shift > ws%gap_minus(i)) then
              ws%f_t(i) = tangential_force(p%chain, i, elastic_force(p%chain, e0, ws%du, i, mean), &
                                           sin_a, ws%du(i))
              n_start = n_start + 1
              ws%slist(n_start) = i
              ws%sdir(n_start) = sign(1.0_dp, ws%f_t(i))
            end if
          end do
        end if
        do k = 1, n_start
          i = ws%slist(k)
          call start_slider(ws, i, ws%sdir(k), n, ws%du, mu)
          ws%acc(i) = ws%f_t(i) - friction*ws%dir(i)
        end do
        ! sliders left with no moving neighbour go back to the pool
        changed = n_start > 0
        do k = 1, n_stop
          i = ws%stops(k)
          do j = max(i - 1, 1), min(i + 1, n)
            if (ws%active(j) .and. ws%nmov(j) == 0) then
              call deactivate(ws, j, shift)
              changed = .true.
            end if
          end do
        end do
        if (changed) call update_runs(ws, n, n_start)
        if (ws%stale) call far_minima(ws, n, xi /= 0.0_dp)
      end if

      if (t > p%max_event_duration) then
        rec%status = status_event_duration_cap
        rec%duration = t
        call abort_event(ws, du, mu, n_stops)
        return
      end if
      if (loading_runaway(p%loading, p%chain%walls, n, ws%m, ws%n_down, sin_a, friction)) then
        rec%status = status_avalanche
        rec%duration = t
        call store_displacements(ws, du)
        return
      end if
    end do
    call store_displacements(ws, du)

    ! ---- the event is over: record it
    n_moved = 0
    do i = ws%i_lo, ws%i_hi
      if (ws%moved(i)) then
        n_moved = n_moved + 1
        ws%sorted(n_moved) = i
      end if
    end do
    rec%n_moved = n_moved
    rec%duration = t
    step = 0.0_dp
    do k = 1, n_moved
      i = ws%sorted(k)
      step = step + (du(i) - ws%du_start(i))
    end do
    rec%work_gravity = loading_work(p%loading, sin_a, step, alpha, du(1) - ws%du_start(1), &
                                    ws%du_start(1))
    rec%elastic_change = &
      spring_energy_change(p%chain, t0, ws%du_start, du, ws%sorted(1:n_moved)) + &
      cantilever_energy_change(p%chain, w0, ws%du_start, du, ws%sorted(1:n_moved), mean0)
    rec%dissipation = friction*ws%path
  end subroutine run_event

  !> Steps of size p%dt from the state, each accepted at once, until one
  !> crosses or the caller has a check due.  Between such steps the caller
  !> (run_event) would do nothing but count: no crossing to process, the
  !> finite check not due (it is after a crossing, beyond the duration cap
  !> and every 1024th step), the interrupt counter below its limit, and the
  !> runaway test unchanged (it depends on the moving sliders only, which
  !> change only at a crossing; after the event's first step it is tested,
  !> so that step is taken alone).  Returns with `crossed` and that step's
  !> trial unaccepted in the trial arrays (dsum_t its sum), or after an
  !> accepted step at which a check is due.  The trial and state arrays
  !> alternate roles from step to step (no swap), and are swapped once at
  !> the end if the state is in the trial arrays.  The accepted steps'
  !> forces are never read, so after the first keep_forces_steps steps of
  !> a call they are not stored (one store per slider less), and a
  !> crossing trial then is computed again with them.
  subroutine quiet_steps(p, ws, e0, sum0, mean0, sin_a, friction, t, rec, unchecked_steps, &
                         dsum_t, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: sum0, mean0, sin_a, friction
    real(dp), intent(inout) :: t
    type(event_record), intent(inout) :: rec
    integer(i8), intent(inout) :: unchecked_steps
    real(dp), intent(out) :: dsum_t
    logical, intent(out) :: crossed
    logical :: flipped, keep_forces
    integer(ip) :: steps
    real(dp) :: shift, excess

    flipped = .false.
    steps = 0
    do
      steps = steps + 1
      keep_forces = steps <= keep_forces_steps
      if (flipped) then
        call trial_arrays(p, ws, e0, p%dt, sum0, mean0, sin_a, friction, keep_forces, ws%du_t, &
                          ws%v_t, ws%acc_t, ws%du, ws%v, ws%acc, ws%f_t, dsum_t, shift, excess)
      else
        call trial_arrays(p, ws, e0, p%dt, sum0, mean0, sin_a, friction, keep_forces, ws%du, &
                          ws%v, ws%acc, ws%du_t, ws%v_t, ws%acc_t, ws%f_t, dsum_t, shift, excess)
      end if
      crossed = excess > 0.0_dp .or. pool_crosses(ws, shift)
      if (crossed) exit
      flipped = .not. flipped
      call count_step(ws, rec, p%dt, dsum_t, t, unchecked_steps)
      if (rec%n_steps == 1 .or. iand(rec%n_steps, 1023_i8) == 0 .or. &
          t > p%max_event_duration .or. unchecked_steps >= interrupt_check_steps) exit
    end do
    if (flipped) call swap_state(ws)
    ! the crossing trial again, the same numbers, now with its forces (the
    ! crossing's bookkeeping reads them)
    if (crossed .and. .not. keep_forces) call trial_step(p, ws, e0, ws%du, p%dt, sum0, mean0, sin_a, friction, dsum_t, &
                                 crossed)
  end subroutine quiet_steps

  !> An accepted step of size h: the event's sums and counters.
  subroutine count_step(ws, rec, h, dsum_t, t, unchecked_steps)
    type(workspace), intent(inout) :: ws
    type(event_record), intent(inout) :: rec
    real(dp), intent(in) :: h, dsum_t
    real(dp), intent(inout) :: t
    integer(i8), intent(inout) :: unchecked_steps

    ws%dsum = dsum_t
    rec%n_steps = rec%n_steps + 1
    rec%slider_steps = rec%slider_steps + ws%m
    t = t + h
    unchecked_steps = unchecked_steps + ws%m
  end subroutine count_step

  !> The trial becomes the state by swapping the arrays, no copy (outside
  !> the spans both hold the same values: a resting slider has du_t = du,
  !> v_t = acc_t = 0; a slider leaving the runs is synchronised by
  !> deactivate).
  subroutine swap_state(ws)
    type(workspace), intent(inout) :: ws
    real(dp), allocatable :: swap(:)

    call move_alloc(ws%du, swap)
    call move_alloc(ws%du_t, ws%du)
    call move_alloc(swap, ws%du_t)
    call move_alloc(ws%v, swap)
    call move_alloc(ws%v_t, ws%v)
    call move_alloc(swap, ws%v_t)
    call move_alloc(ws%acc, swap)
    call move_alloc(ws%acc_t, ws%acc)
    call move_alloc(swap, ws%acc_t)
  end subroutine swap_state

  !> One velocity-Verlet trial of size h from the start of the step, over the
  !> spans: du_t, v_t, acc_t, and the forces f_t.  Resting sliders keep
  !> du_t = du and get v_t = acc_t = 0.  `crossed`: a mover's velocity
  !> changed sign, or a resting slider (active, or in the pool through the
  !> gap minima) exceeds its threshold.
  subroutine trial_step(p, ws, e0, du, h, sum0, mean0, sin_a, friction, dsum_t, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: h, sum0, mean0, sin_a, friction
    real(dp), intent(out) :: dsum_t
    logical, intent(out) :: crossed
    real(dp) :: shift, excess

    call trial_arrays(p, ws, e0, h, sum0, mean0, sin_a, friction, .true., du, ws%v, ws%acc, &
                      ws%du_t, ws%v_t, ws%acc_t, ws%f_t, dsum_t, shift, excess)
    crossed = excess > 0.0_dp .or. pool_crosses(ws, shift)
  end subroutine trial_step

  !> trial_step on the state du, v, acc into the trial du_t, v_t, acc_t, f
  !> given as arguments (quiet_steps alternates them; f only if
  !> keep_forces): the pool's shift and the largest crossing excess of the
  !> spans.  Of ws only the runs, spans, directions and thresholds are read.
  subroutine trial_arrays(p, ws, e0, h, sum0, mean0, sin_a, friction, keep_forces, du, v, acc, &
                          du_t, v_t, acc_t, f, dsum_t, shift, excess)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(in) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: h, sum0, mean0, sin_a, friction
    logical, intent(in) :: keep_forces
    real(dp), contiguous, intent(in) :: du(:), v(:), acc(:)
    real(dp), contiguous, intent(inout) :: du_t(:), v_t(:), acc_t(:), f(:)
    real(dp), intent(out) :: dsum_t, shift, excess
    real(dp) :: mean_t

    dsum_t = ws%dsum
    mean_t = mean0
    shift = 0.0_dp
    if (p%chain%xi /= 0.0_dp) then
      call predict_sum_runs(p%chain%n, ws%n_runs, ws%run_lo, ws%run_hi, h, du, v, acc, du_t, &
                            dsum_t)
      mean_t = (sum0 + dsum_t)/real(p%chain%n, dp)
      shift = p%chain%xi*(mean_t - mean0)
    end if
    call step_spans(p%chain, p%chain%n, ws%n_spans, ws%span_lo, ws%span_hi, e0, h, mean_t, &
                    sin_a, friction, keep_forces, du, v, acc, ws%dir, ws%thr, du_t, f, acc_t, &
                    v_t, excess)
  end subroutine trial_arrays

  !> After a full trial step that crossed: the active sliders that crossed
  !> (excess > 0, the test of step_spans) into ws%cand(1:n_cand), and
  !> whether the pool crossed (its shift beyond a gap minimum) given the
  !> trial's total displacement `sum_t`.
  subroutine crossing_candidates(ws, sum_t, mean0, xi, n, n_cand, pool_crossed)
    type(workspace), intent(inout) :: ws
    real(dp), intent(in) :: sum_t, mean0, xi
    integer(ip), intent(in) :: n
    integer(ip), intent(out) :: n_cand
    logical, intent(out) :: pool_crossed
    integer(ip) :: r, i
    real(dp) :: shift

    n_cand = 0
    do r = 1, ws%n_runs
      do i = ws%run_lo(r), ws%run_hi(r)
        if (crossing_excess(ws%dir(i), ws%v_t(i), ws%f_t(i), ws%thr(i)) > 0.0_dp) then
          n_cand = n_cand + 1
          ws%cand(n_cand) = i
        end if
      end do
    end do
    shift = 0.0_dp
    if (xi /= 0.0_dp) shift = xi*(sum_t/real(n, dp) - mean0)
    pool_crossed = pool_crosses(ws, shift)
  end subroutine crossing_candidates

  !> The crossing test of trial_step restricted to the candidates (and the
  !> pool if pool_crossed): the same operations on the same numbers, so each
  !> candidate's excess is bit-identical to the full trial's.  With xi = 0
  !> only the candidates and their neighbours are predicted; with xi > 0 the
  !> mean needs every active slider's trial position.
  subroutine candidate_trial(p, ws, e0, du, h, sum0, mean0, sin_a, friction, n_cand, &
                             pool_crossed, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: h, sum0, mean0, sin_a, friction
    integer(ip), intent(in) :: n_cand
    logical, intent(in) :: pool_crossed
    logical, intent(out) :: crossed
    integer(ip) :: k, i, lo, hi
    real(dp) :: mean_t, shift, excess, dsum_t
    logical :: decided

    do k = 1, n_cand
      i = ws%cand(k)
      lo = max(i - 1, 1_ip)
      hi = min(i + 1, p%chain%n)
      call predict_run(lo, hi, h, du, ws%v, ws%acc, ws%du_t)
    end do
    mean_t = mean0
    shift = 0.0_dp
    if (p%chain%xi /= 0.0_dp) then
      ! almost always the crossing test is the same for every mean in a
      ! rigorous enclosure of the trial mean, got in O(1): then the exact
      ! mean (O(active)) is not needed
      call enclosed_trial(p, ws, e0, h, sum0, mean0, sin_a, friction, n_cand, pool_crossed, &
                          decided, crossed)
      if (decided) return
      dsum_t = ws%dsum        ! the exact mean (rare): every active slider's increment
      call predict_sum_runs(p%chain%n, ws%n_runs, ws%run_lo, ws%run_hi, h, du, ws%v, ws%acc, &
                            ws%du_t, dsum_t)
      mean_t = (sum0 + dsum_t)/real(p%chain%n, dp)
      shift = p%chain%xi*(mean_t - mean0)
    end if
    ! each candidate a span of its own (its neighbours are predicted above)
    call step_spans(p%chain, p%chain%n, n_cand, ws%cand, ws%cand, e0, h, mean_t, sin_a, &
                    friction, .true., du, ws%v, ws%acc, ws%dir, ws%thr, ws%du_t, ws%f_t, ws%acc_t, &
                    ws%v_t, excess)
    crossed = excess > 0.0_dp
    if (pool_crossed) crossed = crossed .or. pool_crosses(ws, shift)
  end subroutine candidate_trial

  !> The bisection's crossing test when xi > 0, without the exact trial mean
  !> when possible.  The trial mean the exact test uses, fl(fl(sum0 +
  !> dsum_t)/n), has dsum_t = dsum + the sum of the active sliders' rounded
  !> increments fl(fl(du + fl(v h + 0.5 acc h h)) - du), summed in four
  !> lanes; it differs from dsum + h sum(v) + h**2/2 sum(acc) by at most
  !> u [2 sum|du| + 4 (m + 4 runs + 8)(h sum|v| + h**2 sum|acc| + |dsum|)]
  !> (u = 2**-53, m active sliders: the rounding of each increment and of the
  !> sums), taken twice here.  Every floating-point operation of the test is
  !> monotone in the mean (rounding is monotone): a mover's excess lies
  !> between its values at the enclosure's ends, a resting slider's |F| -
  !> thr is largest at an end and monotone if F keeps its sign, and so are
  !> the pool's two tests.  `decided`: the test is the same over the whole
  !> enclosure, and `crossed` is its result, the exact test's bit for bit.
  subroutine enclosed_trial(p, ws, e0, h, sum0, mean0, sin_a, friction, n_cand, pool_crossed, &
                            decided, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: h, sum0, mean0, sin_a, friction
    integer(ip), intent(in) :: n_cand
    logical, intent(in) :: pool_crossed
    logical, intent(out) :: decided, crossed
    real(dp), parameter :: u = epsilon(1.0_dp)/2.0_dp
    real(dp) :: dsum_a, err, mean_lo, mean_hi, e_lo, e_hi, f_lo, f_hi, s_lo, s_hi, xi
    integer(ip) :: k, i
    logical :: all_below

    xi = p%chain%xi
    dsum_a = ws%dsum + (h*ws%sum_v + 0.5_dp*h*h*ws%sum_acc)
    err = 2.0_dp*u*(2.0_dp*ws%abs_du + 4.0_dp*real(ws%n_active + 4*ws%n_runs + 8, dp) &
                    *(h*ws%abs_v + h*h*ws%abs_acc + abs(ws%dsum)) + abs(dsum_a)) + tiny(1.0_dp)
    mean_lo = (sum0 + (dsum_a - err))/real(p%chain%n, dp)
    mean_hi = (sum0 + (dsum_a + err))/real(p%chain%n, dp)
    decided = .true.
    crossed = .true.
    all_below = .true.
    do k = 1, n_cand
      i = ws%cand(k)
      call step_spans(p%chain, p%chain%n, 1_ip, ws%cand(k:k), ws%cand(k:k), e0, h, mean_lo, &
                      sin_a, friction, .true., ws%du, ws%v, ws%acc, ws%dir, ws%thr, ws%du_t, &
                      ws%f_t, ws%acc_t, ws%v_t, e_lo)
      f_lo = ws%f_t(i)
      call step_spans(p%chain, p%chain%n, 1_ip, ws%cand(k:k), ws%cand(k:k), e0, h, mean_hi, &
                      sin_a, friction, .true., ws%du, ws%v, ws%acc, ws%dir, ws%thr, ws%du_t, &
                      ws%f_t, ws%acc_t, ws%v_t, e_hi)
      f_hi = ws%f_t(i)
      if (e_lo > 0.0_dp .and. e_hi > 0.0_dp .and. (ws%dir(i) /= 0.0_dp .or. &
          (f_lo > 0.0_dp .and. f_hi > 0.0_dp) .or. (f_lo < 0.0_dp .and. f_hi < 0.0_dp))) return
      all_below = all_below .and. e_lo <= 0.0_dp .and. e_hi <= 0.0_dp
    end do
    if (pool_crossed) then      ! shift > min_plus rises with the mean, -shift > min_minus falls
      s_lo = xi*(mean_lo - mean0)
      s_hi = xi*(mean_hi - mean0)
      if ((s_lo > ws%min_plus .and. s_hi > ws%min_plus) .or. &
          (-s_lo > ws%min_minus .and. -s_hi > ws%min_minus)) return
      all_below = all_below .and. .not. (s_lo > ws%min_plus .or. s_hi > ws%min_plus .or. &
                                         -s_lo > ws%min_minus .or. -s_hi > ws%min_minus)
    end if
    crossed = .false.
    decided = all_below
  end subroutine enclosed_trial

  !> The sums over the active sliders that enclosed_trial needs (once per
  !> crossing step, at its start).
  subroutine mean_sums(ws)
    type(workspace), intent(inout) :: ws
    integer(ip) :: r, i

    ws%sum_v = 0.0_dp
    ws%sum_acc = 0.0_dp
    ws%abs_du = 0.0_dp
    ws%abs_v = 0.0_dp
    ws%abs_acc = 0.0_dp
    ws%n_active = 0
    do r = 1, ws%n_runs
      ws%n_active = ws%n_active + (ws%run_hi(r) - ws%run_lo(r) + 1)
      do i = ws%run_lo(r), ws%run_hi(r)
        ws%sum_v = ws%sum_v + ws%v(i)
        ws%sum_acc = ws%sum_acc + ws%acc(i)
        ws%abs_v = ws%abs_v + abs(ws%v(i))
        ws%abs_acc = ws%abs_acc + abs(ws%acc(i))
        ws%abs_du = ws%abs_du + abs(ws%du(i))
      end do
    end do
  end subroutine mean_sums

  !> Velocity-Verlet positions over one run: du_t = du + v h + acc h**2/2.
  pure subroutine predict_run(lo, hi, h, du, v, acc, du_t)
    integer(ip), intent(in) :: lo, hi
    real(dp), intent(in) :: h
    real(dp), contiguous, intent(in) :: du(:), v(:), acc(:)
    real(dp), contiguous, intent(inout) :: du_t(:)
    integer(ip) :: i

    do i = lo, hi
      du_t(i) = verlet_position(du(i), v(i), acc(i), h)
    end do
  end subroutine predict_run

  !> predict_run over every run, fused with dsum = dsum + the sum of du_t -
  !> du (xi > 0: the mean moves), run after run.  Four partial sums per
  !> run: the order of the additions is free, the chain of dependent
  !> additions short; it is fixed (slider lo + j goes to sum j mod 4), so
  !> every trial rounds alike.
  pure subroutine predict_sum_runs(n, n_runs, run_lo, run_hi, h, du, v, acc, du_t, dsum)
    integer(ip), intent(in) :: n, n_runs
    integer(ip), intent(in) :: run_lo(n_runs), run_hi(n_runs)
    real(dp), intent(in) :: h
    real(dp), intent(in) :: du(n), v(n), acc(n)
    real(dp), intent(inout) :: du_t(n)
    real(dp), intent(inout) :: dsum
    integer(ip) :: r, i, lo, hi, last
    real(dp) :: s1, s2, s3, s4

    do r = 1, n_runs
      lo = run_lo(r)
      hi = run_hi(r)
      s1 = 0.0_dp
      s2 = 0.0_dp
      s3 = 0.0_dp
      s4 = 0.0_dp
      last = lo + 4*((hi - lo + 1)/4) - 1
      do i = lo, last, 4
        du_t(i) = verlet_position(du(i), v(i), acc(i), h)
        du_t(i + 1) = verlet_position(du(i + 1), v(i + 1), acc(i + 1), h)
        du_t(i + 2) = verlet_position(du(i + 2), v(i + 2), acc(i + 2), h)
        du_t(i + 3) = verlet_position(du(i + 3), v(i + 3), acc(i + 3), h)
        s1 = s1 + (du_t(i) - du(i))
        s2 = s2 + (du_t(i + 1) - du(i + 1))
        s3 = s3 + (du_t(i + 2) - du(i + 2))
        s4 = s4 + (du_t(i + 3) - du(i + 3))
      end do
      do i = last + 1, hi
        du_t(i) = verlet_position(du(i), v(i), acc(i), h)
        s1 = s1 + (du_t(i) - du(i))
      end do
      dsum = dsum + ((s1 + s2) + (s3 + s4))
    end do
  end subroutine predict_sum_runs

  !> The step over every span in one call (explicit-shape arrays: nothing
  !> but base addresses is passed, the loop constants are set up once): with
  !> xi = 0 each span's positions are predicted here (with xi > 0 the
  !> caller predicted them, with the mean's sums), then its forces (the
  !> formula of sliders_chain, written out so that it vectorises; the chain's
  !> end sliders in end_sliders) and the velocity update with the crossing
  !> excess.  A span's force reads no trial position that a later span
  !> predicts: merge_spans leaves at least span_gap + 1 pool sliders
  !> between spans, and candidate_trial (one span per candidate) predicts
  !> every candidate's neighbours first.
  subroutine step_spans(chain, n, n_spans, span_lo, span_hi, e0, h, mean, sin_a, friction, &
                        keep_forces, du, v, acc, dir, thr, du_t, f, acc_t, v_t, excess)
    type(chain_params), intent(in) :: chain
    integer(ip), intent(in) :: n, n_spans
    integer(ip), intent(in) :: span_lo(n_spans), span_hi(n_spans)
    real(dp), intent(in) :: e0(n)
    real(dp), intent(in) :: h, mean, sin_a, friction
    logical, intent(in) :: keep_forces     ! store f (the end sliders' always)
    real(dp), intent(in) :: du(n), v(n), acc(n), dir(n), thr(n)
    real(dp), intent(inout) :: du_t(n), f(n), acc_t(n), v_t(n)
    real(dp), intent(out) :: excess
    integer(ip) :: s, i, lo, hi
    real(dp) :: xi, fi

    xi = chain%xi
    excess = -huge(1.0_dp)
    do s = 1, n_spans
      lo = span_lo(s)
      hi = span_hi(s)
      if (xi == 0.0_dp) then
        do i = lo, hi
          du_t(i) = verlet_position(du(i), v(i), acc(i), h)
        end do
      end if
      if (xi /= 0.0_dp) then
        do i = max(lo, 2_ip), min(hi, n - 1_ip)
          fi = ((e0(i) + ((du_t(i + 1) - du_t(i)) - (du_t(i) - du_t(i - 1)))) &
                - xi*(du_t(i) - mean)) + sin_a
          if (keep_forces) f(i) = fi
          call verlet_correct(h, friction, fi, dir(i), v(i), acc(i), thr(i), acc_t(i), &
                              v_t(i), excess)
        end do
      else
        do i = max(lo, 2_ip), min(hi, n - 1_ip)
          fi = (e0(i) + ((du_t(i + 1) - du_t(i)) - (du_t(i) - du_t(i - 1)))) + sin_a
          if (keep_forces) f(i) = fi
          call verlet_correct(h, friction, fi, dir(i), v(i), acc(i), thr(i), acc_t(i), &
                              v_t(i), excess)
        end do
      end if
      if (lo == 1 .or. hi == n) call end_sliders(chain, e0, lo, hi, mean, sin_a, h, friction, &
                                                 du_t, dir, v, acc, thr, f, acc_t, v_t, excess)
    end do
  end subroutine step_spans

  !> The chain's end sliders within lo..hi, from their trial positions:
  !> force (sliders_chain's elastic_force: walls or free ends) and
  !> verlet_correct.  Slider 1's force is formed here and nowhere else in a
  !> step (a loading acting on slider 1 adds its term here).
  pure subroutine end_sliders(chain, e0, lo, hi, mean, sin_a, h, friction, du_t, dir, v, acc, &
                              thr, f, acc_t, v_t, excess)
    type(chain_params), intent(in) :: chain
    real(dp), contiguous, intent(in) :: e0(:)
    integer(ip), intent(in) :: lo, hi
    real(dp), intent(in) :: mean, sin_a, h, friction
    real(dp), contiguous, intent(in) :: du_t(:), dir(:), v(:), acc(:), thr(:)
    real(dp), contiguous, intent(inout) :: f(:), acc_t(:), v_t(:)
    real(dp), intent(inout) :: excess

    if (lo == 1) then
      f(1) = tangential_force(chain, 1_ip, elastic_force(chain, e0, du_t, 1_ip, mean), sin_a, &
                              du_t(1))
      call verlet_correct(h, friction, f(1), dir(1), v(1), acc(1), thr(1), acc_t(1), v_t(1), &
                          excess)
    end if
    if (hi == chain%n .and. chain%n > 1) then
      f(hi) = elastic_force(chain, e0, du_t, hi, mean) + sin_a
      call verlet_correct(h, friction, f(hi), dir(hi), v(hi), acc(hi), thr(hi), acc_t(hi), &
                          v_t(hi), excess)
    end if
  end subroutine end_sliders

  !> Velocity-Verlet trial position du + v h + acc h**2/2 (one expression,
  !> so that every loop computing it rounds alike).
  elemental function verlet_position(du, v, acc, h) result(du_t)
    real(dp), intent(in) :: du, v, acc, h
    real(dp) :: du_t

    du_t = du + (v*h + 0.5_dp*acc*h*h)
  end function verlet_position

  !> Velocity-Verlet velocity of a slider from its trial force f, and the
  !> largest crossing excess so far (crossing_excess).  For a mover (dir =
  !> +-1, dir**2 = 1) acc_t is f - friction dir exactly, for a resting one
  !> (dir = 0) it is 0 and v_t stays 0.  Branch-free.
  pure subroutine verlet_correct(h, friction, f, dir, v, acc, thr, acc_t, v_t, excess)
    real(dp), intent(in) :: h, friction, f, dir, v, acc, thr
    real(dp), intent(out) :: acc_t, v_t
    real(dp), intent(inout) :: excess

    acc_t = (f - friction*dir)*(dir*dir)
    v_t = v + 0.5_dp*(acc + acc_t)*h
    excess = max(excess, crossing_excess(dir, v_t, f, thr))
  end subroutine verlet_correct

  !> How far a slider is beyond a crossing (a crossing if > 0): -dir v_t for
  !> a mover (its velocity turned against its direction), |f| - thr for a
  !> resting slider (beyond its threshold).  Branch-free (dir = 0 or +-1).
  elemental function crossing_excess(dir, v_t, f, thr) result(excess)
    real(dp), intent(in) :: dir, v_t, f, thr
    real(dp) :: excess

    excess = max(-dir*v_t, (1.0_dp - dir*dir)*abs(f) - thr)
  end function crossing_excess

  !> Whether a pool slider crossed: the pool's shift beyond a gap minimum.
  pure function pool_crosses(ws, shift) result(crossed)
    type(workspace), intent(in) :: ws
    real(dp), intent(in) :: shift
    logical :: crossed

    crossed = shift > ws%min_plus .or. -shift > ws%min_minus
  end function pool_crosses

  !> The caller's du gets the event's displacements (the involved sliders:
  !> no other slider moved).
  subroutine store_displacements(ws, du)
    type(workspace), intent(in) :: ws
    real(dp), contiguous, intent(inout) :: du(:)
    integer(ip) :: k

    do k = 1, ws%ni
      du(ws%ilist(k)) = ws%du(ws%ilist(k))
    end do
  end subroutine store_displacements

  !> After a crossing step, the active sliders (increasing) that stop (with
  !> `stopping`: a mover whose velocity turned against its direction) or
  !> start (a resting one beyond its threshold), into found(1:n_found).  A
  !> crossing step has one or two of them: a vectorised count first, then a
  !> scan that ends at the last one.
  subroutine find_changes(ws, stopping, found, n_found)
    type(workspace), intent(in) :: ws
    logical, intent(in) :: stopping
    integer(ip), contiguous, intent(inout) :: found(:)
    integer(ip), intent(out) :: n_found
    integer(ip) :: r, i, n_count

    n_count = 0                     ! (integer flags: the count has no branch)
    do r = 1, ws%n_runs
      if (stopping) then
        do i = ws%run_lo(r), ws%run_hi(r)
          n_count = n_count + merge(1_ip, 0_ip, ws%dir(i)*ws%v(i) < 0.0_dp)
        end do
      else
        do i = ws%run_lo(r), ws%run_hi(r)
          n_count = n_count + merge(1_ip, 0_ip, ws%dir(i) == 0.0_dp) &
                              *merge(1_ip, 0_ip, abs(ws%f_t(i)) > ws%thr(i))
        end do
      end if
    end do
    n_found = 0
    do r = 1, ws%n_runs
      if (n_found == n_count) exit
      do i = ws%run_lo(r), ws%run_hi(r)
        if (changes(i)) then
          n_found = n_found + 1
          found(n_found) = i
        end if
      end do
    end do

  contains

    !> Whether slider i stops (stopping) or starts.
    pure logical function changes(i)
      integer(ip), intent(in) :: i

      if (stopping) then
        changes = ws%dir(i)*ws%v(i) < 0.0_dp
      else
        changes = ws%dir(i) == 0.0_dp .and. abs(ws%f_t(i)) > ws%thr(i)
      end if
    end function changes

  end subroutine find_changes

  !> Whether du and v of every active slider are finite (a count of the
  !> others: an integer sum vectorises, a chain of .and. did not).
  pure function all_finite(ws, du) result(finite)
    type(workspace), intent(in) :: ws
    real(dp), contiguous, intent(in) :: du(:)
    logical :: finite
    integer(ip) :: r, i, n_bad

    n_bad = 0
    do r = 1, ws%n_runs
      do i = ws%run_lo(r), ws%run_hi(r)
        n_bad = n_bad + merge(0_ip, 1_ip, abs(du(i)) <= huge(1.0_dp) .and. &
                                          abs(ws%v(i)) <= huge(1.0_dp))
      end do
    end do
    finite = n_bad == 0
  end function all_finite

  !> Sets resting slider i moving in direction d; it and its neighbours
  !> become active.  The runs are then out of date (find_runs).
  subroutine start_slider(ws, i, d, n, du, mu)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: d
    integer(ip), intent(in) :: n
    real(dp), contiguous, intent(in) :: du(:), mu(:)
    integer(ip) :: j

    ws%du_phase(i) = du(i)
    ws%moved(i) = .true.
    ws%dir(i) = d
    ws%m = ws%m + 1
    if (d > 0.0_dp) ws%n_down = ws%n_down + 1
    do j = max(i - 1, 1), min(i + 1, n)
      ws%nmov(j) = ws%nmov(j) + 1
      if (.not. ws%active(j)) call activate(ws, j, mu)
    end do
  end subroutine start_slider

  !> Brings moving slider i to rest (v = 0, no direction) and adds the path
  !> of its sliding phase, dir (du - du at start), to ws%path (the sum over
  !> the steps of dir (du_t - du) telescopes to it); it and its neighbours
  !> stay active until the caller deactivates them.
  subroutine stop_slider(ws, i, n, du)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: i, n
    real(dp), contiguous, intent(in) :: du(:)
    integer(ip) :: j

    ws%path = ws%path + ws%dir(i)*(du(i) - ws%du_phase(i))
    if (ws%dir(i) > 0.0_dp) ws%n_down = ws%n_down - 1
    ws%v(i) = 0.0_dp
    ws%acc(i) = 0.0_dp
    ws%dir(i) = 0.0_dp
    ws%m = ws%m - 1
    do j = max(i - 1, 1), min(i + 1, n)
      ws%nmov(j) = ws%nmov(j) - 1
    end do
  end subroutine stop_slider

  !> Slider i leaves the pool: active (and involved for the rest of the
  !> event), with its threshold mu cos(a) + force_tol.
  subroutine activate(ws, i, mu)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: i
    real(dp), contiguous, intent(in) :: mu(:)

    ws%active(i) = .true.
    ws%thr(i) = static_threshold(mu(i), ws%cos_a, ws%force_tol)
    if (i == ws%arg_plus .or. i == ws%arg_minus) ws%stale = .true.
    if (.not. ws%involved(i)) then
      ws%involved(i) = .true.
      ws%ni = ws%ni + 1
      ws%ilist(ws%ni) = i
      ws%i_lo = min(ws%i_lo, i)
      ws%i_hi = max(ws%i_hi, i)
    end if
  end subroutine activate

  !> Resting slider i, with no moving neighbour, joins the pool; its force
  !> f_t(i) is current and `shift` the pool's current shift.
  subroutine deactivate(ws, i, shift)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: shift

    ws%active(i) = .false.
    ws%du_t(i) = ws%du(i)      ! outside the runs both buffers agree (run_event swaps them)
    ws%v_t(i) = 0.0_dp
    ws%acc_t(i) = 0.0_dp
    ws%gap_plus(i) = ws%thr(i) - (ws%f_t(i) - shift)
    ws%gap_minus(i) = ws%thr(i) + (ws%f_t(i) - shift)
    ws%thr(i) = ieee_value(1.0_dp, ieee_positive_inf)   ! never crosses inside a span
    if (ws%arg_plus == 0 .or. ws%gap_plus(i) < ws%min_plus) then
      ws%min_plus = ws%gap_plus(i)
      ws%arg_plus = i
    end if
    if (ws%arg_minus == 0 .or. ws%gap_minus(i) < ws%min_minus) then
      ws%min_minus = ws%gap_minus(i)
      ws%arg_minus = i
    end if
  end subroutine deactivate

  !> The maximal runs of consecutive active sliders, found by a scan of the
  !> range of the involved ones (the active sliders are involved).
  subroutine find_runs(ws)
    type(workspace), intent(inout) :: ws

    ws%n_runs = 0
    call scan_runs(ws, ws%i_lo, ws%i_hi)
    call merge_spans(ws)
  end subroutine find_runs

  !> find_runs after a crossing step, in O(active + starts) instead of
  !> O(range of the involved sliders) (a slip front leaves a range of
  !> thousands behind it): every active slider now was active before (in an
  !> old run) or is a neighbour of one of the n_start sliders in ws%slist
  !> that started in this step, so the maximal runs are found by scanning
  !> the old runs and the starts' neighbourhoods, widened by one and merged
  !> where they overlap or touch (a run cannot cross the edge of such a
  !> merged segment: the slider beyond it is not active).
  subroutine update_runs(ws, n, n_start)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n, n_start
    integer(ip) :: k, j, n_seg, r, lo, hi, key

    ! the starts' positions, increasing (insertion sort: there are few)
    do k = 2, n_start
      key = ws%slist(k)
      j = k - 1
      do while (j >= 1)
        if (ws%slist(j) <= key) exit
        ws%slist(j + 1) = ws%slist(j)
        j = j - 1
      end do
      ws%slist(j + 1) = key
    end do
    ! merge the old runs and the starts, both increasing, into segments
    n_seg = 0
    r = 1
    k = 1
    do while (r <= ws%n_runs .or. k <= n_start)
      if (k > n_start) then
        lo = ws%run_lo(r) - 1
        hi = ws%run_hi(r) + 1
        r = r + 1
      else if (r > ws%n_runs) then
        lo = ws%slist(k) - 1
        hi = ws%slist(k) + 1
        k = k + 1
      else if (ws%run_lo(r) <= ws%slist(k)) then
        lo = ws%run_lo(r) - 1
        hi = ws%run_hi(r) + 1
        r = r + 1
      else
        lo = ws%slist(k) - 1
        hi = ws%slist(k) + 1
        k = k + 1
      end if
      lo = max(lo, 1_ip)
      hi = min(hi, n)
      if (n_seg > 0) then
        if (lo <= ws%seg_hi(n_seg) + 1) then
          ws%seg_hi(n_seg) = max(ws%seg_hi(n_seg), hi)
          cycle
        end if
      end if
      n_seg = n_seg + 1
      ws%seg_lo(n_seg) = lo
      ws%seg_hi(n_seg) = hi
    end do
    ! the maximal runs of active sliders inside the segments
    ws%n_runs = 0
    do k = 1, n_seg
      call scan_runs(ws, ws%seg_lo(k), ws%seg_hi(k))
    end do
    call merge_spans(ws)
  end subroutine update_runs

  !> The spans a step integrates: the runs, merged where at most span_gap
  !> pool sliders separate them.  A pool slider inside a span goes through
  !> the step like a resting active slider (v = acc = 0: du_t = du, v_t =
  !> 0, acc_t = 0) but never crosses there: its ws%thr is +inf (the pool is
  !> tested through the gap minima, as before), so the spans change no
  !> state, no crossing, no bit of any event.  (Padding the spans to a
  !> multiple of the vector width, to skip the loops' remainders, was
  !> measured slower.)
  subroutine merge_spans(ws)
    type(workspace), intent(inout) :: ws
    integer(ip) :: r, lo, hi

    ws%n_spans = 0
    do r = 1, ws%n_runs
      lo = ws%run_lo(r)
      hi = ws%run_hi(r)
      if (ws%n_spans > 0) then
        if (lo - ws%span_hi(ws%n_spans) - 1 <= span_gap) then
          lo = ws%span_lo(ws%n_spans)
          ws%n_spans = ws%n_spans - 1
        end if
      end if
      ws%n_spans = ws%n_spans + 1
      ws%span_lo(ws%n_spans) = lo
      ws%span_hi(ws%n_spans) = hi
    end do
  end subroutine merge_spans

  !> Appends the maximal runs of active sliders within lo..hi to ws%run_lo,
  !> ws%run_hi (the sliders just outside lo..hi are not active).
  subroutine scan_runs(ws, lo, hi)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: lo, hi
    integer(ip) :: i

    i = lo
    do while (i <= hi)
      if (ws%active(i)) then
        ws%n_runs = ws%n_runs + 1
        ws%run_lo(ws%n_runs) = i
        do while (i < hi)
          if (.not. ws%active(i + 1)) exit
          i = i + 1
        end do
        ws%run_hi(ws%n_runs) = i
      end if
      i = i + 1
    end do
  end subroutine scan_runs

  !> Minima of gap_plus and gap_minus over the pool (+inf if it is empty),
  !> and where they are (0 if empty).  Without coupling (`pool` false) the
  !> pool's forces never change and it is left out: +inf, no O(n) scan.
  subroutine far_minima(ws, n, pool)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n
    logical, intent(in) :: pool
    integer(ip) :: i

    ws%min_plus = ieee_value(ws%min_plus, ieee_positive_inf)
    ws%min_minus = ws%min_plus
    ws%arg_plus = 0
    ws%arg_minus = 0
    ws%stale = .false.
    if (.not. pool) return
    do i = 1, n
      if (ws%active(i)) cycle
      if (ws%arg_plus == 0 .or. ws%gap_plus(i) < ws%min_plus) then
        ws%min_plus = ws%gap_plus(i)
        ws%arg_plus = i
      end if
      if (ws%arg_minus == 0 .or. ws%gap_minus(i) < ws%min_minus) then
        ws%min_minus = ws%gap_minus(i)
        ws%arg_minus = i
      end if
    end do
    ws%stale = .false.
  end subroutine far_minima

  !> After a completed event: exact sum of du, elastic forces and instability
  !> angles of the sliders whose force changed (the involved ones with xi = 0,
  !> all with xi > 0), and the workspace back to its between-events state.
  subroutine end_event(p, ws, e0, mu, du)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), contiguous, intent(in) :: du(:)
    integer(ip) :: k, i, n
    real(dp) :: mean

    n = p%chain%n
    if (p%chain%xi /= 0.0_dp) ws%sum_du = total_displacement(du)   ! the mean matters
    mean = ws%sum_du/real(n, dp)
    ! with xi = 0 only the involved sliders' forces changed: the tilt loop
    ! checks them, in increasing order (with xi > 0 it checks every slider)
    if (p%chain%xi == 0.0_dp) then
      ws%n_changed = 0
      do i = ws%i_lo, ws%i_hi
        if (ws%involved(i)) then
          ws%n_changed = ws%n_changed + 1
          ws%changed(ws%n_changed) = i
        end if
      end do
    end if
    !GCC$ novector
    do k = 1, ws%ni             ! only the involved sliders can have a new mu
      call cache_trig(ws, mu, ws%ilist(k))
    end do
    if (p%chain%xi == 0.0_dp) then
      do k = 1, ws%ni
        i = ws%ilist(k)
        ws%elastic(i) = elastic_force(p%chain, e0, du, i, mean)
        call roots_from(ws%elastic(i), ws%radius(i), ws%phi(i), ws%root_down(i), &
                        ws%root_up(i))
        call tree_update(ws, i)
      end do
    else      ! the angles: coupled_next, where they matter
      do i = 1, n
        ws%elastic(i) = elastic_force(p%chain, e0, du, i, mean)
      end do
    end if
    do k = 1, ws%ni
      i = ws%ilist(k)
      ws%involved(i) = .false.
      ws%moved(i) = .false.
      ws%redrawn(i) = .false.
      ws%du_start(i) = du(i)
      ws%du_t(i) = du(i)
      ws%v(i) = 0.0_dp
      ws%v_t(i) = 0.0_dp
      ws%acc(i) = 0.0_dp
      ws%acc_t(i) = 0.0_dp
    end do
    ws%ni = 0
    ws%n_runs = 0
    ws%n_spans = 0
  end subroutine end_event

  ! ------------------------------------------------ next-instability tree

  !> The min-tree over min(root_down, root_up) (xi = 0: between events only
  !> the involved sliders' angles change).  Node k has children 2k and
  !> 2k + 1; slider i is leaf leaves + i - 1; padding leaves are +inf.
  subroutine tree_build(ws, n)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n
    integer(ip) :: k

    ws%tree = ieee_value(1.0_dp, ieee_positive_inf)
    do k = 1, n
      ws%tree(ws%leaves + k - 1) = min(ws%root_down(k), ws%root_up(k))
    end do
    do k = ws%leaves - 1, 1, -1
      ws%tree(k) = min(ws%tree(2*k), ws%tree(2*k + 1))
    end do
  end subroutine tree_build

  !> Slider i's angle changed: its leaf and the path to the root, O(log n).
  subroutine tree_update(ws, i)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: i
    integer(ip) :: k

    k = ws%leaves + i - 1
    ws%tree(k) = min(ws%root_down(i), ws%root_up(i))
    do while (k > 1)
      k = k/2
      ws%tree(k) = min(ws%tree(2*k), ws%tree(2*k + 1))
    end do
  end subroutine tree_update

  !> next_instability from the tree: the same angle, max(min root, alpha),
  !> and the same triggers in increasing order (a left-to-right descent into
  !> the subtrees whose minimum is within tie_tol), O((1 + ties) log n).
  subroutine tree_next(ws, alpha, angle, n_trig)
    type(workspace), intent(inout) :: ws
    real(dp), intent(in) :: alpha
    real(dp), intent(out) :: angle
    integer(ip), intent(out) :: n_trig
    integer(ip) :: stack(64), top, k, i
    real(dp) :: limit

    angle = max(ws%tree(1), alpha)
    n_trig = 0
    if (.not. angle <= huge(1.0_dp)) return     ! no root in [0, pi/2]
    limit = angle + tie_tol
    top = 1
    stack(1) = 1
    do while (top > 0)
      k = stack(top)
      top = top - 1
      if (.not. ws%tree(k) <= limit) cycle
      if (k >= ws%leaves) then
        i = k - ws%leaves + 1
        n_trig = n_trig + 1
        ws%slist(n_trig) = i
        if (ws%root_down(i) <= ws%root_up(i)) then
          ws%sdir(n_trig) = 1.0_dp
        else
          ws%sdir(n_trig) = -1.0_dp
        end if
      else
        stack(top + 1) = 2*k + 1      ! right below left: left is visited first
        stack(top + 2) = 2*k
        top = top + 2
      end if
    end do
  end subroutine tree_next

  !> The loading's per-slider root terms of slider i into the cache
  !> (sliders_loading.tilt_root_cache; its callers' loops are novector).
  subroutine cache_trig(ws, mu, i)
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: mu(:)
    integer(ip), intent(in) :: i

    call tilt_root_cache(mu(i), ws%radius(i), ws%phi(i))
  end subroutine cache_trig

  !> An event that ends the run in error: du, mu and the stop counts back to
  !> the event start, so that the state is the one before the event (a run
  !> continued from it with a larger cap repeats the event exactly).
  subroutine abort_event(ws, du, mu, n_stops)
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    integer(ip) :: k, i

    do k = 1, ws%ni
      i = ws%ilist(k)
      du(i) = ws%du_start(i)
      if (ws%redrawn(i)) then
        mu(i) = ws%mu_start(i)
        n_stops(i) = ws%stops_start(i)
        ws%redrawn(i) = .false.
      end if
    end do
  end subroutine abort_event

end module sliders_events
