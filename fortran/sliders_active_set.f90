!> Which sliders an event integrates: the moving ones and their neighbours
!> (the active sliders), kept as runs and spans, and the resting rest (the
!> pool), tested through two gap minima.
!>
!> In the event loop (sliders_events, run_event): the triggers are started
!> (start_slider) and the runs found (find_runs) at the start of an event;
!> after each crossing step find_changes gives the stops and starts,
!> stop_slider / start_slider apply them, a resting slider left with no
!> moving neighbour goes back to the pool (deactivate), and the runs are
!> updated from the old ones (update_runs).  The steps (sliders_steps) read
!> only the spans, directions and thresholds set here.
!>
!> * Per integration step only the active sliders have their force computed
!>   and their threshold checked; they are kept as runs of consecutive
!>   sliders, merged into spans across short gaps of pool sliders (which
!>   ride along with threshold +inf), so that a step is, per span, two
!>   branch-free loops over contiguous memory.  The involved sliders (every
!>   slider active at some point of the event) are remembered for the
!>   bookkeeping at the end of the event.
!> * Every other slider (resting, not active: the pool) has a fixed force
!>   when xi = 0; when xi > 0 they all feel the same shift
!>   s = xi (mean(du) - mean at event start).  The pool is tested through two
!>   scalars, the minima over it of  gap+ = thr - (F - s)  and
!>   gap- = thr + (F - s)  (thr = mu cos(a) + force_tol, F and s taken when
!>   the slider joined the pool): a pool slider crosses when s > gap+ or
!>   -s > gap-.  A minimum is rescanned (far_minima, O(N), rare: at most
!>   twice per start) only when its slider leaves the pool.
!> * After a crossing the runs are updated from the old runs and the starts
!>   (update_runs), not rescanned over the event's whole range.
module sliders_active_set
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_positive_inf
  use sliders_kinds, only: dp, ip
  use sliders_friction, only: static_threshold
  use sliders_workspace, only: workspace
  implicit none
  private

  public :: start_slider, stop_slider, deactivate
  public :: find_runs, update_runs, far_minima
  public :: find_changes

  !> Runs separated by at most this many pool sliders are integrated as one
  !> span (one loop): a pool slider inside a loop costs less than a loop's
  !> start and end (measured: benchmarks/kernel_speed.py).
  integer(ip), parameter :: span_gap = 16

contains

  ! ------------------------------------------------ moving, active, pool

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

  ! -------------------------------------------------------- runs, spans

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
  !> tested through the gap minima, inside a span as outside), so the spans
  !> change no state, no crossing, no bit of any event.  (Padding the spans
  !> to a multiple of the vector width, to skip the loops' remainders, is
  !> slower: measured.)
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

  ! ---------------------------------------------------------------- pool

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

end module sliders_active_set
