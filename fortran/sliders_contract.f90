!> The engine contract on the kernel's side (src/sliders/engine/contract.py is the
!> one declaration; tests/test_contract.py checks these numbers against it).
!>
!> * Columns of the per-event buffers: contract.EVENT_SCHEMA split by type,
!>   in its order.
!> * The loading protocols' codes (contract.LOADING_CODES).
!> * Positions in the two packed parameter arrays of a kernel call
!>   (contract.REAL_PARAMETERS, contract.INT_PARAMETERS).  Their values, and
!>   so every default, come from the scene (scene.py): the kernel has none.
module sliders_contract
  use sliders_kinds, only: ip
  implicit none
  private

  public :: n_event_real, n_event_int
  public :: ev_drive, ev_duration, ev_work_gravity, ev_elastic_change, ev_dissipation
  public :: ev_n_moved, ev_n_stops, ev_n_steps, ev_slider_steps
  public :: n_real_params, n_int_params
  public :: par_xi, par_mu_d, par_mu_s_mean, par_sigma_mu, par_dt, par_refine_tol, &
            par_max_event_duration, par_alpha_max, par_force_tol, par_drive
  public :: par_incline, par_driver_stiffness, par_drive_max
  public :: par_walls, par_seed, par_record_sparse, par_relax_only, par_max_events, par_loading
  public :: loading_tilt, loading_pushed_end

  !> Columns of the per-event buffers.
  integer(ip), parameter :: n_event_real = 5, n_event_int = 4
  integer(ip), parameter :: ev_drive = 1, ev_duration = 2, ev_work_gravity = 3, &
                            ev_elastic_change = 4, ev_dissipation = 5
  integer(ip), parameter :: ev_n_moved = 1, ev_n_stops = 2, ev_n_steps = 3, &
                            ev_slider_steps = 4

  !> Positions in the real parameter array.
  integer(ip), parameter :: n_real_params = 13
  integer(ip), parameter :: par_xi = 1, par_mu_d = 2, par_mu_s_mean = 3, par_sigma_mu = 4, &
                            par_dt = 5, par_refine_tol = 6, par_max_event_duration = 7, &
                            par_alpha_max = 8, par_force_tol = 9, par_drive = 10, &
                            par_incline = 11, par_driver_stiffness = 12, par_drive_max = 13
  !> Positions in the integer parameter array.
  integer(ip), parameter :: n_int_params = 6
  integer(ip), parameter :: par_walls = 1, par_seed = 2, par_record_sparse = 3, &
                            par_relax_only = 4, par_max_events = 5, par_loading = 6

  !> Loading protocols (contract.LOADING_CODES), the value of par_loading.
  integer(ip), parameter :: loading_tilt = 0, loading_pushed_end = 1

end module sliders_contract
