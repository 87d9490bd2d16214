!> The coupling's mean (xi > 0) in the crossing bisection: the crossing test
!> decided from a rigorous enclosure of the trial mean, without the exact
!> mean when the enclosure leaves no doubt.
!>
!> With xi > 0 every force holds xi (du_i - mean(du)), so the exact crossing
!> test of a bisection trial needs every active slider's trial position
!> (O(active)), although the trial moves only the few crossing candidates'
!> tests.  In the event loop (sliders_events, run_event -> sliders_crossing,
!> refine_crossing) a crossing step first takes mean_sums (O(active), once);
!> each bisection trial (candidate_trial) then asks enclosed_trial, O(1) in
!> the active sliders plus O(candidates), and computes the exact mean only
!> when the enclosure leaves the test open (rare).  The result is the exact
!> test's, bit for bit.
module sliders_coupling_mean
  use sliders_kinds, only: dp, ip
  use sliders_workspace, only: tilt_params, workspace
  use sliders_steps, only: step_spans
  implicit none
  private

  public :: enclosure_sums, mean_sums, enclosed_trial

  !> Sums over the active sliders at the start of a crossing step: v, acc,
  !> |du|, |v|, |acc|, and how many sliders.
  type :: enclosure_sums
    real(dp) :: sum_v = 0.0_dp, sum_acc = 0.0_dp
    real(dp) :: abs_du = 0.0_dp, abs_v = 0.0_dp, abs_acc = 0.0_dp
    integer(ip) :: n_active = 0
  end type enclosure_sums

contains

  !> The sums over the active sliders that enclosed_trial needs (once per
  !> crossing step, at its start, from the accepted state).
  subroutine mean_sums(ws, sums)
    type(workspace), intent(in) :: ws
    type(enclosure_sums), intent(out) :: sums
    integer(ip) :: r, i

    sums%sum_v = 0.0_dp
    sums%sum_acc = 0.0_dp
    sums%abs_du = 0.0_dp
    sums%abs_v = 0.0_dp
    sums%abs_acc = 0.0_dp
    sums%n_active = 0
    do r = 1, ws%n_runs
      sums%n_active = sums%n_active + (ws%run_hi(r) - ws%run_lo(r) + 1)
      do i = ws%run_lo(r), ws%run_hi(r)
        sums%sum_v = sums%sum_v + ws%v(i)
        sums%sum_acc = sums%sum_acc + ws%acc(i)
        sums%abs_v = sums%abs_v + abs(ws%v(i))
        sums%abs_acc = sums%abs_acc + abs(ws%acc(i))
        sums%abs_du = sums%abs_du + abs(ws%du(i))
      end do
    end do
  end subroutine mean_sums

  !> The bisection's crossing test when xi > 0, without the exact trial mean
  !> when possible.  The trial mean the exact test uses, fl(fl(sum0 +
  !> dsum_t)/n), has dsum_t = dsum + the sum of the active sliders' rounded
  !> increments fl(fl(du + fl(v h + 0.5 acc h h)) - du), summed in four
  !> lanes; it differs from dsum + h sum(v) + h**2/2 sum(acc) by at most
  !> u [2 sum|du| + 4 (m + 4 runs + 8)(h sum|v| + h**2 sum|acc| + |dsum|)]
  !> (u = 2**-53, m active sliders: the rounding of each increment and of the
  !> sums; the sums are `sums`, from mean_sums), taken twice here.  Every floating-point operation of the test is
  !> monotone in the mean (rounding is monotone): a mover's excess lies
  !> between its values at the enclosure's ends, a resting slider's |F| -
  !> thr is largest at an end and monotone if F keeps its sign, and so are
  !> the pool's two tests.  `decided`: the test is the same over the whole
  !> enclosure, and `crossed` is its result, the exact test's bit for bit.
  subroutine enclosed_trial(p, ws, sums, e0, h, sum0, mean0, sin_a, friction, n_cand, &
                            pool_crossed, decided, crossed)
    type(tilt_params), intent(in) :: p
    type(workspace), intent(inout) :: ws
    type(enclosure_sums), intent(in) :: sums
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
    dsum_a = ws%dsum + (h*sums%sum_v + 0.5_dp*h*h*sums%sum_acc)
    err = 2.0_dp*u*(2.0_dp*sums%abs_du + 4.0_dp*real(sums%n_active + 4*ws%n_runs + 8, dp) &
                    *(h*sums%abs_v + h*h*sums%abs_acc + abs(ws%dsum)) + abs(dsum_a)) + tiny(1.0_dp)
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

end module sliders_coupling_mean
