!> The integration steps of an event: one velocity-Verlet trial step over
!> the spans of active sliders with its crossing test, and the run of quiet
!> steps between two crossings.
!>
!> In the event loop (sliders_events, run_event) every step is taken here:
!> quiet_steps takes steps of dt, each accepted at once, until one crosses
!> (a mover's velocity turns against its direction, a resting active slider
!> passes its threshold, or the pool's shift passes a gap minimum) or a
!> check of run_event is due.  A crossing step is then cut back by
!> sliders_crossing, whose trials are step_spans on the sliders that
!> crossed in the full step (crossing_candidates) alone, and taken and
!> accepted with trial_step, swap_state and count_step.
!>
!> Per span a step is two branch-free loops over contiguous memory
!> (vectorised): predict (and, per run, the mean's sums when xi > 0), then
!> force + velocity + crossing test (step_spans, one call for all spans).
!> A resting slider has v = acc = 0, so the Verlet update leaves it in
!> place.  The steps between two crossings are taken in one call
!> (quiet_steps), the trial and state arrays (ws%du, v, acc and their trial
!> twins; both agree outside the spans) swapping roles from step to step;
!> the caller's du is written at the end of the event.  The sum of du is
!> kept incrementally during an event (ws%dsum).  Same operations in the
!> same order as the reference (forces, Verlet update, crossing tests), so
!> both round alike.
module sliders_steps
  use sliders_kinds, only: dp, ip, i8
  use sliders_chain, only: chain_params, elastic_force, tangential_force
  use sliders_workspace, only: tilt_params, workspace, event_record, interrupt_check_steps
  implicit none
  private

  public :: quiet_steps, trial_step, swap_state, count_step
  public :: step_spans, predict_neighbours, predict_sum_runs
  public :: crossing_candidates, pool_crosses

  !> quiet_steps stores the forces (which only a crossing reads) in its first
  !> this many steps: a crossing that comes later pays one trial again, less
  !> than the stores it saved (about 5 % of a trial each).
  integer(ip), parameter :: keep_forces_steps = 32

contains

  ! ------------------------------------------------ steps between crossings

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

  ! ---------------------------------------------------------- one trial step

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

  !> Velocity-Verlet positions du_t = du + v h + acc h**2/2 of the sliders
  !> cand(1:n_cand) and their neighbours (a bisection trial's candidates:
  !> sliders_crossing, candidate_trial).
  pure subroutine predict_neighbours(n, n_cand, cand, h, du, v, acc, du_t)
    integer(ip), intent(in) :: n, n_cand
    integer(ip), contiguous, intent(in) :: cand(:)
    real(dp), intent(in) :: h
    real(dp), contiguous, intent(in) :: du(:), v(:), acc(:)
    real(dp), contiguous, intent(inout) :: du_t(:)
    integer(ip) :: k, i

    do k = 1, n_cand
      do i = max(cand(k) - 1, 1_ip), min(cand(k) + 1, n)
        du_t(i) = verlet_position(du(i), v(i), acc(i), h)
      end do
    end do
  end subroutine predict_neighbours

  !> Velocity-Verlet positions (verlet_position) over every run, fused with
  !> dsum = dsum + the sum of du_t - du (xi > 0: the mean moves), run after
  !> run.  Four partial sums per
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
  !> predicts: merge_spans (sliders_active_set) leaves at least span_gap + 1
  !> pool sliders between spans, and candidate_trial (sliders_crossing: one
  !> span per candidate) predicts every candidate's neighbours first.
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

  ! ------------------------------------------------- the crossing test

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

  ! ------------------------------------------------- one slider's update

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

end module sliders_steps
