!> Between events: the drive at which the next event starts, and the
!> sliders that start it.
!>
!> In the event loop (sliders_events, tilt_run) this is asked when no slider
!> is beyond its threshold at the current drive; run_event then starts the
!> triggers it returns (ws%slist, directions in ws%sdir).  A loading whose
!> next drive is in closed form (the pushed end: only slider 1 feels the
!> driver) gives it instead (sliders_loading's loading_next_drive).
!>
!> The instability angle of every slider is cached (ws%root_down,
!> ws%root_up).  With xi = 0 only the involved sliders of the last event
!> have their elastic force and angle recomputed (sliders_events,
!> end_event), and the next angle comes from a min-tree (tree_next, O(log N)
!> per changed slider); the stability check after an event covers the
!> involved sliders only, and the pool needs no thresholds (its forces never
!> change), so an event costs O(involved log N), not O(N).  With xi > 0
!> every elastic force shifts in every event, so every angle changes:
!> coupled_next bounds them all without asin and computes the exact angles
!> of the few that can be the next (hypot(1, mu) and atan(mu) are cached by
!> cache_trig, renewed only for the involved sliders, whose mu may change).
module sliders_next_angle
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_positive_inf
  use sliders_kinds, only: dp, ip
  use sliders_loading, only: tilt_root_cache, roots_from, root_lower_bounds, tie_tol
  use sliders_workspace, only: workspace
  implicit none
  private

  public :: coupled_next
  public :: tree_build, tree_update, tree_next
  public :: cache_trig

contains

  ! ------------------------------------------------------ coupled (xi > 0)

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

  ! ------------------------------------------------------------ the cache

  !> The loading's per-slider root terms of slider i into the cache
  !> (sliders_loading.tilt_root_cache; its callers' loops are novector).
  subroutine cache_trig(ws, mu, i)
    type(workspace), intent(inout) :: ws
    real(dp), contiguous, intent(in) :: mu(:)
    integer(ip), intent(in) :: i

    call tilt_root_cache(mu(i), ws%radius(i), ws%phi(i))
  end subroutine cache_trig

end module sliders_next_angle
