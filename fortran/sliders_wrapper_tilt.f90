! The f2py-facing tilt routine of the sliders kernel (compiled into
! sliders._kernel together with sliders_wrapper.f90).
!
! A plain subroutine outside any module: explicit-shape arrays and
! iso_c_binding kinds only.  The work is done in module sliders_events;
! src/sliders/fortran_engine.py is the Python side.
!
! tilt_advance runs rearrangements from the state (mu_s, n_stops and
! displacement are updated in place, the new angle is alpha_out) until
! max_events are recorded (status 0), the run ends (status codes of
! sliders_status / status.py) or a buffer is full (status 8, call again).
! Buffers, n_cap events: event_real columns alpha, duration, work_gravity,
! elastic_change, dissipation; event_int columns n_moved, n_stops, n_steps,
! slider_steps; CSR sparse_ptr(1:n_events+1) (0-based offsets) into
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

subroutine tilt_advance(n, n_cap, n_sparse_cap, walls, xi, mu_d, mu_s_mean, sigma_mu, &
                        seed, dt, refine_tol, max_event_duration, alpha_max, force_tol, &
                        record_sparse, relax_only, max_events, &
                        elastic_force0, spring_extension0, cantilever_stretch0, &
                        mu_s, n_stops, displacement, alpha, &
                        event_real, event_int, sparse_ptr, sparse_index, sparse_value, &
                        alpha_out, n_events, n_sparse, status, alpha_c, event_time, &
                        final_steps, final_slider_steps, detail, interrupt)
  use iso_c_binding, only: c_double, c_int, c_int64_t
  use sliders_events, only: tilt_params, tilt_run
  implicit none
  integer(c_int), intent(in) :: n
  !f2py threadsafe
  !f2py integer(c_int) intent(hide), depend(elastic_force0) :: n = len(elastic_force0)
  integer(c_int), intent(in) :: n_cap
  !f2py integer(c_int) intent(hide), depend(event_real) :: n_cap = shape(event_real, 0)
  integer(c_int), intent(in) :: n_sparse_cap
  !f2py integer(c_int) intent(hide), depend(sparse_index) :: n_sparse_cap = len(sparse_index)
  integer(c_int), intent(in) :: walls, record_sparse, relax_only, max_events
  real(c_double), intent(in) :: xi, mu_d, mu_s_mean, sigma_mu
  integer(c_int64_t), intent(in) :: seed
  real(c_double), intent(in) :: dt, refine_tol, max_event_duration, alpha_max, force_tol
  real(c_double), intent(in) :: elastic_force0(n), spring_extension0(n + 1)
  real(c_double), intent(in) :: cantilever_stretch0(n)
  real(c_double), intent(inout) :: mu_s(n)
  integer(c_int64_t), intent(inout) :: n_stops(n)
  real(c_double), intent(inout) :: displacement(n)
  real(c_double), intent(in) :: alpha
  real(c_double), intent(inout) :: event_real(n_cap, 5)
  integer(c_int64_t), intent(inout) :: event_int(n_cap, 4)
  integer(c_int64_t), intent(inout) :: sparse_ptr(n_cap + 1)
  integer(c_int64_t), intent(inout) :: sparse_index(n_sparse_cap)
  real(c_double), intent(inout) :: sparse_value(n_sparse_cap)
  real(c_double), intent(out) :: alpha_out, alpha_c, event_time
  integer(c_int64_t), intent(out) :: final_steps, final_slider_steps
  integer(c_int), intent(out) :: n_events, n_sparse, status, detail
  integer(c_int), intent(inout) :: interrupt(1)
  type(tilt_params) :: p
  integer(c_int64_t) :: final_work(2)

  p%chain%n = n
  p%chain%walls = walls /= 0
  p%chain%xi = xi
  p%mu_d = mu_d
  p%mu_s_mean = mu_s_mean
  p%sigma_mu = sigma_mu
  p%seed = seed
  p%dt = dt
  p%refine_tol = refine_tol
  p%max_event_duration = max_event_duration
  p%alpha_max = alpha_max
  p%force_tol = force_tol
  p%record_sparse = record_sparse /= 0
  p%relax_only = relax_only /= 0
  p%max_events = max_events
  alpha_out = alpha
  call tilt_run(p, elastic_force0, spring_extension0, cantilever_stretch0, mu_s, n_stops, &
                displacement, alpha_out, event_real, event_int, sparse_ptr, sparse_index, &
                sparse_value, n_events, n_sparse, status, alpha_c, event_time, final_work, &
                detail, interrupt)
  final_steps = final_work(1)
  final_slider_steps = final_work(2)
end subroutine tilt_advance
