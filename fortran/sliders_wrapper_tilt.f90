! The f2py-facing tilt routine of the sliders kernel (compiled into
! sliders._kernel together with sliders_wrapper.f90).
!
! A plain subroutine outside any module: explicit-shape arrays and
! iso_c_binding kinds only.  The work is done in module sliders_events;
! src/sliders/engine/fortran_engine.py is the Python side, src/sliders/engine/contract.py
! the declaration of the packed arrays (positions in sliders_contract).
!
! A packed boundary (in the manner of pymsis): the scene's values and the
! call's options in two parameter arrays (real_params, int_params), the
! prepared chain in one array chain0 = [E0 (n), w0 (n), T0 (n + 1)], then the
! state and the buffers.  unpack_params (sliders_workspace) reads the two
! parameter arrays, once their widths are checked here.
!
! tilt_advance runs rearrangements from the state (mu_s, n_stops and
! displacement are updated in place, the new drive is drive_out) until
! max_events are recorded (status 0), the run ends (status codes of
! sliders_status / status.py) or a buffer is full (status 8, call again);
! status -1: the packed widths are not those of sliders_contract.
! Buffers, n_cap events: event_real and event_int columns as
! contract.EVENT_SCHEMA; CSR sparse_ptr(1:n_events+1) (0-based offsets) into
! sparse_index (0-based slider numbers, increasing) and sparse_value
! (displacement of the event), all zero with record_sparse = 0.  event_time,
! final_steps and final_slider_steps describe the event that ended the run
! unfinished (avalanche, cap, error; zero otherwise); detail tells what a
! non-finite status refers to (1: the resting chain, 2: the moving state).
!
! The call releases the GIL (threadsafe), so that Python can run it in a
! worker thread and stay responsive to Ctrl-C: setting interrupt(1) /= 0 from
! the main thread ends the call with status 9 (interrupted) within ~1e5
! slider-steps, the event in progress undone (fortran_engine.py).

subroutine tilt_advance(n, n_cap, n_sparse_cap, n_real, n_int, n_real_cols, n_int_cols, real_params, int_params, chain0, &
                        mu_s, n_stops, displacement, &
                        event_real, event_int, sparse_ptr, sparse_index, sparse_value, &
                        interrupt, &
                        drive_out, n_events, n_sparse, status, alpha_c, event_time, &
                        final_steps, final_slider_steps, detail)
  use iso_c_binding, only: c_double, c_int, c_int64_t
  use sliders_contract, only: n_real_params, n_int_params, n_event_real, n_event_int, par_drive
  use sliders_events, only: tilt_params, tilt_run, unpack_params
  implicit none
  integer(c_int), intent(in) :: n
  !f2py threadsafe
  !f2py integer(c_int) intent(hide), depend(mu_s) :: n = len(mu_s)
  integer(c_int), intent(in) :: n_cap
  !f2py integer(c_int) intent(hide), depend(event_real) :: n_cap = shape(event_real, 0)
  integer(c_int), intent(in) :: n_sparse_cap
  !f2py integer(c_int) intent(hide), depend(sparse_index) :: n_sparse_cap = len(sparse_index)
  ! the packed widths: given by the arrays (f2py cannot read sliders_contract),
  ! checked against the contract below
  integer(c_int), intent(in) :: n_real, n_int, n_real_cols, n_int_cols
  !f2py integer(c_int) intent(hide), depend(real_params) :: n_real = len(real_params)
  !f2py integer(c_int) intent(hide), depend(int_params) :: n_int = len(int_params)
  !f2py integer(c_int) intent(hide), depend(event_real) :: n_real_cols = shape(event_real, 1)
  !f2py integer(c_int) intent(hide), depend(event_int) :: n_int_cols = shape(event_int, 1)
  real(c_double), intent(in) :: real_params(n_real)
  integer(c_int64_t), intent(in) :: int_params(n_int)
  real(c_double), intent(in) :: chain0(3*n + 1)
  real(c_double), intent(inout) :: mu_s(n)
  integer(c_int64_t), intent(inout) :: n_stops(n)
  real(c_double), intent(inout) :: displacement(n)
  real(c_double), intent(inout) :: event_real(n_cap, n_real_cols)
  integer(c_int64_t), intent(inout) :: event_int(n_cap, n_int_cols)
  integer(c_int64_t), intent(inout) :: sparse_ptr(n_cap + 1)
  integer(c_int64_t), intent(inout) :: sparse_index(n_sparse_cap)
  real(c_double), intent(inout) :: sparse_value(n_sparse_cap)
  integer(c_int), intent(inout) :: interrupt(1)
  real(c_double), intent(out) :: drive_out, alpha_c, event_time
  integer(c_int64_t), intent(out) :: final_steps, final_slider_steps
  integer(c_int), intent(out) :: n_events, n_sparse, status, detail
  type(tilt_params) :: p
  integer(c_int), parameter :: contract_mismatch = -1
  integer(c_int64_t) :: final_work(2)

  if (n_real /= n_real_params .or. n_int /= n_int_params .or. &
      n_real_cols /= n_event_real .or. n_int_cols /= n_event_int) then
    status = contract_mismatch       ! contract.py and sliders_contract disagree
    drive_out = 0.0_c_double
    alpha_c = 0.0_c_double
    event_time = 0.0_c_double
    final_steps = 0
    final_slider_steps = 0
    n_events = 0
    n_sparse = 0
    detail = 0
    return
  end if
  p = unpack_params(n, real_params, int_params)
  drive_out = real_params(par_drive)
  call tilt_run(p, chain0(1:n), chain0(2*n + 1:3*n + 1), chain0(n + 1:2*n), mu_s, n_stops, &
                displacement, drive_out, event_real, event_int, sparse_ptr, sparse_index, &
                sparse_value, n_events, n_sparse, status, alpha_c, event_time, final_work, &
                detail, interrupt)
  final_steps = final_work(1)
  final_slider_steps = final_work(2)
end subroutine tilt_advance
