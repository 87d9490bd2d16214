!> A step that crossed, cut back to its first crossing by bisection.
!>
!> In the event loop (sliders_events, run_event): when quiet_steps
!> (sliders_steps) returns a full step of dt whose trial crosses,
!> refine_crossing halves the step until the bracket [lo, hi] is within
!> refine_tol and returns hi, the shortest step found to cross; run_event
!> takes and accepts that step (sliders_steps), then applies the stops and
!> starts.
!>
!> The bisection's trials test only the sliders that crossed in the full
!> step (sliders_steps, crossing_candidates; and their neighbours'
!> positions; with xi > 0 the mean through a rigorous enclosure,
!> sliders_coupling_mean, exactly only when the enclosure leaves the test
!> open): a crossing costs two full trials plus O(crossers) per bisection
!> trial, not O(active) per trial (which would make a crossing's cost
!> quadratic in the number of moving sliders for the large late events).
!> The bisection is bounded by max_halvings (status_refine_limit).
module sliders_crossing
  use sliders_kinds, only: dp, ip
  use sliders_workspace, only: tilt_params, workspace
  use sliders_steps, only: step_spans, predict_neighbours, predict_sum_runs, &
                           crossing_candidates, pool_crosses
  use sliders_coupling_mean, only: enclosure_sums, mean_sums, enclosed_trial
  implicit none
  private

  public :: refine_crossing
  public :: max_halvings

  !> A crossing's bracket is halved at most this often (reference.MAX_HALVINGS):
  !> a step of 1 tau closes to 3e-39 within it, so only a refine_tol below
  !> what the step can resolve reaches it (status_refine_limit, never a hang).
  integer(ip), parameter :: max_halvings = 128

contains

  !> The crossing step from the state, whose full trial of p%dt (its sum of
  !> du - du_start dsum_t) crossed, cut back to its first crossing: the
  !> bracket [0, dt] is halved until within p%refine_tol (each trial
  !> candidate_trial), and h is its upper end.  `resolved` false:
  !> max_halvings were not enough (refine_tol below what the step can
  !> resolve).  The trial arrays are left with the last bisection trial's
  !> candidates (run_event's trial_step of size h then writes every span).
  subroutine refine_crossing(p, ws, e0, sum0, mean0, sin_a, friction, dsum_t, h, resolved)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), intent(in) :: sum0, mean0, sin_a, friction, dsum_t
    real(dp), intent(out) :: h
    logical, intent(out) :: resolved
    type(enclosure_sums) :: sums
    integer(ip) :: n_cand, halvings
    real(dp) :: lo, hi, mid, xi
    logical :: pool_crossed, crossed

    xi = p%chain%xi
    resolved = .false.
    h = p%dt
    call crossing_candidates(ws, sum0 + dsum_t, mean0, xi, p%chain%n, n_cand, pool_crossed)
    if (xi /= 0.0_dp) call mean_sums(ws, sums)
    lo = 0.0_dp
    hi = h
    halvings = 0
    do while (hi - lo > p%refine_tol)
      if (halvings == max_halvings) return
      halvings = halvings + 1
      mid = 0.5_dp*(lo + hi)
      call candidate_trial(p, ws, sums, e0, ws%du, mid, sum0, mean0, sin_a, friction, n_cand, &
                           pool_crossed, crossed)
      if (crossed) then
        hi = mid
      else
        lo = mid
      end if
    end do
    h = hi
    resolved = .true.
  end subroutine refine_crossing

  !> The crossing test of trial_step restricted to the candidates (and the
  !> pool if pool_crossed): the same operations on the same numbers, so each
  !> candidate's excess is bit-identical to the full trial's.  With xi = 0
  !> only the candidates and their neighbours are predicted; with xi > 0 the
  !> mean needs every active slider's trial position.
  subroutine candidate_trial(p, ws, sums, e0, du, h, sum0, mean0, sin_a, friction, n_cand, &
                             pool_crossed, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    type(enclosure_sums), intent(in) :: sums
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp), intent(in) :: h, sum0, mean0, sin_a, friction
    integer(ip), intent(in) :: n_cand
    logical, intent(in) :: pool_crossed
    logical, intent(out) :: crossed
    real(dp) :: mean_t, shift, excess, dsum_t
    logical :: decided

    call predict_neighbours(p%chain%n, n_cand, ws%cand, h, du, ws%v, ws%acc, ws%du_t)
    mean_t = mean0
    shift = 0.0_dp
    if (p%chain%xi /= 0.0_dp) then
      ! almost always the crossing test is the same for every mean in a
      ! rigorous enclosure of the trial mean, got in O(1): then the exact
      ! mean (O(active)) is not needed
      call enclosed_trial(p, ws, sums, e0, h, sum0, mean0, sin_a, friction, n_cand, &
                          pool_crossed, decided, crossed)
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

end module sliders_crossing
