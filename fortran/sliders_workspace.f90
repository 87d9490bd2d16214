!> What the event loop works on: the scene's parameters (tilt_params), the
!> work arrays of one tilt_run call (workspace) and what one event produced
!> (event_record).
!>
!> Shared by the modules of the event loop (sliders_events, which holds the
!> loop and says in which order the others come); only allocate_workspace
!> sizes the arrays, once per call.  Each field's comment says what it holds
!> and when; the state between two events is stated on the workspace type.
module sliders_workspace
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_positive_inf
  use sliders_kinds, only: dp, ip, i8
  use sliders_status, only: status_running
  use sliders_chain, only: chain_params
  use sliders_loading, only: loading_params, unpack_loading, driver_stiffness
  use sliders_friction, only: coulomb_friction, unpack_friction
  use sliders_contract, only: par_xi, par_dt, par_refine_tol, par_max_event_duration, &
                              par_force_tol, par_walls, par_seed, par_record_sparse, &
                              par_relax_only, par_max_events
  implicit none
  private

  public :: tilt_params, workspace, event_record
  public :: allocate_workspace, unpack_params
  public :: interrupt_check_steps
  public :: detail_none, detail_resting, detail_state

  !> The interrupt flag is read after this many slider-steps (~0.3 ms) and
  !> before every event.
  integer(i8), parameter :: interrupt_check_steps = 100000_i8

  !> What a non-finite status refers to (for the message).
  integer(ip), parameter :: detail_none = 0, detail_resting = 1, detail_state = 2

  !> Everything of the scene the kernel uses.  No defaults: every field is
  !> set from the packed parameters (contract.py, from the scene's defaults).
  type :: tilt_params
    type(chain_params) :: chain
    type(loading_params) :: loading   !< the drive lambda and its end
    type(coulomb_friction) :: friction   !< the friction law's parameters
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

  !> The parameters of a chain of n sliders from the packed arrays of a
  !> kernel call (positions: sliders_contract); the friction law and the
  !> loading read their own (sliders_friction, sliders_loading), and the
  !> loading says which driver it ties to the chain.
  function unpack_params(n, real_params, int_params) result(p)
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: real_params(:)
    integer(i8), intent(in) :: int_params(:)
    type(tilt_params) :: p

    p%chain%n = n
    p%chain%walls = int_params(par_walls) /= 0
    p%chain%xi = real_params(par_xi)
    p%friction = unpack_friction(real_params)
    p%seed = int_params(par_seed)
    p%dt = real_params(par_dt)
    p%refine_tol = real_params(par_refine_tol)
    p%max_event_duration = real_params(par_max_event_duration)
    p%loading = unpack_loading(real_params, int_params)
    p%chain%driver_stiffness = driver_stiffness(p%loading)
    p%force_tol = real_params(par_force_tol)
    p%record_sparse = int_params(par_record_sparse) /= 0
    p%relax_only = int_params(par_relax_only) /= 0
    p%max_events = int(int_params(par_max_events), ip)
  end function unpack_params

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
    ws%thr = ieee_value(1.0_dp, ieee_positive_inf)     ! the pool's (see sliders_active_set, merge_spans)
    ws%active = .false.
    ws%involved = .false.
    ws%moved = .false.
    ws%redrawn = .false.
    ws%nmov = 0
  end subroutine allocate_workspace

end module sliders_workspace
