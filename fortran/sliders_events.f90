!> The quasi-static loading: next-instability drives, one rearrangement, the
!> loading loop.
!>
!> The loading (sliders_loading) gives the drive's terms: the tilt's sin/cos
!> alpha, or for the pushed end sin/cos of the fixed incline plus the driver's
!> spring on slider 1 (sliders_chain's tangential_force, used wherever a
!> slider's tangential force is formed: between events, at an event's start,
!> for the pool, and for slider 1 in end_sliders).  "drive" below is the drive
!> lambda: the tilt's angle, or the driver's position.
!>
!> This is src/sliders/engine/reference.py (the specification) reorganised so that
!> the cost follows what moves ("integrate only what moves").  This module
!> holds the loop; each part of it is a module of its own, in the order the
!> loop meets them:
!>
!>   tilt_run (here; begin_run sets up the call): per event,
!>     unstable_sliders (here): the stability check at the current drive,
!>     else next_drive (here): the drive of the next event, from
!>       sliders_next_angle (coupled_next for xi > 0, else the min-tree
!>       tree_next), unless the loading gives it in closed form
!>       (sliders_loading's loading_next_drive: the pushed end);
!>     run_event (here): one rearrangement at fixed drive, begin_event then
!>       the steps:
!>       sliders_active_set (the moving sliders and their neighbours as runs
!>         and spans, the resting others as a pool tested through two gap
!>         minima; starts, stops, the runs' update after a crossing),
!>       sliders_steps (velocity-Verlet steps over the spans and their
!>         crossing test; the steps between two crossings in one call,
!>         quiet_steps),
!>       sliders_crossing (a step that crossed, cut back by bisection),
!>         with sliders_coupling_mean (xi > 0: the trial mean's enclosure);
!>       after_crossing (here): stop_crossers (the stops and their redraws,
!>         sliders_friction), start_crossers, release_idle;
!>       record_event (here): the event's energies and moved sliders;
!>     record_row (here): the event's row of the buffers;
!>     end_event (here): the caches after an event (forces, angles, sum).
!>   The steps named "(here)" are private, so that gcc inlines them.
!>   sliders_workspace holds the parameters, the work arrays and the event
!>   record that they all share.
!> The modules are compiled with link-time optimisation (meson.build), so
!> that the per-crossing calls between them are inlined as within one file.
!>
!> * The sum of du is kept incrementally during an event (recomputed exactly
!>   between events).  A pool slider crossing is a start like any other (it
!>   enters the bisection predicate).  A slider already beyond its
!>   threshold at the start of an event is caught the same way.
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
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
  use sliders_kinds, only: dp, ip, i8
  use sliders_status, only: status_running, status_avalanche, status_alpha_max, &
                            status_event_duration_cap, status_non_finite, &
                            status_random_failure, status_relaxed, status_sparse_full, &
                            status_interrupted, status_refine_limit, status_sliding
  use sliders_chain, only: elastic_force, tangential_force, total_displacement, &
                           spring_energy_change, cantilever_energy_change
  use sliders_contract, only: ev_drive, ev_duration, ev_work_gravity, ev_elastic_change, &
                              ev_dissipation, ev_n_moved, ev_n_stops, ev_n_steps, ev_slider_steps
  use sliders_friction, only: static_threshold, kinetic_force, draw_at_stop
  use sliders_loading, only: drive_terms, loading_work, loading_runaway, beyond_limit, &
                             spanning_ends_run, loading_next_drive, roots_from
  use sliders_workspace, only: tilt_params, workspace, event_record, allocate_workspace, &
                               unpack_params, interrupt_check_steps, detail_none, &
                               detail_resting, detail_state
  use sliders_next_angle, only: coupled_next, tree_build, tree_update, tree_next, cache_trig
  use sliders_active_set, only: start_slider, stop_slider, deactivate, find_runs, update_runs, &
                                far_minima, find_changes
  use sliders_steps, only: quiet_steps, trial_step, swap_state, count_step, pool_crosses
  use sliders_crossing, only: refine_crossing, max_halvings
  implicit none
  private

  public :: tilt_params, tilt_run, unpack_params
  public :: max_halvings, interrupt_check_steps
  public :: detail_none, detail_resting, detail_state

contains

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
  !> counts, and the drive back to the last completed event), the completed
  !> events are kept.
  !>
  !> Per event: the stability check at the current drive (unstable_sliders),
  !> else the drive of the next event (next_drive); the event (run_event);
  !> its row (record_row); the caches for the next check (end_event).
  subroutine tilt_run(params, e0, t0, w0, mu, n_stops, du, drive, ev_real, ev_int, &
                      sp_ptr, sp_index, sp_value, n_events, n_sparse, status, &
                      alpha_c, event_time, final_work, detail, interrupt)
    type(tilt_params), intent(in) :: params
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), intent(inout) :: drive
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
    integer(ip) :: n, n_trig, n_bad
    real(dp) :: angle, drive_done

    p = params
    n = p%chain%n
    call begin_run(p, ws, e0, mu, du)
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
      call unstable_sliders(p, ws, mu, du, drive, n_trig, n_bad)
      if (n_bad > 0) then
        status = status_non_finite
        detail = detail_resting
        exit
      end if
      angle = drive
      if (n_trig == 0) then
        if (p%relax_only) then
          status = status_relaxed
          exit
        end if
        if (n_events >= p%max_events) then
          status = status_running
          exit
        end if
        call next_drive(p, ws, mu, du, drive, angle, n_trig)
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
      drive_done = drive
      drive = angle
      p%chain%driver_position = drive

      call run_event(p, ws, e0, t0, w0, mu, n_stops, du, drive, n_trig, interrupt, rec)
      if (rec%status == status_interrupted) then
        ! undone entirely: the state after the last completed event
        status = status_interrupted
        drive = drive_done
        exit
      end if
      if (rec%status /= status_running) then
        status = rec%status
        detail = rec%detail
        event_time = rec%duration
        final_work = [rec%n_steps, rec%slider_steps]
        if (status == status_avalanche) alpha_c = drive
        exit
      end if

      n_events = n_events + 1
      call record_row(p, ws, du, drive, rec, n_events, ev_real, ev_int, sp_ptr, sp_index, &
                      sp_value, n_sparse)
      call end_event(p, ws, e0, mu, du)
      if (spanning_ends_run(p%loading) .and. .not. p%relax_only .and. rec%n_moved == n) then
        status = status_sliding       ! the onset drive is the last event's
        exit
      end if
    end do
  end subroutine tilt_run

  !> The workspace of a call: the state's displacements, every slider's
  !> elastic force and trigonometric cache, with xi = 0 the instability
  !> angles in their min-tree; the first stability check covers every slider.
  subroutine begin_run(p, ws, e0, mu, du)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), contiguous, intent(in) :: du(:)
    integer(ip) :: n, i

    n = p%chain%n
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
    if (p%chain%xi == 0.0_dp) then     ! xi > 0: coupled_next computes the angles it needs
      call roots_from(ws%elastic, ws%radius, ws%phi, ws%root_down, ws%root_up)
      call tree_build(ws, n)
    end if
    ! with xi = 0 the later checks cover only the sliders of the last event
    ! (end_event: no other force changed)
    ws%n_changed = n
    do i = 1, n
      ws%changed(i) = i
    end do
  end subroutine begin_run

  !> The stability check at the drive over the sliders whose force may
  !> have changed (ws%changed): the n_trig unstable ones go to ws%slist with
  !> their directions in ws%sdir; n_bad counts the non-finite elastic forces.
  !> Also puts the pushed end's driver at alpha.
  subroutine unstable_sliders(p, ws, mu, du, drive, n_trig, n_bad)
    type(tilt_params), intent(inout) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: drive
    integer(ip), intent(out) :: n_trig, n_bad
    integer(ip) :: k, i
    real(dp) :: sin_a, cos_a, f

    call drive_terms(p%loading, drive, sin_a, cos_a)
    p%chain%driver_position = drive
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
  end subroutine unstable_sliders

  !> The drive `angle` at which the next event starts from a stable chain at
  !> alpha, and its n_trig triggers in ws%slist / ws%sdir: the loading's own,
  !> in closed form (sliders_loading, loading_next_drive: the pushed end's
  !> slider 1, the only one that feels the driver), else the smallest
  !> instability angle: the coupled chain's bounded search, or the min-tree.
  subroutine next_drive(p, ws, mu, du, drive, angle, n_trig)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: drive
    real(dp), intent(out) :: angle
    integer(ip), intent(out) :: n_trig
    logical :: closed_form

    call loading_next_drive(p%loading, ws%elastic(1), mu(1), du(1), drive, p%force_tol, &
                            closed_form, angle, ws%slist(1), ws%sdir(1))
    if (closed_form) then
      n_trig = 1
    else if (p%chain%xi /= 0.0_dp) then
      call coupled_next(ws, p%chain%n, drive, angle, n_trig)
    else
      call tree_next(ws, drive, angle, n_trig)
    end if
  end subroutine next_drive

  !> Row n_events of the event buffers: the event's record and, with
  !> record_sparse, its moved sliders (0-based) and their displacements.
  subroutine record_row(p, ws, du, drive, rec, n_events, ev_real, ev_int, sp_ptr, sp_index, &
                        sp_value, n_sparse)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(in) :: ws
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: drive
    type(event_record), intent(in) :: rec
    integer(ip), intent(in) :: n_events
    real(dp), intent(inout) :: ev_real(:, :)
    integer(i8), intent(inout) :: ev_int(:, :)
    integer(i8), contiguous, intent(inout) :: sp_ptr(:)
    integer(i8), contiguous, intent(inout) :: sp_index(:)
    real(dp), contiguous, intent(inout) :: sp_value(:)
    integer(ip), intent(inout) :: n_sparse
    integer(ip) :: j, i

    ev_real(n_events, ev_drive) = drive
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
  end subroutine record_row

  ! ------------------------------------------------------------ one event

  !> One rearrangement at a fixed drive, started by the n_trig sliders in
  !> ws%slist with directions ws%sdir (reference.NumpyEngine._event).
  !> On a normal end du holds the new displacements and ws%sorted the moved
  !> sliders; on an error du, mu and n_stops are restored to the event start
  !> (as in the reference); on an avalanche du is the state at detection.
  !>
  !> Steps of dt are accepted in quiet_steps (sliders_steps) until one
  !> crosses (its trial is left unaccepted) or a check is due; a crossing
  !> step is cut back to the first crossing by bisection (sliders_crossing:
  !> it tests only the sliders that crossed in the full step, and the pool if
  !> it did: O(crossers) per trial, not O(active)), then taken, accepted, and
  !> its stops and starts applied (after_crossing).
  subroutine run_event(p, ws, e0, t0, w0, mu, n_stops, du, drive, n_trig, interrupt, rec)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), intent(in) :: drive
    integer(ip), intent(in) :: n_trig
    integer(ip), volatile, intent(inout) :: interrupt(:)   ! only read
    type(event_record), intent(out) :: rec
    integer(i8) :: unchecked_steps
    real(dp) :: sin_a, cos_a, friction, sum0, mean0, t, h, dsum_t
    logical :: crossed, resolved, draws_ok

    call drive_terms(p%loading, drive, sin_a, cos_a)
    friction = kinetic_force(p%friction, cos_a)
    sum0 = ws%sum_du
    mean0 = sum0/real(p%chain%n, dp)
    call begin_event(p, ws, mu, sin_a, cos_a, friction, n_trig)

    t = 0.0_dp
    ws%path = 0.0_dp
    ws%dsum = 0.0_dp
    rec = event_record()
    unchecked_steps = 0
    do while (ws%m > 0)
      call quiet_steps(p, ws, e0, sum0, mean0, sin_a, friction, t, rec, unchecked_steps, &
                       dsum_t, crossed)
      if (crossed) then
        call refine_crossing(p, ws, e0, sum0, mean0, sin_a, friction, dsum_t, h, resolved)
        if (.not. resolved) then    ! refine_tol below the step's resolution
          call fail_event(ws, du, mu, n_stops, status_refine_limit, t, rec)
          return
        end if
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

      ! NaN or infinity: checked before anything else can happen (a crossing,
      ! the duration cap), and every 1024 steps; in between nothing but du
      ! and v (restored on abort) changes, so this is the reference's check
      ! at every step.
      if (crossed .or. t > p%max_event_duration .or. iand(rec%n_steps, 1023_i8) == 0) then
        if (.not. all_finite(ws, ws%du)) then
          rec%detail = detail_state
          call fail_event(ws, du, mu, n_stops, status_non_finite, t, rec)
          return
        end if
      end if

      if (crossed) then
        call after_crossing(p, ws, e0, mu, n_stops, sum0, mean0, sin_a, cos_a, friction, &
                            draws_ok, rec)
        if (.not. draws_ok) then
          call fail_event(ws, du, mu, n_stops, status_random_failure, t, rec)
          return
        end if
      end if

      if (t > p%max_event_duration) then
        call fail_event(ws, du, mu, n_stops, status_event_duration_cap, t, rec)
        return
      end if
      if (loading_runaway(p%loading, p%chain%walls, p%chain%n, ws%m, ws%n_down, sin_a, &
                          friction)) then
        rec%status = status_avalanche
        rec%duration = t
        call store_displacements(ws, du)
        return
      end if
    end do
    call store_displacements(ws, du)
    call record_event(p, ws, t0, w0, du, drive, sin_a, friction, mean0, t, rec)
  end subroutine run_event

  !> The event's start at fixed drive: the triggers start and, with their
  !> neighbours, form the runs; their forces and accelerations; the pool's
  !> gap minima.
  !>
  !> With xi > 0, thresholds and every slider's gaps to them at event start
  !> (O(n)): all resting sliders start in the pool, so one already beyond
  !> its threshold is found by the first step's check, as in the reference.
  !> With xi = 0 no pool force ever changes and none is beyond its threshold
  !> (the tilt loop started every such slider), so only the active sliders
  !> need a threshold, set when they become active.
  subroutine begin_event(p, ws, mu, sin_a, cos_a, friction, n_trig)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), intent(in) :: sin_a, cos_a, friction
    integer(ip), intent(in) :: n_trig
    integer(ip) :: n, i, k, r
    real(dp) :: f, thr

    n = p%chain%n
    ws%cos_a = cos_a
    ws%force_tol = p%force_tol
    if (p%chain%xi /= 0.0_dp) then
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
    call far_minima(ws, n, p%chain%xi /= 0.0_dp)
  end subroutine begin_event

  !> A crossing step taken: the stops (rest, count, redraw), then the starts
  !> (nothing else changes state), then the sliders left with no moving
  !> neighbour back to the pool.  draws_ok false: a redraw failed, the event
  !> is to be undone.
  subroutine after_crossing(p, ws, e0, mu, n_stops, sum0, mean0, sin_a, cos_a, friction, &
                            draws_ok, rec)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), intent(in) :: sum0, mean0, sin_a, cos_a, friction
    logical, intent(out) :: draws_ok
    type(event_record), intent(inout) :: rec
    integer(ip) :: n_stop, n_start
    real(dp) :: mean, shift

    mean = (sum0 + ws%dsum)/real(p%chain%n, dp)
    shift = 0.0_dp
    if (p%chain%xi /= 0.0_dp) shift = p%chain%xi*(mean - mean0)
    call stop_crossers(p, ws, mu, n_stops, cos_a, n_stop, draws_ok, rec)
    if (.not. draws_ok) return
    call start_crossers(p, ws, e0, mu, sin_a, friction, mean, shift, n_start)
    call release_idle(ws, p%chain%n, n_stop, n_start, shift, p%chain%xi /= 0.0_dp)
  end subroutine after_crossing

  !> The sliders that stopped in the step (ws%stops(1:n_stop)) come to rest,
  !> count a stop and draw a new static coefficient (keyed by the 0-based
  !> slider number); the event-start draw is kept for an abort.  The new
  !> coefficients are applied only if every draw succeeded (draws_ok).
  subroutine stop_crossers(p, ws, mu, n_stops, cos_a, n_stop, draws_ok, rec)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    real(dp), intent(in) :: cos_a
    integer(ip), intent(out) :: n_stop
    logical, intent(out) :: draws_ok
    type(event_record), intent(inout) :: rec
    integer(ip) :: k, i, draw_status

    draws_ok = .true.
    call find_changes(ws, .true., ws%stops, n_stop)
    if (n_stop == 0) return
    rec%n_stops = rec%n_stops + n_stop
    do k = 1, n_stop
      i = ws%stops(k)
      call stop_slider(ws, i, p%chain%n, ws%du)
      if (.not. ws%redrawn(i)) then
        ws%redrawn(i) = .true.
        ws%mu_start(i) = mu(i)
        ws%stops_start(i) = n_stops(i)
      end if
      n_stops(i) = n_stops(i) + 1
      ws%mu_new(k) = draw_at_stop(p%friction, p%seed, int(i - 1, i8), n_stops(i), draw_status)
      if (draw_status /= 0) draws_ok = .false.
    end do
    if (.not. draws_ok) return
    do k = 1, n_stop
      i = ws%stops(k)
      mu(i) = ws%mu_new(k)
      ws%thr(i) = static_threshold(mu(i), cos_a, p%force_tol)
    end do
  end subroutine stop_crossers

  !> Every resting slider beyond its threshold now starts: the neighbours of
  !> the moving ones (find_changes) and, rarely, a pool slider whose gap the
  !> coupling's shift closed (found in O(n)).
  subroutine start_crossers(p, ws, e0, mu, sin_a, friction, mean, shift, n_start)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: mu(:)
    real(dp), intent(in) :: sin_a, friction, mean, shift
    integer(ip), intent(out) :: n_start
    integer(ip) :: k, i

    call find_changes(ws, .false., ws%slist, n_start)
    do k = 1, n_start
      ws%sdir(k) = sign(1.0_dp, ws%f_t(ws%slist(k)))
    end do
    if (pool_crosses(ws, shift)) then
      do i = 1, p%chain%n
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
      call start_slider(ws, i, ws%sdir(k), p%chain%n, ws%du, mu)
      ws%acc(i) = ws%f_t(i) - friction*ws%dir(i)
    end do
  end subroutine start_crossers

  !> The neighbours of the n_stop stopped sliders left with no moving
  !> neighbour go back to the pool; the runs are updated if anything
  !> started or left, and the pool's gap minima if one of them went stale.
  subroutine release_idle(ws, n, n_stop, n_start, shift, coupled)
    type(workspace), intent(inout) :: ws
    integer(ip), intent(in) :: n, n_stop, n_start
    real(dp), intent(in) :: shift
    logical, intent(in) :: coupled
    integer(ip) :: k, i, j
    logical :: changed

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
    if (ws%stale) call far_minima(ws, n, coupled)
  end subroutine release_idle

  !> The event is over: its moved sliders (ws%sorted, increasing), duration,
  !> the loading's work, the elastic energy change (local, exact) and the
  !> dissipation (friction times the path length).
  subroutine record_event(p, ws, t0, w0, du, drive, sin_a, friction, mean0, t, rec)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: drive, sin_a, friction, mean0, t
    type(event_record), intent(inout) :: rec
    integer(ip) :: n_moved, i, k
    real(dp) :: step

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
    rec%work_gravity = loading_work(p%loading, sin_a, step, drive, du(1) - ws%du_start(1), &
                                    ws%du_start(1))
    rec%elastic_change = &
      spring_energy_change(p%chain, t0, ws%du_start, du, ws%sorted(1:n_moved)) + &
      cantilever_energy_change(p%chain, w0, ws%du_start, du, ws%sorted(1:n_moved), mean0)
    rec%dissipation = friction*ws%path
  end subroutine record_event

  !> An event ended in error with `status` after time t: the state back to
  !> the event start (abort_event).
  subroutine fail_event(ws, du, mu, n_stops, status, t, rec)
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(inout) :: du(:)
    real(dp), contiguous, intent(inout) :: mu(:)
    integer(i8), contiguous, intent(inout) :: n_stops(:)
    integer(ip), intent(in) :: status
    real(dp), intent(in) :: t
    type(event_record), intent(inout) :: rec

    rec%status = status
    rec%duration = t
    call abort_event(ws, du, mu, n_stops)
  end subroutine fail_event

  !> Whether du and v of every active slider are finite (a count of the
  !> others: an integer sum vectorises, a chain of .and. does not).
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

  ! ------------------------------------------------------- between events

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

end module sliders_events
