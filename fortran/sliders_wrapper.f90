! The f2py-facing layer of the sliders kernel (compiled into sliders._kernel).
!
! Plain subroutines outside any module, so that f2py sees only simple
! signatures: explicit-shape arrays and iso_c_binding kinds.  The work is done
! in the modules (sliders_random, ...); nothing here but argument plumbing.

! ---------------------------------------------------------------- random ----

subroutine random_uniform(n, seed, slider, count, draw, out)
  use iso_c_binding, only: c_double, c_int, c_int64_t
  use sliders_random, only: uniform
  implicit none
  integer(c_int), intent(in) :: n
  !f2py integer(c_int) intent(hide), depend(slider) :: n = len(slider)
  integer(c_int64_t), intent(in) :: seed
  integer(c_int64_t), intent(in) :: slider(n), count(n), draw(n)
  real(c_double), intent(out) :: out(n)

  out = uniform(seed, slider, count, draw)
end subroutine random_uniform

subroutine random_static_coefficient(n, seed, slider, count, mu_s_mean, &
                                     sigma_mu, mu_d, out, status)
  use iso_c_binding, only: c_double, c_int, c_int64_t
  use sliders_random, only: draw_static_coefficient
  implicit none
  integer(c_int), intent(in) :: n
  !f2py integer(c_int) intent(hide), depend(slider) :: n = len(slider)
  integer(c_int64_t), intent(in) :: seed
  integer(c_int64_t), intent(in) :: slider(n), count(n)
  real(c_double), intent(in) :: mu_s_mean, sigma_mu, mu_d
  real(c_double), intent(out) :: out(n)
  integer(c_int), intent(out) :: status
  integer(c_int) :: flags(n)

  call draw_static_coefficient(seed, slider, count, mu_s_mean, sigma_mu, &
                               mu_d, out, flags)
  status = 0
  if (n > 0) status = maxval(flags)
end subroutine random_static_coefficient
